"""Linear-system assembly (SPEC §6.1) and the mapping matrix (§4.5)."""

import numba
import numpy as np
import pytest
from scipy import signal, sparse

from mgelens.convolve import Convolver
from mgelens.grid import pixel_centres
from mgelens.inversion.system import (
    DenseTerms,
    TilePlan,
    WeightedBlurredMapping,
    curvature_matrix,
    data_vector,
    weighted_gram,
)
from mgelens.source.mapping import SourceWeights, mapping_matrix


def random_weights(rng, n_pixels, n_source, sub=2, per_row=3):
    rows = []
    for _ in range(n_pixels * sub * sub):
        chosen = rng.choice(n_source, size=per_row, replace=False)
        w = rng.random(per_row)
        rows.append((chosen, w / w.sum()))
    indptr = np.concatenate([[0], np.cumsum([len(c) for c, _ in rows])])
    indices = np.concatenate([c for c, _ in rows])
    values = np.concatenate([w for _, w in rows])
    return SourceWeights(indptr, indices, values, sub, n_source), rows


def test_mapping_matrix_averages_sub_pixel_weights():
    rng = np.random.default_rng(6)
    weights, rows = random_weights(rng, 40, 9)
    f = mapping_matrix(weights).toarray()
    assert np.allclose(f.sum(axis=1), 1.0)
    expected = np.zeros((40, 9))
    for s, (c, w) in enumerate(rows):
        expected[s // 4, c] += w / 4
    assert np.allclose(f, expected)


def gaussian_kernel(shape, sigma_y, sigma_x):
    y, x = np.mgrid[: shape[0], : shape[1]] - np.array(shape)[:, None, None] // 2
    return np.exp(-0.5 * ((x / sigma_x) ** 2 + (y / sigma_y) ** 2))


@pytest.mark.parametrize("tile_size", [1, 3, 8])
@pytest.mark.parametrize("kernel", ["random", "random_7x7", "gaussian", "two_gaussians"])
def test_curvature_and_data_vector_equal_dense_products(tile_size, kernel):
    """Rows of G built by direct summation or by the stencil route (full-rank kernels:
    5×3 takes the stencil for tiles of 1 and 3, direct summation for 8; 7×7 always the
    stencil) or by row and column passes (one or two separable terms) give the same
    F = Mᵀ W M as dense products."""
    rng = np.random.default_rng(4)
    x, y = pixel_centres((23, 21), 0.1)
    mask = np.hypot(x - 0.1, y) > 0.95
    n_pixels = np.count_nonzero(~mask)
    psf = {
        "random": rng.random((5, 3)),
        "random_7x7": rng.random((7, 7)),
        "gaussian": gaussian_kernel((7, 5), 1.3, 0.9),
        "two_gaussians": gaussian_kernel((9, 9), 1.0, 1.0)
        + 0.2 * gaussian_kernel((9, 9), 2.5, 1.5),
    }[kernel]
    psf /= psf.sum()
    convolver = Convolver(mask, psf)
    weights, _ = random_weights(rng, n_pixels, 30)
    f = mapping_matrix(weights)
    # the blurred mapping matrix column by column, as SPEC §1.4 defines it
    blurred = np.empty((n_pixels, 30))
    for j in range(30):
        native = np.zeros(mask.shape)
        native[~mask] = f[:, j].toarray().ravel()
        blurred[:, j] = signal.convolve2d(native, psf, mode="same")[~mask]
    dense = rng.normal(size=(n_pixels, 4))
    inverse_variance = rng.uniform(0.5, 2.0, n_pixels)
    data = rng.normal(size=n_pixels)
    full = np.hstack([dense, blurred])
    plan = TilePlan.from_mask(mask, psf, tile_size)
    ranks = {"random": 0, "random_7x7": 0, "gaussian": 1, "two_gaussians": 2}
    assert plan.psf_u.shape[0] == ranks[kernel]
    assert plan.stencil == (kernel == "random_7x7" or (kernel == "random" and tile_size < 8))
    operator = convolver.operator(include_blurring=False)
    curvature = curvature_matrix(dense, f, plan, inverse_variance)
    expected = full.T @ (inverse_variance[:, None] * full)
    assert np.allclose(curvature, expected, rtol=1e-12, atol=1e-12)
    assert np.allclose(curvature, curvature.T)
    d = data_vector(dense, f, operator, inverse_variance, data)
    assert np.allclose(d, full.T @ (inverse_variance * data))
    known = operator.T @ (inverse_variance * data)  # Bᵀ W d, as a dataset caches it
    assert np.array_equal(data_vector(dense, f, None, inverse_variance, data, known), d)
    terms = DenseTerms.build(dense, inverse_variance, convolver)
    assert np.allclose(terms.products, operator.T @ (inverse_variance[:, None] * dense))
    cached = curvature_matrix(dense, f, plan, inverse_variance, dense_terms=terms)
    assert np.allclose(cached, expected, rtol=1e-12, atol=1e-12)
    weighted_blurred = WeightedBlurredMapping.build(operator @ f, inverse_variance)
    f_ls = expected[:4, 4:]
    assert np.allclose(weighted_blurred.lens_source(dense), f_ls, rtol=1e-12, atol=1e-12)
    threads = numba.get_num_threads()
    try:  # threads that take the source pixels in parts give the same
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        split = weighted_blurred.lens_source(dense)
    finally:
        numba.set_num_threads(threads)
    assert np.allclose(split, f_ls, rtol=1e-12, atol=1e-12)
    assert np.allclose(terms.lens_source(f), f_ls, rtol=1e-12, atol=1e-12)
    no_light = curvature_matrix(np.zeros((n_pixels, 0)), f, plan, inverse_variance)
    assert np.allclose(no_light, expected[4:, 4:], rtol=1e-12, atol=1e-12)
    only_light = curvature_matrix(dense, None, None, inverse_variance)
    assert np.allclose(only_light, expected[:4, :4])
    assert np.allclose(data_vector(dense, None, None, inverse_variance, data), d[:4])
    assert sparse.issparse(operator)


def test_weighted_gram_is_symmetric_and_takes_no_columns(capfd):
    """Lᵀ W L by syrk equals the general product; with no columns BLAS is not called (it
    prints an illegal-leading-dimension error and returns garbage)."""
    rng = np.random.default_rng(8)
    dense, w = rng.normal(size=(50, 7)), rng.uniform(0.5, 2.0, 50)
    gram = weighted_gram(dense, w)
    assert np.allclose(gram, dense.T @ (w[:, None] * dense), rtol=1e-13, atol=1e-13)
    assert np.array_equal(gram, gram.T)
    assert weighted_gram(np.zeros((50, 0)), w).shape == (0, 0)
    assert "illegal" not in capfd.readouterr().out


def block_mapping(mask, block):
    """f of an unlensed square mesh: each unmasked pixel lies in one source pixel, the
    block × block cell that holds it (a local mapping, like a real mesh's)."""
    rows, cols = np.nonzero(~mask)
    cell = (rows // block) * (mask.shape[1] // block + 1) + cols // block
    _, index = np.unique(cell, return_inverse=True)
    return sparse.csr_matrix((np.ones(rows.size), (np.arange(rows.size), index)))


def test_lens_source_terms_take_the_cheaper_of_a_sparse_pass_and_a_transposed_blur():
    """F_LS = Lᵀ W B f by one sparse pass over W B f costs nnz(B f) per column; by a
    transposed blur, the blur plus nnz(f). On a 3″ mask of 0.05″ pixels with a local
    mapping (a real mesh's kind) the pass is cheaper, for an HST-like 15×15 full-rank
    PSF and even for a 3×3 one; a mapping that sends every pixel to 3 of 30 scattered
    source pixels makes B f nearly dense and the blur (direct, 3×3) cheaper. Both routes
    give Lᵀ W B f."""
    rng = np.random.default_rng(2)
    x, y = pixel_centres((135, 135), 0.05)
    mask = np.hypot(x, y) > 3.0
    n_pixels = np.count_nonzero(~mask)
    local = block_mapping(mask, 5)
    scattered = mapping_matrix(random_weights(rng, n_pixels, 30, sub=1)[0])
    dense = rng.normal(size=(n_pixels, 3))
    inverse_variance = rng.uniform(0.5, 2.0, n_pixels)
    full_rank, small = rng.random((15, 15)), gaussian_kernel((3, 3), 1, 1)
    for psf, f, sparse_pass in (
        (full_rank, local, True),
        (small, local, True),
        (small, scattered, False),
    ):
        convolver = Convolver(mask, psf / psf.sum())
        blurred = convolver.operator(include_blurring=False) @ f
        assert WeightedBlurredMapping.cheaper(blurred, f, convolver) == sparse_pass
        expected = (blurred.T @ (inverse_variance[:, None] * dense)).T
        by_blur = DenseTerms.build(dense, inverse_variance, convolver).lens_source(f)
        by_pass = WeightedBlurredMapping.build(blurred, inverse_variance).lens_source(dense)
        assert np.allclose(by_blur, expected, rtol=1e-12, atol=1e-10)
        assert np.allclose(by_pass, expected, rtol=1e-12, atol=1e-10)

import numba
import numpy as np
import pytest
import scipy.fft
from scipy import signal

from mgelens import convolve
from mgelens.convolve import Convolver, convolve_image, separable_terms, trimmed_psf
from mgelens.grid import pixel_centres


def brute_force_convolution(image, psf):
    ky, kx = psf.shape
    out = np.zeros_like(image)
    for r in range(image.shape[0]):
        for c in range(image.shape[1]):
            total = 0.0
            for a in range(ky):
                for b in range(kx):
                    rr, cc = r - a + ky // 2, c - b + kx // 2
                    if 0 <= rr < image.shape[0] and 0 <= cc < image.shape[1]:
                        total += psf[a, b] * image[rr, cc]
            out[r, c] = total
    return out


@pytest.fixture
def asymmetric_psf():
    rng = np.random.default_rng(7)
    psf = rng.random((5, 3))
    return psf / psf.sum()


@pytest.mark.parametrize("method", ["direct", "fft", "auto"])
def test_convolve_image_equals_direct_summation(asymmetric_psf, method):
    image = np.random.default_rng(1).random((17, 12))
    expected = brute_force_convolution(image, asymmetric_psf)
    assert np.allclose(convolve_image(image, asymmetric_psf, method), expected, atol=1e-14)


def test_convolution_moves_light_the_right_way():
    psf = np.zeros((3, 3))
    psf[2, 1] = 1.0  # kernel shifts by +1 row (+y)
    image = np.zeros((5, 5))
    image[2, 2] = 1.0
    out = convolve_image(image, psf)
    assert out[3, 2] == 1.0


def fit_masks() -> dict:
    """A disc, and an annulus with a masked bar across it: rows with two separate runs of
    pixels, rows without any, holes the PSF reaches across."""
    x, y = pixel_centres((31, 29), 0.1)
    radius = np.hypot(x - 0.2, y)
    return {
        "disc": radius > 1.1,
        "annulus_with_bar": (radius > 1.3) | (radius < 0.4) | (np.abs(y - 0.5) < 0.15),
    }


@pytest.mark.parametrize("shape", ["disc", "annulus_with_bar"])
@pytest.mark.parametrize("include_blurring", [True, False])
@pytest.mark.parametrize("method", ["direct", "fft", "separable"])
def test_blur_columns_equals_masked_native_convolution(
    asymmetric_psf, include_blurring, method, shape
):
    mask = fit_masks()[shape]
    conv = Convolver(mask, asymmetric_psf)
    in_mask = conv.input_mask(include_blurring)
    rng = np.random.default_rng(2)
    columns = rng.random((np.count_nonzero(~in_mask), 4))
    out = conv.blur_columns(columns, include_blurring, method)
    for k in range(4):
        native = np.zeros(mask.shape)
        native[~in_mask] = columns[:, k]
        expected = signal.convolve2d(native, asymmetric_psf, mode="same")[~mask]
        assert np.allclose(out[:, k], expected, atol=1e-13)
    single = conv.blur_columns(columns[:, 0], include_blurring, method)
    assert np.allclose(single, out[:, 0], atol=1e-14)
    # into chosen columns of a wider array: the same columns there, the others untouched
    wide = np.zeros((out.shape[0], 7))
    wide[:, 3] = 5.0
    at = np.array([6, 0, 4, 2])
    assert conv.blur_columns(columns, include_blurring, method, out=wide, at=at) is wide
    np.testing.assert_array_equal(wide[:, at], out)
    assert np.all(wide[:, [1, 5]] == 0.0)
    assert np.all(wide[:, 3] == 5.0)


def test_transpose_blur_is_the_transpose_of_the_mask_operator(asymmetric_psf):
    """Bᵀ through the flipped kernel equals the sparse operator's transpose, for an
    asymmetric PSF (a symmetric one would not tell a missing flip)."""
    x, y = pixel_centres((31, 29), 0.1)
    mask = np.hypot(x - 0.2, y) > 1.1
    conv = Convolver(mask, asymmetric_psf)
    columns = np.random.default_rng(3).random((np.count_nonzero(~mask), 3))
    expected = conv.operator(include_blurring=False).T @ columns
    assert np.allclose(conv.transpose_blur_columns(columns), expected, atol=1e-13)
    assert not np.allclose(conv.blur_columns(columns, include_blurring=False), expected)


@pytest.mark.parametrize("threads", [1, 2])
def test_fft_blurring_runs_large_batches_on_the_jobs_threads(asymmetric_psf, monkeypatch, threads):
    """scipy.fft gets numba's thread count as its workers for a batch of at least
    PARALLEL_FFT_MIN_POINTS points and one worker below: a one-thread phase job must not
    spread its FFTs over every core (two such jobs side by side then slowed each other),
    and a small batch on two threads cost more than on one (LIGHT on an HST PSF)."""
    workers = []
    forward = scipy.fft.rfft2

    def spy(*args, **kwargs):
        workers.append(kwargs.get("workers"))
        return forward(*args, **kwargs)

    monkeypatch.setattr(scipy.fft, "rfft2", spy)
    x, y = pixel_centres((31, 29), 0.1)
    conv = Convolver(np.hypot(x, y) > 1.1, asymmetric_psf)
    columns = np.random.default_rng(4).random((np.count_nonzero(~conv.input_mask(True)), 3))
    job_threads = min(threads, numba.config.NUMBA_NUM_THREADS)
    previous = numba.get_num_threads()
    numba.set_num_threads(job_threads)
    blurred = {}
    try:
        for smallest_parallel in (1, 10**9):
            monkeypatch.setattr(convolve, "PARALLEL_FFT_MIN_POINTS", smallest_parallel)
            workers.clear()
            blurred[smallest_parallel] = conv.blur_columns(columns, True, "fft")
            data_ffts = [w for w in workers if w is not None]  # None: a kernel's FFT, once
            assert data_ffts
            assert set(data_ffts) == {job_threads if smallest_parallel == 1 else 1}
    finally:
        numba.set_num_threads(previous)
    assert np.allclose(blurred[1], blurred[10**9], rtol=0, atol=1e-14)


def gaussian_psf(size: int, sigma: float, q: float = 1.0) -> np.ndarray:
    x, y = pixel_centres((size, size), 1.0)
    psf = np.exp(-0.5 * (x**2 + (y / q) ** 2) / sigma**2)
    return psf / psf.sum()


def test_separable_terms_rebuild_the_kernel_with_the_fewest_terms(asymmetric_psf):
    u, v = separable_terms(gaussian_psf(9, 1.0, q=0.7))
    assert u.shape == (1, 9)  # an axis-aligned Gaussian is rank one
    assert v.shape == (1, 9)
    u, v = separable_terms(asymmetric_psf)
    assert u.shape == (3, 5)  # a random kernel needs every term
    assert v.shape == (3, 3)
    assert np.abs(u.T @ v - asymmetric_psf).max() <= 1e-12 * asymmetric_psf.max()
    two_widths = gaussian_psf(11, 1.0) + 0.3 * gaussian_psf(11, 2.5, q=0.8)
    u, v = separable_terms(two_widths)
    assert u.shape[0] == 2  # two axis-aligned Gaussians: two terms
    assert np.abs(u.T @ v - two_widths).max() <= 1e-12 * two_widths.max()


def test_auto_blurs_a_gaussian_psf_separably_and_a_full_rank_one_otherwise(asymmetric_psf):
    x, y = pixel_centres((61, 61), 0.05)
    mask = np.hypot(x, y) > 1.2
    gaussian = Convolver(mask, gaussian_psf(9, 1.0))
    n_in = np.count_nonzero(~gaussian.extended_mask)
    assert gaussian._method_for(True, "auto") == "separable"
    assert gaussian.column_cost(True) == 18 * n_in  # one term: a row and a column pass
    full_rank = np.random.default_rng(3).random((9, 9))
    full = Convolver(mask, full_rank / full_rank.sum())
    assert full._method_for(True, "auto") != "separable"
    assert full.column_cost(True) < 9 * 18 * n_in


def test_blurring_region_lets_outside_light_in(asymmetric_psf):
    x, y = pixel_centres((21, 21), 0.1)
    mask = np.hypot(x, y) > 0.6
    conv = Convolver(mask, asymmetric_psf)
    assert np.count_nonzero(~conv.extended_mask) > np.count_nonzero(~mask)
    values = np.where(mask[~conv.extended_mask], 1.0, 0.0)  # light only outside the mask
    assert conv.blur_columns(values, include_blurring=True).max() > 0.0


def test_bad_inputs_raise(asymmetric_psf):
    mask = np.zeros((9, 9), dtype=bool)
    with pytest.raises(ValueError, match="odd"):
        Convolver(mask, np.ones((4, 3)))
    with pytest.raises(ValueError, match="NaN"):
        convolve_image(np.ones((5, 5)), np.full((3, 3), np.nan))
    conv = Convolver(mask, asymmetric_psf)
    with pytest.raises(ValueError, match="rows"):
        conv.blur_columns(np.ones((5, 2)))
    with pytest.raises(ValueError, match="method"):
        convolve_image(np.ones((5, 5)), asymmetric_psf, method="magic")


def test_trimmed_psf_keeps_the_kernel_above_the_floor():
    yy, xx = np.mgrid[:21, :21] - 10
    psf = np.exp(-(xx**2 + yy**2) / 2.0)
    psf /= psf.sum()
    trimmed = trimmed_psf(psf, 1e-10)
    # exp(-r²/2) ≥ 1e-10 reaches r = 6.79 pixels along the axes: a 13×13 kernel
    assert trimmed.shape == (13, 13)
    assert np.array_equal(trimmed, psf[4:17, 4:17])
    assert psf.sum() - trimmed.sum() < 1e-9
    assert trimmed_psf(psf, 0.0).shape == (21, 21)
    asymmetric = np.zeros((7, 9))
    asymmetric[3, 4] = 1.0
    asymmetric[3, 5] = 1e-3
    assert trimmed_psf(asymmetric, 1e-6).shape == (1, 3)


def test_fft_frame_of_a_disc_in_its_blurring_region_needs_no_padding(asymmetric_psf):
    """Outputs sit h pixels inside the inputs' box, so a circular convolution over the box
    itself is already the linear one there (the equality test above checks the values)."""
    x, y = pixel_centres((61, 61), 0.05)
    conv = Convolver(np.hypot(x, y) > 1.2, asymmetric_psf)
    rows, cols = np.nonzero(~conv.extended_mask)
    box = (rows.max() - rows.min() + 1, cols.max() - cols.min() + 1)
    shape = conv._fft_geometries[True].shape
    assert shape == tuple(scipy.fft.next_fast_len(n, real=True) for n in box)
    rows, cols = np.nonzero(~conv.mask)  # mask-only inputs: outputs reach the box edge
    padded = conv._fft_geometries[False].shape
    assert padded[0] >= rows.max() - rows.min() + 1 + 2  # half-height of the 5×3 kernel
    assert padded[1] >= cols.max() - cols.min() + 1 + 1


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("shape", ["disc", "annulus_with_bar"])
@pytest.mark.parametrize("include_blurring", [True, False])
def test_fft_blur_of_compact_columns_equals_native_convolution(
    asymmetric_psf, include_blurring, shape, threads
):
    """Columns that are zero outside small boxes (a narrow Gaussian's) are blurred in
    windows cropped to them: boxes at the frame's corners and edges, one pixel, an all-zero
    column, and a dense one sharing the call; on one numba thread and on two."""
    mask = fit_masks()[shape]
    conv = Convolver(mask, asymmetric_psf)
    in_mask = conv.input_mask(include_blurring)
    rows, cols = np.nonzero(~in_mask)
    rng = np.random.default_rng(5)
    extremes = [0, rows.size - 1, np.argmin(cols), np.argmax(cols), rows.size // 2]
    boxes = [(rows[j], cols[j], size) for j, size in zip(extremes, (3, 5, 4, 2, 1), strict=True)]
    columns = np.zeros((rows.size, len(boxes) + 2))
    for k, (r, c, size) in enumerate(boxes):
        inside = (np.abs(rows - r) <= size // 2) & (np.abs(cols - c) <= size // 2)
        assert inside.any()
        columns[inside, k] = rng.random(inside.sum())
    columns[:, -1] = rng.random(rows.size)  # dense; column -2 stays zero
    windows = conv._fft_geometries[include_blurring].windows(columns)
    assert len(windows) > 1  # some columns did go to cropped windows
    previous = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        out = conv.blur_columns(columns, include_blurring, "fft")
    finally:
        numba.set_num_threads(previous)
    for k in range(columns.shape[1]):
        native = np.zeros(mask.shape)
        native[~in_mask] = columns[:, k]
        expected = signal.convolve2d(native, asymmetric_psf, mode="same")[~mask]
        assert np.allclose(out[:, k], expected, atol=1e-14)
    assert not out[:, -2].any()

"""Regularization matrices (SPEC §5) against their defining sums."""

import numpy as np
import pytest

from mgelens.source.interpolate import (
    cross_points,
    natural_neighbour_weights,
    nearest_cell_weights,
)
from mgelens.source.mapping import SourceWeights
from mgelens.source.mesh import VoronoiMesh
from mgelens.source.regularization import (
    JITTER,
    AdaptiveBrightness,
    AdaptiveBrightnessSplit,
    Constant,
    ConstantSplit,
    adaptive_pixel_signals,
    adaptive_weights,
    cross_difference_matrix,
)


@pytest.fixture(scope="module")
def mesh():
    rng = np.random.default_rng(8)
    r = np.sqrt(rng.random(150))
    theta = rng.random(150) * 2 * np.pi
    return VoronoiMesh.from_points(r * np.cos(theta), r * np.sin(theta))


@pytest.fixture(scope="module")
def weights(mesh):
    rng = np.random.default_rng(9)
    n_pixels, sub = 60, 2
    qx, qy = rng.uniform(-0.6, 0.6, size=(2, n_pixels * sub * sub))
    indptr, indices, values = natural_neighbour_weights(mesh, qx, qy)
    return SourceWeights(indptr, indices, values, sub, mesh.n_points)


def test_constant_penalty_is_squared_neighbour_differences(mesh):
    s = np.random.default_rng(1).normal(size=mesh.n_points)
    h = Constant(2.5).matrix(mesh, None)
    expected = 2.5**2 * sum((s[j] - s[k]) ** 2 for j, k in mesh.edges) + JITTER * s @ s
    assert s @ (h @ s) == pytest.approx(expected, rel=1e-12)
    assert abs(h - h.T).max() == 0.0


def test_adaptive_signals_and_weights(mesh, weights):
    adapt = np.linspace(0.1, 1.0, weights.n_pixels)
    signals = adaptive_pixel_signals(weights, adapt, signal_scale=0.5)
    # brute force over sub-pixels and their neighbours
    total = np.zeros(mesh.n_points)
    count = np.zeros(mesh.n_points)
    weight_sum = np.zeros(mesh.n_points)
    for s in range(weights.indptr.size - 1):
        pixel = s // 4
        for p in range(weights.indptr[s], weights.indptr[s + 1]):
            total[weights.indices[p]] += adapt[pixel] * weights.values[p]
            count[weights.indices[p]] += 1
            weight_sum[weights.indices[p]] += weights.values[p]
    expected = total / np.maximum(count, 1)
    expected = (expected / expected.max()) ** 0.5
    assert np.allclose(signals, expected, rtol=1e-12)
    weighted = np.where(weight_sum > 0, total / np.where(weight_sum > 0, weight_sum, 1), 0)
    weighted = (weighted / weighted.max()) ** 0.5
    assert np.allclose(adaptive_pixel_signals(weights, adapt, 0.5, "weighted"), weighted)
    with pytest.raises(ValueError, match="average must be one of"):
        adaptive_pixel_signals(weights, adapt, 0.5, "median")
    w = adaptive_weights(signals, 3.0, 0.5)
    assert np.allclose(w, (3.0 * signals + 0.5 * (1 - signals)) ** 2)


def test_signal_averages_agree_for_nearest_cell_mapping(mesh):
    qx, qy = np.random.default_rng(4).uniform(-0.6, 0.6, size=(2, 400))
    weights = SourceWeights(*nearest_cell_weights(mesh, qx, qy), 2, mesh.n_points)
    adapt = np.random.default_rng(5).uniform(0.1, 1.0, weights.n_pixels)
    anchor = adaptive_pixel_signals(weights, adapt, 0.7)
    assert np.array_equal(anchor, adaptive_pixel_signals(weights, adapt, 0.7, "weighted"))


def test_weighted_signals_are_continuous_as_a_sub_pixel_moves(mesh):
    """A sub-pixel moving in steps of 1e−4″ gains and loses natural neighbours at vanishing
    weight: the anchor's per-count average jumps there, the weighted average does not."""
    rng = np.random.default_rng(6)
    qx, qy = rng.uniform(-0.6, 0.6, size=(2, 4 * 60))
    adapt = rng.uniform(0.1, 1.0, 60)
    path = np.linspace(-0.3, 0.3, 6001)
    largest = {}
    for average in ("anchor", "weighted"):
        previous, steps = None, []
        for t in path:
            qx[0], qy[0] = t, 0.37 * t + 0.05
            w = SourceWeights(*natural_neighbour_weights(mesh, qx, qy), 2, mesh.n_points)
            signals = adaptive_pixel_signals(w, adapt, 1.0, average)
            if previous is not None:
                steps.append(np.abs(signals - previous).max())
            previous = signals
        largest[average] = max(steps)
    assert largest["anchor"] > 0.005  # measured 0.014
    assert largest["weighted"] < 2e-4  # measured 4e-5, the smooth change of a 1e-4 step


def test_adaptive_matrix_squares_the_weights_per_directed_pair(mesh, weights):
    adapt = np.linspace(0.1, 1.0, weights.n_pixels)
    scheme = AdaptiveBrightness(2.0, 0.3, 1.0)
    h = scheme.matrix(mesh, weights, adapt)
    w = adaptive_weights(adaptive_pixel_signals(weights, adapt, 1.0), 2.0, 0.3)
    s = np.random.default_rng(2).normal(size=mesh.n_points)
    expected = sum((w[j] ** 2 + w[k] ** 2) * (s[j] - s[k]) ** 2 for j, k in mesh.edges)
    assert s @ (h @ s) == pytest.approx(expected + JITTER * s @ s, rel=1e-12)
    with pytest.raises(ValueError, match="adapt image"):
        scheme.matrix(mesh, weights, None)


def test_split_rows_are_differences_to_cross_point_interpolation(mesh):
    b = cross_difference_matrix(mesh).toarray()
    assert b.shape == (4 * mesh.n_points, mesh.n_points)
    # constants are never penalised: every row sums to zero
    assert np.allclose(b.sum(axis=1), 0.0, atol=1e-12)
    # linear functions: b_jm · s = a · (p_j − q_jm) wherever q_jm is inside the hull
    a = np.array([0.7, -1.3])
    s = mesh.points @ a + 0.4
    cross = cross_points(mesh)
    inside = mesh.delaunay.find_simplex(cross) >= 0
    owner = np.repeat(mesh.points, 4, axis=0)
    assert np.allclose((b @ s)[inside], ((owner - cross) @ a)[inside], atol=1e-10)


def test_split_matrices_weight_each_pixel(mesh, weights):
    b = cross_difference_matrix(mesh).toarray()
    s = np.random.default_rng(3).normal(size=mesh.n_points)
    per_row = (b @ s) ** 2
    h = ConstantSplit(1.7).matrix(mesh, None)
    assert s @ (h @ s) == pytest.approx(1.7**2 * per_row.sum() + JITTER * s @ s, rel=1e-10)
    adapt = np.linspace(0.1, 1.0, weights.n_pixels)
    h_adaptive = AdaptiveBrightnessSplit(2.0, 0.3, 0.8).matrix(mesh, weights, adapt)
    w = adaptive_weights(adaptive_pixel_signals(weights, adapt, 0.8), 2.0, 0.3)
    expected = np.sum(np.repeat(w**2, 4) * per_row) + JITTER * s @ s
    assert s @ (h_adaptive @ s) == pytest.approx(expected, rel=1e-10)
    paper = ConstantSplit(1.0, offset="paper").matrix(mesh, None)
    assert abs(paper - ConstantSplit(1.0).matrix(mesh, None)).max() > 0

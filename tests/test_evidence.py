"""Tests of the log determinants and the log evidence (SPEC §7)."""

import numpy as np
import pytest
import scipy.sparse
import scipy.stats

from mgelens.inversion.cholesky import InversionError
from mgelens.inversion.evidence import (
    log_det_cholesky,
    log_det_regularization,
    log_evidence,
    log_likelihood,
    noise_normalization,
)


def random_spd(seed, n, condition):
    rng = np.random.default_rng(seed)
    V, _ = np.linalg.qr(rng.standard_normal((n, n)))
    A = (V * np.logspace(0.0, np.log10(condition), n)) @ V.T
    return 0.5 * (A + A.T)


def grid_laplacian(rows, columns):
    """Graph Laplacian of a rows × columns 4-neighbour grid (sparse)."""

    def path(m):
        return scipy.sparse.diags([np.ones(m - 1), np.ones(m - 1)], offsets=[-1, 1])

    adjacency = scipy.sparse.kronsum(path(columns), path(rows), format="csc")
    return scipy.sparse.diags(np.asarray(adjacency.sum(axis=1)).ravel()) - adjacency


def assert_logdet_matches_numpy(value, dense):
    sign, expected = np.linalg.slogdet(dense)
    assert sign == 1.0
    assert abs(value - expected) <= 1e-10 * abs(expected)


@pytest.mark.parametrize(("seed", "n", "condition"), [(0, 20, 1e2), (1, 150, 1e6), (2, 300, 1e3)])
def test_log_det_cholesky_matches_slogdet(seed, n, condition):
    A = 3.0 * random_spd(seed, n, condition)
    assert_logdet_matches_numpy(log_det_cholesky(A), A)
    assert_logdet_matches_numpy(log_det_regularization(A), A)


@pytest.mark.parametrize(
    ("rows", "columns", "coefficient", "epsilon"),
    [(5, 7, 1.0, 1e-2), (30, 50, 2.5, 1e-8), (40, 40, 0.1, 1e-3)],
)
def test_log_det_regularization_sparse_laplacian(rows, columns, coefficient, epsilon):
    n = rows * columns
    H = coefficient * grid_laplacian(rows, columns) + epsilon * scipy.sparse.identity(n)
    for matrix in (H.tocsc(), H.tocsr(), scipy.sparse.csc_array(H)):
        assert_logdet_matches_numpy(log_det_regularization(matrix), H.toarray())


def test_log_det_regularization_sparse_random_spd():
    rng = np.random.default_rng(4)
    B = scipy.sparse.random(300, 300, density=0.02, random_state=rng)
    H = (B @ B.T + 0.5 * scipy.sparse.identity(300)).tocsc()
    assert_logdet_matches_numpy(log_det_regularization(H), H.toarray())


def test_log_det_of_diagonal_matrix_by_hand():
    assert log_det_cholesky(np.diag([2.0, 3.0])) == pytest.approx(np.log(6.0), rel=1e-15)
    H = scipy.sparse.diags([2.0, 0.5, 4.0]).tocsc()
    assert log_det_regularization(H) == pytest.approx(np.log(4.0), rel=1e-15)


@pytest.mark.parametrize(
    "matrix",
    [np.diag([1.0, -1.0]), np.array([[1.0, 2.0], [2.0, 1.0]]), np.zeros((3, 3))],
)
def test_log_det_not_positive_definite_raises(matrix):
    with pytest.raises(InversionError):
        log_det_cholesky(matrix)
    with pytest.raises(InversionError):
        log_det_regularization(matrix)
    with pytest.raises(InversionError):
        log_det_regularization(scipy.sparse.csc_matrix(matrix))


def test_noise_normalization_and_log_likelihood():
    sigma = np.array([1.0, 2.0, 0.5])
    expected = np.log(2 * np.pi) + np.log(8 * np.pi) + np.log(0.5 * np.pi)
    assert noise_normalization(sigma) == pytest.approx(expected, rel=1e-15)
    assert log_likelihood(3.0, expected) == pytest.approx(-0.5 * (3.0 + expected), rel=1e-15)
    with pytest.raises(ValueError, match="positive"):
        noise_normalization(np.array([1.0, 0.0]))


def test_log_evidence_one_pixel_by_hand():
    """d = 2, σ = 1, M = 1, H = 1: s = D/(F + H) = 1, χ² = 1, sHs = 1, ln ε = −1 − ½ ln 4π."""
    value = log_evidence(
        chi_squared=1.0,
        regularization_term=1.0,
        log_det_curvature_reg=log_det_cholesky(np.array([[2.0]])),
        log_det_regularization=log_det_regularization(scipy.sparse.csc_matrix([[1.0]])),
        noise_normalization=noise_normalization(np.array([1.0])),
    )
    assert value == pytest.approx(-1.0 - 0.5 * np.log(4 * np.pi), rel=1e-15)


def test_log_evidence_is_the_gaussian_marginal_likelihood():
    """With prior s ~ N(0, H⁻¹), ln ε = ln N(d; 0, diag σ² + M H⁻¹ Mᵀ) exactly."""
    rng = np.random.default_rng(5)
    n_pixels, n_source = 12, 4
    M = rng.uniform(0.0, 1.0, (n_pixels, n_source))
    sigma = rng.uniform(0.5, 2.0, n_pixels)
    d = M @ rng.uniform(0.0, 3.0, n_source) + sigma * rng.standard_normal(n_pixels)
    H = 0.7 * grid_laplacian(2, 2).toarray() + 0.1 * np.eye(n_source)
    F = M.T @ (M / sigma[:, None] ** 2)
    s = np.linalg.solve(F + H, M.T @ (d / sigma**2))
    value = log_evidence(
        chi_squared=float(np.sum(((d - M @ s) / sigma) ** 2)),
        regularization_term=float(s @ H @ s),
        log_det_curvature_reg=log_det_cholesky(F + H),
        log_det_regularization=log_det_regularization(scipy.sparse.csc_matrix(H)),
        noise_normalization=noise_normalization(sigma),
    )
    covariance = np.diag(sigma**2) + M @ np.linalg.solve(H, M.T)
    expected = scipy.stats.multivariate_normal(np.zeros(n_pixels), covariance).logpdf(d)
    assert value == pytest.approx(expected, rel=1e-12)


def test_without_pixelization_the_evidence_is_the_likelihood():
    assert log_evidence(4.0, 0.0, 0.0, 0.0, 7.5) == log_likelihood(4.0, 7.5)

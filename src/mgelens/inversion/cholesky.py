"""Checked Cholesky factorisations and solves shared by the inversion's solves (SPEC §6.2–6.3).

The normal equations Q x = D have Q = F + H_tot symmetric positive definite (SPEC §6.1).
:mod:`mgelens.inversion.solve` (the unconstrained and the constrained solves) and
:mod:`mgelens.inversion.nnls` (the non-negative one) validate (Q, D), factorise and solve
with the functions here. Every failure (Q not positive definite, a non-finite solution)
raises :class:`InversionError`; a sampler rejects the sample (SPEC §8.4).
"""

import numpy as np
import scipy.linalg
import scipy.linalg.lapack


class InversionError(RuntimeError):
    """A linear solve of the inversion failed; the sample is to be rejected (SPEC §8.4)."""


def validated_system(Q: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Q and D as C-contiguous float64 arrays, checking that Q is square and matches D."""
    Q = np.ascontiguousarray(Q, dtype=np.float64)
    D = np.ascontiguousarray(D, dtype=np.float64)
    if Q.ndim != 2 or D.ndim != 1 or Q.shape != (D.size, D.size):
        raise ValueError(f"Q must be (n, n) and D (n,), got {Q.shape} and {D.shape}")
    return Q, D


def upper_cholesky(U: np.ndarray) -> np.ndarray:
    """U with UᵀU = the C-ordered matrix passed in, computed in place (upper triangle; the
    strict lower triangle is zeroed); :class:`InversionError` if it is not positive
    definite."""
    # U.T is Fortran-ordered: LAPACK writes L there in place, i.e. U = Lᵀ into U.
    _, info = scipy.linalg.lapack.dpotrf(U.T, lower=1, clean=1, overwrite_a=1)
    if info != 0:
        raise InversionError(f"matrix not positive definite (potrf info {info})")
    return U


def factor_log_det(U: np.ndarray) -> float:
    """ln det A = 2 Σ ln diag U of A = UᵀU (or LLᵀ) from its Cholesky factor."""
    return float(2.0 * np.sum(np.log(np.diag(U))))


def cholesky_solve(Q: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Q⁻¹D by Cholesky; :class:`InversionError` if Q is not PD or Q⁻¹D is not finite."""
    try:
        factor = scipy.linalg.cho_factor(Q, lower=True, check_finite=False)
    except np.linalg.LinAlgError as error:
        raise InversionError(f"matrix not positive definite: {error}") from error
    return finite_solution(scipy.linalg.cho_solve(factor, D, check_finite=False))


def finite_solution(x: np.ndarray) -> np.ndarray:
    """``x``, or :class:`InversionError` if a Cholesky solve gave non-finite values."""
    if not np.all(np.isfinite(x)):
        raise InversionError("Cholesky solve gave a non-finite solution")
    return x

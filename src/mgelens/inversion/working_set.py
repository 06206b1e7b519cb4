"""The non-negative solve with dense columns brought in as they are needed (SPEC §6.3).

A phase with a pixelized source solves for hundreds of lens-light Gaussians (190 with
six sets and the point set) beside the source pixels, but the non-negative solution
keeps only a few of them (6–10 on a real lens): the rest sit at zero. The full curvature
matrix still costs every column's Gram row and F_LS row, the lens-source block that
dominates LIGHT's call on a 3″ mask (docs/benchmarks.md, "The non-negative solve over a
working set").

:func:`solve_on_working_set` runs the same NNLS
(:func:`~mgelens.inversion.nnls.reconstruction_positive_only`) on a Q whose dense rows and
columns are filled only where they are needed:

1. the source block F_SS + H, and the dense unknowns of the warm start (the passive set
   the sampler passes), are filled first;
2. the NNLS runs over the filled unknowns; an unfilled dense unknown j has x_j = 0;
3. when no filled unknown may enter, the unfilled ones are checked: j satisfies the full
   problem's optimality condition when its gradient w_j = D_j − (Qx)_j = L_jᵀ W (r − m) is
   at most the NNLS's tolerance (r the data less any fixed light, m the model image of
   x): one product of the dense columns with the weighted residual, no curvature row;
4. those above it, the largest first, have their rows and columns filled and enter the
   passive set, and the NNLS goes on with the same factor.

Q is positive definite, so the constrained minimum is unique and the result is the full
solve's to rounding (``tests/test_working_set.py``). ln det of the source block, the
evidence term, is the same as the full solve's.
"""

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from mgelens.inversion.cholesky import upper_cholesky
from mgelens.inversion.nnls import reconstruction_positive_only
from mgelens.inversion.solve import LinearSolution
from mgelens.inversion.system import weighted_gram


@dataclass(frozen=True, eq=False)
class DenseSourceProblem:
    """The linear problem [dense columns L | source pixels] of one fit, in parts; a
    problem without a pixelized source (SP) leaves the source fields at their defaults.

    Attributes
    ----------
    dense : LazyBlurredColumns-like
        The blurred dense columns L (lens-light and source Gaussians): ``n_columns``,
        ``columns(indices)`` → (N_I, k) and ``transposed_product(v)`` → Lᵀv (n_dense,)
        (:class:`mgelens.light.LazyBlurredColumns`, which blurs a column only when it is
        asked for).
    inverse_variance : ndarray (N_I,)
        w_i = 1/σ_i².
    residual : ndarray (N_I,)
        r = data − fixed light.
    dense_diagonal : float
        Added to the dense block's diagonal (``FitSettings.mge_diagonal``).
    source_block : ndarray (n_s, n_s)
        F_SS + H, read only.
    source_data : ndarray (n_s,)
        The source part of D, fᵀBᵀ W r.
    lens_source : callable or None
        ``lens_source(columns)`` → F_LS (k, n_s) of dense columns (N_I, k).
    source_image : callable or None
        ``source_image(fluxes)`` → B f s (N_I,), the blurred lensed source.
    log_det_source : float or None
        ln det(F_SS + H) if known (a source held fixed across calls); else the solve
        factorises the block.
    """

    dense: object
    inverse_variance: np.ndarray
    residual: np.ndarray
    dense_diagonal: float
    source_block: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    source_data: np.ndarray = field(default_factory=lambda: np.zeros(0))
    lens_source: Callable[[np.ndarray], np.ndarray] | None = None
    source_image: Callable[[np.ndarray], np.ndarray] | None = None
    log_det_source: float | None = None

    @property
    def n_dense(self) -> int:
        return self.dense.n_columns


class _DenseColumnSupply:
    """The rows and columns of Q of the dense unknowns, filled when the NNLS needs them
    (the ``supply`` of :func:`~mgelens.inversion.nnls.reconstruction_positive_only`).
    The filled columns are kept side by side (column-major), for the cross terms of
    later ones and the model image."""

    def __init__(self, problem: DenseSourceProblem, unknown: np.ndarray):
        self.problem = problem
        self.unknown = unknown
        self.weighted_residual = problem.inverse_variance * problem.residual
        self._columns = np.empty((problem.residual.size, problem.n_dense), order="F")
        self._indices = np.empty(problem.n_dense, dtype=np.int64)
        self._n_filled = 0

    def fill(self, q: np.ndarray, columns: np.ndarray) -> None:
        """Fill Q's rows and columns of the dense ``columns`` against every filled dense
        unknown, each other and the source, and mark them filled."""
        p, k, e = self.problem, self._n_filled, columns.size
        filled = self._indices[:k]
        new = self._columns[:, k : k + e]
        new[:] = p.dense.columns(columns)
        weighted = p.inverse_variance[:, None] * new
        cross = weighted.T @ self._columns[:, :k]
        q[np.ix_(columns, filled)] = cross
        q[np.ix_(filled, columns)] = cross.T
        gram = weighted_gram(new, p.inverse_variance)
        gram[np.arange(e), np.arange(e)] += p.dense_diagonal
        q[np.ix_(columns, columns)] = gram
        if e and p.lens_source is not None:
            f_ls = p.lens_source(new)
            q[columns, p.n_dense :] = f_ls
            q[p.n_dense :, columns] = f_ls.T
        self._indices[k : k + e] = columns
        self._n_filled = k + e
        self.unknown[columns] = False

    def enter(self, q: np.ndarray, x: np.ndarray, tol: float, k: int) -> np.ndarray:
        """Up to ``k`` unfilled dense unknowns whose gradient D_j − (Qx)_j = L_jᵀ W (r − m)
        (m the model image of ``x``; x_j = 0) exceeds ``tol``, largest first, filled."""
        p = self.problem
        candidates = np.flatnonzero(self.unknown[: p.n_dense])
        if candidates.size == 0:
            return candidates
        n = self._n_filled
        model = self._columns[:, :n] @ x[self._indices[:n]]
        if p.source_image is not None:
            model += p.source_image(x[p.n_dense :])
        weighted = self.weighted_residual - p.inverse_variance * model
        gradient = p.dense.transposed_product(weighted)[candidates]
        above = np.flatnonzero(gradient > tol)
        chosen = candidates[above[np.argsort(-gradient[above], kind="stable")[:k]]]
        self.fill(q, chosen)
        return chosen


def solve_on_working_set(
    problem: DenseSourceProblem,
    passive_start: np.ndarray,
    fixed_zero: np.ndarray | None = None,
) -> LinearSolution:
    """The non-negative solution of ``problem`` over all its unknowns, with the dense
    columns' rows of Q filled only for the warm start's dense unknowns and for those the
    NNLS brings in (module docstring).

    Parameters
    ----------
    problem : DenseSourceProblem
    passive_start : ndarray of bool (n_dense + n_s,)
        Warm start of the NNLS; its dense unknowns are filled first.
    fixed_zero : ndarray of bool (n_s,), optional
        Source unknowns forced to zero (SPEC §6.3's edge pixels): never passive.

    Returns
    -------
    LinearSolution
        Over [dense | source] as :func:`~mgelens.inversion.solve.solve_linear_system`'s.

    Raises
    ------
    InversionError
        As :func:`~mgelens.inversion.nnls.reconstruction_positive_only`, or if the source
        block is not positive definite.
    """
    n_dense, n_source = problem.n_dense, problem.source_block.shape[0]
    n = n_dense + n_source
    q = np.zeros((n, n))
    q[n_dense:, n_dense:] = problem.source_block
    unknown = np.ones(n, dtype=bool)
    unknown[n_dense:] = False if fixed_zero is None else fixed_zero
    supply = _DenseColumnSupply(problem, unknown)
    start = np.array(passive_start, dtype=bool)
    supply.fill(q, np.flatnonzero(start[:n_dense]))
    start &= ~unknown
    d = np.concatenate(
        [problem.dense.transposed_product(supply.weighted_residual), problem.source_data]
    )
    log_det_source = problem.log_det_source
    if log_det_source is None and n_source:
        factor = upper_cholesky(problem.source_block.copy())
        log_det_source = float(2.0 * np.sum(np.log(np.diag(factor))))
    result = reconstruction_positive_only(q, d, initial_passive=start, supply=supply)
    return LinearSolution(result.x, True, result.x == 0.0, result.n_iterations, log_det_source)

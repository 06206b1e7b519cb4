"""Solves of the inversion's normal equations (SPEC §6.2–6.3).

The linear system is Q x = D with Q = F + H_tot symmetric positive definite (curvature plus
regularization, SPEC §6.1) and D the data vector. Minimising
Φ(x) = xᵀQx − 2Dᵀx (χ² plus regularization up to a constant) gives

* the unconstrained ("pn-MGE") solution x = Q⁻¹D by Cholesky
  (:func:`reconstruction_positive_negative`);
* the non-negative ("nn-MGE", the paper's default) solution min Φ subject to x ≥ 0, by the fast
  NNLS of Bro & De Jong (1997) on the normal equations, reproducing the anchor's variant
  (:func:`mgelens.inversion.nnls.reconstruction_positive_only`);
* either of them with some unknowns forced to zero (:func:`solve_linear_system`).

A warm-started non-negative solve with a pixelized source first works on the Schur
complement of the source block (:func:`_source_schur_solve`): the Gaussians' active set
is then g × g instead of the whole system's, and the result is checked against the full
problem's KKT conditions (the same unique minimum), with the full NNLS as the fallback.

Every failure (Q not positive definite, non-finite solution, NNLS iteration cap, degenerate
pn source) raises :class:`~mgelens.inversion.cholesky.InversionError`; a sampler rejects the
sample (SPEC §8.4).
"""

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.linalg.blas

from mgelens.inversion.cholesky import (
    InversionError,
    cholesky_solve,
    factor_log_det,
    finite_solution,
    upper_cholesky,
    validated_system,
)
from mgelens.inversion.nnls import (
    EPSILON,
    back_substitute_scatter,
    forward_substitute_transposed,
    reconstruction_positive_only,
)

SOURCE_ROUNDS = 8
"""Rounds of :func:`_source_schur_solve` (each a change of the source pixels held at
zero) before the full NNLS takes over."""


@dataclass(frozen=True)
class LinearSolution:
    """Output of :func:`solve_linear_system`.

    Attributes
    ----------
    x : numpy.ndarray
        Solution for all unknowns, float64.
    positive_only : bool
        Whether the non-negative solver ran.
    active_zero : numpy.ndarray
        Bool mask of unknowns pinned at exactly zero by the non-negativity constraint or by
        ``fixed_zero``; all False for the unconstrained solve.
    n_iterations : int
        Outer NNLS iterations (0 for the unconstrained solve).
    log_det_source : float or None
        ln det of Q's source block (F_SS + H, the evidence term of SPEC §7) when a
        ``source_block`` was given, from the same Cholesky factorisation; else None.
    """

    x: np.ndarray
    positive_only: bool
    active_zero: np.ndarray
    n_iterations: int
    log_det_source: float | None = None


def reconstruction_positive_negative(
    Q: np.ndarray, D: np.ndarray, source_block: slice | None = None
) -> np.ndarray:
    """Unconstrained solution x = Q⁻¹D by Cholesky (SPEC §6.2).

    Parameters
    ----------
    Q : numpy.ndarray
        (n, n) symmetric positive-definite matrix F + H_tot.
    D : numpy.ndarray
        (n,) data vector.
    source_block : slice, optional
        Unknowns of the pixelized source. If given, the anchor's sanity check is applied: the
        solution is rejected when all of them are equal (``numpy.allclose`` to the first one,
        default tolerances, as the anchor's ``check_reconstruction``).

    Returns
    -------
    numpy.ndarray
        (n,) float64 solution.

    Raises
    ------
    InversionError
        If Q is not positive definite, the solution is not finite, or the source is flat.
    """
    Q, D = validated_system(Q, D)
    x = cholesky_solve(Q, D)
    if source_block is not None:
        _check_source_not_flat(x[source_block])
    return x


def solve_linear_system(
    Q: np.ndarray,
    D: np.ndarray,
    positive_only: bool = True,
    fixed_zero: np.ndarray | None = None,
    source_block: slice | None = None,
    passive_start: np.ndarray | None = None,
    unconstrained: slice | None = None,
    source_log_det: float | None = None,
    source_factor: np.ndarray | None = None,
) -> LinearSolution:
    """Solve the inversion's normal equations, optionally non-negative (SPEC §6.2–6.3).

    Parameters
    ----------
    Q : numpy.ndarray
        (n, n) symmetric positive-definite matrix F + H_tot.
    D : numpy.ndarray
        (n,) data vector.
    positive_only : bool
        Non-negative solve (anchor default) instead of the unconstrained one.
    fixed_zero : numpy.ndarray, optional
        (n,) bool mask of unknowns forced to zero, the source pixels on the convex hull
        (SPEC §6.3). Their rows and columns are removed, the rest is solved by NNLS (with the
        tolerance and initial passive set of the reduced system, as the anchor) and the
        solution is scattered back with exact zeros. Only allowed with ``positive_only``, the
        only path where the anchor forces edge pixels to zero.
    source_block : slice, optional
        Unknowns of the pixelized source. Enables the pn sanity check (see
        :func:`reconstruction_positive_negative`; the non-negative solve ignores it, as the
        anchor) and ``log_det_source``: Q is then factorised once in the order (free source,
        fixed source, the rest), whose leading block is the source block, and that factor
        gives ln det(F_SS + H), the unconstrained solution and the NNLS's initial passive
        set (the fixed unknowns are eliminated from the factor by a small update of the
        trailing block). ``fixed_zero`` may then mark source unknowns only.
    passive_start : numpy.ndarray, optional
        (n,) bool: start the NNLS from this passive set (minus ``fixed_zero``) instead of
        the positive set of the unconstrained solution. A warm start: Q is positive
        definite, so the minimum is the same from any start (to rounding, ~1e−11
        relative), but a start close to the final set needs far fewer iterations (a
        phase's samples share most of their passive set). Ignored by the unconstrained
        solve.
    unconstrained : slice, optional
        With ``positive_only``: unknowns left free of the non-negativity, the others kept
        ≥ 0 (the 3×Sérsic runs' lens light non-negative and source free, SPEC §8.1;
        :func:`_solve_partly_constrained`). ``fixed_zero`` does not apply then, and a
        ``source_block`` must lie inside it.
    source_log_det : float, optional
        ln det of the source block if the caller has it (a source held fixed across
        calls, :class:`mgelens.fit.SourceSystem`): the warm-started non-negative solve
        then factorises no source block of its own. Other solves ignore it.
    source_factor : numpy.ndarray, optional
        With ``source_log_det``: the upper Cholesky factor of the source block (a caller
        whose source is fixed across calls keeps it:
        :attr:`mgelens.fit.SourceSystem.curvature_regularization_factor`), so that the
        warm-started non-negative solve can work on the source block's Schur complement
        (:func:`_source_schur_solve`). Without ``source_log_det`` the solve factorises
        the source block itself for both.

    Returns
    -------
    LinearSolution
        Solution and solver bookkeeping.

    Raises
    ------
    InversionError
        See :func:`reconstruction_positive_negative` and :func:`reconstruction_positive_only`.
    ValueError
        If ``fixed_zero`` is given with ``positive_only=False`` or has the wrong shape.
    """
    Q, D = validated_system(Q, D)
    n = D.size
    if not positive_only and fixed_zero is not None:
        raise ValueError("fixed_zero applies to the positive-only solve only (SPEC §6.3)")
    if unconstrained is not None:
        if not positive_only or fixed_zero is not None:
            raise ValueError(
                "unconstrained applies to the positive-only solve without fixed_zero "
                "(the unknowns it frees are not bounded)"
            )
        return _solve_partly_constrained(Q, D, unconstrained, source_block, passive_start)
    free = np.ones(n, dtype=bool) if fixed_zero is None else ~np.asarray(fixed_zero, dtype=bool)
    if free.shape != (n,):
        raise ValueError(f"fixed_zero must have shape ({n},), got {free.shape}")
    start = None
    if positive_only and passive_start is not None:
        start = np.asarray(passive_start, dtype=bool)
        if start.shape != (n,):
            raise ValueError(f"passive_start must have shape ({n},), got {start.shape}")
        start = start[free]
    if source_block is not None:
        return _solve_source_first(
            Q, D, positive_only, free, source_block, start, source_log_det, source_factor
        )
    if not positive_only:
        x = reconstruction_positive_negative(Q, D)
        return LinearSolution(x, False, np.zeros(n, dtype=bool), 0)
    x = np.zeros(n)
    n_iterations = 0
    if free.any():
        reduced = reconstruction_positive_only(
            Q[np.ix_(free, free)], D[free], initial_passive=start
        )
        x[free] = reduced.x
        n_iterations = reduced.n_iterations
    return LinearSolution(x, True, x == 0.0, n_iterations)


def _solve_source_first(
    Q: np.ndarray,
    D: np.ndarray,
    positive_only: bool,
    free: np.ndarray,
    source_block: slice,
    start: np.ndarray | None,
    source_log_det: float | None = None,
    source_factor: np.ndarray | None = None,
) -> LinearSolution:
    """:func:`solve_linear_system` with one Cholesky of Q ordered (A, E, M).

    A = free source unknowns, E = fixed (zero) source unknowns, M = the rest. With UᵀU = Q
    in that order, U[:A+E, :A+E] factorises the source block (its log det), and the
    factor of the reduced system (A, M) is U_AA, U_AM and a corner Ũ with
    ŨᵀŨ = U_EMᵀU_EM + U_MMᵀU_MM (M×M, cheap). ``start`` is the NNLS's initial passive
    set over the free unknowns; without it the unconstrained solution gives it.

    With ``start`` the NNLS needs no factor of Q, so only the source block is factorised
    (in its own order: the log det does not depend on it), and Q is not copied when
    nothing is fixed (docs/design_notes.md, "Warm-started solves"). A Q that is not
    positive definite outside the source block is then noticed only through a passive
    block (:func:`reconstruction_positive_only`).
    """
    n = D.size
    in_source = np.zeros(n, dtype=bool)
    in_source[source_block] = True
    if np.any(~free & ~in_source):
        raise ValueError("fixed_zero may only mark source unknowns when source_block is given")
    a = np.flatnonzero(in_source & free)
    e = np.flatnonzero(in_source & ~free)
    m = np.flatnonzero(~in_source)
    n_a, n_s = a.size, a.size + e.size
    reduced_q, reduced_d = (Q, D) if free.all() else (Q[np.ix_(free, free)], D[free])
    if positive_only and start is not None:
        return _solve_without_factor_of_q(
            Q,
            reduced_q,
            reduced_d,
            free,
            source_block,
            in_source,
            start,
            source_log_det,
            source_factor,
        )
    order = np.concatenate([a, e, m])
    try:
        U = upper_cholesky(Q[np.ix_(order, order)])
    except InversionError:
        if not positive_only:
            raise
        return _solve_without_factor_of_q(
            Q, reduced_q, reduced_d, free, source_block, in_source, None
        )
    x = np.zeros(n)
    log_det_source = factor_log_det(U[:n_s, :n_s])
    work = np.empty(n)
    if not positive_only:
        y = np.empty(n)
        forward_substitute_transposed(U, n, D[order], y)
        back_substitute_scatter(U, n, y, order, work, x)
        _check_source_not_flat(finite_solution(x)[source_block])
        return LinearSolution(x, False, np.zeros(n, dtype=bool), 0, log_det_source)
    reduced_order = np.concatenate([a, m])
    unconstrained = np.zeros(n)  # scattered back to the original index order of the NNLS
    unconstrained[reduced_order] = finite_solution(
        _reduced_solve(U, n_a, n_s, D[reduced_order], work)
    )
    result = reconstruction_positive_only(reduced_q, reduced_d, unconstrained=unconstrained[free])
    x[free] = result.x
    return LinearSolution(x, True, x == 0.0, result.n_iterations, log_det_source)


def _solve_without_factor_of_q(
    Q: np.ndarray,
    reduced_q: np.ndarray,
    reduced_d: np.ndarray,
    free: np.ndarray,
    source_block: slice,
    in_source: np.ndarray,
    start: np.ndarray | None,
    source_log_det: float | None = None,
    source_factor: np.ndarray | None = None,
) -> LinearSolution:
    """The positive-only solve of :func:`_solve_source_first` without a factor of Q: the
    NNLS from the passive set ``start`` (None: the empty set), which factorises only the
    blocks it frees, and ln det of the source block alone (F_SS + H; ``source_log_det``
    if given). Taken with a warm start, and when Q as a whole does not factorise
    (numerically singular outside the source block: lens-light columns that are nearly
    copies of each other, or whose scales differ by ~10¹⁹); the same minimum, without
    the unconstrained start. The source unknowns (``in_source``, an (n,) bool mask of
    ``source_block``) are the warm start's ``stable`` ones
    (:func:`~mgelens.inversion.nnls.reconstruction_positive_only`): between a phase's
    samples its source pixels' passive set changes far less than its Gaussians'.

    With a start and no fixed unknowns, the source block's factor (its own, computed for
    its log det, or ``source_factor``) first serves :func:`_source_schur_solve`,
    which needs no factor of the whole passive set; the full NNLS runs only where its
    rounds do not settle, from the passive set they reached."""
    log_det_source, factor = source_log_det, source_factor
    if log_det_source is None:
        factor = upper_cholesky(Q[source_block, source_block].copy())
        log_det_source = factor_log_det(factor)
    if start is not None and factor is not None and free.all():
        solved = _source_schur_solve(Q, reduced_d, in_source, start, factor, SOURCE_ROUNDS)
        if isinstance(solved, tuple):
            return LinearSolution(solved[0], True, solved[0] == 0.0, solved[1], log_det_source)
        start = solved
    if start is None:
        result = reconstruction_positive_only(reduced_q, reduced_d, use_initial_passive=False)
    else:
        result = reconstruction_positive_only(
            reduced_q,
            reduced_d,
            initial_passive=start,
            stable=in_source[free],
        )
    x = np.zeros(free.size)
    x[free] = result.x
    return LinearSolution(x, True, x == 0.0, result.n_iterations, log_det_source)


def _source_schur_solve(
    Q: np.ndarray,
    D: np.ndarray,
    in_source: np.ndarray,
    start: np.ndarray,
    factor: np.ndarray,
    rounds: int,
) -> tuple[np.ndarray, int] | np.ndarray:
    """The NNLS minimum found on the Schur complement of the source block and the rounds
    it took, or, where the rounds below do not settle, the passive set they reached (an
    (n,) bool mask, a closer start than ``start`` for the full NNLS that then runs).

    ``factor`` is the upper Cholesky factor U of the source block A = Q_ss (all source
    pixels s, ascending); W = U⁻ᵀQ_sg and v = U⁻ᵀD_s for the unknowns g off the source.
    The source pixels held at zero, R, start as those off ``start``. For a given R the
    other source pixels are solved exactly: A without R has the inverse, padded with
    zeros, A⁻¹ − E K⁻¹ Eᵀ with E = A⁻¹ on R's columns = U⁻¹G, G = U⁻ᵀ on R's unit
    vectors, and K = GᵀG. So the g solve the NNLS of the g × g system
    S = Q_gg − WᵀW + Cᵀ K⁻¹ C with data D_g − Wᵀv + Cᵀ K⁻¹ Gᵀv (C = GᵀW), from the start's
    set of g and with the full system's tolerance (every active-set step g × g instead of
    n × n, and A never factorised again), and the source pixels are
    U⁻¹(y − G K⁻¹ (U⁻¹y)_R), y = v − W x_g. After each solve the source pixels at or below
    the tolerance join R and those of R whose gradient D − Qx is above it leave; when
    neither happens the point meets the full problem's KKT conditions and is its unique
    minimum (Q is positive definite). At most ``rounds`` rounds."""
    n = D.size
    tol = n * EPSILON
    s = np.flatnonzero(in_source)
    g = np.flatnonzero(~in_source)
    lower = factor.T  # Fortran-ordered lower factor Uᵀ
    w = scipy.linalg.blas.dtrsm(1.0, lower, Q[np.ix_(g, s)].T, lower=1)
    v = scipy.linalg.blas.dtrsv(lower, D[s], lower=1)
    schur_full = Q[np.ix_(g, g)] - w.T @ w
    data_full = D[g] - w.T @ v
    zero = ~start[s]  # R, as a mask over s
    columns = {}  # G's column of each source pixel that has been in R
    passive_g = start[g].copy()
    x = np.zeros(n)
    for round_ in range(rounds):
        r = np.flatnonzero(zero)
        new = [j for j in r.tolist() if j not in columns]
        if new:
            unit = np.zeros((s.size, len(new)), order="F")
            unit[new, np.arange(len(new))] = 1.0
            solved = scipy.linalg.blas.dtrsm(1.0, lower, unit, lower=1, overwrite_b=1)
            columns.update(zip(new, solved.T, strict=True))
        schur, data = schur_full, data_full
        if r.size:
            g_r = np.array([columns[j] for j in r.tolist()]).T  # (m, r)
            try:
                k_lower = scipy.linalg.cholesky(g_r.T @ g_r, lower=True, check_finite=False)
            except np.linalg.LinAlgError:  # K singular in rounding: the full NNLS decides
                break
            m = scipy.linalg.solve_triangular(k_lower, g_r.T @ w, lower=True)
            mu = scipy.linalg.solve_triangular(k_lower, g_r.T @ v, lower=True)
            schur = schur + m.T @ m
            data = data + m.T @ mu
        if g.size:
            reduced = reconstruction_positive_only(
                schur, data, initial_passive=passive_g, tolerance=tol
            )
            x[g] = reduced.x
            passive_g = reduced.passive
        y = v - w @ x[g]
        source = scipy.linalg.blas.dtrsv(lower, y, lower=1, trans=1)
        if r.size:
            held = scipy.linalg.cho_solve((k_lower, True), source[r], check_finite=False)
            source = scipy.linalg.blas.dtrsv(lower, y - g_r @ held, lower=1, trans=1)
            source[r] = 0.0
        x[s] = source
        leaving = ~zero & (source <= tol)
        entering = np.zeros_like(zero)
        entering[r] = D[s[r]] - Q[s[r]] @ x > tol
        if not leaving.any() and not entering.any():
            return finite_solution(x), round_ + 1
        zero = (zero | leaving) & ~entering
    closer = np.zeros(n, dtype=bool)
    closer[s[~zero]] = True
    closer[g[passive_g]] = True
    return closer


def _reduced_solve(U: np.ndarray, n_a: int, n_s: int, b: np.ndarray, work: np.ndarray):
    """Solve the (A, M) system whose factor is U_AA, U_AM and the updated corner (see
    :func:`_solve_source_first`); ``b`` and the result are in the order (A, M)."""
    u_am, u_em, u_mm = U[:n_a, n_s:], U[n_a:n_s, n_s:], np.triu(U[n_s:, n_s:])
    corner = u_em.T @ u_em + u_mm.T @ u_mm
    try:
        corner_u = scipy.linalg.cholesky(corner, lower=False, check_finite=False)
    except np.linalg.LinAlgError as error:
        raise InversionError(f"matrix not positive definite: {error}") from error
    y_a = np.empty(n_a)
    forward_substitute_transposed(U, n_a, b[:n_a], y_a)
    y_m = scipy.linalg.solve_triangular(corner_u, b[n_a:] - u_am.T @ y_a, trans="T")
    x_m = scipy.linalg.solve_triangular(corner_u, y_m)
    x_a = np.empty(n_a)
    back_substitute_scatter(U, n_a, y_a - u_am @ x_m, np.arange(n_a), work, x_a)
    return np.concatenate([x_a, x_m])


def _check_source_not_flat(source: np.ndarray) -> None:
    """The anchor's pn sanity check: reject a solution whose source values are all equal."""
    if source.size and np.allclose(source, source[0]):
        raise InversionError("pn solve rejected: all source values are equal")


def _solve_partly_constrained(
    Q: np.ndarray,
    D: np.ndarray,
    unconstrained: slice,
    source_block: slice | None,
    passive_start: np.ndarray | None,
) -> LinearSolution:
    """min ½xᵀQx − Dᵀx with x ≥ 0 except on the ``unconstrained`` unknowns F.

    For any x_C of the constrained unknowns C the best x_F is Q_FF⁻¹(D_F − Q_FC x_C), so
    x_C solves the NNLS of the Schur complement, Q′ = Q_CC − Q_CF Q_FF⁻¹ Q_FC (positive
    definite, as Q is) and D′ = D_C − Q_CF Q_FF⁻¹ D_F, and x_F follows. With U_FᵀU_F =
    Q_FF, W = U_F⁻ᵀQ_FC and w = U_F⁻ᵀD_F: Q′ = Q_CC − WᵀW, D′ = D_C − Wᵀw and
    x_F = U_F⁻¹(w − W x_C). The factor U_F gives ln det of the source block when it is F.
    """
    n = D.size
    free = np.zeros(n, dtype=bool)
    free[unconstrained] = True
    f, c = np.flatnonzero(free), np.flatnonzero(~free)
    U = upper_cholesky(Q[np.ix_(f, f)])
    W = scipy.linalg.solve_triangular(U, Q[np.ix_(f, c)], trans="T", check_finite=False)
    w = scipy.linalg.solve_triangular(U, D[f], trans="T", check_finite=False)
    x = np.zeros(n)
    n_iterations = 0
    if c.size:
        start = None if passive_start is None else np.asarray(passive_start, dtype=bool)[c]
        schur = Q[np.ix_(c, c)] - W.T @ W
        reduced = reconstruction_positive_only(
            0.5 * (schur + schur.T), D[c] - W.T @ w, initial_passive=start
        )
        x[c] = reduced.x
        n_iterations = reduced.n_iterations
    x[f] = finite_solution(scipy.linalg.solve_triangular(U, w - W @ x[c], check_finite=False))
    log_det_source = None
    if source_block is not None:
        in_source = np.zeros(n, dtype=bool)
        in_source[source_block] = True
        if np.any(in_source & ~free):
            raise ValueError("source_block must lie inside the unconstrained unknowns")
        block = (
            upper_cholesky(Q[source_block, source_block].copy()) if np.any(free & ~in_source) else U
        )
        log_det_source = factor_log_det(block)
        _check_source_not_flat(x[source_block])
    active_zero = np.zeros(n, dtype=bool)
    active_zero[c] = x[c] == 0.0
    return LinearSolution(x, True, active_zero, n_iterations, log_det_source)

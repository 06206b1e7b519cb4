"""Non-negative solve of the inversion's normal equations: the fast NNLS (SPEC §6.3).

Contract: :func:`reconstruction_positive_only` minimises Φ(x) = xᵀQx − 2Dᵀx (χ² plus
regularization up to a constant, SPEC §6.1) subject to x ≥ 0, for Q = F + H_tot symmetric
positive definite and D the data vector. It returns the constrained minimum (exactly zero
off the final passive set), that passive set and the number of outer iterations. Every
failure (Q or a passive block not positive definite, an iteration cap, a non-finite
solution) raises :class:`~mgelens.inversion.cholesky.InversionError`; a sampler rejects
the sample (SPEC §8.4). This is the "nn-MGE" solve, the paper's default, called by
:func:`mgelens.inversion.solve.solve_linear_system`.

The method is Bro & De Jong's (1997) active set on the normal equations, as the anchor's
``fnnls_cholesky``::

    P ← initial passive set; x ← 0; w ← D − Qx (= D); tol ← n·2.2204e−16
    if P ≠ ∅: z_P ← Q_PP⁻¹D_P; x ← max(z, 0)
    while P ≠ all and max_{j∉P} w_j > tol:
        P ← P ∪ {argmax_{j∉P} w_j}; z_P ← Q_PP⁻¹D_P, z ← 0 off P
        while min_{j∈P} z_j ≤ tol:
            α ← min over {j∈P: z_j ≤ tol} of x_j/(x_j − z_j); x ← x + α(z − x)
            P ← P minus {j: x_j ≤ tol}; z_P ← Q_PP⁻¹D_P, z ← 0 off P
        x ← z; w ← D − Qx

Anchor specifics reproduced: the initial passive set is {j: (Q⁻¹D)_j > 0}; the
tolerance is absolute, n·2.2204e−16.

Deliberate deviation from the anchor: the anchor starts from x = max(z, 0) and takes the
first gradient at x = 0 (w = D). When D ≤ tol off P that skips the loop and returns a
point that is not the constrained minimum (common for small systems). Here the start is
made feasible instead: unknowns whose restricted solution is ≤ tol leave P until the
restricted solution is positive, then x = z and w = D − Qx is the true gradient. The
result is the exact NNLS minimum from the same starting set.

Deviation for ill-conditioned systems: the anchor stops when P is unchanged for 3
consecutive outer iterations. In exact arithmetic an unknown with w_j > 0 that enters has
z_j > 0; where Q's diagonal spans many decades (a source block under a regularization
coefficient of 10⁵, diagonal up to 10²²), an entering unknown's z_j can round to ≤ tol, so
it leaves at once, and the anchor's rule then stopped with other unknowns' gradients still
positive: on one SPix2 sample of slacs1103+5322 it ended 316 above the minimum of Φ with
the lens light's passive set wrong (scipy's NNLS found the minimum). Here, after an
outer iteration that leaves P unchanged, the unknowns that entered, and every unknown off
P whose step on its own would be below the tolerance (w_j ≤ tol·Q_jj; z_j ≥ w_j/Q_jj
bounds a single entry's step from below), are not offered again until P changes, and the
loop stops only when no other unknown has w_j > tol: the KKT condition over the unknowns
that can enter. A system that never leaves P unchanged takes the anchor's iterates.

A warm start may name its ``stable`` unknowns, those least likely to leave (a phase's
source pixels, whose passive set changes little between samples, against its lens-light
Gaussians, which churn): they are factorised first, and the feasible start drops the
other unknowns with z_j ≤ tol first, and stable ones only once no other is left to drop
(a Gaussian that should not be in the set often drives source pixels negative that come
back positive once it leaves). Deleting an unstable unknown is then a short Givens sweep
at the end of the factor. The minimum is the same.

Second deviation, for speed: up to :data:`ENTERING_BLOCK` unknowns (those of largest
w_j > tol) enter per outer iteration, one after a stagnant iteration (below). Outer
iterations therefore count entering blocks. Within the inner loop, entered unknowns still
at x_j = 0 whose z_j ≤ tol leave before any step is taken.

Two guards that change nothing in the generic case: the blocking index of each inner step
is set to exactly 0 (rounding could otherwise leave it above an absolute tolerance when x
is large), and α is taken over the indices with x_j > z_j only and capped at 1 (the ratio
is undefined or above 1 only when x_j ≤ tol, an index that leaves anyway).

Implementation: the upper Cholesky factor U of Q_PP (UᵀU = Q_PP, P the passive set in
factor order) and y = U⁻ᵀD_P are kept up to date. An entering index borders U by one
triangular solve; leaving indices are deleted by Givens rotations applied to U and y, or U is
refactorised when that is cheaper. Each sub-problem solve is then one back substitution
z_P = U⁻¹y. The anchor's initial passive set is factorised in order of decreasing unconstrained
value, so that the indices most likely to leave sit at the end of the factor, where deleting
them is cheap. The order changes the rounding only, not the iterates.

Each outer iteration lets the :data:`ENTERING_BLOCK` unknowns of largest positive gradient
enter at once, bordering U with one blocked triangular solve (one pass over U for all of
them). This changes the iterates, not the result: Q is positive definite, so the constrained
minimum is unique and the stopping test is the KKT condition. Block members whose
restricted solution is not positive leave again at once, without a step (a step would be
α = 0 and send the useful members out too; on M2's MASS systems that made every block of
6 leave and cost twice the iterations). An outer iteration that leaves the passive set
unchanged is followed by a single-entry one (Lawson–Hanson's step, which always makes
progress in exact arithmetic), the refused unknowns left out (above).
"""

from dataclasses import dataclass

import numpy as np
import scipy.linalg.lapack

from mgelens._jit import njit
from mgelens.inversion.cholesky import InversionError, cholesky_solve, validated_system

EPSILON = 2.2204e-16
"""Machine epsilon as written in the anchor; the NNLS tolerance is n·EPSILON (absolute)."""
MAX_ITERATIONS = 10_000
"""Cap on outer and on (cumulative) inner NNLS iterations before :class:`InversionError`."""
ENTERING_BLOCK = 10
"""Unknowns entering the passive set per outer NNLS iteration (the largest gradients):
fewer outer iterations per solve, each a little dearer; 10 is the fastest measured
(docs/design_notes.md, "NNLS entering block")."""
_REFACTOR_SPEEDUP = 6.0
"""Time of a Givens element operation over that of a LAPACK Cholesky flop (measured 4–8)."""
_FASTMATH = {"reassoc", "contract", "nsz"}
"""Lets LLVM vectorise the reductions (no assumptions about NaN or infinity)."""


@dataclass(frozen=True)
class NNLSResult:
    """Output of :func:`reconstruction_positive_only`.

    Attributes
    ----------
    x : numpy.ndarray
        Solution, float64, exactly zero off the passive set.
    passive : numpy.ndarray
        Bool mask of the final passive (unconstrained) set.
    n_iterations : int
        Number of outer iterations (indices that entered the passive set).
    """

    x: np.ndarray
    passive: np.ndarray
    n_iterations: int


def reconstruction_positive_only(
    Q: np.ndarray,
    D: np.ndarray,
    initial_passive: np.ndarray | None = None,
    use_initial_passive: bool = True,
    max_iterations: int = MAX_ITERATIONS,
    unconstrained: np.ndarray | None = None,
    stable: np.ndarray | None = None,
    tolerance: float | None = None,
) -> NNLSResult:
    """Minimise Φ(x) = xᵀQx − 2Dᵀx subject to x ≥ 0 (fast NNLS, SPEC §6.3).

    Bro & De Jong's active-set method on the normal equations with the anchor's specifics,
    from a feasible start and with blocks of entering unknowns (module docstring): the
    exact NNLS minimum from the given starting set.

    Parameters
    ----------
    Q : numpy.ndarray
        (n, n) symmetric positive-definite matrix.
    D : numpy.ndarray
        (n,) data vector.
    initial_passive : numpy.ndarray, optional
        (n,) bool initial passive set; overrides ``use_initial_passive``.
    use_initial_passive : bool
        Start from the positive set of the unconstrained solution (anchor default); otherwise
        start from the empty set (classic fnnls, where w = D is the true gradient).
    max_iterations : int
        Cap on the outer and on the cumulative inner iterations.
    unconstrained : numpy.ndarray, optional
        Q⁻¹D if the caller has it already (the default start then needs no Cholesky of Q).
    stable : numpy.ndarray, optional
        (n,) bool: with ``initial_passive``, the unknowns least likely to leave the
        passive set. They are factorised first and leave the feasible start only when no
        other unknown of it has z_j ≤ tol (module docstring). Changes the iterates, not
        the minimum.
    tolerance : float, optional
        The absolute tolerance; n·EPSILON by default (the anchor's). A part of a larger
        system (:func:`mgelens.inversion.solve.solve_linear_system`'s Schur complement)
        passes the whole system's.

    Returns
    -------
    NNLSResult
        Solution, final passive set and number of outer iterations.

    Raises
    ------
    InversionError
        If a Cholesky factorisation fails (Q or a passive block not positive definite), an
        iteration cap is reached or the solution is not finite. Only the default start
        factorises the whole of Q; otherwise a non-PD Q is noticed only through a passive block.
    """
    Q, D = validated_system(Q, D)
    n = D.size
    tol = n * EPSILON if tolerance is None else tolerance
    if initial_passive is None and use_initial_passive:
        if unconstrained is None:
            unconstrained = cholesky_solve(Q, D)
        passive = unconstrained > 0.0
        if passive.all():
            return NNLSResult(x=unconstrained, passive=passive, n_iterations=0)
        order = _by_decreasing(unconstrained, np.flatnonzero(passive))
    else:
        passive = _given_passive(initial_passive, n)
        stable = _given_stable(stable, n)
        order = _stable_first(passive, stable)
    factor = _PassiveCholesky(Q, D)
    factor.reset(order)
    x, n_inner = _feasible_start(factor, passive, tol, max_iterations, stable)
    x, n_outer = _outer_iterations(Q, D, factor, passive, x, tol, max_iterations, n_inner)
    if not np.all(np.isfinite(x)):
        raise InversionError("NNLS gave a non-finite solution")
    return NNLSResult(x=x, passive=passive, n_iterations=n_outer)


def _given_passive(initial_passive: np.ndarray | None, n: int) -> np.ndarray:
    """The (n,) bool passive set the caller gave (a copy), or the empty set if none."""
    if initial_passive is None:
        return np.zeros(n, dtype=bool)
    passive = np.array(initial_passive, dtype=bool)
    if passive.shape != (n,):
        raise ValueError(f"initial_passive must have shape ({n},), got {passive.shape}")
    return passive


def _given_stable(stable: np.ndarray | None, n: int) -> np.ndarray | None:
    """The caller's (n,) bool ``stable`` mask as an array, or None."""
    if stable is None:
        return None
    stable = np.asarray(stable, dtype=bool)
    if stable.shape != (n,):
        raise ValueError(f"stable must have shape ({n},), got {stable.shape}")
    return stable


def _stable_first(passive: np.ndarray, stable: np.ndarray | None) -> np.ndarray:
    """Indices of ``passive``, those in ``stable`` (None: all) first, each group
    ascending."""
    if stable is None:
        return np.flatnonzero(passive)
    return np.concatenate([np.flatnonzero(passive & stable), np.flatnonzero(passive & ~stable)])


def _feasible_start(
    factor: "_PassiveCholesky",
    passive: np.ndarray,
    tol: float,
    max_iterations: int,
    stable: np.ndarray | None = None,
) -> tuple[np.ndarray, int]:
    """The feasible warm start (module docstring) and the inner iterations it took.

    Unknowns whose restricted solution is ≤ ``tol`` leave ``passive`` (in place) and the
    factor until the restricted solution z is positive, those outside ``stable`` ((n,)
    bool, or None) first; returns z (zeros for an empty passive set) and the count.
    """
    x = np.zeros(passive.size)
    n_inner = 0
    if passive.any():
        z, z_min = factor.solution()
        while z_min <= tol:
            n_inner = _counted(n_inner, max_iterations, "inner")
            leaving = z[factor.passive_order] <= tol
            if stable is not None:
                unstable = leaving & ~stable[factor.passive_order]
                leaving = unstable if unstable.any() else leaving
            positions = np.flatnonzero(leaving)[::-1]
            passive[factor.passive_order[positions]] = False
            factor.remove(positions)
            z, z_min = factor.solution()
        x = z
    return x, n_inner


def _outer_iterations(
    Q: np.ndarray,
    D: np.ndarray,
    factor: "_PassiveCholesky",
    passive: np.ndarray,
    x: np.ndarray,
    tol: float,
    max_iterations: int,
    n_inner: int,
) -> tuple[np.ndarray, int]:
    """The outer loop from the feasible ``x``: the solution and the number of outer
    iterations. ``passive`` and the factor are updated in place; ``n_inner`` inner
    iterations were already taken."""
    n_outer = 0
    gradient = np.empty(D.size)
    refused = np.zeros(D.size, dtype=bool)
    diagonal = np.diagonal(Q)
    block = ENTERING_BLOCK
    entering = _largest_gradients_off_passive(Q, D, x, passive, tol, block, gradient)
    while entering.size:
        n_outer = _counted(n_outer, max_iterations, "outer")
        previous = passive.copy()
        factor.append(entering)
        passive[entering] = True
        x, n_inner = _restricted_minimum(factor, passive, x, tol, max_iterations, n_inner)
        unchanged = np.array_equal(passive, previous)
        if unchanged:  # the gradients of this x are still in ``gradient``
            refused[entering] = True
            refused |= ~passive & (gradient <= tol * diagonal)
        else:
            refused[:] = False
        block = 1 if unchanged else ENTERING_BLOCK
        entering = _largest_gradients_off_passive(Q, D, x, passive | refused, tol, block, gradient)
    return x, n_outer


def _restricted_minimum(
    factor: "_PassiveCholesky",
    passive: np.ndarray,
    x: np.ndarray,
    tol: float,
    max_iterations: int,
    n_inner: int,
) -> tuple[np.ndarray, int]:
    """The inner loop: steps from ``x`` (in place) towards the restricted solution z until z
    is positive on the passive set, the leaving unknowns removed from ``passive`` and the
    factor; returns z and the cumulative inner-iteration count."""
    z, z_min = factor.solution()
    while z_min <= tol:
        n_inner = _counted(n_inner, max_iterations, "inner")
        leaving = _step_to_boundary(x, z, factor.passive_order, tol)
        passive[factor.passive_order[leaving]] = False
        factor.remove(leaving)
        z, z_min = factor.solution()
    return z, n_inner


def _counted(count: int, max_iterations: int, kind: str) -> int:
    """``count + 1``; :class:`InversionError` if ``count`` has reached ``max_iterations``."""
    if count >= max_iterations:
        raise InversionError(f"NNLS reached {max_iterations} {kind} iterations")
    return count + 1


def _by_decreasing(values: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """``indices`` sorted by decreasing ``values`` (stable)."""
    return indices[np.argsort(-values[indices], kind="stable")]


class _PassiveCholesky:
    """Upper Cholesky factor of Q_PP for an ordered passive set, updated in place.

    With ``p`` passive unknowns ``order[:p]``, ``U[:p, :p]`` holds U with
    UᵀU = Q[order, order] (only the upper triangle is meaningful) and ``y[:p]`` holds
    U⁻ᵀD[order], so the restricted solution is U⁻¹y.
    """

    def __init__(self, Q: np.ndarray, D: np.ndarray):
        n = D.size
        self.Q, self.D = Q, D
        self.U = np.empty((n, n))
        self.y = np.empty(n)
        self.order = np.empty(n, dtype=np.int64)
        self.p = 0
        self._work = np.empty(n)

    @property
    def passive_order(self) -> np.ndarray:
        """The passive unknowns in factor order (a view)."""
        return self.order[: self.p]

    def reset(self, indices: np.ndarray) -> None:
        """Factorise Q_PP afresh for the unknowns ``indices``, in that order."""
        p = indices.size
        self.order[:p] = indices
        self.p = p
        if p == 0:
            return
        block = self.Q.take(indices, axis=0).take(indices, axis=1)
        # block.T is Fortran-ordered: LAPACK writes L there in place, i.e. U = Lᵀ into block.
        _, info = scipy.linalg.lapack.dpotrf(block.T, lower=1, clean=1, overwrite_a=1)
        if info != 0:
            raise InversionError(f"passive-set matrix not positive definite (potrf info {info})")
        self.U[:p, :p] = block
        forward_substitute_transposed(self.U, p, self.D[indices], self.y)

    def append(self, indices: np.ndarray) -> None:
        """Add ``indices`` at the end of the factor order (one blocked triangular solve)."""
        p, k = self.p, indices.size
        self.order[p : p + k] = indices
        rows = self.Q[indices]
        if _append_columns(self.U, p, self.y, rows, self.order, self.D[indices]):
            self.p = p + k
        else:  # rounding made a new pivot non-positive: try a fresh factorisation
            self.reset(self.order[: p + k].copy())

    def remove(self, positions: np.ndarray) -> None:
        """Delete the unknowns at ``positions`` (factor order, descending) from the factor.

        Deleting position k by Givens costs about (p − k)(2p − k) element operations, a fresh
        factorisation p³/3 + 2p² flops at LAPACK speed; the cheaper one is used.
        """
        if positions.size == 0:
            return
        p = self.p
        givens_cost = sum((p - k) * (2 * p - k) for k in positions.tolist())
        if givens_cost * _REFACTOR_SPEEDUP > p**3 / 3.0 + 2.0 * p * p:
            self.reset(np.delete(self.order[:p], positions))
        else:
            self.p = _delete_positions(self.U, p, self.y, self.order, positions)

    def solution(self) -> tuple[np.ndarray, float]:
        """(n,) solution of the restricted problem (zero off P) and its minimum over P."""
        z = np.zeros(self.D.size)
        z_min = back_substitute_scatter(self.U, self.p, self.y, self.order, self._work, z)
        return z, z_min


@njit
def _step_to_boundary(x, z, passive_order, tol):
    """Inner NNLS step, in place on x; returns the leaving positions (descending).

    If some passive unknowns are at zero (x_j ≤ tol: members of the entering block) with
    z_j ≤ tol, they leave and x stays: they should not have entered, and the step
    below would be α = 0 and send the whole block back out, the useful members too.
    Otherwise α = min over passive j with z_j ≤ tol and x_j > z_j of x_j/(x_j − z_j),
    capped at 1; x ← x + α(z − x) with the blocking unknown set exactly to 0 (x ← z if
    α = 1), and the passive unknowns with x_j ≤ tol leave. Returns their positions in
    ``passive_order``.
    """
    leaving = np.empty(passive_order.size, dtype=np.int64)
    count = 0
    for position in range(passive_order.size - 1, -1, -1):
        j = passive_order[position]
        if x[j] <= tol and z[j] <= tol:
            leaving[count] = position
            count += 1
    if count:
        return leaving[:count]
    alpha = 1.0
    blocking = -1
    for j in passive_order:
        if z[j] <= tol and x[j] > z[j]:
            ratio = x[j] / (x[j] - z[j])
            if ratio < alpha:
                alpha = ratio
                blocking = j
    if blocking < 0:
        x[:] = z
    else:
        for k in range(x.size):
            x[k] += alpha * (z[k] - x[k])
        x[blocking] = 0.0
    for position in range(passive_order.size - 1, -1, -1):
        if x[passive_order[position]] <= tol:
            leaving[count] = position
            count += 1
    return leaving[:count]


@njit(fastmath=_FASTMATH)
def back_substitute_scatter(U, p, y, order, work, z):
    """Solve U[:p, :p] w = y[:p], scatter z[order[:p]] = w; return min(w) (inf if p = 0)."""
    z_min = np.inf
    for i in range(p - 1, -1, -1):
        row = U[i, i + 1 : p]
        tail = work[i + 1 : p]
        total = 0.0
        for c in range(row.size):
            total += row[c] * tail[c]
        value = (y[i] - total) / U[i, i]
        work[i] = value
        z[order[i]] = value
        z_min = min(z_min, value)
    return z_min


@njit(fastmath=_FASTMATH)
def forward_substitute_transposed(U, p, b, u):
    """Solve U[:p, :p]ᵀ u = b[:p] for upper-triangular U (column-oriented, in u)."""
    u[:p] = b[:p]
    for k in range(p):
        u[k] /= U[k, k]
        uk = u[k]
        row = U[k, k + 1 : p]
        tail = u[k + 1 : p]
        for i in range(row.size):
            tail[i] -= uk * row[i]


@njit(fastmath=_FASTMATH)
def _append_columns(U, p, y, rows, order, d_new):
    """Border U[:p, :p] for the unknowns ``order[p:p + k]`` whose rows of Q are ``rows`` (k, n).

    V = U⁻ᵀ Q[order[:p], new] for all k columns in one pass over U's rows, then the new k×k corner
    column by column: t = (Q_new,new − the parts already known) / pivots, pivot
    sqrt(Q_jj − |V_j|² − |t|²), and y extended the same way. Returns False, leaving p
    meaningful entries of U and y untouched, if a pivot is not positive.
    """
    k = rows.shape[0]
    v = np.empty((k, p))
    for j in range(k):
        for r in range(p):
            v[j, r] = rows[j, order[r]]
    for r in range(p):  # Uᵀ v = Q[P, new]: row r of U is read once (from cache) per column
        row = U[r, r + 1 : p]
        for j in range(k):
            value = v[j, r] / U[r, r]
            v[j, r] = value
            tail = v[j, r + 1 : p]
            for i in range(row.size):
                tail[i] -= value * row[i]
    column = np.empty(p + k)
    for j in range(k):
        column[:p] = v[j]
        for i in range(j):  # rows of the corner already appended
            total = rows[j, order[p + i]]
            for r in range(p + i):
                total -= U[r, p + i] * column[r]
            column[p + i] = total / U[p + i, p + i]
        pivot = rows[j, order[p + j]]
        projected = d_new[j]
        for r in range(p + j):
            pivot -= column[r] * column[r]
            projected -= column[r] * y[r]
        if not pivot > 0.0:
            return False
        root = np.sqrt(pivot)
        for r in range(p + j):
            U[r, p + j] = column[r]
        U[p + j, p + j] = root
        y[p + j] = projected / root
    return True


@njit
def _delete_positions(U, p, y, order, positions):
    """Delete the unknowns at ``positions`` (descending) from U[:p, :p], y and order.

    Dropping column k of U leaves rows k.. upper Hessenberg; Givens rotations of rows
    (i, i+1), i = k..p−2, restore the triangle (the last row becomes zero and is dropped).
    The same rotations applied to y keep Uᵀy = D_P. Returns the new p.
    """
    for k in positions:
        for i in range(p):
            start = max(k + 1, i)
            source = U[i, start:p]
            target = U[i, start - 1 : p - 1]
            for c in range(source.size):
                target[c] = source[c]
        for i in range(k, p - 1):
            a = U[i, i]
            b = U[i + 1, i]
            r = np.hypot(a, b)
            cos = a / r
            sin = b / r
            U[i, i] = r
            upper = U[i, i + 1 : p - 1]
            lower = U[i + 1, i + 1 : p - 1]
            for c in range(upper.size):
                above = upper[c]
                below = lower[c]
                upper[c] = cos * above + sin * below
                lower[c] = cos * below - sin * above
            above = y[i]
            below = y[i + 1]
            y[i] = cos * above + sin * below
            y[i + 1] = cos * below - sin * above
            order[i] = order[i + 1]
        p -= 1
    return p


@njit(fastmath=_FASTMATH)
def _largest_gradients_off_passive(Q, D, x, passive, tol, k, gradient):
    """Up to ``k`` unknowns off the passive set with w = D − Qx above ``tol``, largest
    first (the lower index on ties); ``gradient`` is (n,) work space."""
    for j in range(D.size):
        gradient[j] = -np.inf
        if passive[j]:
            continue
        row = Q[j]
        total = 0.0
        for c in range(row.size):
            total += row[c] * x[c]
        gradient[j] = D[j] - total
    chosen = np.empty(k, dtype=np.int64)
    count = 0
    while count < k:
        best = tol
        index = -1
        for j in range(D.size):
            if gradient[j] > best:
                best = gradient[j]
                index = j
        if index < 0:
            break
        chosen[count] = index
        gradient[index] = -np.inf
        count += 1
    return chosen[:count]

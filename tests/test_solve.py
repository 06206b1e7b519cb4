"""Tests of the normal-equation solves (SPEC §6.2–6.3).

The NNLS oracle is ``scipy.optimize.nnls`` on the Cholesky factor: with Q = L Lᵀ,
min ‖Lᵀx − L⁻¹D‖² = Φ(x) + DᵀQ⁻¹D where Φ(x) = xᵀQx − 2Dᵀx (SPEC §6.3).
"""

import numpy as np
import pytest
import scipy.linalg
import scipy.optimize
import scipy.sparse
from scipy.spatial import KDTree

from mgelens.inversion import solve as solve_module
from mgelens.inversion.cholesky import InversionError, upper_cholesky
from mgelens.inversion.nnls import NNLSResult, _step_to_boundary, reconstruction_positive_only
from mgelens.inversion.solve import (
    SOURCE_ROUNDS,
    _reduced_solve,
    _source_schur_solve,
    reconstruction_positive_negative,
    solve_linear_system,
)

N_MGE = 70


def objective(Q, D, x):
    """Φ(x) = xᵀQx − 2Dᵀx."""
    return float(x @ Q @ x - 2.0 * D @ x)


def scipy_nnls(Q, D):
    """Oracle: scipy's NNLS on Z = Lᵀ, y = L⁻¹D with Q = L Lᵀ."""
    L = np.linalg.cholesky(Q)
    y = scipy.linalg.solve_triangular(L, D, lower=True)
    x, _ = scipy.optimize.nnls(L.T, y, maxiter=50 * D.size)
    return x


def random_system(seed, n, condition):
    """Random SPD Q with log-spaced eigenvalues in [1, condition] and D ~ N(0, diag Q)."""
    rng = np.random.default_rng(seed)
    V, _ = np.linalg.qr(rng.standard_normal((n, n)))
    Q = (V * np.logspace(0.0, np.log10(condition), n)) @ V.T
    Q = 0.5 * (Q + Q.T)
    return Q, rng.standard_normal(n) * np.sqrt(np.diag(Q))


def inversion_like_system(seed=0, n_source=1500, noise=0.05, coefficient=1.0):
    """(Q, D) of a toy lens inversion with N_MGE + n_source = 1570 unknowns.

    64×64 pixels of 0.05″ in a 1.6″ circular mask, an SIS (θ_E = 1″) maps each pixel to its 3
    nearest source centres (random traced pixels) with Dirichlet weights; N_MGE circular
    Gaussians model the lens; all columns blurred by a separable 5×5 Gaussian PSF. Data are a
    positive truth plus Gaussian noise, H = coefficient × (6-nearest-neighbour graph
    Laplacian) + 1e−8 I, Q = MᵀM/σ² + blockdiag(1e−3 I, H), D = Mᵀd/σ².
    """
    rng = np.random.default_rng(seed)
    side, pixel = 64, 0.05
    axis = (np.arange(side) - (side - 1) / 2) * pixel
    x, y = (grid.ravel() for grid in np.meshgrid(axis, axis))
    r = np.hypot(x, y)
    mask = r < 1.6
    x, y, r = x[mask], y[mask], r[mask]
    traced = np.column_stack([x - x / r, y - y / r])
    centres = traced[rng.choice(x.size, n_source, replace=False)]
    tree = KDTree(centres)
    _, nearest = tree.query(traced, k=3)
    weights = rng.dirichlet(np.ones(3), size=x.size)
    mapping = scipy.sparse.csr_matrix(
        (weights.ravel(), (np.repeat(np.arange(x.size), 3), nearest.ravel())),
        shape=(x.size, n_source),
    )
    sigmas = np.logspace(-2, np.log10(1.6), N_MGE)
    gaussians = np.exp(-0.5 * (r[:, None] / sigmas) ** 2) / (2 * np.pi * sigmas**2) * pixel**2
    taps = np.exp(-0.5 * np.arange(-2, 3) ** 2)
    row = scipy.sparse.diags(taps / taps.sum(), offsets=np.arange(-2, 3), shape=(side, side))
    blur = scipy.sparse.kron(row, row).tocsr()[mask][:, mask]
    M = scipy.sparse.hstack([scipy.sparse.csr_matrix(blur @ gaussians), blur @ mapping]).tocsc()
    truth = np.concatenate(
        [
            5.0 * np.exp(-0.5 * (np.log(sigmas / 0.3) / 0.8) ** 2),
            np.exp(-0.5 * np.sum((centres - [0.1, -0.05]) ** 2, axis=1) / 0.1**2),
        ]
    )
    data = M @ truth + noise * rng.standard_normal(x.size)
    _, neighbours = tree.query(centres, k=7)
    adjacency = scipy.sparse.csr_matrix(
        (np.ones(6 * n_source), (np.repeat(np.arange(n_source), 6), neighbours[:, 1:].ravel())),
        shape=(n_source, n_source),
    )
    adjacency = ((adjacency + adjacency.T) > 0).astype(float)
    laplacian = scipy.sparse.diags(np.asarray(adjacency.sum(axis=1)).ravel()) - adjacency
    H = coefficient * laplacian.toarray() + 1e-8 * np.eye(n_source)
    Q = (M.T @ M).toarray() / noise**2 + scipy.linalg.block_diag(1e-3 * np.eye(N_MGE), H)
    return Q, M.T @ data / noise**2


@pytest.fixture(scope="module")
def inversion_system():
    return inversion_like_system()


def assert_kkt(Q, D, result, rtol=1e-9):
    """x ≥ 0, zero off P; ∇Φ/2 = Qx − D ≥ −tol where x = 0 and ≈ 0 on the passive set."""
    x = result.x
    gradient = Q @ x - D
    scale = np.abs(Q) @ np.abs(x) + np.abs(D)
    assert np.all(x >= 0.0)
    assert np.all(x[~result.passive] == 0.0)
    assert np.all(gradient[x == 0.0] >= -rtol * scale[x == 0.0])
    assert np.all(np.abs(gradient[x > 0.0]) <= rtol * scale[x > 0.0])


def assert_same_minimum(Q, D, x, reference, rtol=1e-8):
    phi, phi_reference = objective(Q, D, x), objective(Q, D, reference)
    assert abs(phi - phi_reference) <= rtol * abs(phi_reference)


@pytest.mark.parametrize("use_initial_passive", [True, False])
@pytest.mark.parametrize("n", [10, 50, 200])
@pytest.mark.parametrize("seed", range(4))
def test_fnnls_matches_scipy_well_conditioned(seed, n, use_initial_passive):
    Q, D = random_system(seed, n, condition=1e2)
    result = reconstruction_positive_only(Q, D, use_initial_passive=use_initial_passive)
    assert_same_minimum(Q, D, result.x, scipy_nnls(Q, D))
    assert_kkt(Q, D, result)


@pytest.mark.parametrize("condition", [1e8, 1e10])
@pytest.mark.parametrize("n", [20, 100])
@pytest.mark.parametrize("seed", range(3))
def test_fnnls_matches_scipy_ill_conditioned(seed, n, condition):
    Q, D = random_system(seed, n, condition)
    result = reconstruction_positive_only(Q, D)
    assert_same_minimum(Q, D, result.x, scipy_nnls(Q, D))
    assert np.all(result.x >= 0.0)


def test_fnnls_matches_scipy_on_inversion_sized_system(inversion_system):
    Q, D = inversion_system
    assert Q.shape == (1570, 1570)
    result = reconstruction_positive_only(Q, D)
    assert_same_minimum(Q, D, result.x, scipy_nnls(Q, D))
    assert_kkt(Q, D, result)
    # A non-trivial case: many constraints active, outer iterations needed.
    assert result.n_iterations >= 5
    assert 0.2 < np.mean(result.x == 0.0) < 0.8


def test_warm_start_is_made_feasible_before_the_first_gradient():
    """Q⁻¹D = (−0.19, −1.83, 2.46), so P = {2}, z = (0, 0, 2), and D ≤ 0 on {0, 1}.

    The anchor takes its first gradient at x = 0 (w = D) and stops at once at (0, 0, 2),
    although D − Qz = (0.5, −1.6, 0) violates optimality. mgelens takes the true gradient
    at the feasible start and reaches the minimum (2/3, 0, 7/3).
    """
    Q = np.array([[1.0, -0.5, -0.5], [-0.5, 1.0, 0.3], [-0.5, 0.3, 1.0]])
    D = np.array([-0.5, -1.0, 2.0])
    warm = reconstruction_positive_only(Q, D)
    np.testing.assert_allclose(warm.x, [2 / 3, 0.0, 7 / 3], rtol=1e-14, atol=1e-15)
    classic = reconstruction_positive_only(Q, D, use_initial_passive=False)
    np.testing.assert_allclose(classic.x, warm.x, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(classic.x, scipy_nnls(Q, D), rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("seed", range(20))
def test_small_systems_reach_the_nnls_minimum(seed):
    Q, D = random_system(seed, 10, condition=1e2)
    assert_same_minimum(Q, D, reconstruction_positive_only(Q, D).x, scipy_nnls(Q, D))


def scaled_source_system(seed, n_light=12, n_source=30):
    """(Q, D) whose source block is diagonal with entries 10²⁰–10²² (a regularization
    coefficient of ~10⁵ on a SPix2 sample) and whose source gradients exceed the light's:
    each source unknown's restricted solution D_j/Q_jj ~ 10⁻¹⁸ rounds below the
    tolerance, so it enters and leaves at once."""
    rng = np.random.default_rng(seed)
    M = rng.standard_normal((60, n_light))
    light = M.T @ M + 1e-3 * np.eye(n_light)
    d_light = 5.0 * M.T @ rng.standard_normal(60)
    Q = scipy.linalg.block_diag(light, np.diag(10.0 ** rng.uniform(20, 22, n_source)))
    d_source = rng.uniform(1e3, 1e4, n_source) + 100.0 * np.abs(d_light).max()
    return Q, np.concatenate([d_light, d_source]), n_light


@pytest.mark.parametrize("seed", range(8))
def test_unknowns_that_round_out_of_the_passive_set_do_not_stop_the_nnls(seed):
    """The anchor stopped after 3 outer iterations that left the passive set unchanged; on
    seeds 2–6 that ended with the light's passive set wrong, Φ 10⁻³–1.3 above the minimum.
    The minimum here: scipy's NNLS on the light block, and D_j/Q_jj on the independent
    source unknowns."""
    Q, D, n_light = scaled_source_system(seed)
    light = scipy_nnls(Q[:n_light, :n_light], D[:n_light])
    reference = np.concatenate([light, D[n_light:] / np.diag(Q)[n_light:]])
    for result in (
        reconstruction_positive_only(Q, D),
        solve_linear_system(Q, D, positive_only=True, source_block=slice(n_light, None)),
    ):
        assert objective(Q, D, result.x) == pytest.approx(objective(Q, D, reference), abs=1e-6)
        np.testing.assert_array_equal(result.x[:n_light] > 0.0, light > 0.0)


def test_explicit_initial_passive_set():
    Q, D = random_system(7, 60, condition=1e3)
    reference = scipy_nnls(Q, D)
    optimal = reconstruction_positive_only(Q, D, initial_passive=reference > 0.0)
    assert_same_minimum(Q, D, optimal.x, reference)
    assert_kkt(Q, D, optimal)
    # any starting set, even everything, ends at the same minimum
    everything = reconstruction_positive_only(Q, D, initial_passive=np.ones(60, dtype=bool))
    assert_same_minimum(Q, D, everything.x, reference)


def test_stable_unknowns_leave_the_warm_start_only_after_the_others():
    """From the passive set {0, 1, 2} the restricted solution is (0.90, −0.32, −0.69).
    Unknowns 0 and 1 are stable: 2 leaves first, which makes z = (0.499, 0.195) positive,
    the minimum (2's gradient −1.21). Dropping both non-positive ones at once needs one
    outer iteration to bring 1 back. Both reach scipy's minimum."""
    Q = np.array([[2.8, -0.5, 2.0], [-0.5, 2.3, -2.0], [2.0, -2.0, 4.4]])
    D = np.array([1.3, 0.2, -0.6])
    start = np.ones(3, dtype=bool)
    expected = np.r_[np.linalg.solve(Q[:2, :2], D[:2]), 0.0]
    staged = reconstruction_positive_only(Q, D, initial_passive=start, stable=[True, True, False])
    at_once = reconstruction_positive_only(Q, D, initial_passive=start)
    for result, outer in ((staged, 0), (at_once, 1)):
        np.testing.assert_allclose(result.x, expected, rtol=1e-14, atol=0)
        assert result.n_iterations == outer
    np.testing.assert_allclose(staged.x, scipy_nnls(Q, D), rtol=1e-12, atol=1e-14)
    with pytest.raises(ValueError, match="stable must have shape"):
        reconstruction_positive_only(Q, D, initial_passive=start, stable=[True, False])


def test_stable_unknowns_change_no_minimum(inversion_system):
    """Source pixels stable, from starts with the light's final set inverted: scipy's
    minimum and the KKT conditions."""
    Q, D = inversion_system
    reference = scipy_nnls(Q, D)
    stable = np.arange(D.size) >= N_MGE
    for flip in (slice(0, N_MGE), slice(None)):
        start = reference > 0.0
        start[flip] = ~start[flip]
        result = reconstruction_positive_only(Q, D, initial_passive=start, stable=stable)
        assert_same_minimum(Q, D, result.x, reference)
        assert_kkt(Q, D, result)


@pytest.mark.parametrize("flip", [0, 40, 400])
def test_the_source_schur_complement_reaches_the_nnls_minimum(inversion_system, flip):
    """From the final passive set with ``flip`` source pixels and a third of the light
    Gaussians flipped, the rounds on the source block's Schur complement settle on
    scipy's minimum with the KKT conditions met; allowed one round only, they hand on
    the set they reached, from which the full NNLS reaches the same minimum."""
    Q, D = inversion_system
    reference = scipy_nnls(Q, D)
    start = reference > 0.0
    rng = np.random.default_rng(flip)
    start[rng.choice(N_MGE, N_MGE // 3, replace=False)] ^= True
    start[N_MGE + rng.choice(D.size - N_MGE, flip, replace=False)] ^= True
    in_source = np.arange(D.size) >= N_MGE
    factor = upper_cholesky(Q[N_MGE:, N_MGE:].copy())
    x, rounds = _source_schur_solve(Q, D, in_source, start, factor, SOURCE_ROUNDS)
    assert 1 <= rounds <= SOURCE_ROUNDS
    assert_same_minimum(Q, D, x, reference)
    assert_kkt(Q, D, NNLSResult(x, x > 0.0, rounds))
    if rounds > 1:
        reached = _source_schur_solve(Q, D, in_source, start, factor, rounds=1)
        assert reached.dtype == bool
        assert reached.shape == start.shape
        final = reference > 0.0
        assert np.count_nonzero(reached != final) < np.count_nonzero(start != final)
        result = reconstruction_positive_only(Q, D, initial_passive=reached, stable=in_source)
        assert_same_minimum(Q, D, result.x, reference)


def test_a_source_factor_from_the_caller_is_used(inversion_system, monkeypatch):
    """With ln det of the source block given (a fixed source), the warm-started solve
    works with the caller's factor of the source block and reaches the minimum of the
    solve that factorises everything itself; with one round allowed, the full NNLS
    finishes from the set the round reached."""
    Q, D = inversion_system
    source = slice(N_MGE, None)
    cold = solve_linear_system(Q, D, source_block=source)
    start = ~cold.active_zero
    start[:N_MGE] = True
    start[N_MGE + np.random.default_rng(5).choice(D.size - N_MGE, 40, replace=False)] ^= True
    factor = upper_cholesky(Q[source, source].copy())
    full_runs = []
    full_nnls = solve_module.reconstruction_positive_only

    def counted(*args, **kwargs):
        full_runs.append("stable" in kwargs)
        return full_nnls(*args, **kwargs)

    monkeypatch.setattr(solve_module, "reconstruction_positive_only", counted)
    for rounds in (SOURCE_ROUNDS, 1):
        monkeypatch.setattr(solve_module, "SOURCE_ROUNDS", rounds)
        full_runs.clear()
        given = solve_linear_system(
            Q,
            D,
            source_block=source,
            passive_start=start,
            source_log_det=cold.log_det_source,
            source_factor=factor,
        )
        assert any(full_runs) == (rounds == 1)
        np.testing.assert_allclose(given.x, cold.x, rtol=0, atol=1e-9 * np.abs(cold.x).max())
        np.testing.assert_array_equal(given.active_zero, cold.active_zero)
        assert given.log_det_source == cold.log_det_source


@pytest.mark.parametrize("seed", range(3))
def test_positive_negative_matches_numpy_solve(seed):
    Q, D = random_system(seed, 150, condition=1e3)
    expected = np.linalg.solve(Q, D)
    x = reconstruction_positive_negative(Q, D)
    assert np.linalg.norm(x - expected) <= 1e-10 * np.linalg.norm(expected)
    solution = solve_linear_system(Q, D, positive_only=False)
    np.testing.assert_array_equal(solution.x, x)
    assert not solution.positive_only
    assert not solution.active_zero.any()
    assert solution.n_iterations == 0


@pytest.mark.parametrize("seed", range(3))
def test_positive_only_has_no_negative_entries(seed):
    Q, D = random_system(seed, 120, condition=1e4)
    assert np.any(np.linalg.solve(Q, D) < 0.0)
    solution = solve_linear_system(Q, D)
    assert solution.positive_only
    assert np.all(solution.x >= 0.0)
    np.testing.assert_array_equal(solution.active_zero, solution.x == 0.0)
    assert solution.active_zero.any()


def test_agrees_exactly_with_unconstrained_when_that_is_non_negative():
    Q, _ = random_system(3, 80, condition=1e3)
    D = Q @ np.random.default_rng(3).uniform(0.5, 2.0, 80)
    unconstrained = solve_linear_system(Q, D, positive_only=False)
    assert np.all(unconstrained.x > 0.0)
    constrained = solve_linear_system(Q, D)
    np.testing.assert_array_equal(constrained.x, unconstrained.x)
    assert constrained.n_iterations == 0
    assert not constrained.active_zero.any()


def test_fixed_zero_solves_the_reduced_problem():
    Q, D = random_system(11, 90, condition=1e3)
    fixed = np.zeros(90, dtype=bool)
    fixed[::7] = True
    solution = solve_linear_system(Q, D, fixed_zero=fixed)
    free = ~fixed
    reduced = reconstruction_positive_only(Q[np.ix_(free, free)], D[free])
    assert np.all(solution.x[fixed] == 0.0)
    np.testing.assert_array_equal(solution.x[free], reduced.x)
    assert np.all(solution.active_zero[fixed])
    np.testing.assert_array_equal(solution.active_zero[free], reduced.x == 0.0)
    assert solution.n_iterations == reduced.n_iterations
    everything = solve_linear_system(Q, D, fixed_zero=np.ones(90, dtype=bool))
    assert np.all(everything.x == 0.0)
    assert everything.active_zero.all()


@pytest.mark.parametrize("positive_only", [True, False])
def test_source_first_factorisation_matches_the_plain_solve(inversion_system, positive_only):
    """One Cholesky in the order (free source, fixed source, MGE) gives the same solution
    as the plain path and the log det of the source block, with edge pixels fixed."""
    Q, D = inversion_system
    source = slice(N_MGE, None)
    fixed = np.zeros(D.size, dtype=bool)
    if positive_only:
        fixed[N_MGE::37] = True
    fixed_zero = fixed if positive_only else None
    joint = solve_linear_system(Q, D, positive_only, fixed_zero, source_block=source)
    plain = solve_linear_system(Q, D, positive_only, fixed_zero)
    assert plain.log_det_source is None
    np.testing.assert_allclose(joint.x, plain.x, rtol=0, atol=1e-9 * np.abs(plain.x).max())
    np.testing.assert_array_equal(joint.active_zero, plain.active_zero)
    sign, log_det = np.linalg.slogdet(Q[source, source])
    assert sign == 1.0
    assert joint.log_det_source == pytest.approx(log_det, rel=1e-12)
    with pytest.raises(ValueError, match="source unknowns"):
        solve_linear_system(Q, D, fixed_zero=np.arange(D.size) == 3, source_block=source)


def test_a_system_singular_outside_the_source_still_reaches_the_nnls_minimum():
    """A lens-light column that is zero in the mask (a Gaussian entirely outside it) makes
    Q singular, so it has no Cholesky factor: the positive-only solve then starts the NNLS
    from the empty passive set (the zero column never enters) and reaches scipy's NNLS
    minimum, with ln det of the source block; the unconstrained solve still refuses it."""
    rng = np.random.default_rng(5)
    n_pixels, n_source = 400, 30
    source = np.abs(rng.normal(size=(n_pixels, n_source)))
    light = np.exp(-np.linspace(0.0, 4.0, n_pixels))[:, None] * np.ones((1, 3))
    light[:, 1] = 0.0
    light[:, 2] = np.linspace(1.0, 0.0, n_pixels)
    design = np.hstack([source, light])
    data = design @ np.concatenate([rng.uniform(0.5, 1.5, n_source), [0.7, 0.0, 0.3]])
    data += 0.01 * rng.normal(size=n_pixels)
    Q, D = design.T @ design, design.T @ data
    with pytest.raises(InversionError):
        upper_cholesky(Q.copy())
    block = slice(0, n_source)
    solution = solve_linear_system(Q, D, positive_only=True, source_block=block)
    reference = scipy.optimize.nnls(design, data)[0]
    np.testing.assert_allclose(design @ solution.x, design @ reference, atol=1e-6)
    assert (solution.x >= 0.0).all()
    assert solution.log_det_source == pytest.approx(np.linalg.slogdet(Q[block, block])[1])
    with pytest.raises(InversionError):
        solve_linear_system(Q, D, positive_only=False, source_block=block)


@pytest.mark.parametrize("edge_step", [37, None])
@pytest.mark.parametrize("source_first", [True, False])
def test_passive_start_reaches_the_same_minimum_from_any_set(
    inversion_system, source_first, edge_step
):
    """Warm-starting from another system's final passive set, from its complement, or from
    the system's own final set gives the minimum of the cold start (scipy's NNLS) and, with
    a source block, the same ln det of it (the warm start factorises only that block); the
    own final set needs at most one outer iteration (the KKT check). With and without
    fixed edge pixels."""
    Q, D = inversion_system
    fixed = np.zeros(D.size, dtype=bool)
    if edge_step is not None:
        fixed[N_MGE::edge_step] = True
    free = ~fixed
    source = slice(N_MGE, None) if source_first else None
    reference = solve_linear_system(Q, D, fixed_zero=fixed, source_block=source)
    nearby = D * (1.0 + 0.01 * np.random.default_rng(1).standard_normal(D.size))
    cold = solve_linear_system(Q, nearby, fixed_zero=fixed, source_block=source)
    oracle = scipy_nnls(Q[np.ix_(free, free)], nearby[free])
    assert_same_minimum(Q[np.ix_(free, free)], nearby[free], cold.x[free], oracle)
    for start in (~reference.active_zero, reference.active_zero, ~cold.active_zero):
        warm = solve_linear_system(
            Q, nearby, fixed_zero=fixed, source_block=source, passive_start=start
        )
        np.testing.assert_allclose(warm.x, cold.x, rtol=0, atol=1e-9 * np.abs(cold.x).max())
        np.testing.assert_array_equal(warm.active_zero, cold.active_zero)
        assert warm.log_det_source == pytest.approx(cold.log_det_source, rel=1e-13)
    assert cold.n_iterations > 10
    assert warm.n_iterations <= 1


def test_block_members_that_should_not_enter_leave_without_sending_the_others_out():
    """x = (1, 0, 0) after a block {1, 2} entered; z = (2, −1, 3). Only unknown 1 leaves
    and x stays; a step would have α = 0 and send unknown 2 (z = 3) out as well."""
    x = np.array([1.0, 0.0, 0.0])
    z = np.array([2.0, -1.0, 3.0])
    leaving = _step_to_boundary(x, z, np.array([0, 1, 2]), 1e-15)
    np.testing.assert_array_equal(leaving, [1])
    np.testing.assert_array_equal(x, [1.0, 0.0, 0.0])
    # without such members the usual step: α = 0.5, blocked by unknown 0, which leaves
    x = np.array([1.0, 1.0, 0.0])
    leaving = _step_to_boundary(x, np.array([-1.0, 0.0, 3.0]), np.array([0, 1]), 1e-15)
    np.testing.assert_array_equal(leaving, [0])
    np.testing.assert_allclose(x, [0.0, 0.5, 1.5], rtol=1e-15)


def test_passive_start_is_checked_and_ignored_by_the_unconstrained_solve():
    Q, D = random_system(3, 12, condition=10.0)
    with pytest.raises(ValueError, match="passive_start must have shape"):
        solve_linear_system(Q, D, passive_start=np.ones(11, dtype=bool))
    unconstrained = solve_linear_system(Q, D, positive_only=False)
    started = solve_linear_system(Q, D, positive_only=False, passive_start=np.ones(5, dtype=bool))
    np.testing.assert_array_equal(started.x, unconstrained.x)


def test_reduced_solve_eliminates_the_fixed_block_from_the_factor():
    """The (A, M) system solved from the (A, E, M) factor equals a direct dense solve."""
    Q, D = random_system(5, 60, condition=1e4)
    n_a, n_s = 35, 48  # A = 0..34, E = 35..47, M = 48..59
    U = scipy.linalg.cholesky(Q, lower=False)
    keep = np.r_[0:n_a, n_s:60]
    x = _reduced_solve(np.ascontiguousarray(U), n_a, n_s, D[keep], np.empty(60))
    np.testing.assert_allclose(x, np.linalg.solve(Q[np.ix_(keep, keep)], D[keep]), rtol=1e-9)


def test_fixed_zero_is_rejected_outside_the_positive_only_path():
    Q, D = random_system(0, 10, condition=10.0)
    with pytest.raises(ValueError, match="positive-only"):
        solve_linear_system(Q, D, positive_only=False, fixed_zero=np.zeros(10, dtype=bool))
    with pytest.raises(ValueError, match="shape"):
        solve_linear_system(Q, D, fixed_zero=np.zeros(9, dtype=bool))


@pytest.mark.parametrize(
    "Q",
    [
        np.diag([1.0, -1.0, 2.0]),
        np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
        np.diag([1.0, np.nan, 1.0]),
    ],
)
def test_not_positive_definite_raises(Q):
    D = np.array([1.0, -1.0, 1.0])
    with pytest.raises(InversionError):
        reconstruction_positive_negative(Q, D)
    with pytest.raises(InversionError):
        reconstruction_positive_only(Q, D)


def test_not_positive_definite_passive_block_raises():
    Q = np.array([[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(InversionError, match="not positive definite"):
        reconstruction_positive_only(Q, np.ones(2), initial_passive=np.array([True, True]))


def test_iteration_caps_raise(inversion_system):
    Q, D = random_system(1, 200, condition=1e2)
    needed = reconstruction_positive_only(Q, D, use_initial_passive=False).n_iterations
    with pytest.raises(InversionError, match="outer iterations"):
        reconstruction_positive_only(Q, D, use_initial_passive=False, max_iterations=needed - 1)
    assert needed > 1
    exact = reconstruction_positive_only(Q, D, use_initial_passive=False, max_iterations=needed)
    assert exact.n_iterations == needed
    # The anchor's start leaves many indices to drop in the first outer iteration.
    with pytest.raises(InversionError, match="inner iterations"):
        reconstruction_positive_only(*inversion_system, max_iterations=5)


def test_pn_sanity_check_rejects_flat_source():
    Q = np.eye(5)
    D = np.array([3.0, -1.0, 2.0, 2.0, 2.0])
    with pytest.raises(InversionError, match="source values are equal"):
        solve_linear_system(Q, D, positive_only=False, source_block=slice(2, 5))
    x = solve_linear_system(Q, D, positive_only=False, source_block=slice(1, 5)).x
    np.testing.assert_array_equal(x, D)
    # The non-negative path does not apply the check (as in the anchor).
    np.testing.assert_array_equal(solve_linear_system(Q, D, source_block=slice(2, 5)).x[2:], 2.0)


def test_inputs_are_validated_and_not_modified():
    Q, D = random_system(2, 30, condition=1e3)
    Q_copy, D_copy = Q.copy(), D.copy()
    reconstruction_positive_only(np.asfortranarray(Q), D)
    np.testing.assert_array_equal(Q, Q_copy)
    np.testing.assert_array_equal(D, D_copy)
    with pytest.raises(ValueError, match="Q must be"):
        reconstruction_positive_only(Q, D[:-1])
    with pytest.raises(ValueError, match="initial_passive"):
        reconstruction_positive_only(Q, D, initial_passive=np.ones(3, dtype=bool))


def bounded_least_squares(Q, D, lower):
    """The same minimum by scipy's bounded least squares (an independent algorithm): with
    LᵀL = Q, ½xᵀQx − Dᵀx = ½|Lx − L⁻ᵀD|² + const."""
    L = np.linalg.cholesky(Q).T
    b = scipy.linalg.solve_triangular(L, D, trans="T")
    return scipy.optimize.lsq_linear(L, b, bounds=(lower, np.inf), tol=1e-14).x


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_partly_constrained_solve_matches_bounded_least_squares(seed):
    """Lens light ≥ 0, source free (the 3×Sérsic runs, SPEC §8.1): the Schur-complement
    solve equals scipy's bounded least squares, some bounds active and source values of
    both signs, and ln det of the source block equals a direct one."""
    rng = np.random.default_rng(seed)
    n_lens, n = 6, 40
    A = rng.normal(size=(120, n))
    Q = A.T @ A + 0.1 * np.eye(n)
    D = A.T @ (A @ np.concatenate([rng.normal(size=n_lens), rng.normal(size=n - n_lens)]))
    source = slice(n_lens, None)
    solution = solve_linear_system(Q, D, unconstrained=source, source_block=source)
    lower = np.where(np.arange(n) < n_lens, 0.0, -np.inf)
    np.testing.assert_allclose(solution.x, bounded_least_squares(Q, D, lower), atol=1e-7)
    assert np.any(solution.x[:n_lens] == 0.0)
    assert np.all(solution.x[:n_lens] >= 0.0)
    assert np.any(solution.x[source] < 0.0)
    assert np.any(solution.x[source] > 0.0)
    np.testing.assert_array_equal(solution.active_zero, solution.x == 0.0)
    direct = np.linalg.slogdet(Q[source, source])[1]
    assert solution.log_det_source == pytest.approx(direct, rel=1e-12)
    # the limits: everything free is the unconstrained solve, nothing free the NNLS
    free = solve_linear_system(Q, D, unconstrained=slice(0, None)).x
    np.testing.assert_allclose(free, np.linalg.solve(Q, D), rtol=1e-9, atol=1e-12)
    none = solve_linear_system(Q, D, unconstrained=slice(0, 0)).x
    np.testing.assert_allclose(none, scipy_nnls(Q, D), atol=1e-8)
    with pytest.raises(ValueError, match="unconstrained applies to the positive-only"):
        solve_linear_system(Q, D, positive_only=False, unconstrained=source)

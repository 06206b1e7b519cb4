"""The non-negative solve that fills dense columns of Q as the NNLS needs them (SPEC §6.3):
the same minimum as scipy's NNLS and as the full solve, on matrices and on LIGHT's fits."""

import numpy as np
import pytest
import scipy.linalg
import scipy.optimize
from test_fit import MASS, NOISE, PIXEL, SHAPE, lens_sets, make_dataset, pixelized_source

from mgelens import fit as fit_module
from mgelens.convolve import Convolver
from mgelens.fit import LensModel, MGESource, SourceSystem, fit, source_light_columns
from mgelens.fit_settings import FitSettings
from mgelens.geometry import ell_comps_from
from mgelens.inversion.system import WeightedBlurredMapping
from mgelens.inversion.working_set import DenseSourceProblem, solve_on_working_set
from mgelens.light import MGESet
from mgelens.source.regularization import ConstantSplit

N_PIXELS, N_DENSE, N_SOURCE = 400, 40, 30
MU = 1e-3


class ArrayColumns:
    """Dense columns held as one array, with the interface of
    :class:`mgelens.light.LazyBlurredColumns`."""

    def __init__(self, array: np.ndarray):
        self.array = array
        self.n_columns = array.shape[1]

    def columns(self, indices):
        return self.array[:, indices]

    def transposed_product(self, vector):
        return self.array.T @ vector


def synthetic_problem(seed: int):
    """A [dense | source] problem with known matrices: dense columns that overlap (as
    MGE Gaussians do), a random non-negative 'blurred mapping' S, H = 0.5 I, and data
    that few dense columns explain."""
    rng = np.random.default_rng(seed)
    radius = np.linspace(0.0, 3.0, N_PIXELS)
    widths = np.geomspace(0.05, 3.0, N_DENSE)
    dense = np.exp(-0.5 * (radius[:, None] / widths) ** 2)
    mapping = rng.random((N_PIXELS, N_SOURCE)) * (rng.random((N_PIXELS, N_SOURCE)) < 0.1)
    weights = rng.uniform(0.5, 2.0, N_PIXELS)
    truth = np.zeros(N_DENSE)
    truth[[5, 17, 30]] = (3.0, 1.0, 0.2)
    data = dense @ truth + mapping @ rng.random(N_SOURCE) + rng.normal(0, 0.05, N_PIXELS)
    h = 0.5 * np.eye(N_SOURCE)
    problem = DenseSourceProblem(
        dense=ArrayColumns(dense),
        inverse_variance=weights,
        residual=data,
        dense_diagonal=MU,
        source_block=mapping.T @ (weights[:, None] * mapping) + h,
        source_data=mapping.T @ (weights * data),
        lens_source=lambda columns: columns.T @ (weights[:, None] * mapping),
        source_image=lambda fluxes: mapping @ fluxes,
    )
    operator = np.hstack([dense, mapping])
    q = operator.T @ (weights[:, None] * operator)
    q[:N_DENSE, :N_DENSE] += MU * np.eye(N_DENSE)
    q[N_DENSE:, N_DENSE:] += h
    return problem, q, operator.T @ (weights * data)


def scipy_minimum(q: np.ndarray, d: np.ndarray) -> np.ndarray:
    """argmin xᵀQx − 2dᵀx, x ≥ 0, by scipy's Lawson–Hanson NNLS on ‖Ux − U⁻ᵀd‖²."""
    u = scipy.linalg.cholesky(q, lower=False)
    target = scipy.linalg.solve_triangular(u, d, trans="T")
    return scipy.optimize.nnls(u, target, maxiter=50 * q.shape[0])[0]


@pytest.mark.parametrize("start", ["no dense", "wrong dense", "all"])
def test_working_set_solve_matches_scipy_nnls_from_any_start(start):
    problem, q, d = synthetic_problem(seed=3)
    passive = np.ones(N_DENSE + N_SOURCE, dtype=bool)
    if start == "no dense":
        passive[:N_DENSE] = False
    elif start == "wrong dense":
        passive[:N_DENSE] = False
        passive[[0, 1, 2, 39]] = True
    solution = solve_on_working_set(problem, passive)
    expected = scipy_minimum(q, d)
    scale = np.abs(expected).max()
    np.testing.assert_allclose(solution.x, expected, atol=1e-8 * scale)
    assert np.count_nonzero(solution.x[:N_DENSE]) < N_DENSE // 2  # a sparse dense part
    np.testing.assert_array_equal(solution.active_zero, solution.x == 0.0)
    objective = solution.x @ q @ solution.x - 2 * d @ solution.x
    assert objective <= expected @ q @ expected - 2 * d @ expected + 1e-9 * abs(objective)
    sign, log_det = np.linalg.slogdet(problem.source_block)
    assert sign > 0
    assert solution.log_det_source == pytest.approx(log_det, rel=1e-12)


def test_fixed_source_unknowns_stay_zero_and_the_rest_is_the_reduced_minimum():
    problem, q, d = synthetic_problem(seed=5)
    fixed = np.zeros(N_SOURCE, dtype=bool)
    fixed[[0, 7, 8]] = True
    solution = solve_on_working_set(problem, np.ones(N_DENSE + N_SOURCE, bool), fixed)
    free = np.concatenate([np.ones(N_DENSE, bool), ~fixed])
    expected = np.zeros(free.size)
    expected[free] = scipy_minimum(q[np.ix_(free, free)], d[free])
    assert np.all(solution.x[N_DENSE:][fixed] == 0.0)
    np.testing.assert_allclose(solution.x, expected, atol=1e-8 * np.abs(expected).max())


def test_columns_off_the_start_are_filled_only_when_they_would_enter():
    problem, q, d = synthetic_problem(seed=3)
    requested = []

    class Counting(ArrayColumns):
        def columns(self, indices):
            requested.extend(np.asarray(indices).tolist())
            return super().columns(indices)

    counted = DenseSourceProblem(**{**vars(problem), "dense": Counting(problem.dense.array)})
    passive = np.ones(N_DENSE + N_SOURCE, dtype=bool)
    passive[:N_DENSE] = scipy_minimum(q, d)[:N_DENSE] > 0
    solution = solve_on_working_set(counted, passive)
    assert sorted(requested) == np.flatnonzero(passive[:N_DENSE]).tolist()
    np.testing.assert_allclose(solution.x, scipy_minimum(q, d), atol=1e-8 * np.abs(d).max())


@pytest.fixture(scope="module")
def light_fits():
    """LIGHT's pattern on a small lens: mass and source object fixed, lens light changing.
    Returns the dataset, its models and their full-solve fits (a fresh dataset each, so
    the whole system is built and solved from the unconstrained start)."""
    rng = np.random.default_rng(11)
    blank = make_dataset()
    sets = lens_sets()
    source = pixelized_source(blank, ConstantSplit(0.5))
    truth = np.geomspace(5.0, 0.05, blank.lens_light_columns(sets).shape[1])
    image = blank.lens_light_columns(sets) @ truth + rng.normal(0.02, NOISE, blank.data.size)
    data = np.zeros(SHAPE)
    data[~blank.mask] = image
    models = [
        LensModel(mass=MASS, lens_light=s, source=source) for s in ((sets[0],), (sets[1],), sets)
    ]
    return data, models, [fit(make_dataset(data), m) for m in models]


@pytest.mark.parametrize("edge_pixels_zero", [False, True])
def test_light_fits_on_the_working_set_equal_the_full_solve(
    light_fits, edge_pixels_zero, monkeypatch
):
    """The working set is taken unless the PSF blurs by separable terms; the tests'
    small Gaussian PSF is made to take it too, and both routes to F_LS are exercised."""
    monkeypatch.setattr(Convolver, "route", lambda self, include_blurring: "fft")
    monkeypatch.setattr(WeightedBlurredMapping, "cheaper", lambda *args: edge_pixels_zero)
    taken = []
    monkeypatch.setattr(
        fit_module,
        "solve_on_working_set",
        lambda *args, **kwargs: taken.append(1) or solve_on_working_set(*args, **kwargs),
    )
    data, models, _ = light_fits
    settings = FitSettings(lp_sub_size_centre=8, force_edge_pixels_to_zero=edge_pixels_zero)
    dataset = make_dataset(data, settings)
    for model in models:
        full = fit(make_dataset(data, settings), model)
        fit(dataset, model)  # the first fit of a mass and source builds no SourceSystem
        start = full.passive_set.copy()
        start[: full.n_lens_light] = False  # every lens-light column must be brought in
        for passive in (full.passive_set, start):
            reused = fit(dataset, model, passive)
            assert isinstance(dataset._source_cache["system"], SourceSystem)
            assert reused.log_evidence == pytest.approx(full.log_evidence, rel=1e-11)
            np.testing.assert_allclose(
                reused.solution.x, full.solution.x, atol=1e-7 * full.solution.x.max()
            )
            np.testing.assert_array_equal(reused.solution.active_zero, reused.solution.x == 0.0)
            if edge_pixels_zero:
                assert np.all(reused.source.fluxes[reused.source.mesh.edge_pixels] == 0.0)
    assert len(taken) == 2 * len(models)


def test_a_separable_psf_keeps_the_full_solve(light_fits, monkeypatch):
    """With a Gaussian PSF all columns blur in one batch for little more than one: the
    fits keep the full solve."""
    monkeypatch.setattr(fit_module, "solve_on_working_set", None)  # would raise if called
    data, models, _ = light_fits
    dataset = make_dataset(data)
    assert dataset.convolver.route(include_blurring=True) == "separable"
    fit(dataset, models[0])
    reused = fit(dataset, models[0], fit(make_dataset(data), models[0]).passive_set)
    assert np.isfinite(reused.log_evidence)


def test_a_parametric_source_fit_on_the_working_set_equals_the_full_solve(monkeypatch):
    """SP's pattern: lens-light and source Gaussians, no pixelized source; from a warm
    start without any Gaussian (all brought in by their gradient) and from the full
    solve's own passive set, the same intensities, χ² and ln L."""
    monkeypatch.setattr(Convolver, "route", lambda self, include_blurring: "fft")
    rng = np.random.default_rng(8)
    blank = make_dataset()
    sets = lens_sets()
    source_sets = (MGESet.extended((0.05, 0.0), ell_comps_from(0.8, 20.0), PIXEL, 0.6, 10),)
    lens = blank.lens_light_columns(sets) @ np.geomspace(5.0, 0.05, 20)
    arcs = source_light_columns(blank, MASS, source_sets) @ np.geomspace(3.0, 0.3, 10)
    data = np.zeros(SHAPE)
    data[~blank.mask] = lens + arcs + rng.normal(0.0, NOISE, blank.data.size)
    model = LensModel(mass=MASS, lens_light=sets, source=MGESource(source_sets))
    full = fit(make_dataset(data), model)
    empty = np.zeros(full.passive_set.size, dtype=bool)
    for start in (full.passive_set, empty):
        warm = fit(make_dataset(data), model, start)
        assert warm.log_likelihood == pytest.approx(full.log_likelihood, rel=1e-11)
        assert warm.log_evidence == warm.log_likelihood
        assert warm.solution.log_det_source is None
        np.testing.assert_allclose(
            warm.solution.x, full.solution.x, atol=1e-7 * full.solution.x.max()
        )
        np.testing.assert_allclose(warm.lensed_source_image, full.lensed_source_image, atol=1e-9)
        assert 0 < np.count_nonzero(warm.source_light_intensities) < 10

"""SP's start from the lensed arcs (mgelens.pipeline.sp_start): the arcs' mass against the
SIE that made them, the whole search against a mock's truth, the passed priors, the
fallback without arcs, and the reuse of start.json."""

import dataclasses
import json
import logging
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from mgelens import mock_lenses, simulate
from mgelens.fit import FitDataset
from mgelens.geometry import axis_ratio_and_angle_from
from mgelens.grid import pixel_centres
from mgelens.imaging import Imaging
from mgelens.mass import SIE, ExternalShear, ray_trace
from mgelens.pipeline import models, run, sp_start
from mgelens.pipeline.parameters import width_of
from mgelens.pipeline.phases import sp as sp_phase
from mgelens.pipeline.settings import LensSpec, profile_settings, settings_from_mapping
from mgelens.rejection import REJECTED_LOG_LIKELIHOOD
from mgelens.search.model import ParameterSpace
from mgelens.search.priors import TruncatedGaussian, Uniform, passed_prior

ROOT = Path(__file__).resolve().parents[1]
PIXEL = 0.1
MASK_RADIUS = 2.0
LENS = LensSpec(mask_radius=MASK_RADIUS)


def test_arc_mass_recovers_the_sie_shear_and_source_that_made_the_arcs():
    centre = (0.05, -0.03)
    sie = SIE.from_ell_comps(centre, (0.08, -0.05), 1.15)
    shear = ExternalShear(0.03, -0.02)
    source = (0.12, -0.08)
    x, y = pixel_centres((121, 121), 0.025)
    bx, by = ray_trace((sie, shear), x.ravel(), y.ravel())
    # the pixels of a 0.06″ source (an extended source, as arcs are) and their "flux"
    distance = np.hypot(bx - source[0], by - source[1])
    arc = distance < 0.06
    weight = np.exp(-0.5 * (distance[arc] / 0.03) ** 2)
    assert arc.sum() > 100
    arcs = sp_start.arc_mass(x.ravel()[arc], y.ravel()[arc], weight, centre, MASK_RADIUS)
    # the isothermal-sphere scan alone lands within 10 %; the refinement within 2 %
    assert abs(arcs.sphere_einstein_radius / 1.15 - 1) < 0.10
    assert abs(arcs.einstein_radius / 1.15 - 1) < 0.02
    assert np.hypot(arcs.source_x - source[0], arcs.source_y - source[1]) < 0.03
    assert arcs.scatter < 0.05
    assert arcs.n_pixels == arc.sum()
    # a wrong θ_E scatters the traced pixels: the scan has something to find
    wrong = sp_start._scatter((0.8, 0.0, 0.0, 0.0, 0.0), centre, x.ravel()[arc],
                              y.ravel()[arc], weight)[2]  # fmt: skip
    assert np.sqrt(wrong) > 5 * arcs.scatter


@pytest.mark.parametrize("mass_centre", ["free", "light"])
def test_polish_boxes_a_free_mass_centre_and_follows_a_tied_one(mass_centre):
    """The polish on an analytic ln L (a Gaussian around a target point whose mass centre
    is 0.5″ from its light centre, the light centre three times better measured): a free
    mass centre stops at the box, 0.3″ from the light; a tied one is no free parameter
    and drags the light only a little way, and θ_E still reaches its target."""
    specs = models.mge_specs(2, False, PIXEL, MASK_RADIUS)
    space = sp_phase.space(specs, mass_centre=mass_centre)
    target = {name: 0.0 for name in space.names}
    target |= {"lens_light.set_0.centre_x": 0.1, "mass.centre_x": 0.6, "mass.einstein_radius": 1.2,
               "mass.ell_comps_1": 0.1, "shear.gamma_1": 0.03}  # fmt: skip

    def likelihood(x):
        values = space.values(x)
        light = sum(((values[n] - target[n]) / 0.01) ** 2 for n in space.free_names
                    if not n.startswith("mass.centre"))  # fmt: skip
        mass = sum(((values[f"mass.{a}"] - target[f"mass.{a}"]) / 0.03) ** 2
                   for a in ("centre_x", "centre_y"))  # fmt: skip
        return -0.5 * (light + mass)

    posterior = sp_start._Posterior(likelihood, space)
    start = space.vector({**target, "mass.centre_x": 0.1, "mass.einstein_radius": 1.0})
    x, _, _ = sp_start.polish(posterior, start, space.free_names, (0.1, 0.0), 1.2)
    found = space.values(x)
    assert found["mass.einstein_radius"] == pytest.approx(1.2, abs=0.01)
    if mass_centre == "free":
        assert space.n_free == 17
        assert found["lens_light.set_0.centre_x"] == pytest.approx(0.1, abs=0.01)
        assert 0.35 < found["mass.centre_x"] <= 0.1 + sp_start.MASS_CENTRE_RANGE + 1e-9
    else:
        assert space.n_free == 15
        assert found["mass.centre_x"] == found["lens_light.set_0.centre_x"]
        assert 0.1 < found["mass.centre_x"] < 0.2


def _mock_folder(folder, noise_factor: float, with_source: bool = True):
    """M1 at 0.1″ in a 45×45 image; the noise raised ``noise_factor`` times; without its
    source if ``with_source`` is False (lens light only)."""
    observation = simulate.Observation(
        image_size=45,
        pixel_scale=PIXEL,
        sub_size=4,
        psf_sigma=0.1,
        psf_size=5,
        source_plane_size=81,
        source_plane_pixel_scale=0.025,
    )
    mock = simulate.simulate(mock_lenses.paper_mock("M1"), observation)
    model = mock.model if with_source else mock.model - mock.lensed_source_blurred
    noise = noise_factor * mock.imaging.noise_map
    data = model + noise * np.random.default_rng(3).standard_normal(noise.shape)
    Imaging(data, noise, mock.imaging.psf, PIXEL, unit=mock.imaging.unit).to_fits(folder)
    return folder


@pytest.fixture(scope="module")
def mock_folder(tmp_path_factory):
    return _mock_folder(tmp_path_factory.mktemp("m1_start"), noise_factor=3.0)


@pytest.fixture(scope="module")
def mock_problem(mock_folder):
    return sp_phase.problem(mock_folder, mock_folder, settings_from_mapping({}), LENS)


def _search(problem):
    likelihood = run.PhaseLikelihood(problem.dataset, problem.space, problem.model)
    return sp_start.search(
        problem.dataset, problem.space, problem.model, likelihood, problem.mask_radius
    )


SEARCH_SETTINGS = settings_from_mapping(
    {"allow_unconverged": True, "sp_start": "search",
     "samplers": {"sp": {"n_live": 36, "max_calls": 200, "progress_every": 1e9}}}
)  # fmt: skip
"""The start search with SP's sampler capped: the start is what these tests are about."""


@pytest.fixture(scope="module")
def started_sp(mock_folder, tmp_path_factory):
    """(folder, result) of run_phase("sp") with the start search on the mock, run once
    for the module: the search costs about a minute."""
    folder = tmp_path_factory.mktemp("started_sp")
    return folder, run.run_phase("sp", mock_folder, folder, SEARCH_SETTINGS, LENS)


@pytest.fixture(scope="module")
def mock_start(started_sp):
    """The search's start as the SP phase recorded it (start.json)."""
    folder, _ = started_sp
    recorded = json.loads((folder / "sp" / sp_start.START_FILE).read_text())
    return sp_start.SPStart.from_dict(recorded["start"])


def test_search_finds_the_mocks_mass_from_nothing_but_the_data(mock_problem, mock_start):
    truth = mock_lenses.paper_mock("M1").mass[0]
    values = mock_start.values
    # M1's EPL (γ 2.1, θ_E 1.2″) seen by an SIE: θ_E 1.18″ in M1's full SP
    assert abs(values["mass.einstein_radius"] / truth.einstein_radius - 1) < 0.05
    # within 1.5 pixels of the truth: the sampler's centre prior (σ 0.05″) reaches it
    assert np.hypot(values["mass.centre_x"] - truth.centre[0],
                    values["mass.centre_y"] - truth.centre[1]) < 0.15  # fmt: skip
    q = (1 - np.hypot(values["mass.ell_comps_1"], values["mass.ell_comps_2"])) / (
        1 + np.hypot(values["mass.ell_comps_1"], values["mass.ell_comps_2"])
    )
    assert abs(q - truth.axis_ratio) < 0.1
    light = (values["lens_light.set_0.centre_x"], values["lens_light.set_0.centre_y"])
    assert abs(values["mass.centre_x"] - light[0]) <= sp_start.MASS_CENTRE_RANGE
    assert abs(values["mass.centre_y"] - light[1]) <= sp_start.MASS_CENTRE_RANGE
    assert mock_start.n_arc_pixels >= sp_start.MIN_ARC_PIXELS
    # the sphere scan, then two polishes from each of three starting points
    scan_and_polishes = sp_start.EINSTEIN_RADIUS_GRID + 6 * sp_start.POLISH_CALLS
    assert mock_start.n_calls <= sp_start.LIGHT_CALLS + scan_and_polishes + 50
    # the sphere of highest ln P lies within one grid step (6 %) of M1's 1.2″
    assert abs(mock_start.scanned_einstein_radius / truth.einstein_radius - 1) < 0.06
    # the polished point beats the anchor-prior medians and the arcs' start
    space = mock_problem.space
    likelihood = run.PhaseLikelihood(mock_problem.dataset, space, mock_problem.model)
    medians = space.prior_transform(np.full(space.n_free, 0.5))
    x = space.vector(values)
    assert mock_start.log_posterior == pytest.approx(likelihood(x) + space.log_prior(x))
    assert mock_start.log_posterior > likelihood(medians) + space.log_prior(medians) + 1000


def test_started_space_passes_each_free_parameter_with_slams_width(mock_problem, mock_start):
    space = sp_start.started_space(mock_problem.space, mock_start)
    assert space.free_names == mock_problem.space.free_names
    for name in space.free_names:
        prior = space.parameter(name).prior
        limits = mock_problem.space.parameter(name).limits
        assert isinstance(prior, TruncatedGaussian)
        expected = passed_prior(name, mock_start.values[name], 0.0, width_of(name), limits, "2024")
        assert prior == expected
    theta = space.parameter("mass.einstein_radius").prior
    assert theta.sigma == pytest.approx(0.25 * mock_start.values["mass.einstein_radius"])
    assert space.parameter("mass.centre_x").prior.sigma == 0.05
    assert space.parameter("shear.gamma_1").prior.sigma == 0.05


def test_lens_light_alone_has_no_arcs_and_keeps_the_anchor_priors(tmp_path):
    folder = _mock_folder(tmp_path, noise_factor=3.0, with_source=False)
    lens = LensSpec(mask_radius=2.0)
    problem = sp_phase.problem(folder, folder, settings_from_mapping({}), lens)
    start = _search(problem)
    assert start.values is None
    assert start.arcs is None
    assert start.n_arc_pixels < sp_start.MIN_ARC_PIXELS
    assert start.n_calls <= sp_start.LIGHT_CALLS + 50
    assert sp_start.started_space(problem.space, start) is problem.space


def _light_only_fit_values(problem) -> dict:
    """The search's step 1 alone: the lens-light maximum under a mass that lenses nothing."""
    likelihood = run.PhaseLikelihood(problem.dataset, problem.space, problem.model)
    posterior = sp_start._Posterior(likelihood, problem.space)
    names = problem.space.free_names
    x = problem.space.prior_transform(np.full(problem.space.n_free, 0.5))
    x[names.index("mass.einstein_radius")] = sp_start.NO_LENSING_EINSTEIN_RADIUS
    light = [i for i, n in enumerate(names) if n.startswith(models.LENS_LIGHT + ".")]
    bounds = [sp_start._light_bounds(problem.space, i) for i in light]
    x, _ = sp_start._maximise(posterior, x, light, bounds, sp_start.LIGHT_CALLS)
    return problem.space.values(x)


def test_a_faint_sources_arcs_are_found_in_boxes(tmp_path):
    """M1 with its noise raised 30 times: fewer than ten single pixels of the light-only
    fit exceed 3σ, but the 3×3 boxes along the arcs do, and the arcs they give trace back
    through an isothermal mass within 10 % of M1's θ_E."""
    folder = _mock_folder(tmp_path, noise_factor=30.0)
    problem = sp_phase.problem(folder, folder, settings_from_mapping({}), LENS)
    values = _light_only_fit_values(problem)
    result = sp_start.fit(problem.dataset, problem.model.build(values))
    px, py = problem.dataset.pixel_centres
    distance = np.hypot(px, py)
    annulus = (distance > sp_start.ARC_INNER_RADIUS) & (
        distance < sp_start.ARC_OUTER_FRACTION * MASK_RADIUS
    )
    single = np.count_nonzero(annulus & (result.normalized_residuals > sp_start.ARC_SIGNIFICANCE))
    assert single < sp_start.MIN_ARC_PIXELS
    x, y, weight, centre = sp_start.arc_pixels(problem.dataset, values, problem.model, MASK_RADIUS)
    assert len(x) >= 5 * sp_start.MIN_ARC_PIXELS
    assert (weight > 0).all()
    arcs = sp_start.arc_mass(x, y, weight, centre, MASK_RADIUS)
    truth = mock_lenses.paper_mock("M1").mass[0]
    assert abs(arcs.einstein_radius / truth.einstein_radius - 1) < 0.1


def test_box_residuals_of_white_noise_are_unit_normal():
    """Σ r / √n over each box of white unit noise is N(0, 1) (also at the mask's edge,
    where a box holds fewer pixels); the mean residual is the box's mean."""
    rng = np.random.default_rng(5)
    x, y = pixel_centres((80, 80), 1.0)
    mask = np.hypot(x, y) > 35.0
    normalized = rng.standard_normal(np.count_nonzero(~mask))
    significance, mean = sp_start.box_residuals(normalized, 2.0 * normalized, mask, 3)
    assert np.std(significance) == pytest.approx(1.0, abs=0.03)
    assert abs(np.mean(significance)) < 0.15  # boxes overlap: σ of the mean ≈ 0.05
    native = np.zeros(mask.shape)
    native[~mask] = normalized
    row, column = 40, 40  # an interior pixel: its box is the 3×3 around it
    inside = np.flatnonzero(~mask.ravel()).tolist().index(row * 80 + column)
    box = native[row - 1 : row + 2, column - 1 : column + 2]
    assert significance[inside] == pytest.approx(box.sum() / 3.0)
    assert mean[inside] == pytest.approx(2.0 * box.mean())


def test_the_light_stage_starts_at_the_datas_second_moments():
    """An elliptical Gaussian galaxy (q 0.6 at φ 30°, σ 0.4″ along its major axis, centred
    0.05″ off the prior's mean): the moments within 1″ give its angle to a degree and an
    axis ratio a little rounder than its own (the circle cuts the major axis's wings);
    each lens-light ell_comps pair of the start takes them, nothing else changes."""
    x, y = pixel_centres((81, 81), 0.05)
    xp, yp = x - 0.05, y + 0.02
    phi = np.deg2rad(30.0)
    major = xp * np.cos(phi) + yp * np.sin(phi)
    minor = -xp * np.sin(phi) + yp * np.cos(phi)
    image = np.exp(-0.5 * ((major / 0.4) ** 2 + (minor / 0.24) ** 2))
    mask = np.hypot(x, y) > 3.0
    dataset = SimpleNamespace(
        pixel_centres=(x[~mask], y[~mask]), imaging=SimpleNamespace(data=image), mask=mask
    )
    priors = {
        "lens_light.set_0.centre_x": TruncatedGaussian(0.0, 0.1, -np.inf, np.inf),
        "lens_light.set_0.centre_y": TruncatedGaussian(0.0, 0.1, -np.inf, np.inf),
        "lens_light.set_0.ell_comps_1": Uniform(-1.0, 1.0),
        "lens_light.set_0.ell_comps_2": Uniform(-1.0, 1.0),
        "lens_light.set_1.ell_comps_1": Uniform(-1.0, 1.0),
        "lens_light.set_1.ell_comps_2": Uniform(-1.0, 1.0),
        "mass.einstein_radius": Uniform(0.0, 8.0),
    }
    space = ParameterSpace.from_priors(priors)
    ell_comps = sp_start.light_moments(dataset, (0.0, 0.0))
    q, angle = axis_ratio_and_angle_from(ell_comps)
    assert angle == pytest.approx(30.0, abs=1.0)
    assert 0.6 < q < 0.7
    start = sp_start.with_light_ellipticity(np.zeros(7), space.free_names, ell_comps)
    assert start.tolist() == [0.0, 0.0, *ell_comps, *ell_comps, 0.0]
    round_galaxy = SimpleNamespace(
        pixel_centres=(x[~mask], y[~mask]), imaging=SimpleNamespace(data=np.zeros_like(x)),
        mask=mask,
    )  # fmt: skip
    assert sp_start.light_moments(round_galaxy, (0.0, 0.0)) == (0.0, 0.0)


def test_start_json_is_reused_for_the_same_fingerprint_only(tmp_path, mock_start):
    runs = []

    def run():
        runs.append(1)
        return mock_start

    fingerprint = {"inputs": {"data.fits": "abc"}, "mask_centre": (0.0, 0.0)}
    first = sp_start.read_or_search(tmp_path, fingerprint, run)
    again = sp_start.read_or_search(tmp_path, fingerprint, run)
    assert len(runs) == 1
    assert again.values == first.values
    assert again.arcs == first.arcs
    recorded = json.loads((tmp_path / sp_start.START_FILE).read_text())
    assert recorded["start"]["n_calls"] == mock_start.n_calls
    assert recorded["fingerprint"] == {"inputs": {"data.fits": "abc"}, "mask_centre": [0, 0]}
    sp_start.read_or_search(tmp_path, {**fingerprint, "inputs": {"data.fits": "xyz"}}, run)
    assert len(runs) == 2
    (tmp_path / sp_start.START_FILE).write_text("{broken")
    sp_start.read_or_search(tmp_path, fingerprint, run)
    assert len(runs) == 3


def test_sp_phase_samples_the_started_priors_and_reuses_its_start(
    mock_folder, mock_problem, started_sp, mock_start, tmp_path, caplog
):
    """run_phase("sp") with ``sp_start: search``: start.json written, result.json's priors
    passed from it; a rerun reads it back instead of searching again (same priors, so a
    checkpoint would resume). The sampler is capped: only the plumbing is tested here."""
    folder, result = started_sp
    theta = result.space.parameter("mass.einstein_radius").prior
    assert theta.mean == pytest.approx(mock_start.values["mass.einstein_radius"])
    assert theta.sigma == pytest.approx(0.25 * theta.mean)
    started = sp_start.started_space(mock_problem.space, mock_start)
    assert result.space.to_dict() == started.to_dict()
    with caplog.at_level(logging.INFO, logger="mgelens.pipeline.sp_start"):
        again = run.run_phase("sp", mock_folder, folder, SEARCH_SETTINGS, LENS)
    assert "SP start read from" in caplog.text
    assert again.space.to_dict() == result.space.to_dict()
    prior = dataclasses.replace(SEARCH_SETTINGS, sp_start="prior")
    anchor = run.run_phase("sp", mock_folder, tmp_path / "prior", prior, LENS).space
    assert anchor.parameter("mass.einstein_radius").prior == models.EINSTEIN_RADIUS_PRIOR
    assert not (tmp_path / "prior" / "sp" / sp_start.START_FILE).exists()


def test_the_quick_profile_and_the_real_samples_start_sp_from_the_search():
    assert profile_settings("quick").sp_start == "search"
    assert profile_settings("paper").sp_start == "prior"
    for config in ("slacs.yaml", "paper.yaml"):
        content = yaml.safe_load((ROOT / "config" / config).read_text())
        assert settings_from_mapping(content["slam"]).sp_start == "search", config
    with pytest.raises(ValueError, match=r"slam\.sp_start"):
        settings_from_mapping({"sp_start": "grid"})


def test_light_stage_stays_in_its_box(mock_problem):
    space = mock_problem.space
    for i, name in enumerate(space.free_names):
        if not name.startswith(models.LENS_LIGHT):
            continue
        lower, upper = sp_start._light_bounds(space, i)
        mean = float(space.priors[i].transform(0.5))
        assert lower < mean < upper
        assert upper - lower <= 2 * sp_start.LIGHT_ELL_COMPS_RANGE + 1e-12


def test_the_polish_keeps_the_mass_centre_in_its_box_around_the_light():
    """A likelihood that pulls the mass 1.6″ away (as slacs1250+0523's did) gets the box's
    edge, not its own optimum; inside the box the posterior is the likelihood + prior."""
    space = ParameterSpace.from_priors(
        {"mass.centre_x": Uniform(-3.0, 3.0), "mass.centre_y": Uniform(-3.0, 3.0)}
    )

    def likelihood(x):
        return -((x[0] + 1.6) ** 2) - (x[1] - 0.3) ** 2

    half = sp_start.MASS_CENTRE_RANGE
    posterior = sp_start._Posterior(likelihood, space).boxed({0: (-half, half), 1: (-half, half)})
    inside = np.array([0.1, 0.2])
    assert posterior(inside) == pytest.approx(likelihood(inside) + space.log_prior(inside))
    assert posterior(np.array([-0.31, 0.0])) == REJECTED_LOG_LIKELIHOOD
    x, value = sp_start._maximise(posterior, np.zeros(2), [0, 1], None, 400)
    assert abs(x[0] + half) < 0.01
    assert abs(x[1] - 0.3) < 0.01
    assert value == pytest.approx(likelihood(x) + space.log_prior(x))


MASS_SPACE = ParameterSpace.from_priors(
    {
        "mass.centre_x": Uniform(-3.0, 3.0),
        "mass.centre_y": Uniform(-3.0, 3.0),
        "mass.einstein_radius": Uniform(0.0, 8.0),
    }
)


def test_the_free_polish_follows_arcs_that_overestimate_the_einstein_radius():
    """slacs1032+5322's case: the arcs said 1.71″, the mass is near 1.04″ (0.6 of it),
    outside the held polish's range; the free polish reaches it and is kept."""
    arcs = 1.7

    def likelihood(x):
        return -((x[0] - 0.05) ** 2) - x[1] ** 2 - 50.0 * (x[2] - 0.6 * arcs) ** 2

    posterior = sp_start._Posterior(likelihood, MASS_SPACE)
    x, value, held = sp_start.polish(
        posterior, np.array([0.0, 0.0, arcs]), MASS_SPACE.free_names, (0.0, 0.0), arcs
    )
    assert not held
    assert x[2] == pytest.approx(0.6 * arcs, abs=0.01)
    assert value == pytest.approx(likelihood(x) + MASS_SPACE.log_prior(x))
    assert posterior.box == {}  # the boxes do not outlive the polish


def test_the_held_polish_wins_where_it_reaches_the_higher_posterior(monkeypatch):
    """3×Sérsic M1's case: the free polish carried θ_E from the arcs' 1.27″ to 2.20″ at
    ln P −73,930, the held one stayed at 1.28″ at −34,238 (docs/paper_mocks.md)."""
    boxes = []

    def maximise(posterior, x, free, bounds, max_calls):
        boxes.append(dict(posterior.box))
        theta, value = (2.195, -73929.8) if len(boxes) == 1 else (1.283, -34237.7)
        return np.array([0.0, 0.0, theta]), value

    monkeypatch.setattr(sp_start, "_maximise", maximise)
    posterior = sp_start._Posterior(lambda x: 0.0, MASS_SPACE)
    x, value, held = sp_start.polish(
        posterior, np.array([0.0, 0.0, 1.268]), MASS_SPACE.free_names, (0.1, -0.2), 1.268
    )
    half = sp_start.MASS_CENTRE_RANGE
    centre_box = {0: (0.1 - half, 0.1 + half), 1: (-0.2 - half, -0.2 + half)}
    low, high = sp_start.ARC_EINSTEIN_RANGE
    assert boxes[0] == pytest.approx(centre_box)
    assert boxes[1] == pytest.approx(centre_box | {2: (low * 1.268, high * 1.268)})
    assert held
    assert x[2] == 1.283
    assert value == -34237.7


SHAPE_SPACE = ParameterSpace.from_priors(
    {
        "mass.einstein_radius": Uniform(0.0, 8.0),
        "mass.ell_comps_1": Uniform(-1.0, 1.0),
        "mass.ell_comps_2": Uniform(-1.0, 1.0),
        "shear.gamma_1": Uniform(-0.3, 0.3),
        "shear.gamma_2": Uniform(-0.3, 0.3),
    }
)


def test_the_polish_keeps_the_mass_and_shear_plausible():
    """slacs1032+5322's case: a likelihood peaked at mass ell_comps (0.82, 0.18) (q ≈ 0.09)
    and a shear of 0.26 gets the edges of q ≥ 0.3 and |γ| ≤ 0.15 in the direction of its
    peak (Powell stops somewhere on the edge), not its peak."""
    peak = np.array([1.2, 0.82, 0.18, 0.18, 0.18])

    def likelihood(x):
        return -float(np.sum((x - peak) ** 2))

    posterior = sp_start._Posterior(likelihood, SHAPE_SPACE)
    x, value, _ = sp_start.polish(
        posterior, np.array([1.2, 0.1, 0.0, 0.0, 0.0]), SHAPE_SPACE.free_names, (0.0, 0.0), 1.2
    )
    modulus = (1 - sp_start.MIN_MASS_AXIS_RATIO) / (1 + sp_start.MIN_MASS_AXIS_RATIO)
    assert np.hypot(x[1], x[2]) == pytest.approx(modulus, abs=0.01)
    assert np.hypot(x[1], x[2]) <= modulus
    assert x[1] > 0.4
    assert x[2] > 0.0
    assert np.hypot(x[3], x[4]) == pytest.approx(sp_start.MAX_SHEAR, abs=0.01)
    assert x[3] > 0.0
    assert x[4] > 0.0
    assert x[0] == pytest.approx(1.2, abs=0.01)
    assert value == pytest.approx(likelihood(x) + SHAPE_SPACE.log_prior(x))
    assert posterior.plausible is None  # the limits do not outlive the polish


def test_plausible_mass_checks_the_named_pairs_only():
    plausible = sp_start.plausible_mass(SHAPE_SPACE.free_names)
    q_limit = (1 - 0.3) / (1 + 0.3)
    assert plausible(np.array([1.0, 0.0, 0.99 * q_limit, 0.1, 0.1]))
    assert not plausible(np.array([1.0, 0.0, 1.01 * q_limit, 0.0, 0.0]))
    assert not plausible(np.array([1.0, 0.0, 0.0, 0.11, 0.11]))  # |γ| 0.156
    only_mass = sp_start.plausible_mass(["mass.einstein_radius", "mass.ell_comps_1",
                                         "mass.ell_comps_2"])  # fmt: skip
    assert only_mass(np.array([1.0, 0.3, 0.3]))
    assert not only_mass(np.array([1.0, 0.6, 0.0]))
    assert sp_start.plausible_mass(MASS_SPACE.free_names)(np.array([0.0, 0.0, 9.0]))


def test_a_start_beyond_the_limits_is_shrunk_to_them_at_its_angle():
    """M3's case: the light-shaped start takes a light of q < 0.3; the posterior rejects
    it, and a polish from there would not move. Shrunk inside, it is polished."""
    names = SHAPE_SPACE.free_names
    start = np.array([1.1, 0.6, 0.45, 0.0, -0.2])
    shrunk = sp_start.made_plausible(start, names)
    q_limit = (1 - sp_start.MIN_MASS_AXIS_RATIO) / (1 + sp_start.MIN_MASS_AXIS_RATIO)
    assert np.hypot(*shrunk[1:3]) == pytest.approx(q_limit, rel=2e-3)
    assert np.hypot(*shrunk[1:3]) < q_limit
    assert shrunk[2] / shrunk[1] == pytest.approx(0.45 / 0.6)
    assert shrunk[3:] == pytest.approx([0.0, -sp_start.MAX_SHEAR], rel=2e-3)
    assert shrunk[0] == 1.1
    assert sp_start.plausible_mass(names)(shrunk)
    inside = np.array([1.1, 0.2, 0.1, 0.05, 0.0])
    assert np.array_equal(sp_start.made_plausible(inside, names), inside)
    assert start[1] == 0.6  # the input is not modified

    peak = np.array([1.0, 0.1, 0.0, 0.02, 0.0])

    def likelihood(x):
        return -float(np.sum((x - peak) ** 2))

    posterior = sp_start._Posterior(likelihood, SHAPE_SPACE)
    x, _, _ = sp_start.polish(posterior, start, names, (0.0, 0.0), 1.1)
    assert x == pytest.approx(peak, abs=0.01)


def test_dataset_pixel_centres_are_the_unmasked_pixels(mock_problem):
    dataset: FitDataset = mock_problem.dataset
    x, y = dataset.pixel_centres
    assert x.shape == dataset.data.shape
    assert np.all(np.hypot(x, y) <= MASK_RADIUS + PIXEL)


def test_the_light_shaped_start_has_the_lights_ellipticity_and_no_shear():
    names = ["lens_light.set_0.ell_comps_1", "lens_light.set_0.ell_comps_2",
             "mass.ell_comps_1", "mass.ell_comps_2", "shear.gamma_1", "shear.gamma_2",
             "lens_light.set_1.ell_comps_1"]  # fmt: skip
    start = dict(zip(names, [0.07, 0.12, 0.37, -0.2, 0.05, -0.21, 0.3], strict=True))
    shaped = sp_start.light_shaped(start, names)
    assert shaped == start | {"mass.ell_comps_1": 0.07, "mass.ell_comps_2": 0.12,
                              "shear.gamma_1": 0.0, "shear.gamma_2": 0.0}  # fmt: skip
    assert start["mass.ell_comps_1"] == 0.37  # the arcs' start is not changed


@pytest.mark.parametrize(
    ("values", "chosen"),
    [
        ((-82720.8, -75084.4, -75500.0), 1),
        ((18157.4, 16160.6, 24000.0), 2),
        ((-5.0, -5.0, -5.0), 0),
    ],
)
def test_the_start_with_the_higher_polished_posterior_wins(monkeypatch, values, chosen):
    """M3's case (docs/paper_mocks.md): from the arcs' SIE + shear the polish reached ln P
    −82,720.8 in an elongated mass with a strong shear, from the light-shaped mass
    −75,084.4; slacs1032+5322's: the arcs' θ_E was far too large and the sphere scan's
    start polishes highest; a tie keeps the earliest start. Each start's held polish
    stays near its own θ_E."""
    starts = [(np.array([0.0, 0.0, 1.7]), 1.7), (np.array([0.0, 0.0, 1.8]), 1.7),
              (np.array([0.0, 0.0, 1.0]), 1.0)]  # fmt: skip
    held_near = []

    def polish(posterior, x, names, centre, einstein_radius):
        held_near.append(einstein_radius)
        index = next(i for i, (start, _) in enumerate(starts) if start[2] == x[2])
        return x + 0.01, values[index], index == 0

    monkeypatch.setattr(sp_start, "polish", polish)
    posterior = sp_start._Posterior(lambda x: 0.0, MASS_SPACE)
    (x, value, held, index), polished = sp_start.polish_starts(
        posterior, starts, MASS_SPACE.free_names, (0.0, 0.0)
    )
    assert held_near == [1.7, 1.7, 1.0]
    assert [p["log_posterior"] for p in polished] == list(values)
    for record, (start, _) in zip(polished, starts, strict=True):
        assert list(record["values"].values()) == pytest.approx(start + 0.01)
    assert index == chosen
    assert value == values[chosen]
    assert held is (chosen == 0)
    assert x == pytest.approx(starts[chosen][0] + 0.01)


SCAN_SPACE = ParameterSpace.from_priors(
    {name: Uniform(-3.0, 3.0) for name in ("mass.centre_x", "mass.centre_y", "mass.ell_comps_1",
     "mass.ell_comps_2", "shear.gamma_1", "shear.gamma_2", "source.set_0.centre_x",
     "source.set_0.centre_y")} | {"mass.einstein_radius": Uniform(0.0, 8.0)}
)  # fmt: skip


def test_the_sphere_scan_scores_each_sphere_with_its_traced_source():
    """A double in the way of slacs1032+5322: the flux of the extended outer image (at
    1.85″) swamps the inner one (0.8″ on the other side), so the scatter criterion puts
    θ_E near the outer image; the scan keeps the sphere of highest ln P (here an analytic
    ln P peaked at the double's 1.325″ with the source where that sphere traces the
    pixels), round and without shear, with the source on the traced weighted mean."""
    centre = (0.02, -0.01)
    rng = np.random.default_rng(4)
    outer = np.array([1.85, 0.0]) + rng.normal(0.0, 0.25, (400, 2))
    inner = np.array([-0.8, 0.0]) + rng.normal(0.0, 0.03, (30, 2))
    x, y = np.concatenate([outer, inner]).T + np.array(centre)[:, None]
    weight = np.ones(x.size)
    assert sp_start.arc_mass(x, y, weight, centre, 3.0).sphere_einstein_radius > 1.5
    truth = 1.325

    def likelihood(vector):
        v = SCAN_SPACE.values(vector)
        traced = sp_start._scatter((truth, 0.0, 0.0, 0.0, 0.0), centre, x, y, weight)
        source = (v["source.set_0.centre_x"] - traced[0]) ** 2 + (
            v["source.set_0.centre_y"] - traced[1]
        ) ** 2
        return -200.0 * (v["mass.einstein_radius"] - truth) ** 2 - source

    posterior = sp_start._Posterior(likelihood, SCAN_SPACE)
    values = {name: 0.5 for name in SCAN_SPACE.names}
    point, einstein_radius = sp_start.scanned_start(posterior, values, x, y, weight, centre, 3.0)
    grid = sp_start._einstein_radius_grid(3.0)
    assert einstein_radius == grid[np.argmin(np.abs(grid - truth))]
    assert posterior.calls == sp_start.EINSTEIN_RADIUS_GRID
    source = sp_start._scatter((einstein_radius, 0.0, 0.0, 0.0, 0.0), centre, x, y, weight)[:2]
    assert (point["source.set_0.centre_x"], point["source.set_0.centre_y"]) == source
    assert point["mass.einstein_radius"] == einstein_radius
    assert (point["mass.centre_x"], point["mass.centre_y"]) == centre
    assert all(point[n] == 0.0 for n in ("mass.ell_comps_1", "mass.ell_comps_2",
                                         "shear.gamma_1", "shear.gamma_2"))  # fmt: skip


def test_pn_mge_searches_its_start_with_the_non_negative_solve(mock_folder, tmp_path, monkeypatch):
    """With ``positive_only: false`` (pn-MGE) the start's likelihood is the non-negative
    one, point for point (docs/paper_mocks.md, M3 pn-MGE), while SP samples pn-MGE."""
    pn = sp_phase.problem(
        mock_folder, mock_folder, settings_from_mapping({"fit": {"positive_only": False}}), LENS
    )
    nn = sp_phase.problem(mock_folder, mock_folder, settings_from_mapping({}), LENS)
    assert nn.dataset.non_negative() is nn.dataset
    seen = {}

    def search(dataset, space, model, likelihood, radius):
        seen.update(dataset=dataset, likelihood=likelihood)
        return sp_start.SPStart(None, None, 0.0, None, 0, 0, 0.0)

    monkeypatch.setattr(sp_start, "search", search)
    started = run.started_sp(pn, tmp_path, {})
    assert started.dataset is pn.dataset
    assert not started.dataset.settings.positive_only
    assert seen["dataset"].settings.positive_only
    assert seen["dataset"].light_grid is pn.dataset.light_grid
    truth = mock_lenses.paper_mock("M1").mass[0]
    x = pn.space.prior_transform(np.full(pn.space.n_free, 0.5))
    x[pn.space.free_names.index("mass.einstein_radius")] = truth.einstein_radius
    nn_value = run.PhaseLikelihood(nn.dataset, nn.space, nn.model)(x)
    pn_value = run.PhaseLikelihood(pn.dataset, pn.space, pn.model)(x)
    assert seen["likelihood"](x) == pytest.approx(nn_value, rel=1e-12)
    # the unconstrained solve fits at least as well: a different likelihood
    assert pn_value > nn_value + 1.0


def test_sps_sampler_checks_its_posterior_against_the_start(
    mock_problem, mock_start, tmp_path, monkeypatch
):
    """The start is SP's reference point: run_nested receives its vector in the started
    space, and the quick profile's SP samples again if its posterior falls short of it."""
    monkeypatch.setattr(sp_start, "search", lambda *_: mock_start)
    started = run.started_sp(mock_problem, tmp_path, {})
    assert started.reference == mock_start.values
    seen = []

    def sampled(likelihood, space, sampler, checkpoint, seed, log, reference):
        seen.append(reference)
        raise RuntimeError("stop before sampling")

    monkeypatch.setattr(run, "run_nested", sampled)
    sampler = profile_settings("quick").samplers["sp"]
    with pytest.raises(RuntimeError, match="stop before sampling"):
        run._sample_problems([started], sampler, [0], [tmp_path / "c.pickle"], tmp_path, tmp_path)
    np.testing.assert_array_equal(seen[0], started.space.vector(mock_start.values))
    assert (sampler.peak_restarts, sampler.peak_evaluations) == (1, 0)

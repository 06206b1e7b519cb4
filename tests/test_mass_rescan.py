"""SPix1's rescan of θ_E (mgelens.pipeline.mass_rescan) on analytic ln ε surfaces with a
second basin, the re-centred priors, the record's reuse, and where MASS takes its image
positions from."""

import dataclasses
import json
from types import SimpleNamespace

import numpy as np
import pytest

from mgelens.mass import SIE
from mgelens.pipeline import mass_rescan, models, run, sp_start
from mgelens.pipeline.problem import positions_penalty
from mgelens.pipeline.settings import profile_settings, settings_from_mapping
from mgelens.rejection import REJECTED_LOG_LIKELIHOOD
from mgelens.search.model import ParameterSpace
from mgelens.search.priors import LogUniform, TruncatedGaussian

SP_MASS = {
    "mass.centre_x": 0.0,
    "mass.centre_y": 0.0,
    "mass.ell_comps_1": 0.05,
    "mass.ell_comps_2": 0.0,
    "mass.einstein_radius": 1.45,
    "shear.gamma_1": 0.0,
    "shear.gamma_2": 0.0,
}
"""SP's (wrong) mass: the passed priors' means."""
TRUE_MASS = {
    "mass.centre_x": 0.03,
    "mass.centre_y": -0.02,
    "mass.ell_comps_1": 0.0,
    "mass.ell_comps_2": -0.04,
    "mass.einstein_radius": 1.18,
    "shear.gamma_1": 0.02,
    "shear.gamma_2": -0.03,
}
WIDTHS = {"einstein_radius": 0.005, "centre_x": 0.05, "centre_y": 0.05}
"""Widths of each basin in ln ε (arcsec); 0.03 for ell_comps and shear."""


def spix1_space() -> ParameterSpace:
    """SPix1's eight free parameters, the mass and shear around :data:`SP_MASS` (priors
    wide enough that ln P is ln ε to within 0.1 at every point compared)."""
    priors = {
        name: TruncatedGaussian(value, 0.25 * value if name.endswith("radius") else 1.0,
                                0.0 if name.endswith("radius") else -np.inf, np.inf)
        for name, value in SP_MASS.items()
    }  # fmt: skip
    priors["regularization.coefficient"] = LogUniform(1e-6, 1e6)
    return ParameterSpace.from_priors(priors)


def basin(space, x, centre: dict, height: float, scale: float = 1.0) -> float:
    """ln ε of a Gaussian basin at ``centre``, :data:`WIDTHS` times ``scale`` wide."""
    values = space.values(x)
    chi = [(values[n] - centre[n]) / (scale * WIDTHS.get(n.split(".")[1], 0.03)) for n in centre]
    coefficient = (np.log10(values["regularization.coefficient"]) - 1.0) ** 2
    return height - 0.5 * float(np.sum(np.square(chi))) - coefficient


def two_basins(space, far_height: float):
    """ln ε: SP's basin (peak 0) and the true mass's (peak ``far_height``)."""

    def likelihood(x):
        return max(basin(space, x, SP_MASS, 0.0), basin(space, x, TRUE_MASS, far_height))

    return likelihood


def test_a_far_better_basin_recentres_the_mass_priors_on_it():
    space = spix1_space()
    found = mass_rescan.rescan(space, two_basins(space, 300.0), (0.0, 0.0))
    assert found.reference_einstein_radius == pytest.approx(1.45, abs=1e-3)
    assert abs(found.far_einstein_radius - 1.18) < 0.015  # the scan's 1 % grid
    assert found.far_log_posterior > found.near_log_posterior + 250
    assert found.moved
    # SP's basin polished holds its θ_E (within NEAR of SP's)
    assert found.polished_near_einstein_radius == pytest.approx(1.45, abs=0.002)
    assert found.polished_far > found.polished_near + 290
    assert found.polished_far_einstein_radius == pytest.approx(1.18, abs=0.002)
    for name, truth in TRUE_MASS.items():
        assert found.values[name] == pytest.approx(truth, abs=0.01), name
    # ln ε alone peaks at 10; the LogUniform prior's 1/c makes 1 the grid's best ln P
    assert found.values["regularization.coefficient"] == pytest.approx(1.0)
    recentred = mass_rescan.recentred_space(space, found)
    for name in TRUE_MASS:
        before, after = space.parameter(name).prior, recentred.parameter(name).prior
        assert after.mean == pytest.approx(found.values[name])
        assert (after.sigma, after.lower, after.upper) == (before.sigma, before.lower, before.upper)
    coefficient = "regularization.coefficient"
    assert recentred.parameter(coefficient).prior == space.parameter(coefficient).prior


def test_a_far_basin_below_the_threshold_keeps_sps_priors_after_the_scan_alone():
    space = spix1_space()
    height = mass_rescan.THRESHOLD - 10.0
    found = mass_rescan.rescan(space, two_basins(space, height), (0.0, 0.0))
    assert not found.moved
    assert found.polished_near is None
    assert found.polished_far is None
    assert found.near_einstein_radius == pytest.approx(1.45, abs=1e-3)
    assert found.far_log_posterior < found.near_log_posterior + mass_rescan.THRESHOLD
    n_scan = int(np.ceil(np.log(1.6 / 0.6) / np.log(1.01))) + 1
    assert found.n_calls == len(mass_rescan.COEFFICIENT_GRID) + n_scan + 1
    assert mass_rescan.recentred_space(space, found) is space


def test_a_far_basin_that_is_not_lensed_is_never_taken():
    """SPix1's ``lensing`` check (several images of the source's brightest point) refuses
    the far point: an unlensed copy of the image, which a pixelized source fits well."""
    space = spix1_space()
    asked = []

    def lensing(values):
        asked.append(values["mass.einstein_radius"])
        return False

    found = mass_rescan.rescan(space, two_basins(space, 300.0), (0.0, 0.0), lensing)
    assert asked == [pytest.approx(1.18, abs=0.002)]
    assert found.polished_far > found.near_log_posterior + 290
    assert not found.moved


def test_the_polishes_hold_their_einstein_radius_against_a_barely_lensing_slope():
    """Below θ_E 0.8″, under the scan's range, ln ε climbs as the mass lenses less (a
    pixelized source copies the image there) and soars above both basins. Each polish of
    step 4 stays within NEAR of the θ_E it starts from, so the far basin is still found
    and taken, where a polish free in θ_E could slide down the slope to a mass the images
    check refuses (P05, docs/coverage.md)."""
    space = spix1_space()
    theta = space.free_names.index("mass.einstein_radius")
    basins = two_basins(space, 300.0)

    def likelihood(x):
        radius = x[theta]
        slope = 2000.0 - 1000.0 * radius if 0.2 < radius < 0.8 else -np.inf
        return max(basins(x), slope)

    found = mass_rescan.rescan(
        space, likelihood, (0.0, 0.0), lambda values: values["mass.einstein_radius"] > 0.9
    )
    assert abs(found.polished_near_einstein_radius / 1.45 - 1) <= mass_rescan.NEAR
    assert found.polished_far_einstein_radius == pytest.approx(1.18, abs=0.002)
    assert found.moved
    assert found.values["mass.einstein_radius"] == pytest.approx(1.18, abs=0.002)


@pytest.mark.parametrize("far_height", [45.0, 80.0])
def test_the_polished_basins_decide_against_the_threshold(far_height):
    """SP's values sit 5 widths from their own basin's peak in the mass centre, so the scan
    finds the far point 57 or 92 above them. Polished, SP's basin (which its polish does
    not leave) comes within 45 of the far one, under the threshold, and SP's priors are
    kept; or within 80, and they move."""
    space = spix1_space()
    own_peak = {**SP_MASS, "mass.centre_x": 0.25}
    far = {**SP_MASS, "mass.einstein_radius": 1.18}

    def likelihood(x):
        return max(basin(space, x, own_peak, 0.0), basin(space, x, far, far_height))

    found = mass_rescan.rescan(space, likelihood, (0.0, 0.0))
    assert found.far_log_posterior >= found.near_log_posterior + mass_rescan.THRESHOLD
    assert found.polished_near_einstein_radius == pytest.approx(1.45, abs=0.002)
    assert found.polished_far_einstein_radius == pytest.approx(1.18, abs=0.002)
    assert found.polished_far - found.polished_near == pytest.approx(far_height, abs=1.0)
    assert found.moved is (far_height > mass_rescan.THRESHOLD)


def test_the_rescan_record_is_reused_for_the_same_fingerprint_only(tmp_path):
    space = spix1_space()
    calls = []

    def run():
        calls.append(1)
        return mass_rescan.rescan(space, two_basins(space, 1000.0), (0.0, 0.0))

    first = mass_rescan.read_or_rescan(tmp_path, {"inputs": "a"}, run)
    again = mass_rescan.read_or_rescan(tmp_path, {"inputs": "a"}, run)
    assert len(calls) == 1
    assert again == first
    mass_rescan.read_or_rescan(tmp_path, {"inputs": "b"}, run)
    assert len(calls) == 2


def test_mass_takes_the_image_positions_spix1_sampled_with():
    settings = settings_from_mapping({"positions_penalty": True})
    sp_positions = {"positions": [[1.0, 0.0], [-1.0, 0.1]], "threshold": 0.2}
    spix1_positions = {"positions": [[0.0, 1.2], [0.1, -1.1], [0.9, 0.3]], "threshold": 0.25}
    sp = SimpleNamespace(record={"positions": sp_positions})
    spix1 = SimpleNamespace(result=SimpleNamespace(settings={"positions": spix1_positions}))
    older = SimpleNamespace(result=SimpleNamespace(settings={}))
    penalty = positions_penalty(sp, settings, spix1)
    np.testing.assert_array_equal(penalty.positions, spix1_positions["positions"])
    assert penalty.threshold == 0.25
    for earlier in (None, older):
        penalty = positions_penalty(sp, settings, earlier)
        np.testing.assert_array_equal(penalty.positions, sp_positions["positions"])
    off = settings_from_mapping({"positions_penalty": False})
    assert positions_penalty(sp, off, spix1) is None
    assert isinstance(positions_penalty(sp, settings), models.PositionsPenalty)


def test_the_quick_profile_rescans_and_the_paper_profile_does_not():
    assert profile_settings("quick").spix1_rescan is True
    assert profile_settings("paper").spix1_rescan is False
    with pytest.raises(ValueError, match=r"slam\.spix1_rescan"):
        settings_from_mapping({"spix1_rescan": "yes please"})


PASSED_WIDTHS = {"centre": 0.05, "ell_comps": 0.2, "gamma": 0.05}
"""SLaM's width modifiers (SPEC §8.2; θ_E 25 %): SPix1's passed priors around SP's mass."""
LIGHT_SHAPED = {
    **SP_MASS,
    "mass.centre_x": 0.2,
    "mass.ell_comps_1": -0.05,
    "mass.einstein_radius": 1.43,
    "shear.gamma_1": -0.1,
}
"""P18's case: a basin at SP's θ_E (so the θ_E scan, which holds SP's centre and shear,
does not see it) 4 passed widths away in the centre and 2 in the shear."""


def passed_space(around: dict = SP_MASS) -> ParameterSpace:
    """SPix1's free parameters with the passed widths of :data:`PASSED_WIDTHS` around
    ``around`` (SP's mass)."""
    priors = {}
    for name, value in around.items():
        if name.endswith("radius"):
            priors[name] = TruncatedGaussian(value, 0.25 * value, 0.0, np.inf)
            continue
        width = next(w for key, w in PASSED_WIDTHS.items() if key in name)
        priors[name] = TruncatedGaussian(value, width, -np.inf, np.inf)
    priors["regularization.coefficient"] = LogUniform(1e-6, 1e6)
    return ParameterSpace.from_priors(priors)


def sp_and_light_shaped(space, height: float):
    """ln ε: SP's basin and the light-shaped one, each a fifth of :data:`WIDTHS` wide."""

    def likelihood(x):
        return max(basin(space, x, SP_MASS, 0.0, 0.2), basin(space, x, LIGHT_SHAPED, height, 0.2))

    return likelihood


def offset(point: dict, by: float) -> dict:
    """``point`` with every mass and shear value moved by ``by`` (a polish's imprecision)."""
    return {name: value + by for name, value in point.items()}


def test_a_start_polish_outside_sps_basin_recentres_the_priors_on_it():
    """SP chose the arcs' start; its light-shaped polish lies in a basin SPix1 prefers by
    300 that no θ_E scan reaches. Its other unchosen polish, inside SP's basin, counts for
    nothing."""
    space = passed_space()
    inside = offset(SP_MASS, 0.002)
    found = mass_rescan.rescan(
        space,
        sp_and_light_shaped(space, 300.0),
        (0.0, 0.0),
        start_points=[offset(LIGHT_SHAPED, 0.004), inside],
    )
    assert found.far_log_posterior < found.near_log_posterior  # the scan saw nothing
    assert found.start_widths[0] == pytest.approx(
        mass_rescan.widths_from_sp(space, space.vector({**inside, **LIGHT_SHAPED,
                                                        "regularization.coefficient": 1.0})),
        abs=0.3,
    )  # fmt: skip
    assert found.start_widths[0] > 4.0
    assert found.start_widths[1] < 0.2
    assert found.start_log_posteriors[0] > found.near_log_posterior + 250
    assert found.polished_start > found.near_log_posterior + 290
    assert found.polished_near_einstein_radius == pytest.approx(1.45, abs=0.002)
    assert found.polished_start - found.polished_near == pytest.approx(300.0 - 10.1, abs=1.0)
    assert found.polished_far is None
    assert found.moved
    for name, value in LIGHT_SHAPED.items():
        assert found.values[name] == pytest.approx(value, abs=0.01), name
    recentred = mass_rescan.recentred_space(space, found)
    assert recentred.parameter("mass.centre_x").prior.mean == pytest.approx(0.2, abs=0.01)
    assert recentred.parameter("mass.centre_x").prior.sigma == PASSED_WIDTHS["centre"]


@pytest.mark.parametrize("height", [40.0, 300.0])
def test_a_start_polish_needs_the_threshold_and_several_images(height):
    space = passed_space()
    asked = []

    def lensing(values):
        asked.append(values["mass.centre_x"])
        return False

    found = mass_rescan.rescan(
        space,
        sp_and_light_shaped(space, height),
        (0.0, 0.0),
        lensing,
        start_points=[LIGHT_SHAPED],
    )
    assert not found.moved
    coefficient = {"regularization.coefficient": 1.0}
    prior = space.log_prior(space.vector(LIGHT_SHAPED | coefficient)) - space.log_prior(
        space.vector(SP_MASS | coefficient)
    )
    assert prior == pytest.approx(-0.5 * (4.0**2 + 2.0**2 + 0.5**2 + (0.02 / 0.3625) ** 2))
    assert found.start_log_posteriors[0] == pytest.approx(
        found.near_log_posterior + height + prior, abs=0.1
    )
    if height < mass_rescan.THRESHOLD:
        assert found.polished_start is None
        assert asked == []
    else:
        assert asked == [pytest.approx(0.2, abs=0.01)]


def test_a_better_start_polish_within_sps_basin_moves_nothing():
    """P17's case: SP's chosen polish scored 121 above SP's posterior medians in SPix1,
    0.3 passed widths from them; SPix1 samples it within its priors anyway."""
    space = passed_space()
    own_peak = {**SP_MASS, "shear.gamma_1": 0.015}

    def likelihood(x):
        values = space.values(x)
        return basin(space, x, SP_MASS, 0.0) + 0.5 * ((values["shear.gamma_1"] / 0.03) ** 2 - (
            (values["shear.gamma_1"] - 0.015) / 0.001) ** 2)  # fmt: skip

    found = mass_rescan.rescan(space, likelihood, (0.0, 0.0), start_points=[own_peak])
    assert found.start_widths[0] == pytest.approx(0.3, abs=0.01)
    assert found.start_log_posteriors[0] > found.near_log_posterior + 100
    assert found.polished_start is None
    assert not found.moved


def test_sp_start_records_keep_every_polish_and_name_the_unchosen(tmp_path):
    polishes = tuple({"values": {"mass.einstein_radius": r}, "log_posterior": v}
                     for r, v in ((1.08, 3221.2), (1.03, 2443.4), (1.034, 2841.0)))  # fmt: skip
    start = sp_start.SPStart({"mass.einstein_radius": 1.08}, 3221.2, -4e5, None, 1538, 9440,
                             119.0, polishes=polishes)  # fmt: skip
    assert start.chosen == 0
    path = tmp_path / sp_start.START_FILE
    path.write_text(json.dumps({"start": start.to_dict(), "fingerprint": {}}))
    assert sp_start.unchosen_polishes(path) == [{"mass.einstein_radius": 1.03},
                                                {"mass.einstein_radius": 1.034}]  # fmt: skip
    scanned = dataclasses.replace(start, light_shaped_mass=True, scanned_mass=True)
    assert scanned.chosen == 2
    assert [p["mass.einstein_radius"] for p in scanned.unchosen_polishes()] == [1.08, 1.03]
    older = {k: v for k, v in start.to_dict().items() if k != "polishes"}
    path.write_text(json.dumps({"start": older}))
    assert sp_start.unchosen_polishes(path) == []
    assert sp_start.unchosen_polishes(tmp_path / "absent.json") == []
    path.write_text("{")
    with pytest.raises(ValueError, match="delete it and rerun phase 'sp'"):
        sp_start.unchosen_polishes(path)


def test_sp_start_records_give_their_arcs_sphere_as_a_round_mass_at_the_light(tmp_path):
    arcs = sp_start.ArcMass(245, 1.061, 1.195, 0.2, 0.0, 0.1, 0.0, 0.17, -0.09, 0.28)
    start = sp_start.SPStart({"mass.einstein_radius": 0.919}, -18727.1, -20157.9, arcs, 245,
                             9440, 200.0)  # fmt: skip
    path = tmp_path / sp_start.START_FILE
    path.write_text(json.dumps({"start": start.to_dict(), "fingerprint": {}}))
    assert sp_start.arcs_sphere(path, (-0.002, 0.004)) == {
        "mass.centre_x": -0.002,
        "mass.centre_y": 0.004,
        "mass.ell_comps_1": 0.0,
        "mass.ell_comps_2": 0.0,
        "mass.einstein_radius": 1.061,
        "shear.gamma_1": 0.0,
        "shear.gamma_2": 0.0,
    }
    path.write_text(json.dumps({"start": dataclasses.replace(start, arcs=None).to_dict()}))
    assert sp_start.arcs_sphere(path, (0.0, 0.0)) is None
    assert sp_start.arcs_sphere(tmp_path / "absent.json", (0.0, 0.0)) is None


SP_FLATTENED = {**SP_MASS, "mass.ell_comps_1": 0.39, "mass.einstein_radius": 1.023}
"""slacs1451−0239's case: SP's mass flattened by its parametric source (q ≈ 0.44)."""
ROUND_MASS = {**SP_MASS, "mass.einstein_radius": 1.1}
"""A round mass at the light centre, of another θ_E (on slacs1451−0239 Bolton's b 1.04″)."""


def test_the_arcs_sphere_reaches_a_round_basin_that_the_flattened_polishes_miss():
    """The round basin lies 65 of its widths from SP's ellipticity and 77 from SP's θ_E, so
    neither the θ_E scan (which holds SP's ellipticity) nor a polish from SP's basin or
    from SP's flattened polishes sees it, and SP's weak shear leaves step 6 out; only the
    arcs' sphere, half a width off in θ_E, starts within its reach."""
    space = passed_space(SP_FLATTENED)

    def likelihood(x):
        return max(basin(space, x, SP_FLATTENED, 0.0, 0.2), basin(space, x, ROUND_MASS, 300.0, 0.2))

    polishes = [{**SP_FLATTENED, "mass.einstein_radius": r} for r in (1.195, 1.309)]
    sphere = {**ROUND_MASS, "mass.einstein_radius": 1.1005}
    without = mass_rescan.rescan(space, likelihood, (0.0, 0.0), start_points=polishes)
    assert not without.moved
    assert without.shear_free is None
    found = mass_rescan.rescan(space, likelihood, (0.0, 0.0), start_points=[*polishes, sphere])
    assert found.start_log_posteriors[2] > found.near_log_posterior + 250
    assert found.moved
    for name, value in ROUND_MASS.items():
        assert found.values[name] == pytest.approx(value, abs=0.005), name


SP_SHEARED = {**SP_MASS, "mass.einstein_radius": 1.0, "shear.gamma_2": -0.17}
"""P25's case: SP's SIE with a strong shear, 3.4 passed widths from no shear."""
ROUND_TRUTH = {
    **SP_MASS,
    "mass.centre_x": 0.03,
    "mass.einstein_radius": 0.87,
    "shear.gamma_1": 0.01,
    "shear.gamma_2": -0.03,
}
"""The true mass: another θ_E, a weak shear; a fifth of :data:`WIDTHS` wide, so that the
θ_E scan at SP's shear (0.14 away) sees nothing of it."""


def sheared_and_round(space, height: float):
    def likelihood(x):
        return max(basin(space, x, SP_SHEARED, 0.0, 0.2), basin(space, x, ROUND_TRUTH, height, 0.2))

    return likelihood


def test_sps_mass_without_its_shear_finds_the_basin_no_scan_reaches():
    space = passed_space(SP_SHEARED)
    found = mass_rescan.rescan(space, sheared_and_round(space, 300.0), (0.0, 0.0))
    # step 2 saw no more than a tail of it
    assert found.far_log_posterior < found.near_log_posterior + mass_rescan.THRESHOLD
    assert found.polished_far is None
    assert found.start_log_posteriors == ()
    assert found.shear_free > found.near_log_posterior + 250
    assert found.polished_shear_free_einstein_radius == pytest.approx(0.87, abs=0.002)
    assert found.polished_shear_free_widths > 2.5
    assert found.polished_near_einstein_radius == pytest.approx(1.0, abs=0.002)
    assert found.moved
    for name, value in ROUND_TRUTH.items():
        assert found.values[name] == pytest.approx(value, abs=0.005), name
    recentred = mass_rescan.recentred_space(space, found)
    assert recentred.parameter("shear.gamma_2").prior.mean == pytest.approx(-0.03, abs=0.005)


@pytest.mark.parametrize("height", [None, 300.0])
def test_a_right_strong_shear_or_an_unlensed_basin_keeps_sps_priors(height):
    """Without a second basin the polish from no shear stays below SP's basin and nothing
    more is polished; a better shear-free basin that forms one image is not taken."""
    space = passed_space(SP_SHEARED)
    if height is None:

        def likelihood(x):
            return basin(space, x, SP_SHEARED, 0.0, 0.2)

    else:
        likelihood = sheared_and_round(space, height)
    found = mass_rescan.rescan(space, likelihood, (0.0, 0.0), lambda values: False)
    assert not found.moved
    assert found.shear_free is not None
    if height is None:
        assert found.shear_free < found.near_log_posterior + mass_rescan.THRESHOLD
        assert found.polished_shear_free is None
        assert found.n_calls < 700
    else:
        assert found.polished_shear_free > found.polished_near + 250


def test_a_weak_shear_is_not_rescanned_without_it():
    space = passed_space()
    found = mass_rescan.rescan(space, sp_and_light_shaped(space, 300.0), (0.0, 0.0))
    assert found.shear_free is None
    assert found.polished_shear_free is None


def test_a_polish_from_beyond_the_centre_box_moves_inside_it():
    """SP's mass centre can end beyond the polish's box around the light (slacs1250+0523:
    0.305″); the boxed posterior rejects that point, and a polish from it must still climb
    rather than return its start."""
    space = spix1_space()
    posterior = sp_start._Posterior(two_basins(space, 0.0), space)
    x = space.vector(
        {**SP_MASS, **TRUE_MASS, "mass.centre_x": 0.305, "regularization.coefficient": 10.0}
    )
    assert posterior.boxed({0: (-0.3, 0.3)})(x) == REJECTED_LOG_LIKELIHOOD
    posterior.boxed({})
    start = posterior(x)
    polished, value = mass_rescan._polish(posterior, x, (0.0, 0.0), calls=600)
    assert value > start + 10.0
    assert space.values(polished)["mass.centre_x"] == pytest.approx(0.03, abs=0.01)


@pytest.mark.parametrize(("einstein_radius", "expected"), [(1.0, True), (0.3, False)])
def test_the_rescan_moves_only_to_a_mass_that_multiply_images_most_of_the_arcs(
    einstein_radius, expected
):
    """A ring of radius 1″ seen through a sphere of θ_E 1″ traces to the caustic point,
    imaged many times; through θ_E 0.3″ it traces to a circle of 0.7″, imaged once
    (slacs1250+0523's rescan preferred such a barely lensing mass)."""
    pixel = 0.05
    x, y = np.meshgrid(pixel * (np.arange(81) - 40.0), pixel * (np.arange(81) - 40.0))
    mask = np.hypot(x, y) > 2.0
    x, y = x[~mask], y[~mask]
    ring = 10.0 * np.exp(-0.5 * ((np.hypot(x, y) - 1.0) / 0.05) ** 2)
    dataset = SimpleNamespace(
        pixel_centres=(x, y),
        noise_map=np.ones(x.size),
        mask=mask,
        imaging=SimpleNamespace(pixel_scale=pixel),
    )
    result = SimpleNamespace(
        dataset=dataset,
        model=SimpleNamespace(mass=(SIE((0.0, 0.0), einstein_radius, 1.0, 0.0),)),
        lensed_source_image=ring,
    )
    assert run.multiply_imaged(result, 2.0) is expected

"""Isophotes of a fitted lens light against the truth's (mgelens.isophote_recovery): the
measured truth against a mock's analytic isophote table, and the scores against known
changes of shape."""

import dataclasses

import numpy as np
import pandas as pd
import pytest

from mgelens import mock_lenses, mock_light, simulate
from mgelens.convolve import convolve_image
from mgelens.isophote_recovery import (
    COMPARISON_RADII,
    ISOPHOTE_TOLERANCES,
    PROFILE_COLUMNS,
    angle_difference,
    compare_isophotes,
    isophote_recovery,
    profile_on_radii,
    true_light_centre,
)
from mgelens.isophotes import isophote_table
from mgelens.plot.isophote_recovery import isophote_recovery_figure
from mgelens.recovery import recovery_summary, recovery_table

PIXEL_SCALE = 0.05
SHAPE = (151, 151)


def table(sma, q, pa, a4) -> pd.DataFrame:
    """A minimal isophote table (the columns the comparison reads)."""
    n = len(sma)
    return pd.DataFrame(
        {
            "sma": sma,
            "q": np.broadcast_to(q, n),
            "pa": np.broadcast_to(pa, n),
            "a4_a": np.broadcast_to(a4, n),
        }
    )


def analytic_table(light: mock_light.IsophoteLight) -> pd.DataFrame:
    """truth.json's isophote table of a population mock as an isophote table."""
    truth = light.isophote_table()
    return table(truth["sma"], truth["axis_ratio"], truth["angle"], truth["a4_over_a"])


def light_image(light, psf=True) -> np.ndarray:
    image = simulate.oversampled_image(light, SHAPE, PIXEL_SCALE, 8)
    return convolve_image(image, simulate.Observation().psf()) if psf else image


@pytest.fixture(scope="module")
def population_light() -> mock_light.IsophoteLight:
    """Population lens 1: q 0.83 → 0.73 and a 16° twist over 0.5–2.5″, boxy a₄/a −0.013."""
    return mock_lenses.population_lens(1).light


@pytest.fixture(scope="module")
def measured_truth(population_light) -> pd.DataFrame:
    """The isophote analysis of the PSF-convolved true light (the recovery's reference)."""
    return isophote_table(light_image(population_light), PIXEL_SCALE, population_light.centre)


def test_angle_difference_wraps_axis_angles_into_plus_minus_90_degrees():
    assert angle_difference(179.0, 1.0) == pytest.approx(-2.0)
    assert angle_difference(1.0, 179.0) == pytest.approx(2.0)
    assert angle_difference(100.0, 10.0) == pytest.approx(-90.0)
    assert angle_difference(45.0, 44.5) == pytest.approx(0.5)


def test_profile_interpolates_in_log_radius_and_through_the_180_degree_wrap():
    sma = np.geomspace(0.2, 3.0, 9)
    q = 0.6 + 0.05 * np.log(sma)
    pa = np.mod(170.0 + 10.0 * np.log(sma / 0.2), 180.0)  # 170° at 0.2″, past 180° beyond 0.54″
    profile = profile_on_radii(table(sma, q, pa, 0.0), [0.1, 0.3, 1.0, 2.0, 4.0])
    inside = profile.iloc[1:4]
    assert inside["q"].to_numpy() == pytest.approx(0.6 + 0.05 * np.log([0.3, 1.0, 2.0]))
    expected = np.mod(170.0 + 10.0 * np.log(np.array([0.3, 1.0, 2.0]) / 0.2), 180.0)
    assert inside["pa"].to_numpy() == pytest.approx(expected)
    assert profile[["q", "pa", "a4_a"]].iloc[[0, 4]].isna().all(axis=None)


def test_identical_profiles_recover_exactly_and_a_changed_one_names_its_error():
    sma = np.geomspace(0.3, 3.0, 30)
    truth = table(sma, 0.7, 30.0, -0.01)
    same = isophote_recovery(truth, truth)
    assert same.within_tolerance
    assert same.n_compared == same.n_radii == len(COMPARISON_RADII)
    assert same.max_abs_axis_ratio_error == same.max_abs_angle_error == 0.0
    rounder = isophote_recovery(table(sma, 0.73, 30.0, -0.01), truth)
    assert rounder.max_abs_axis_ratio_error == pytest.approx(0.03)
    assert not rounder.within_tolerance
    turned = isophote_recovery(table(sma, 0.7, 210.0 - 3.0, -0.01), truth)
    assert turned.max_abs_angle_error == pytest.approx(3.0)
    assert not turned.within_tolerance
    boxier = isophote_recovery(table(sma, 0.7, 30.0, -0.016), truth)
    assert boxier.max_abs_a4_error == pytest.approx(0.006)
    assert not boxier.within_tolerance
    short = isophote_recovery(table(sma[sma < 1.5], 0.7, 30.0, -0.01), truth)
    assert short.n_compared < short.n_radii
    assert short.max_abs_axis_ratio_error == 0.0
    assert not short.within_tolerance  # the whole range 0.5–2.5″ is asked for


def test_round_true_isophotes_have_no_angle_to_compare():
    sma = np.geomspace(0.3, 3.0, 30)
    profile = compare_isophotes(table(sma, 0.97, 80.0, 0.0), table(sma, 0.97, 10.0, 0.0))
    assert list(profile.columns) == list(PROFILE_COLUMNS)
    assert profile["pa_error"].isna().all()
    turned = isophote_recovery(table(sma, 0.97, 80.0, 0.0), table(sma, 0.97, 10.0, 0.0))
    assert turned.within_tolerance


def test_measured_truth_matches_the_mocks_analytic_isophotes_before_the_psf(population_light):
    """The isophote analysis of the unconvolved true light reproduces truth.json's table;
    the PSF rounds the inner isophotes by more than the q tolerance allows, which is why
    the recovery measures the PSF-convolved truth rather than reading the table."""
    analytic = analytic_table(population_light)
    raw = isophote_table(
        light_image(population_light, psf=False), PIXEL_SCALE, population_light.centre
    )
    exact = isophote_recovery(raw, analytic)
    assert exact.n_compared == exact.n_radii
    assert exact.max_abs_axis_ratio_error < 0.003
    assert exact.max_abs_angle_error < 0.05
    assert exact.max_abs_a4_error < 0.0003
    truth = exact.true_statistics
    assert truth["delta_q_max"] > 0.08
    assert truth["delta_pa_max"] > 10.0
    convolved = isophote_table(light_image(population_light), PIXEL_SCALE, population_light.centre)
    rounded = compare_isophotes(convolved, analytic)
    assert rounded["q_error"].iloc[0] > 0.005  # rounder at 0.5″ after the PSF
    assert abs(rounded["q_error"].iloc[-1]) < 0.002


def test_a_fitted_light_of_changed_shape_fails_and_the_true_one_passes(
    population_light, measured_truth
):
    itself = isophote_recovery(measured_truth, measured_truth)
    assert itself.within_tolerance
    assert itself.max_abs_axis_ratio_error == 0.0
    q = population_light.axis_ratio
    flatter = dataclasses.replace(
        population_light,
        axis_ratio=dataclasses.replace(q, inner=q.inner - 0.03, outer=q.outer - 0.03),
    )
    fitted = isophote_table(light_image(flatter), PIXEL_SCALE, population_light.centre)
    result = isophote_recovery(fitted, measured_truth)
    assert not result.within_tolerance
    assert 0.02 < result.max_abs_axis_ratio_error < 0.04
    assert result.max_abs_angle_error < ISOPHOTE_TOLERANCES.angle
    profile = pd.DataFrame(result.profile)
    assert (profile["q_error"] < 0).all()
    figure = isophote_recovery_figure(fitted, measured_truth, profile, "population 1")
    assert len(figure.axes) == 6
    assert figure.axes[0].get_xscale() == "log"
    assert "arcsec" in figure.axes[3].get_xlabel()


def test_the_record_and_table_carry_the_isophote_scores(measured_truth):
    result = isophote_recovery(measured_truth, measured_truth)
    record = recovery_summary("mock", [], None, isophotes=result)
    assert record["criteria"]["isophotes_within_tolerance"] is True
    assert record["isophotes"]["n_compared"] == len(COMPARISON_RADII)
    row = recovery_table([record]).iloc[0]
    assert row["isophotes.max_abs_axis_ratio_error"] == 0.0
    assert row["isophotes.true.delta_pa_max"] == pytest.approx(
        result.true_statistics["delta_pa_max"]
    )
    bare = recovery_table([recovery_summary("mock", [], None)]).iloc[0]
    assert np.isnan(bare["isophotes.max_abs_axis_ratio_error"])
    assert bare["isophotes_within_tolerance"] is None


def test_true_light_centre_of_paper_and_population_truths(population_light):
    m1 = simulate.simulate(mock_lenses.paper_mock("M1"), simulate.Observation(image_size=31)).truth
    assert true_light_centre(m1) == (0.013, -0.07)
    assert true_light_centre({"lens_light": population_light.to_dict()}) == pytest.approx(
        population_light.centre
    )
    with pytest.raises(ValueError, match="no centre"):
        true_light_centre({"lens_light": {"model": "image"}})

"""Tests of mgelens.published: ids, θ_E conventions (SPEC §3.3), reference tables, slope."""

import logging
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mgelens import published
from mgelens.mass import EPL

REFERENCE_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "reference"


@pytest.fixture(scope="module")
def reference_dir():
    if not (REFERENCE_DIR / published.BOLTON_FILE).is_file():
        pytest.skip(f"published reference tables absent: expected them in {REFERENCE_DIR}")
    return REFERENCE_DIR


def test_lens_keys_match_across_the_three_naming_schemes():
    for name in ("slacs0008-0004", "J0008-0004", "SDSSJ0008-0004", " SDSSJ0008-0004 "):
        assert published.lens_key(name) == "J0008-0004"
    assert published.lens_key("slacs1020+1122") == "J1020+1122"
    assert published.lens_key("M1") is None
    assert published.lens_key("P07") is None


def test_conversion_matches_the_spec_formula():
    theta, q, slope = 1.2, 0.8, 2.2
    expected = theta * math.sqrt(q) * (2.0 / (1.0 + q)) ** (1.0 / (slope - 1.0))
    assert published.einstein_radius_lt(theta, q, slope) == pytest.approx(expected, rel=1e-14)
    assert expected == pytest.approx(1.17181, abs=1e-5)  # by hand: 1.2 · 0.894427 · 1.09182
    # SIE limit: factor 2√q/(1+q); round bodies: no change at any slope
    for q in (0.3, 0.7, 0.95):
        factor = published.einstein_radius_lt(1.0, q, 2.0)
        assert factor == pytest.approx(2.0 * math.sqrt(q) / (1.0 + q), rel=1e-14)
    for slope in (1.6, 2.0, 2.7):
        assert published.einstein_radius_lt(1.3, 1.0, slope) == pytest.approx(1.3, rel=1e-14)


def test_conversion_round_trips_and_broadcasts():
    rng = np.random.default_rng(0)
    theta = rng.uniform(0.5, 2.0, 50)
    q = rng.uniform(0.2, 1.0, 50)
    slope = rng.uniform(1.5, 2.9, 50)
    lt = published.einstein_radius_lt(theta, q, slope)
    np.testing.assert_allclose(published.einstein_radius_ag(lt, q, slope), theta, rtol=1e-13)
    assert published.einstein_radius_lt(theta, 0.8, 2.0).shape == (50,)


def test_converted_radius_gives_lenstronomys_convergence():
    """κ of our EPL equals lenstronomy's κ = (2 − t)/2 · (θ_LT / √(q x′² + y′²/q))^t."""
    theta, q, slope = 1.1, 0.65, 2.3
    profile = EPL((0.0, 0.0), theta, q, 0.0, slope)
    theta_lt = published.einstein_radius_lt(theta, q, slope)
    x = np.array([0.3, 1.0, -0.7, 0.2, 2.0])
    y = np.array([0.1, -0.4, 0.9, 1.5, 0.3])
    t = slope - 1.0
    expected = (2.0 - t) / 2.0 * (theta_lt / np.sqrt(q * x**2 + y**2 / q)) ** t
    np.testing.assert_allclose(profile.convergence(x, y), expected, rtol=1e-10)


def test_posterior_is_converted_sample_by_sample():
    samples = pd.DataFrame(
        {
            "weight": [1.0, 2.0, 1.0],
            "mass.einstein_radius": [1.0, 1.1, 1.2],
            "mass.axis_ratio": [0.5, 0.8, 1.0],
            "mass.slope": [2.0, 2.0, 2.0],
        }
    )
    values = published.posterior_einstein_radius(samples)
    assert values["theta_e"] == 1.1
    assert values["slope"] == 2.0
    converted = [2 * math.sqrt(0.5) / 1.5, 1.1 * 2 * math.sqrt(0.8) / 1.8, 1.2]
    assert values["theta_e_lt"] == pytest.approx(converted[1], rel=1e-14)
    assert values["theta_e_lt_lower"] == pytest.approx(converted[0], rel=1e-14)
    assert values["theta_e_lt_upper"] == pytest.approx(converted[2], rel=1e-14)
    with pytest.raises(KeyError):
        published.posterior_einstein_radius(samples.drop(columns="mass.slope"))


def test_published_values_match_ids_and_keep_imaging_only_rows(reference_dir):
    lenses = ["slacs0029-0055", "slacs0008-0004", "M1"]
    table = published.published_values(lenses, reference_dir)
    assert list(table.index) == lenses
    assert list(table.columns) == list(published.PUBLISHED_COLUMNS)
    assert table.loc["slacs0029-0055", "bolton_b_sie"] == 0.96
    assert table.loc["slacs0029-0055", "shajib_theta_e"] == pytest.approx(0.950615, abs=1e-6)
    assert table.loc["slacs0029-0055", "shajib_gamma"] == pytest.approx(2.456279, abs=1e-6)
    assert table.loc["slacs0008-0004", "bolton_b_sie"] == 1.16
    assert math.isnan(table.loc["slacs0008-0004", "shajib_theta_e"])  # flag_imaging = 0
    assert table.loc["M1"].isna().all()
    assert published.read_shajib(reference_dir).shape[0] == 21


def test_absent_reference_folder_gives_nan_and_says_so(tmp_path, caplog):
    with caplog.at_level(logging.WARNING):
        table = published.published_values(["slacs0029-0055"], tmp_path / "nowhere")
    assert table.isna().all().all()
    assert "published lens models not found" in caplog.text
    assert published.published_values([], None).empty


def test_slope_through_origin_recovers_a_known_line():
    rng = np.random.default_rng(1)
    x = rng.uniform(0.8, 1.6, 200)
    y = 1.03 * x + rng.normal(0.0, 0.01, 200)
    slope, error, n = published.slope_through_origin(np.append(x, np.nan), np.append(y, 1.0))
    assert n == 200
    assert slope == pytest.approx(1.03, abs=3 * error)
    assert error == pytest.approx(0.01 / np.sqrt(np.sum(x * x)), rel=0.15)
    exact = published.slope_through_origin([1.0, 2.0], [0.5, 1.0])
    assert exact == (0.5, 0.0, 2)
    assert math.isnan(published.slope_through_origin([], [])[0])
    assert math.isnan(published.slope_through_origin([2.0], [1.0])[1])


def test_slope_text_drops_an_undefined_error_and_counts_in_the_singular():
    assert published.slope_text(0.8747, 0.0803, 5) == "a = 0.875 ± 0.080 (5 lenses)"
    assert published.slope_text(0.9943, math.nan, 1) == "a = 0.994 (1 lens)"

"""Recovery of a mock's truth (SPEC §11 criteria): mass against credible intervals, lens
light against the true image."""

import dataclasses
import json
from types import SimpleNamespace

import numpy as np
import pytest

from mgelens import simulate
from mgelens.grid import pixel_centres
from mgelens.recovery import (
    lens_light_recovery,
    mass_recovery,
    recovery_summary,
    recovery_table,
    true_mass_parameters,
)


def truth_of(lens) -> dict:
    """The ``mass`` block of a mock's truth.json."""
    entries = [{"type": type(p).__name__, "parameters": dataclasses.asdict(p)} for p in lens.mass]
    return {"mass": entries}


def test_true_mass_parameters_of_paper_and_population_mocks():
    m1 = true_mass_parameters(truth_of(simulate.paper_mock("M1")))
    assert m1 == {
        "mass.centre_x": 0.013,
        "mass.centre_y": -0.07,
        "mass.einstein_radius": 1.2,
        "mass.axis_ratio": 0.8,
        "mass.angle": 45.0,
        "mass.slope": 2.1,
        "shear.gamma_1": 0.0,
        "shear.gamma_2": 0.0,
    }
    lens = simulate.population_lens(0)
    population = true_mass_parameters(truth_of(lens))
    assert population["shear.gamma_1"] == lens.mass[1].gamma_1
    with pytest.raises(ValueError, match="no EPL"):
        true_mass_parameters({"mass": []})


def fake_phase(median: dict, interval: dict):
    return SimpleNamespace(median=median, interval=lambda sigma: interval)


def test_mass_recovery_intervals_and_angle_wrap():
    truth = {"mass": [{"type": "EPL", "parameters": {
        "centre": [0.0, 0.1], "einstein_radius": 1.0, "axis_ratio": 0.8, "angle": 179.0,
        "slope": 2.0}}]}  # fmt: skip
    median = {"mass.centre_x": 0.01, "mass.einstein_radius": 1.03, "mass.angle": 1.0,
              "mass.slope": 2.2}  # fmt: skip
    interval = {"mass.centre_x": (-0.01, 0.03), "mass.einstein_radius": (1.01, 1.05),
                "mass.angle": (-2.0, 4.0), "mass.slope": (2.1, 2.3)}  # fmt: skip
    rows = {row.name: row for row in mass_recovery(truth, fake_phase(median, interval))}
    assert set(rows) == set(median)  # parameters the phase did not fit are skipped
    assert rows["mass.centre_x"].within_3sigma
    assert not rows["mass.einstein_radius"].within_3sigma
    assert rows["mass.angle"].within_3sigma  # 179° = −1° inside (−2°, 4°)
    assert rows["mass.angle"].error == pytest.approx(2.0)
    assert not rows["mass.slope"].within_3sigma
    summary = recovery_summary("X", list(rows.values()), None)
    assert summary["einstein_radius_relative_error"] == pytest.approx(0.03)
    table = recovery_table([json.loads(json.dumps(summary))])
    assert table.loc[0, "mass.angle.within_3sigma"]
    assert table.loc[0, "mass.slope.median"] == 2.2
    assert np.isnan(table.loc[0, "lens_light.mean"])
    assert summary["criteria"] == {
        "einstein_radius_within_2_percent": False,
        "epl_within_3sigma": False,
        "lens_light_within_5_percent": None,
    }
    json.dumps(summary)


def test_lens_light_recovery_excludes_the_centre_and_outside_the_mask():
    shape, pixel_scale, centre = (41, 41), 0.1, (0.1, -0.1)
    x, y = pixel_centres(shape, pixel_scale)
    radius = np.hypot(x - centre[0], y - centre[1])
    true = np.exp(-radius / 0.5)
    model = true * (1.0 + 0.02 * np.cos(3 * np.arctan2(y, x)))
    model[radius <= 0.2] *= 3.0  # the excluded centre
    mask = np.hypot(x, y) > 1.5
    model[mask] = 0.0  # outside the mask (the fit's LENS image is zero there)
    light = lens_light_recovery(true, model, mask, pixel_scale, centre)
    assert light.n_pixels == np.count_nonzero(~mask & (radius > 0.2))
    assert light.max_abs == pytest.approx(0.02, rel=1e-3)
    assert abs(light.mean) < 2e-3
    assert light.fraction_within_tolerance == 1.0
    summary = recovery_summary("X", [], light)
    assert summary["criteria"]["lens_light_within_5_percent"] is True
    assert summary["criteria"]["epl_within_3sigma"] is False  # nothing fitted, nothing shown
    with pytest.raises(ValueError, match="shape"):
        lens_light_recovery(true, model[:-1], mask, pixel_scale, centre)

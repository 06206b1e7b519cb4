"""The quick profile on the paper's mock M1 at full size (SPEC §10): slow, real searches."""

import pytest

from mgelens import simulate
from mgelens.pipeline import phases
from mgelens.pipeline.settings import profile_settings
from mgelens.recovery import true_mass_parameters


@pytest.mark.slow
def test_quick_sp_lands_in_the_true_mass_basin_of_m1(tmp_path):
    """SP hands its maximum-likelihood SIE + shear on to every later phase (priors,
    positions penalty, fixed lens-light geometry), so it must find the true basin.

    The truth is an EPL (γ = 2.1, q = 0.8, φ = 45°, centre (0.013, −0.070)) without
    shear. With 36 live points the quick SP stopped in a false mode (q 0.65, shear 0.067,
    centre y −0.004, max ln L −39,655); with the profile's 60 it reached q 0.80, shear
    0.006, centre (0.014, −0.074) and θ_E 1.187 (max ln L −7,019; −7,428 with seed 1).
    """
    mock = simulate.simulate(simulate.paper_mock("M1"))
    truth = true_mass_parameters(mock.truth)
    lens_dir = simulate.write_mock(mock, tmp_path / "mock")
    result = phases.run_phase(
        "sp", lens_dir, tmp_path / "results", profile_settings("quick"), seed=0, threads=2
    )
    best = result.max_likelihood
    assert best["mass.axis_ratio"] == pytest.approx(truth["mass.axis_ratio"], abs=0.05)
    assert best["mass.centre_x"] == pytest.approx(truth["mass.centre_x"], abs=0.02)
    assert best["mass.centre_y"] == pytest.approx(truth["mass.centre_y"], abs=0.02)
    assert best["mass.einstein_radius"] == pytest.approx(truth["mass.einstein_radius"], rel=0.03)
    assert best["shear.magnitude"] < 0.03
    assert result.output.log_likelihoods.max() > -20_000

"""SLaM pipeline: parameter spaces, values → profiles, prior passing, settings, products,
a tiny end-to-end SP phase and checkpoint resume (SPEC §8)."""

import dataclasses
import json
import logging
import re
import shutil
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pytest
from astropy.io import fits
from sampler_outputs import equal_weight_run

from mgelens import mock_lenses, simulate
from mgelens.cli import main
from mgelens.fit import FitError, MGESource, fit
from mgelens.geometry import axis_ratio_and_angle_from, ell_comps_from
from mgelens.grid import pixel_centres
from mgelens.imaging import Imaging
from mgelens.isophotes import STATISTICS_SMA_RANGE, isophote_table
from mgelens.mask import contaminant_regions_from_noise
from mgelens.mass import EPL, SIE, ExternalShear, ray_trace
from mgelens.pipeline import (
    mass_rescan,
    mesh_pool,
    mesh_tuning,
    models,
    problem,
    products,
    records,
    run,
    sp_start,
)
from mgelens.pipeline.job_cost import recorded_cpu_seconds
from mgelens.pipeline.phases import light as light_phase
from mgelens.pipeline.phases import mass as mass_phase
from mgelens.pipeline.phases import sp as sp_phase
from mgelens.pipeline.phases import spix1 as spix1_phase
from mgelens.pipeline.phases import spix2 as spix2_phase
from mgelens.pipeline.settings import (
    PHASES,
    LensSpec,
    SettingsError,
    load_settings,
    profile_settings,
    settings_from_mapping,
)
from mgelens.recovery import true_light_refit
from mgelens.search.priors import LogUniform, TruncatedGaussian, Uniform
from mgelens.search.results import PhaseResult
from mgelens.source.image_mesh import kmeans_centres, kmeans_weights, overlay_centres
from mgelens.source_share import source_share

PIXEL = 0.1
MASK_RADIUS = 1.4
LENS = LensSpec(mask_radius=MASK_RADIUS)
"""The small mock's lens spec (its truth.json holds another radius)."""
SP_SPECS = models.mge_specs(2, False, PIXEL, MASK_RADIUS)

SP_VALUES = {
    "lens_light.set_0.centre_x": 0.01,
    "lens_light.set_0.centre_y": -0.07,
    "lens_light.set_0.ell_comps_1": 0.05,
    "lens_light.set_0.ell_comps_2": -0.1,
    "lens_light.set_1.ell_comps_1": 0.2,
    "lens_light.set_1.ell_comps_2": 0.1,
    "mass.centre_x": 0.013,
    "mass.centre_y": -0.07,
    "mass.ell_comps_1": 0.0,
    "mass.ell_comps_2": 0.11,
    "mass.einstein_radius": 1.2,
    "shear.gamma_1": 0.01,
    "shear.gamma_2": -0.02,
    "source.set_0.centre_x": 0.05,
    "source.set_0.centre_y": 0.02,
    "source.set_0.ell_comps_1": 0.1,
    "source.set_0.ell_comps_2": 0.0,
}
SP_FULL_VALUES = sp_phase.space(SP_SPECS).values(sp_phase.space(SP_SPECS).vector(SP_VALUES))
"""SP_VALUES with the tied centres of ``set_1`` filled in."""
SPIX2_VALUES = {
    "mesh.weight_floor": 0.3,
    "mesh.weight_power": 2.0,
    "regularization.inner_coefficient": 1.0,
    "regularization.outer_coefficient": 2.0,
    "regularization.signal_scale": 0.5,
}


def fake_result(phase, space, centre, scale=0.01, n=400, seed=0) -> PhaseResult:
    """A result whose samples are N(centre, scale²) in every free parameter, equal weights."""
    rng = np.random.default_rng(seed)
    mean = np.array([centre[name] for name in space.free_names])
    samples = mean + scale * rng.standard_normal((n, mean.size))
    log_likelihoods = -0.5 * np.sum(((samples - mean) / scale) ** 2, axis=1)
    output = equal_weight_run(space.free_names, samples, log_likelihoods, seed=seed)
    return PhaseResult(phase, space, output)


@pytest.fixture(scope="module")
def chain():
    """Fake SP, SPix1, SPix2 and LIGHT results (4 sets + point set)."""
    sp = fake_result("sp", sp_phase.space(SP_SPECS), SP_VALUES)
    spix1_space = spix1_phase.space(sp)
    spix1 = fake_result(
        "spix1", spix1_space, {**SP_VALUES, "regularization.coefficient": 3.0}, scale=0.005
    )
    spix2 = fake_result("spix2", spix2_phase.space(sp, spix1), SPIX2_VALUES)
    specs = models.mge_specs(4, True, PIXEL, MASK_RADIUS)
    light_space = light_phase.space(specs, sp, spix1, spix2)
    light_values = {n: 0.05 for n in light_space.free_names}
    light = fake_result("light", light_space, light_values)
    return {"sp": sp, "spix1": spix1, "spix2": spix2, "light": light}


# -- parameter spaces -------------------------------------------------------------------
def test_sp_space_has_17_parameters_and_one_shared_lens_light_centre():
    space = sp_phase.space(SP_SPECS)
    assert space.n_free == 17
    assert space.parameter("lens_light.set_1.centre_x").tied_to == "lens_light.set_0.centre_x"
    assert space.parameter("lens_light.set_1.centre_y").tied_to == "lens_light.set_0.centre_y"
    values = space.values(space.vector(SP_VALUES))
    first, second = models.lens_light_components(values, SP_SPECS)
    assert first.centre == second.centre == (0.01, -0.07)
    assert first.ell_comps == (0.05, -0.1)
    assert second.ell_comps == (0.2, 0.1)
    assert first.n_gaussians == second.n_gaussians == 30
    assert first.sigmas[0] == pytest.approx(PIXEL / 5)
    assert first.sigmas[-1] == pytest.approx(MASK_RADIUS)


def test_sp_mass_centre_tied_to_the_light_is_freed_by_spix1_with_the_width_of_a_tied_centre():
    """``sp_mass_centre: light``: SP's SIE centre follows the lens light's (15 free), and
    SPix1 frees it with N(SP's centre, 0.05″) (SPEC §8.2: a tied centre has no width of
    its own), however narrow the light centre's posterior was."""
    space = sp_phase.space(SP_SPECS, mass_centre="light")
    assert space.n_free == 15
    assert space.parameter("mass.centre_x").tied_to == "lens_light.set_0.centre_x"
    assert space.parameter("mass.centre_y").tied_to == "lens_light.set_0.centre_y"
    values = space.values(space.vector(SP_VALUES))
    sie, _ = models.mass_profiles(values)
    assert sie.centre == (SP_VALUES["lens_light.set_0.centre_x"],
                          SP_VALUES["lens_light.set_0.centre_y"])  # fmt: skip
    sp = fake_result("sp", space, SP_VALUES, scale=0.002)
    spix1 = spix1_phase.space(sp)
    assert spix1.n_free == 8
    for axis in ("centre_x", "centre_y"):
        prior = spix1.parameter(f"mass.{axis}").prior
        assert prior.mean == pytest.approx(sp.median[f"lens_light.set_0.{axis}"])
        assert prior.sigma == 0.05
    with pytest.raises(ValueError, match="'free' or 'light'"):
        sp_phase.space(SP_SPECS, mass_centre="fixed")
    with pytest.raises(SettingsError, match=r"slam\.sp_mass_centre"):
        settings_from_mapping({"sp_mass_centre": "fixed"})
    assert settings_from_mapping({"sp_mass_centre": "light"}).sp_mass_centre == "light"
    assert profile_settings("quick").sp_mass_centre == "free"


def test_phase_spaces_have_the_papers_free_parameter_counts(chain):
    assert spix1_phase.space(chain["sp"]).n_free == 8
    assert spix2_phase.space(chain["sp"], chain["spix1"]).n_free == 5
    assert mass_phase.space(chain["light"], chain["spix1"], chain["spix2"]).n_free == 8


@pytest.mark.parametrize(
    ("n_sets", "point_set", "expected"),
    [(2, False, 6), (2, True, 10), (4, True, 14), (6, True, 18)],
)
def test_light_space_counts(chain, n_sets, point_set, expected):
    specs = models.mge_specs(n_sets, point_set, PIXEL, MASK_RADIUS)
    space = light_phase.space(specs, chain["sp"], chain["spix1"], chain["spix2"])
    assert space.n_free == expected
    if point_set:
        assert specs[-1].name == "point"
        assert specs[-1].sigmas.size == 10
        assert space.parameter("lens_light.point.centre_x").prior is not None


def test_light_space_priors_follow_spec_notes(chain):
    specs = models.mge_specs(4, True, PIXEL, MASK_RADIUS)
    space = light_phase.space(specs, chain["sp"], chain["spix1"], chain["spix2"])
    cx = chain["sp"].max_likelihood["lens_light.set_0.centre_x"]
    assert space.parameter("lens_light.set_0.centre_x").prior == Uniform(cx - 0.1, cx + 0.1)
    assert space.parameter("lens_light.point.centre_x").prior == Uniform(cx - 0.1, cx + 0.1)
    assert space.parameter("lens_light.set_3.ell_comps_2").prior == Uniform(-0.7, 0.7)
    assert space.parameter("lens_light.point.ell_comps_1").prior == TruncatedGaussian(
        0.0, 0.3, -1.0, 1.0
    )
    assert space.parameter("lens_light.set_2.centre_y").tied_to == "lens_light.set_0.centre_y"


def test_fixed_components_take_the_earlier_maximum_likelihood(chain):
    spix2 = spix2_phase.space(chain["sp"], chain["spix1"])
    best = chain["spix1"].max_likelihood
    for name in ("mass.einstein_radius", "mass.ell_comps_2", "shear.gamma_1"):
        assert spix2.parameter(name).value == best[name]
    assert spix2.parameter("lens_light.set_1.centre_x").tied_to == "lens_light.set_0.centre_x"
    mass = mass_phase.space(chain["light"], chain["spix1"], chain["spix2"])
    light_best = chain["light"].max_likelihood
    assert (
        mass.parameter("lens_light.point.ell_comps_1").value
        == light_best["lens_light.point.ell_comps_1"]
    )
    assert (
        mass.parameter("regularization.signal_scale").value
        == chain["spix2"].max_likelihood["regularization.signal_scale"]
    )


def test_smoothness_prior_adds_lights_lambda_and_mass_keeps_it(chain, tmp_path):
    """``lens_light_prior: smoothness``: LIGHT samples ``lens_light.smoothness``
    (LogUniform(1e−3, 1e7)) beside the MGE geometry, MASS fixes it at LIGHT's best, the
    models built in both carry the prior on the extended sets and not the point set, and
    MASS refuses a LIGHT fitted under the other choice."""
    sp, spix1, spix2 = chain["sp"], chain["spix1"], chain["spix2"]
    specs = models.mge_specs(4, True, PIXEL, MASK_RADIUS)
    space = light_phase.space(specs, sp, spix1, spix2, smoothness_prior=True)
    assert space.n_free == 15
    assert space.parameter(models.SMOOTHNESS).prior == LogUniform(1e-3, 1e7)
    values = {n: 0.05 for n in space.free_names} | {models.SMOOTHNESS: 40.0}
    light = fake_result("light", space, values)
    mass = mass_phase.space(light, spix1, spix2)
    assert mass.parameter(models.SMOOTHNESS).value == light.max_likelihood[models.SMOOTHNESS]
    assert models.SMOOTHNESS not in mass.free_names
    model = models.PhaseModel(specs, models.MGESourceModel(), smoothness_prior=True)
    sample = {**SP_VALUES, **light.max_likelihood}
    built = model.build(sample)
    assert built.lens_light_prior.coefficient == light.max_likelihood[models.SMOOTHNESS]
    assert built.lens_light_prior.penalised == (True, True, True, True, False)
    assert model.describe()["lens_light_prior"] == "smoothness"
    assert models.PhaseModel(specs, models.MGESourceModel()).build(sample).lens_light_prior is None
    with pytest.raises(ValueError, match="needs extended MGE sets"):
        models.PhaseModel(specs[-1:], models.MGESourceModel(), smoothness_prior=True)
    record = {"lens_light": {"components": [s.describe() for s in specs]}}
    fitted = problem.EarlierPhase(tmp_path / "light", light, record)
    plain = problem.EarlierPhase(tmp_path / "light", chain["light"], record)
    assert fitted.smoothness_prior
    assert not plain.smoothness_prior
    prior = settings_from_mapping({"lens_light_prior": "smoothness"})
    fitted.check_lens_light(prior, prior=True)
    plain.check_lens_light(prior)
    with pytest.raises(problem.PhaseInputError, match="lens_light_prior = 'none'"):
        plain.check_lens_light(prior, prior=True)
    with pytest.raises(problem.PhaseInputError, match="lens_light_prior = 'smoothness'"):
        fitted.check_lens_light(settings_from_mapping({}), prior=True)
    with pytest.raises(SettingsError, match="lens_light_prior: smoothness applies to the MGE"):
        settings_from_mapping(
            {
                "lens_light_model": "sersic",
                "lens_light_prior": "smoothness",
                "fit": {"positive_only": True},
            }
        )


def test_arcs_support_adds_spix2s_arc_threshold_and_later_phases_keep_it(chain):
    """``source_support: arcs``: SPix2 samples ``mesh.arc_threshold`` (LogUniform(1e−3,
    0.3)) beside its five hyper-parameters; LIGHT and MASS fix it at SPix2's best value,
    and the k-means source then solves only the pixels the arcs reach."""
    sp, spix1 = chain["sp"], chain["spix1"]
    space = spix2_phase.space(sp, spix1, "arcs")
    assert space.n_free == 6
    assert space.parameter(models.ARC_THRESHOLD).prior == models.ARC_THRESHOLD_PRIOR
    assert models.ARC_THRESHOLD_PRIOR == LogUniform(1e-3, 0.3)
    spix2 = fake_result("spix2", space, {**SPIX2_VALUES, models.ARC_THRESHOLD: 0.05})
    best = spix2.max_likelihood[models.ARC_THRESHOLD]
    specs = models.mge_specs(4, True, PIXEL, MASK_RADIUS)
    light = light_phase.space(specs, sp, spix1, spix2)
    mass = mass_phase.space(chain["light"], spix1, spix2)
    for later in (light, mass):
        assert later.parameter(models.ARC_THRESHOLD).value == best
        assert models.ARC_THRESHOLD not in later.free_names
    x, y = pixel_centres((21, 21), PIXEL)
    adapt = np.exp(-((np.hypot(x, y).ravel() - 1.0) ** 2) / 0.02)
    values = {**SPIX2_VALUES, models.ARC_THRESHOLD: 0.05}
    for support, expected in (("mask", None), ("arcs", adapt > 0.05 * adapt.max())):
        kmeans = models.KMeansSourceModel(x.ravel(), y.ravel(), adapt, 40, support=support)
        source = kmeans.build(values)
        if expected is None:
            assert source.arc_pixels is None
        else:
            assert np.array_equal(source.arc_pixels, expected)
        assert kmeans.describe()["source_support"] == support
    for seeding in ("kmeans++", "systematic"):
        kmeans = models.KMeansSourceModel(x.ravel(), y.ravel(), adapt, 40, seeding=seeding)
        expected = kmeans_centres(
            x.ravel(), y.ravel(), kmeans_weights(adapt, 0.1, 2.0), 40, seeding=seeding
        )
        centres = kmeans.centres({"mesh.weight_floor": 0.1, "mesh.weight_power": 2.0})
        assert all(np.array_equal(a, b) for a, b in zip(centres, expected, strict=True))
        assert kmeans.describe()["kmeans_seeding"] == seeding
    noise = np.full(adapt.size, 0.1)
    noise[: adapt.size // 2] = 0.5  # the lower half: arcs need 3 σ = 1.5 there, above the peak
    floored = models.KMeansSourceModel(
        x.ravel(), y.ravel(), adapt, 40, support="arcs", arc_noise_floor=3.0, noise_map=noise
    )
    expected = (adapt > 0.05 * adapt.max()) & (adapt > 3.0 * noise)
    assert 0 < expected.sum() < (adapt > 0.05 * adapt.max()).sum()
    assert np.array_equal(floored.build(values).arc_pixels, expected)
    assert floored.describe()["arc_noise_floor"] == 3.0
    assert "arc_noise_floor" not in kmeans.describe()
    for support, noise_map in (("mask", noise), ("arcs", None)):
        with pytest.raises(ValueError, match="noise floor needs the arcs' support and the noise"):
            models.KMeansSourceModel(
                x.ravel(), y.ravel(), adapt, 40, support=support, arc_noise_floor=3.0,
                noise_map=noise_map,
            )  # fmt: skip
    held = models.KMeansSourceModel(x.ravel(), y.ravel(), adapt, 40, support="arcs").fixed(
        {**spix2.max_likelihood, models.ARC_THRESHOLD: 0.05}
    )
    assert held.source.support_mass == models.mass_profiles(spix2.max_likelihood)
    assert held.source.signals_mass is None
    assert "adaptive_signals_mass" not in held.describe()
    signals_held = models.KMeansSourceModel(
        x.ravel(), y.ravel(), adapt, 40, signals_mass="spix2"
    ).fixed(spix2.max_likelihood)
    assert signals_held.source.signals_mass == models.mass_profiles(spix2.max_likelihood)
    assert signals_held.describe()["adaptive_signals_mass"] == "spix2"
    assert (
        "adaptive_signals_mass"
        not in models.KMeansSourceModel(
            x.ravel(), y.ravel(), adapt, 40, signals_mass="spix2"
        ).describe()
    )


SERSIC_VALUES = {
    **{k: v for k, v in SP_VALUES.items() if not k.startswith("lens_light.")},
    "lens_light.sersic_0.centre_x": 0.01,
    "lens_light.sersic_0.centre_y": -0.07,
    "lens_light.sersic_0.ell_comps_1": 0.05,
    "lens_light.sersic_0.ell_comps_2": -0.1,
    "lens_light.sersic_0.effective_radius": 0.6,
    "lens_light.sersic_0.sersic_index": 3.5,
    "lens_light.sersic_1.ell_comps_1": 0.2,
    "lens_light.sersic_1.ell_comps_2": 0.1,
    "lens_light.sersic_1.effective_radius": 1.5,
    "lens_light.sersic_1.sersic_index": 1.2,
}


def test_sersic_spaces_follow_the_papers_comparison_chain(chain):
    """3×Sérsic (SPEC §2.3, §8.1): SP 2 Sérsics sharing a centre (21 free), LIGHT 3 (14),
    MASS fits the Sérsics with the EPL (22), their priors passed from LIGHT."""
    sp_space = sp_phase.space(models.sersic_specs(2))
    assert sp_space.n_free == 21
    tie = sp_space.parameter("lens_light.sersic_1.centre_y").tied_to
    assert tie == "lens_light.sersic_0.centre_y"
    assert sp_space.parameter("lens_light.sersic_1.effective_radius").prior == Uniform(0.0, 30.0)
    assert sp_space.parameter("lens_light.sersic_0.sersic_index").prior == Uniform(0.8, 5.0)
    values = sp_space.values(sp_space.vector(SERSIC_VALUES))
    first, second = models.lens_light_components(values, models.sersic_specs(2))
    assert first.centre == second.centre == (0.01, -0.07)
    assert (second.effective_radius, second.sersic_index) == (1.5, 1.2)
    with pytest.raises(models.UnphysicalSample, match="effective_radius"):
        models.SersicSpec("sersic_0").component(
            {**values, "lens_light.sersic_0.effective_radius": 0.0}
        )

    sp = fake_result("sp", sp_space, SERSIC_VALUES)
    assert models.light_centre(sp) == pytest.approx((0.01, -0.07), abs=0.05)
    light_space = light_phase.space(models.sersic_specs(3), sp, chain["spix1"], chain["spix2"])
    assert light_space.n_free == 14
    cx = sp.max_likelihood["lens_light.sersic_0.centre_x"]
    assert light_space.parameter("lens_light.sersic_0.centre_x").prior == Uniform(
        cx - 0.1, cx + 0.1
    )
    light_values = {n: 0.05 for n in light_space.free_names}
    light_values.update({n: 1.0 for n in light_space.free_names if n.endswith("radius")})
    light_values.update({n: 4.9 for n in light_space.free_names if n.endswith("index")})
    light = fake_result("light", light_space, light_values, scale=0.02)

    fixed = mass_phase.space(light, chain["spix1"], chain["spix2"])
    assert fixed.n_free == 8
    space = mass_phase.space(light, chain["spix1"], chain["spix2"], free_lens_light=True)
    assert space.n_free == 22
    assert space.parameter("lens_light.sersic_2.centre_x").tied_to == "lens_light.sersic_0.centre_x"
    radius = space.parameter("lens_light.sersic_1.effective_radius").prior
    assert radius.mean == pytest.approx(light.median["lens_light.sersic_1.effective_radius"])
    assert radius.sigma == pytest.approx(radius.mean)  # relative width 1.0 beats 3σ ≈ 0.06
    assert (radius.lower, radius.upper) == (0.0, np.inf)
    index = space.parameter("lens_light.sersic_0.sersic_index").prior
    assert (index.sigma, index.lower, index.upper) == (1.5, 0.8, 5.0)


# -- prior passing ----------------------------------------------------------------------
def test_spix1_priors_are_passed_from_sp(chain):
    sp = chain["sp"]
    space = spix1_phase.space(sp)
    median, interval = sp.median, sp.interval(3)
    widths = {"mass.centre_x": 0.05, "mass.einstein_radius": 0.25 * median["mass.einstein_radius"]}
    for name, width in widths.items():
        prior = space.parameter(name).prior
        half = max(interval[name][1] - median[name], median[name] - interval[name][0])
        assert isinstance(prior, TruncatedGaussian)
        assert prior.mean == pytest.approx(median[name])
        assert prior.sigma == pytest.approx(max(half, width))
    assert space.parameter("regularization.coefficient").prior.lower == 1e-6


def test_mass_phase_passes_sie_parameters_from_spix1_and_frees_the_slope(chain):
    space = mass_phase.space(chain["light"], chain["spix1"], chain["spix2"])
    spix1 = chain["spix1"]
    prior = space.parameter("mass.ell_comps_2").prior
    assert prior.mean == pytest.approx(spix1.median["mass.ell_comps_2"])
    assert prior.sigma == pytest.approx(0.2)  # width modifier beats a narrow posterior
    assert (prior.lower, prior.upper) == (-1.0, 1.0)
    assert space.parameter("mass.slope").prior == Uniform(1.5, 3.0)
    assert space.parameter("shear.gamma_2").prior.mean == pytest.approx(
        spix1.median["shear.gamma_2"]
    )


# -- values → profiles ------------------------------------------------------------------
def test_mass_profiles_map_sie_epl_and_shear():
    sie, shear = models.mass_profiles(SP_VALUES)
    assert isinstance(sie, SIE)
    assert isinstance(shear, ExternalShear)
    assert (shear.gamma_1, shear.gamma_2) == (0.01, -0.02)
    q, angle = axis_ratio_and_angle_from((0.0, 0.11))
    assert sie.centre == (0.013, -0.07)
    assert (sie.axis_ratio, sie.angle) == pytest.approx((q, angle))
    assert sie.angle == pytest.approx(45.0)
    epl, _ = models.mass_profiles({**SP_VALUES, "mass.slope": 2.1})
    assert isinstance(epl, EPL)
    assert epl.slope == 2.1
    assert epl.einstein_radius == 1.2
    steep, _ = models.mass_profiles({**SP_VALUES, "mass.slope": 2.95})  # inside U(1.5, 3)
    assert steep.slope == 2.95
    with pytest.raises(models.UnphysicalSample, match="slope"):
        models.mass_profiles({**SP_VALUES, "mass.slope": 3.0})


def test_phase_model_builds_the_lens_model():
    model = models.PhaseModel(SP_SPECS, models.MGESourceModel())
    lens = model.build(SP_FULL_VALUES)
    assert isinstance(lens.source, MGESource)
    (source,) = lens.source.sets
    assert source.centre == (0.05, 0.02)
    assert source.sigmas[[0, -1]] == pytest.approx([0.01, 1.0])
    assert len(lens.lens_light) == 2
    assert isinstance(lens.mass[0], SIE)


def test_regularization_from_values():
    values = {"regularization.coefficient": 2.0, **SPIX2_VALUES}
    assert models.regularization_from(values, "constant").coefficient == 2.0
    assert models.regularization_from(values, "constant_split").coefficient == 2.0
    adaptive = models.regularization_from(values, "adaptive_split")
    assert (adaptive.inner_coefficient, adaptive.outer_coefficient) == (1.0, 2.0)
    assert adaptive.signal_scale == 0.5
    assert (adaptive.offset, adaptive.signals) == ("anchor", "anchor")
    weighted = models.regularization_from(values, "adaptive_split", "paper", "weighted")
    assert (weighted.offset, weighted.signals) == ("paper", "weighted")


# -- positions penalty --------------------------------------------------------------------
def test_multiple_image_positions_and_penalty():
    mass = (SIE((0.0, 0.0), 1.2, 0.8, 30.0), ExternalShear(0.01, 0.0))
    x, y = pixel_centres((73, 73), 0.05)
    outside = np.hypot(x, y) > 1.8
    x, y = np.where(outside, np.nan, x), np.where(outside, np.nan, y)
    source_centre = (0.05, 0.02)
    positions = models.multiple_image_positions(mass, source_centre, x, y)
    assert len(positions) == 4
    bx, by = ray_trace(mass, positions[:, 0], positions[:, 1])
    np.testing.assert_allclose(bx, source_centre[0], atol=1e-3)
    np.testing.assert_allclose(by, source_centre[1], atol=1e-3)
    penalty = models.PositionsPenalty(positions, 0.2)
    assert penalty.separation(mass) < 2e-3
    assert penalty.log_likelihood(mass) is None
    demagnified = (SIE((0.0, 0.0), 0.5, 0.8, 30.0), ExternalShear(0.01, 0.0))
    excess = penalty.separation(demagnified) - 0.2
    assert excess > 0.5
    assert penalty.log_likelihood(demagnified) == pytest.approx(-1e10 - 1e8 * excess)


# -- settings ---------------------------------------------------------------------------
def test_profiles_paper_and_quick():
    paper = profile_settings("paper")
    assert [paper.samplers[p].n_live for p in PHASES] == [200, 150, 100, 150, 150]
    assert [paper.samplers[p].method for p in ("sp", "spix2")] == ["dynesty_static"] * 2
    assert paper.source_pixels == 1500
    assert paper.overlay_shape == (34, 34)
    quick = profile_settings("quick")
    assert all(quick.samplers[p].n_live <= 60 for p in PHASES)
    assert 500 <= quick.source_pixels <= 800
    assert quick.fit.positive_only
    assert quick.positions_penalty
    assert not paper.positions_penalty
    assert (paper.fit.psf_trim, quick.fit.psf_trim) == (1e-10, 1e-4)
    # quick: wide lens-light Gaussians in closed form (docs/benchmarks.md); paper: sub-grid
    assert (paper.fit.lp_analytic_tolerance, quick.fit.lp_analytic_tolerance) == (0.0, 1e-4)
    assert (paper.fit.sub_size, quick.fit.sub_size) == (4, 2)
    # quick: the continuous edge rule (SPEC §4 deviations, docs/slam.md), MASS on two meshes
    assert (paper.fit.edge_rule, quick.fit.edge_rule) == ("anchor", "continuous")
    assert (paper.fit.force_edge_pixels_to_zero, quick.fit.force_edge_pixels_to_zero) == (
        True,
        False,
    )
    assert (paper.adaptive_signals, quick.adaptive_signals) == ("anchor", "weighted")
    assert (paper.mass_meshes, quick.mass_meshes) == (1, 2)


def test_fit_settings_reach_the_fit(mock_dir):
    for trim, force_edge, rule, analytic in (
        (1e-10, True, "anchor", 0.0),
        (1e-4, False, "continuous", 1e-4),
    ):
        fit = {
            "psf_trim": trim,
            "force_edge_pixels_to_zero": force_edge,
            "edge_rule": rule,
            "lp_analytic_tolerance": analytic,
        }
        settings = settings_from_mapping({"fit": fit})
        dataset, _ = problem.load_dataset(mock_dir, settings, LENS, (0.0, 0.0))
        assert dataset.settings is settings.fit
        assert dataset.settings.psf_trim == trim
        assert (dataset.light_grid.analytic_sigma < 1.0) is (analytic > 0)
        assert dataset.settings.force_edge_pixels_to_zero is force_edge
        assert dataset.settings.edge_rule == rule


def test_contaminant_circles_give_their_pixels_the_sentinel_noise(mock_dir):
    """The lens's contaminants raise the noise of the pixels inside them by 1e8 (the
    SLACS sentinel), leave every other pixel and the mask as they are, and the figures
    and the quality check see them as masked contaminants."""
    settings = profile_settings("quick")
    plain, _ = problem.load_dataset(mock_dir, settings, LENS, (0.0, 0.0))
    circle = (0.3, -0.2, 0.25)
    lens = dataclasses.replace(LENS, contaminants=(circle,))
    marked, _ = problem.load_dataset(mock_dir, settings, lens, (0.0, 0.0))
    np.testing.assert_array_equal(marked.mask, plain.mask)
    x, y = marked.pixel_centres
    inside = np.hypot(x - circle[0], y - circle[1]) <= circle[2]
    assert inside.sum() == pytest.approx(
        np.pi * (circle[2] / marked.imaging.pixel_scale) ** 2, rel=0.15
    )
    np.testing.assert_allclose(
        plain.inverse_variance[inside] / marked.inverse_variance[inside], 1e16
    )
    np.testing.assert_array_equal(marked.inverse_variance[~inside], plain.inverse_variance[~inside])
    np.testing.assert_array_equal(marked.data, plain.data)
    assert (contaminant_regions_from_noise(marked.imaging.noise_map)[~marked.mask] == inside).all()


def test_sersic_lens_light_needs_its_solve_stated():
    """No setting silently changes another: 3×Sérsic without positive_only is refused
    (the default, true, is the MGE's; the paper's Sérsic runs were unconstrained)."""
    assert settings_from_mapping({}).fit.positive_only
    with pytest.raises(SettingsError, match=r"sersic needs slam\.fit\.positive_only"):
        settings_from_mapping({"lens_light_model": "sersic"}, origin="run.yaml")
    unconstrained = {"lens_light_model": "sersic", "fit": {"positive_only": False}}
    assert not settings_from_mapping(unconstrained).fit.positive_only
    explicit = {"lens_light_model": "sersic", "fit": {"positive_only": True}}
    assert settings_from_mapping(explicit).fit.positive_only
    papers = {"lens_light_model": "sersic", "fit": {"positive_only": True, "free_source": True}}
    assert settings_from_mapping(papers).fit.free_source
    with pytest.raises(SettingsError, match=r"slam\.fit\.free_source applies to the non-neg"):
        settings_from_mapping({"fit": {"positive_only": False, "free_source": True}})
    assert not settings_from_mapping({"fit": {"positive_only": False}}).fit.positive_only


def test_settings_from_yaml_override_the_profile(tmp_path):
    path = tmp_path / "config.yaml"
    path.write_text(
        "samples: config/lenses.tsv\n"
        "slam:\n"
        "  profile: paper\n"
        "  fit: {positive_only: false, sub_size: 3}\n"
        "  overlay_shape: [30, 30]\n"
        "  samplers:\n"
        "    mass: {n_live: 77}\n"
    )
    settings = load_settings(path)
    assert settings.profile == "paper"
    assert not settings.fit.positive_only
    assert settings.fit.sub_size == 3
    assert settings.fit.lp_sub_size == profile_settings("paper").fit.lp_sub_size
    assert settings.overlay_shape == (30, 30)
    assert settings.samplers["mass"].n_live == 77
    assert settings.samplers["mass"].method == "nautilus"
    assert settings.samplers["sp"].n_live == 200
    assert load_settings(path, profile="quick").samplers["sp"].n_live < 200
    assert load_settings(None, "paper") == profile_settings("paper")
    # --slam overrides (JSON from the workflow) merge over the file, sampler by sampler
    merged = load_settings(
        path, None, {"fit": {"sub_size": 2}, "samplers": {"mass": {"dlogz": 2.0}}}
    )
    assert merged.fit.sub_size == 2
    assert not merged.fit.positive_only
    assert merged.samplers["mass"].n_live == 77
    assert merged.samplers["mass"].dlogz == 2.0
    only = load_settings(None, None, {"profile": "paper", "source_pixels": 900})
    assert only.profile == "paper"
    assert only.source_pixels == 900
    with pytest.raises(SettingsError, match=r"--slam: unknown key slam\.pixels"):
        load_settings(None, None, {"pixels": 3})


@pytest.mark.parametrize(
    ("section", "message"),
    [
        ({"n_gausians": 20}, "slam.n_gausians"),
        ({"samplers": {"sp": {"nlive": 3}}}, "slam.samplers.sp.*nlive"),
        ({"samplers": {"source": {}}}, "slam.samplers.source"),
        ({"mge_sets": 6}, r"slam\.mge_sets is set per lens.*--mge-sets"),
        ({"mask_radius": 2}, r"slam\.mask_radius is set per lens.*mask_radius column"),
        ({"positive_only": False}, r"slam\.positive_only is a fit setting: .*slam\.fit\."),
        ({"fit": {"sub_sise": 2}}, r"unknown key slam\.fit\.sub_sise"),
        ({"fit": 2}, r"slam\.fit must be a mapping"),
        ({"profile": "fast"}, "fast"),
        ({"fit": {"positive_only": "false"}}, "positive_only must be true or false, got 'false'"),
        ({"fit": {"force_edge_pixels_to_zero": 0}}, "force_edge_pixels_to_zero must be true or"),
        ({"adaptive_signals": "mean"}, "adaptive_signals must be one of"),
        ({"fit": {"edge_rule": "smooth"}}, "edge_rule must be one of"),
        ({"mass_meshes": 0}, "mass_meshes must be an integer >= 1, got 0"),
        ({"mass_meshes": 1.5}, "mass_meshes must be an integer >= 1"),
        ({"mass_meshes": True}, "mass_meshes must be an integer >= 1"),
        # issue 33: every value is checked where its key is, named by its dotted path
        ({"fit": {"sub_size": "2"}}, r"slam\.fit\.sub_size must be an integer >= 1, got '2'"),
        ({"fit": {"sub_size": 0}}, r"slam\.fit\.sub_size must be an integer >= 1, got 0"),
        ({"kmeans_seed": "x"}, r"slam\.kmeans_seed must be an integer >= 0, got 'x'"),
        ({"positions_factor": "big"}, r"slam\.positions_factor must be a number > 0, got 'big'"),
        ({"fit": {"lp_centre_radius": -1}}, r"slam\.fit\.lp_centre_radius must be a number >="),
        ({"source_pixels": "many"}, r"slam\.source_pixels must be an integer >= 3, got 'many'"),
        ({"mass_source_pixels": 2}, r"slam\.mass_source_pixels must be an integer >= 3, got 2"),
        ({"source_support": "ring"}, r"slam\.source_support must be one of \['mask', 'arcs'\]"),
        ({"kmeans_seeding": "random"}, r"slam\.kmeans_seeding must be one of \['kmeans\+\+', "),
        ({"arc_noise_floor": -1}, r"slam\.arc_noise_floor must be a number >= 0, got -1"),
        (
            {"profile": "paper", "arc_noise_floor": 3},
            r"slam\.arc_noise_floor: 3\.0 applies to the arcs' support only, not to "
            "source_support: mask",
        ),
        ({"overlay_shape": [24]}, r"slam\.overlay_shape must be two integers >= 2"),
        ({"fit": {"psf_trim": 1}}, r"slam\.fit\.psf_trim must be a number in \[0, 1\), got 1"),
        ({"allow_unconverged": "yes"}, r"slam\.allow_unconverged must be true or false"),
        ({"profile": 3}, r"slam\.profile must be one of \['paper', 'quick'\], got 3"),
        ({"samplers": 3}, r"slam\.samplers must be a mapping"),
        ({"samplers": {"sp": 5}}, r"slam\.samplers\.sp must be a mapping"),
        ({"samplers": {"sp": {"n_live": "many"}}}, r"slam\.samplers\.sp\.n_live must be an"),
        ({"samplers": {"mass": {"f_live": 0}}}, r"slam\.samplers\.mass\.f_live must be a number"),
        ({"samplers": {"sp": {"bound": "box"}}}, r"slam\.samplers\.sp\.bound must be one of"),
    ],
)
def test_invalid_settings_name_the_key(section, message):
    with pytest.raises(SettingsError, match=message):
        settings_from_mapping(section)


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"mge_sets": 3}, r"mge_sets must be one of \[2, 4, 6\], got 3 \(--mge-sets, or the "),
        ({"mge_sets": "4"}, r"mge_sets must be an integer >= 1, got '4'"),
        ({"mask_radius": "3"}, r"mask_radius must be a number > 0, got '3' \(--mask-radius"),
        ({"mask_radius": 0}, r"mask_radius must be a number > 0, got 0"),
        ({"mask_centre": [1]}, r"mask_centre must be two numbers \(x, y\) in arcsec"),
        ({"pixel_scale": -0.05}, r"pixel_scale must be a number > 0.*--pixel-scale"),
        ({"point_set": "yes"}, r"point_set must be true or false"),
        ({"contaminants": [[1, 2, 0]]}, r"contaminants must be .* radius > 0, got \[1, 2, 0\] in"),
        ({"contaminants": [[1, 2]]}, r"contaminants must be a list of circles .*--contaminants"),
        ({"contaminants": "c.txt"}, r"contaminants must be a list of circles"),
    ],
)
def test_invalid_lens_values_name_the_option(values, message):
    with pytest.raises(SettingsError, match=message):
        LensSpec(**values)


def test_lens_spec_is_recorded_and_read_back(tmp_path):
    """result.json records the chain's settings (fit nested) and the lens spec apart, and
    records written before they were apart (flat ``slam``) read into the same two."""
    settings = settings_from_mapping({"fit": {"sub_size": 3}, "source_pixels": 600})
    lens = LensSpec(
        mask_radius=1.5,
        mask_centre=(0.1, -0.2),
        mge_sets=6,
        point_set=False,
        contaminants=((0.5, -0.4, 0.2),),
    )
    record = {"slam": settings.to_dict(), "lens": lens.to_dict()}
    record = json.loads(json.dumps(record))  # as result.json holds it
    assert records.recorded_settings(record) == (settings, lens)
    flat = {k: v for k, v in settings.to_dict().items() if k != "fit"}
    flat.update(settings.fit.to_dict())
    flat.update(lens.to_dict())
    assert records.recorded_settings({"slam": flat}) == (settings, lens)
    assert records.recorded_lens({"slam": {"mask_centre": [0, 1]}}).mask_centre == (0.0, 1.0)


def test_sampler_for_raises_dynesty_live_points_to_its_minimum():
    quick = profile_settings("quick").samplers["light"]
    assert run.sampler_for(quick, 14).n_live == quick.n_live == 30
    assert run.sampler_for(quick, 18).n_live == 38


# -- small mock and products ------------------------------------------------------------
def small_mock() -> tuple[np.ndarray, np.ndarray, Imaging]:
    """Data and noise map of a 31×31 M1-like mock at 0.1″ with the noise raised 100× (a
    broad, fast posterior), and the mock's noise-free imaging (PSF, unit)."""
    observation = simulate.Observation(
        image_size=31,
        pixel_scale=PIXEL,
        sub_size=4,
        psf_sigma=0.1,
        psf_size=5,
        source_plane_size=41,
        source_plane_pixel_scale=0.05,
    )
    mock = simulate.simulate(mock_lenses.paper_mock("M1"), observation)
    rng = np.random.default_rng(5)
    noise = 100.0 * mock.imaging.noise_map
    return mock.model + noise * rng.standard_normal(noise.shape), noise, mock.imaging


@pytest.fixture(scope="module")
def mock_dir(tmp_path_factory):
    """:func:`small_mock` as an imaging folder."""
    data, noise, imaging = small_mock()
    folder = tmp_path_factory.mktemp("mock")
    Imaging(data, noise, imaging.psf, PIXEL, unit=imaging.unit).to_fits(folder)
    return folder


def tiny_settings():
    """The quick profile with a coarser centre over-sampling and SP's progress lines off."""
    sp = {"progress_every": 1e9}
    return settings_from_mapping({"fit": {"lp_sub_size_centre": 4}, "samplers": {"sp": sp}})


def test_model_fits_extensions_and_units(mock_dir, tmp_path):
    settings = tiny_settings()
    problem = sp_phase.problem(mock_dir, tmp_path, settings, LENS)
    values = problem.space.values(problem.space.vector(SP_VALUES))
    result = fit(problem.dataset, problem.model.build(values))
    path = tmp_path / "model.fits"
    products.write_model_fits(path, result, {"PHASE": "sp"})
    mask = problem.dataset.mask
    with fits.open(path) as hdus:
        names = [h.name for h in hdus[1:]]
        assert names == list(products.MODEL_EXTENSIONS)
        assert hdus[0].header["PHASE"] == "sp"
        assert hdus[0].header["SOLVER"] == "nnls"
        for hdu in hdus[1:6]:
            assert hdu.data.shape == mask.shape
            assert np.all(hdu.data[mask] == 0.0)
            assert hdu.header["BUNIT"] == ("" if hdu.name == "NRESID" else "electron/s")
        data = problem.dataset.imaging.data
        np.testing.assert_allclose(hdus["RESID"].data[~mask], data[~mask] - result.model_image)
        np.testing.assert_allclose(
            hdus["NRESID"].data[~mask], result.residuals / problem.dataset.noise_map
        )
        np.testing.assert_allclose(
            hdus["MODEL"].data, hdus["LENS"].data + hdus["LENSED"].data, atol=1e-12
        )
        source = hdus["SRCPLANE"]
        assert source.data.shape == products.SOURCE_PLANE_SHAPE
        assert source.header["PIXSCALE"] > 0
        assert source.data.max() > 0


def test_pixelized_products_and_adapt_image(mock_dir, tmp_path):
    problem = sp_phase.problem(mock_dir, tmp_path, tiny_settings(), LENS)
    dataset = problem.dataset
    x, y = overlay_centres(dataset.mask, PIXEL, (12, 12))
    source = models.MeshSourceModel(x, y, "constant")
    model = models.PhaseModel(SP_SPECS, source)
    result = fit(dataset, model.build({**SP_FULL_VALUES, "regularization.coefficient": 1.0}))
    products.write_model_fits(tmp_path / "model.fits", result, {})
    products.write_adapt_image(tmp_path / "adapt.fits", result)
    with fits.open(tmp_path / "model.fits") as hdus:
        assert np.isfinite(hdus["SRCPLANE"].data).all()
        assert hdus["SRCPLANE"].header["BUNIT"] == "electron/s"
    adapt = products.read_adapt_image(tmp_path / "adapt.fits", dataset.mask)
    np.testing.assert_allclose(adapt, result.lensed_source_image)


# -- phases end to end ------------------------------------------------------------------
def test_missing_earlier_phase_is_named(mock_dir, tmp_path):
    with pytest.raises(records.PhaseInputError, match=r"sp/result.json not found"):
        run.run_phase("spix1", mock_dir, tmp_path, tiny_settings(), LENS)


@pytest.fixture(scope="module")
def sp_run(mock_dir, tmp_path_factory):
    results = tmp_path_factory.mktemp("results")
    result = run.run_phase("sp", mock_dir, results, tiny_settings(), LENS, seed=3, threads=1)
    return results, result


def test_spix1_samples_around_a_moved_rescan_with_its_own_image_positions(
    sp_run, mock_dir, tmp_path, monkeypatch
):
    """When the rescan (:mod:`mgelens.pipeline.mass_rescan`, its search tested in
    test_mass_rescan.py; here replaced by a fixed outcome) moves the mass, SPix1's mass and
    shear priors are centred on the rescan's point with their passed widths, and SPix1
    samples and records the images of its source's brightest point under that mass, which
    MASS then reads; a second run reads rescan.json back."""
    results, _ = sp_run
    shutil.copytree(results / "sp", tmp_path / "sp")
    settings = dataclasses.replace(
        settings_from_mapping({"allow_unconverged": True,
                               "samplers": {"spix1": {"max_iterations": 5}}}),
        fit=tiny_settings().fit,
    )  # fmt: skip
    problem = spix1_phase.problem(mock_dir, tmp_path, settings, LENS)
    passed_space = problem.space
    medians = passed_space.values(passed_space.prior_transform(np.full(passed_space.n_free, 0.5)))

    def moved_by(factor: float) -> dict:
        """SP's medians with θ_E scaled by ``factor``, the centre and shear moved."""
        return {n: medians[n] for n in passed_space.free_names} | {
            "mass.einstein_radius": factor * medians["mass.einstein_radius"],
            "mass.centre_x": medians["mass.centre_x"] + 0.03,
            "shear.gamma_1": 0.02,
        }

    def fittable(values: dict) -> bool:
        try:
            fit(problem.dataset, problem.model.build({**medians, **values}))
        except FitError:
            return False
        return True

    # a rescan moves only to a point it has fitted; this SP's result depends on the host's
    # rounding, and under it one of these masses can trace the overlay grid to a
    # zero-area triangle (0.9 did on one host)
    moved = next(m for m in map(moved_by, (0.9, 0.92, 0.94, 0.88, 0.96)) if fittable(m))
    outcome = mass_rescan.Rescan(medians["mass.einstein_radius"], 0, 0, 0, 0, 0, 0, 0, 0, moved,
                                 100, 0.1)  # fmt: skip
    # SP's start as if it had found arcs and chosen its first polish (this mock's SP finds
    # too few arc pixels to polish anything)
    polishes = [{**medians, "mass.einstein_radius": r} for r in (1.0, 1.1, 1.2)]
    start = sp_start.SPStart(
        polishes[0],
        0.0,
        0.0,
        None,
        50,
        1,
        0.1,
        polishes=tuple({"values": v, "log_posterior": 0.0} for v in polishes),
    )
    (tmp_path / "sp" / sp_start.START_FILE).write_text(json.dumps({"start": start.to_dict()}))
    calls = []
    monkeypatch.setattr(mass_rescan, "rescan", lambda *a: calls.append(a) or outcome)
    result = run.run_phase("spix1", mock_dir, tmp_path, settings, LENS)
    assert calls[0][-1] == polishes[1:]  # SP's start's other polishes go to the rescan
    recorded = json.loads((tmp_path / "spix1" / mass_rescan.RESCAN_FILE).read_text())
    assert recorded["fingerprint"]["start_points"] == polishes[1:]
    for name in models.PASSED_MASS_NAMES:
        prior, passed = result.space.parameter(name).prior, passed_space.parameter(name).prior
        assert prior.mean == pytest.approx(moved[name])
        assert prior.sigma == passed.sigma
    sp_positions = json.loads((tmp_path / "sp" / "result.json").read_text())["max_likelihood_fit"]
    spix1_positions = json.loads((tmp_path / "spix1" / "result.json").read_text())["settings"]
    own = spix1_positions["positions"]
    assert own != sp_positions["positions"]
    penalty = models.PositionsPenalty(np.asarray(own["positions"]), own["threshold"])
    assert len(penalty.positions) >= 2
    mass = spix1_phase.problem(mock_dir, tmp_path, settings, LENS).model.build({**medians, **moved})
    assert penalty.log_likelihood(mass.mass) is None  # they re-converge under the moved mass
    assert penalty.separation(mass.mass) <= own["threshold"]
    run.run_phase("spix1", mock_dir, tmp_path, settings, LENS)
    assert len(calls) == 1


def test_sp_phase_writes_its_folder_and_round_trips(sp_run, mock_dir):
    results, result = sp_run
    folder = results / "sp"
    for name in ("result.json", "samples.csv", "model.fits", "phase.log"):
        assert (folder / name).is_file()
    assert not list(folder.glob("checkpoint-*"))
    assert PhaseResult.read(folder) == result
    summary = json.loads((folder / "result.json").read_text())
    files = ("data.fits", "noise_map.fits", "psf.fits")
    assert set(summary["input_checksums"]) == {str(mock_dir / f) for f in files}
    assert summary["sampler"]["n_rejected"] >= 0
    assert "mass.axis_ratio" in summary["median"]
    assert "lens_light.set_1.angle" in summary["max_likelihood"]
    assert "phase sp" in (folder / "phase.log").read_text()
    positions = summary["max_likelihood_fit"]["positions"]
    assert positions["threshold"] >= 0.2
    assert summary["converged"] is True
    assert summary["sampler"]["method"] == "nautilus"  # the quick profile's SP sampler
    assert summary["stop_reason"].startswith("stopping criteria reached (f_live 0.05")


@pytest.mark.parametrize(
    "changes",
    [
        {"spix1_regularization": "constant_split"},  # same parameter space, other prior
        {"interpolation": "nearest"},
        {"overlay_shape": (20, 20)},
        {"positions_penalty": False},
        {"lens": {"mask_radius": 1.2}},
        {"lens": {"contaminants": ((0.3, 0.2, 0.2),)}},  # same mask, other noise
        {"fit": {"sub_size": 3}},
    ],
)
def test_checkpoint_fingerprint_follows_every_input_of_the_likelihood(sp_run, mock_dir, changes):
    """A checkpoint written for one likelihood must not resume another (SPix1 here)."""
    results, _ = sp_run

    def fingerprint(settings, lens=LENS):
        problem = spix1_phase.problem(mock_dir, results, settings, lens)
        sampler = run.sampler_for(settings.samplers["spix1"], problem.space.n_free)
        return run.checkpoint_fingerprint(problem, sampler, 0, {})

    base = tiny_settings()
    assert base.positions_penalty
    assert fingerprint(base) == fingerprint(tiny_settings())
    changes = dict(changes)
    lens = dataclasses.replace(LENS, **changes.pop("lens", {}))
    fit_changes = changes.pop("fit", {})
    changed = dataclasses.replace(base, fit=dataclasses.replace(base.fit, **fit_changes), **changes)
    assert fingerprint(changed, lens) != fingerprint(base)


def test_lens_light_and_mass_models_rebuild_from_json(sp_run):
    results, result = sp_run
    folder = results / "sp"
    gaussians = records.lens_light_profiles(folder)
    best = result.max_likelihood
    assert len(gaussians) == 60
    assert gaussians[45].centre == pytest.approx(
        (best["lens_light.set_0.centre_x"], best["lens_light.set_0.centre_y"])
    )
    assert gaussians[45].ell_comps == pytest.approx(
        (best["lens_light.set_1.ell_comps_1"], best["lens_light.set_1.ell_comps_2"])
    )
    assert gaussians[45].sigma == pytest.approx(SP_SPECS[1].sigmas[15])
    assert all(g.intensity >= 0 for g in gaussians)
    sie, shear = records.mass_model(folder)
    assert isinstance(sie, SIE)
    assert sie.einstein_radius == pytest.approx(best["mass.einstein_radius"])
    assert shear.gamma_2 == pytest.approx(best["shear.gamma_2"])
    q, angle = axis_ratio_and_angle_from(ell_comps_from(sie.axis_ratio, sie.angle))
    assert q == pytest.approx(best["mass.axis_ratio"])
    assert angle == pytest.approx(best["mass.angle"])


def test_interrupted_phase_resumes_to_the_uninterrupted_result(sp_run, mock_dir, tmp_path, caplog):
    _, reference = sp_run
    config = tmp_path / "config.yaml"
    config.write_text(
        "slam:\n"
        "  fit: {lp_sub_size_centre: 4}\n"
        "  samplers:\n"
        "    sp: {progress_every: 1000000000, checkpoint_every: 0.2}\n"
    )
    results = tmp_path / "results"
    command = [sys.executable, "-m", "mgelens", "phase", "sp", "--lens-dir", str(mock_dir)]
    command += ["--results", str(results), "--config", str(config), "--seed", "3"]
    command += ["--mask-radius", str(MASK_RADIUS)]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while not list((results / "sp").glob("checkpoint-*.h5")):  # nautilus's checkpoint
            assert process.poll() is None, "the phase ended before writing a checkpoint"
            assert time.monotonic() < deadline, "no checkpoint within 60 s"
            time.sleep(0.02)
    finally:
        process.kill()
        process.wait()
    assert not (results / "sp" / "result.json").exists()
    with caplog.at_level(logging.INFO, logger="mgelens.pipeline"):
        resumed = run.run_phase("sp", mock_dir, results, tiny_settings(), LENS, seed=3, threads=1)
    so_far = re.search(r"nautilus: .*, (\d+) calls so far", caplog.text)
    assert so_far
    assert int(so_far.group(1)) > 0
    assert resumed.output.n_resumes == 1
    np.testing.assert_array_equal(resumed.output.samples, reference.output.samples)
    np.testing.assert_array_equal(resumed.output.log_weights, reference.output.log_weights)
    assert resumed.output.log_evidence == reference.output.log_evidence
    assert resumed.output.n_calls == reference.output.n_calls
    assert resumed.max_likelihood == reference.max_likelihood


# -- isophotes of a phase's lens light --------------------------------------------------
def test_isophotes_of_a_phase_render_its_lens_light(sp_run, mock_dir, tmp_path):
    """``mgelens isophotes --phase`` renders the phase's MGE lens light, PSF-convolved, on a
    ±3.5″ grid at the imaging's pixel scale (here 0.1″, read from model.fits): inside
    the mask it equals the fit's own lens-light image in model.fits; the summary carries
    the phase's mass."""
    folder = sp_run[0] / "sp"
    image_path, summary_path = tmp_path / "lens_light.fits", tmp_path / "isophotes.json"
    arguments = ["isophotes", "--phase", str(folder), "--psf", str(mock_dir / "psf.fits")]
    arguments += ["--save-image", str(image_path)]
    arguments += ["--summary", str(summary_path), "--out", str(tmp_path / "isophotes.csv")]
    assert main(arguments) == 0
    rendered = fits.getdata(image_path).astype(float)
    assert fits.getheader(image_path)["PIXSCALE"] == PIXEL
    assert rendered.shape == (71, 71)
    fitted = fits.getdata(folder / "model.fits", extname="LENS")
    cut = rendered[20:51, 20:51]
    x, y = pixel_centres(fitted.shape, PIXEL)
    centre = json.loads((folder / "result.json").read_text())["max_likelihood_fit"]
    centre = centre["lens_light"]["components"][0]["centre"]
    radius = np.hypot(x - centre[0], y - centre[1])
    # beyond 0.5″ the fit's coarser over-sampling (quick profile: 2×2) has converged to
    # 1e-3 of the peak (measured 1.2e-4; the same image turned by 90° differs by 5e-2). A
    # relative tolerance would fail on the far tails of a compact fitted light (values
    # 1e-12 of the peak), which depend on the over-sampling.
    inside = (np.hypot(x, y) < MASK_RADIUS - 0.3) & (radius > 0.5)
    assert inside.sum() > 100
    np.testing.assert_allclose(cut[inside], fitted[inside], rtol=0.0, atol=1e-3 * fitted.max())
    summary = json.loads(summary_path.read_text())
    sie = records.mass_model(folder)[0]
    assert summary["mass"]["axis_ratio"] == pytest.approx(sie.axis_ratio)
    # the table and statistics are those of the rendered image (with the noise raised
    # 100×, the fitted light may be compact, leaving no isophote in 0.5–2.5″)
    table = pd.read_csv(tmp_path / "isophotes.csv")
    expected = isophote_table(rendered, PIXEL, centre=tuple(summary["inputs"]["centre"]))
    assert len(table) == len(expected)
    sma = table["sma"].to_numpy(dtype=float)
    np.testing.assert_allclose(sma, expected["sma"].to_numpy(dtype=float), rtol=1e-6)
    low, high = STATISTICS_SMA_RANGE
    in_range = np.count_nonzero((sma >= low) & (sma <= high))
    assert summary["statistics"]["n_isophotes"] == in_range
    assert summary["inputs"]["phase"] == str(folder)
    # the lensed-source share along each isophote, from the fit's own images
    with fits.open(folder / "model.fits") as hdus:
        images = [hdus[name].data for name in ("LENS", "LENSED", "MODEL")]
    shares = source_share(table, *images, PIXEL)
    np.testing.assert_allclose(table["source_share"].to_numpy(dtype=float), shares)
    assert np.all(shares[np.isfinite(shares)] >= 0.0)
    window = (sma >= low) & (sma <= high)
    a4 = table["a4_a"].to_numpy(dtype=float)[window]
    share = shares[window][np.argmax(np.abs(a4))] if a4.size else np.nan
    assert summary["statistics"]["a4_a_source_share"] == (
        None if np.isnan(share) else pytest.approx(share)
    )


def test_isophotes_of_a_phase_need_the_psf(sp_run, tmp_path, caplog):
    folder = sp_run[0] / "sp"
    assert main(["isophotes", "--phase", str(folder), "--out", str(tmp_path / "t.csv")]) == 1
    assert "--phase needs --psf" in caplog.text


def test_isophotes_of_a_phase_take_the_imaging_pixel_scale(sp_run, mock_dir, tmp_path, caplog):
    """The PSF is sampled on the imaging's pixels, so another render scale is refused."""
    arguments = ["isophotes", "--phase", str(sp_run[0] / "sp"), "--psf",
                 str(mock_dir / "psf.fits"), "--pixel-scale", "0.05", "--out",
                 str(tmp_path / "t.csv")]  # fmt: skip
    assert main(arguments) == 1
    assert "--pixel-scale does not apply with --phase" in caplog.text


# -- the 3×Sérsic chain -------------------------------------------------------------------
def sersic_settings(positive_only=False, **changes):
    """The 3×Sérsic chain, capped, every linear unknown free unless ``positive_only``; the
    paper's source support (``mask``) unless ``changes`` sets another."""
    capped = {"progress_every": 1e9, "n_live": 12}
    iterations = {"sp": 60, "spix1": 20, "spix2": 15, "light": 20, "mass": 20}
    return settings_from_mapping(
        {
            "fit": {"lp_sub_size_centre": 4, "positive_only": positive_only},
            "lens_light_model": "sersic",
            "source_pixels": 60,
            "overlay_shape": [8, 8],
            "allow_unconverged": True,
            "source_support": "mask",
            "samplers": {
                p: {**capped, "method": "dynesty_static", "max_iterations": n}
                for p, n in iterations.items()
            },
            **changes,
        }
    )


@pytest.fixture(scope="module")
def sersic_run(mock_dir, tmp_path_factory):
    """The five phases with ``lens_light_model: sersic`` and capped samplers (plumbing:
    each phase builds on unconverged earlier ones)."""
    results = tmp_path_factory.mktemp("sersic")
    settings = sersic_settings()
    for phase in PHASES:
        run.run_phase(phase, mock_dir, results, settings, LENS, seed=1, threads=1)
    return results


def _components(folder):
    record = json.loads((folder / "result.json").read_text())["max_likelihood_fit"]
    return record["lens_light"]["components"]


def test_capped_phases_record_that_they_did_not_converge(sersic_run):
    """The Sérsic chain's samplers are capped: each result says so, with a WARNING."""
    for phase in PHASES:
        summary = json.loads((sersic_run / phase / "result.json").read_text())
        assert summary["converged"] is False
        assert "stopped at max_iterations" in summary["stop_reason"]  # MASS: per mesh
        assert "WARNING mgelens.pipeline: phase" in (sersic_run / phase / "phase.log").read_text()


def test_quality_of_a_chains_mass_phase(sersic_run, mock_dir, tmp_path):
    """``mgelens quality`` on a real MASS model.fits: the fit mask comes from result.json
    (1.4″ at 0.1″: 2×2-pixel blocks), and the 100× noise leaves residuals like noise."""
    out = tmp_path / "quality.json"
    arguments = ["quality", "--phase", str(sersic_run / "mass"), "--lens-dir", str(mock_dir)]
    assert main([*arguments, "--out", str(out)]) == 0
    record = json.loads(out.read_text())
    assert record["measured"] is True
    assert record["flag"] is False
    assert record["block_pixels"] == 2
    with fits.open(sersic_run / "mass" / "model.fits") as hdus:
        fitted = int(np.count_nonzero(hdus["NRESID"].data))
    assert 0 < record["n_pixels"] <= fitted
    assert abs(record["significance"]) < 5


def test_quality_leaves_out_the_contaminants_the_fit_recorded(sersic_run, mock_dir, tmp_path):
    """The quality check reads the lens's contaminant circles from the MASS record, as the
    fit saw them, and leaves their pixels out of its statistic."""
    counts = []
    for contaminants in ([], [[0.0, 0.6, 0.4]]):
        phase = tmp_path / f"mass{len(contaminants)}"
        shutil.copytree(sersic_run / "mass", phase)
        record = json.loads((phase / "result.json").read_text())
        record["settings"]["lens"]["contaminants"] = contaminants
        (phase / "result.json").write_text(json.dumps(record))
        out = phase / "quality.json"
        arguments = ["quality", "--phase", str(phase), "--lens-dir", str(mock_dir)]
        assert main([*arguments, "--out", str(out)]) == 0
        counts.append(json.loads(out.read_text())["n_pixels"])
    circle_pixels = np.pi * (0.4 / PIXEL) ** 2
    assert counts[0] - counts[1] == pytest.approx(circle_pixels, rel=0.3)


def test_a_phase_refuses_an_unconverged_earlier_phase(sersic_run, mock_dir, tmp_path):
    shutil.copytree(sersic_run / "sp", tmp_path / "sp")
    settings = sersic_settings(allow_unconverged=False)
    message = r"sp/result\.json is not converged \(stopped at max_iterations = 60.*allow_unconv"
    with pytest.raises(records.PhaseInputError, match=message):
        run.run_phase("spix1", mock_dir, tmp_path, settings, LENS)
    assert not (tmp_path / "spix1" / "result.json").exists()
    assert problem.read_phase(tmp_path, "sp", allow_unconverged=True).result.phase == "sp"


def test_sersic_chain_fixes_sps_sersics_in_the_spix_phases(sersic_run, mock_dir):
    sp, spix1 = _components(sersic_run / "sp"), _components(sersic_run / "spix1")
    assert [c["kind"] for c in sp] == ["sersic", "sersic"]
    assert all(c["fixed"] for c in spix1)
    for solved, fixed in zip(sp, spix1, strict=True):
        for key in ("centre", "ell_comps", "effective_radius", "sersic_index", "intensity"):
            assert fixed[key] == pytest.approx(solved[key])
    # the lens light of SPix1/SPix2 is SP's solved Sérsic light, subtracted unchanged (SP's
    # own image differs only by its over-sampling centre, the prior centre (0, 0))
    dataset = spix1_phase.problem(mock_dir, sersic_run, sersic_settings(), LENS).dataset
    expected = dataset.light_grid.blurred_image(
        list(records.lens_light_profiles(sersic_run / "sp"))
    )
    sp_lens = fits.getdata(sersic_run / "sp" / "model.fits", extname="LENS")
    scale = np.abs(sp_lens).max()
    for phase in ("spix1", "spix2"):
        lens = fits.getdata(sersic_run / phase / "model.fits", extname="LENS")
        np.testing.assert_allclose(lens[~dataset.mask], expected, rtol=1e-6, atol=1e-9 * scale)
        np.testing.assert_allclose(lens, sp_lens, atol=0.01 * scale)
        assert PhaseResult.read(sersic_run / phase).space.n_free == (8 if phase == "spix1" else 5)


def test_sersic_chain_refits_three_sersics_and_frees_them_with_the_mass(sersic_run):
    light, mass = PhaseResult.read(sersic_run / "light"), PhaseResult.read(sersic_run / "mass")
    assert light.space.n_free == 14
    assert mass.space.n_free == 22
    assert mass.space.parameter("mass.slope").prior == Uniform(1.5, 3.0)
    assert isinstance(
        mass.space.parameter("lens_light.sersic_2.sersic_index").prior, TruncatedGaussian
    )
    profiles = records.lens_light_profiles(sersic_run / "mass")
    assert [type(p).__name__ for p in profiles] == ["Sersic"] * 3
    best = mass.max_likelihood
    assert profiles[2].effective_radius == pytest.approx(
        best["lens_light.sersic_2.effective_radius"]
    )
    assert all(not c.get("fixed", False) for c in _components(sersic_run / "mass"))
    summary = json.loads((sersic_run / "mass" / "result.json").read_text())
    assert summary["max_likelihood_fit"]["positive_only"] is False


def test_adaptive_signals_setting_reaches_the_pixelized_phases(sersic_run, mock_dir):
    values = PhaseResult.read(sersic_run / "mass").max_likelihood
    for signals in ("anchor", "weighted"):
        settings = sersic_settings(adaptive_signals=signals)
        for build in (spix2_phase.problem, mass_phase.problem):
            model = build(mock_dir, sersic_run, settings, LENS).model
            assert model.describe()["source"]["adaptive_signals"] == signals
            assert model.build(values).source.regularization.signals == signals


def test_sersic_and_mge_results_do_not_mix(sersic_run, mock_dir):
    with pytest.raises(records.PhaseInputError, match="lens_light_model = 'sersic'"):
        spix1_phase.problem(mock_dir, sersic_run, sersic_settings(lens_light_model="mge"), LENS)


def test_isophotes_of_a_sersic_phase(sersic_run, mock_dir, tmp_path):
    folder = sersic_run / "mass"
    arguments = ["isophotes", "--phase", str(folder), "--psf", str(mock_dir / "psf.fits")]
    arguments += ["--summary", str(tmp_path / "summary.json")]
    assert main([*arguments, "--out", str(tmp_path / "isophotes.csv")]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    epl = records.mass_model(folder)[0]
    assert summary["mass"]["axis_ratio"] == pytest.approx(epl.axis_ratio)
    assert summary["inputs"]["phase"] == str(folder)


def test_nnls_warm_start_of_a_phase_changes_no_value(sersic_run, mock_dir, monkeypatch):
    """MASS (non-negative here) starts every sample's NNLS from the passive set of the fit
    at the prior medians with the SIE's slope 2; the values match cold starts to rounding.
    SPix2's k-means mesh moves with its samples, so it gets no warm start."""
    settings = sersic_settings(positive_only=True)
    spix2 = spix2_phase.problem(mock_dir, sersic_run, settings, LENS)
    assert run.reference_passive_set(spix2) is None
    problem = mass_phase.problem(mock_dir, sersic_run, settings, LENS)
    slopes = []

    def recording_fit(dataset, model, *arguments):
        slopes.append(model.mass[0].slope)
        return fit(dataset, model, *arguments)

    monkeypatch.setattr(run, "fit", recording_fit)
    start = run.reference_passive_set(problem)
    assert slopes == [2.0]
    assert start.dtype == bool
    assert 0 < start.sum() < start.size
    cold = run.PhaseLikelihood(problem.dataset, problem.space, problem.model)
    warm = run.PhaseLikelihood(problem.dataset, problem.space, problem.model, None, start)
    rng = np.random.default_rng(2)
    centre = problem.space.prior_transform(np.full(problem.space.n_free, 0.5))
    points = [centre] + [
        problem.space.prior_transform(0.5 + 0.05 * (rng.random(problem.space.n_free) - 0.5))
        for _ in range(4)
    ]
    values = [(cold(x), warm(x)) for x in points]
    assert all(c > -1e90 for c, _ in values)
    for c, w in values:
        assert w == pytest.approx(c, rel=1e-10, abs=1e-7)


def test_light_warm_start_is_the_union_of_seeded_prior_draws(sersic_run, mock_dir, monkeypatch):
    """LIGHT samples only the lens light's shape: its NNLS starts from the union of the
    passive sets of the fits at REFERENCE_LIGHT_DRAWS seeded prior draws (after the fit at
    the medians, which checks that the phase can be fitted), two calls agree, and warm
    values match cold starts to rounding. MASS keeps the medians' set."""
    settings = sersic_settings(positive_only=True)
    problem = light_phase.problem(mock_dir, sersic_run, settings, LENS)
    assert all(name.startswith("lens_light.") for name in problem.space.free_names)
    sets = []

    def recording_fit(dataset, model, *arguments):
        result = fit(dataset, model, *arguments)
        sets.append(result.passive_set)
        return result

    monkeypatch.setattr(run, "fit", recording_fit)
    start = run.reference_passive_set(problem)
    assert len(sets) == 1 + run.REFERENCE_LIGHT_DRAWS
    np.testing.assert_array_equal(start, np.logical_or.reduce(sets[1:]))
    assert start.sum() > sets[0].sum()
    np.testing.assert_array_equal(run.reference_passive_set(problem), start)
    cold = run.PhaseLikelihood(problem.dataset, problem.space, problem.model)
    warm = run.PhaseLikelihood(problem.dataset, problem.space, problem.model, None, start)
    rng = np.random.default_rng(3)
    for unit in rng.random((4, problem.space.n_free)):
        x = problem.space.prior_transform(unit)
        assert warm(x) == pytest.approx(cold(x), rel=1e-10, abs=1e-7)
    sets.clear()
    run.reference_passive_set(mass_phase.problem(mock_dir, sersic_run, settings, LENS))
    assert len(sets) == 1


def test_quick_mass_holds_the_adaptive_signals_at_spix2s_mass(sersic_run, mock_dir):
    """The quick profile's MASS traces its adaptive signals through SPix2's mass
    (``adaptive_signals_mass: spix2``), the paper's through each sampled mass."""
    assert profile_settings("quick").adaptive_signals_mass == "spix2"
    assert profile_settings("paper").adaptive_signals_mass == "fitted"
    spix2 = json.loads((sersic_run / "spix2" / "result.json").read_text())["max_likelihood"]
    for choice, held in (("spix2", models.mass_profiles(spix2)), ("fitted", None)):
        settings = sersic_settings(adaptive_signals_mass=choice)
        model = mass_phase.problem(mock_dir, sersic_run, settings, LENS).model
        assert model.source.source.signals_mass == held
        assert ("adaptive_signals_mass" in model.describe()["source"]) == (held is not None)


def test_mass_phase_pools_equal_weight_runs_on_two_source_meshes(sersic_run, mock_dir):
    """The quick profile samples MASS on two k-means meshes (seeds 0 and 1) and pools the
    runs with equal weights; the maximum-likelihood fit is rebuilt on the mesh of the run
    that holds the highest-likelihood sample."""
    assert profile_settings("quick").mass_meshes == 2
    assert profile_settings("paper").mass_meshes == 1
    summary = json.loads((sersic_run / "mass" / "result.json").read_text())
    meshes = summary["settings"]["meshes"]
    assert [m["kmeans_seed"] for m in meshes] == [0, 1]
    table = pd.read_csv(sersic_run / "mass" / "samples.csv")
    sizes = [m["n_samples"] for m in meshes]
    assert sum(sizes) == len(table) == summary["sampler"]["n_samples"]
    weights = table["weight"].to_numpy()
    assert weights[: sizes[0]].sum() == pytest.approx(0.5)
    assert weights[sizes[0] :].sum() == pytest.approx(0.5)
    assert summary["sampler"]["n_calls"] == sum(m["n_calls"] for m in meshes)
    assert summary["log_evidence"] == pytest.approx(np.mean([m["log_evidence"] for m in meshes]))
    holder = [m for m in meshes if m["holds_max_likelihood"]]
    assert len(holder) == 1
    assert holder[0]["max_log_likelihood"] == summary["max_log_likelihood"]
    assert summary["settings"]["model"]["source"]["kmeans_seed"] == holder[0]["kmeans_seed"]
    # the meshes differ, so the runs' likelihoods at their own medians differ
    assert meshes[0]["median"] != meshes[1]["median"]
    # the written fit is the max-likelihood sample refitted on its own mesh
    settings = sersic_settings(kmeans_seed=holder[0]["kmeans_seed"], mass_meshes=1)
    problem = mass_phase.problem(mock_dir, sersic_run, settings, LENS)
    values = problem.space.values(
        table.loc[int(np.argmax(table["log_likelihood"])), list(problem.space.free_names)].to_numpy(
            dtype=float
        )
    )
    written = fits.getheader(sersic_run / "mass" / records.MODEL_FILE)["LOGEVID"]
    refit = fit(problem.dataset, problem.model.build(values))
    assert refit.log_evidence == pytest.approx(written, abs=1e-6)
    other = sersic_settings(kmeans_seed=1 - holder[0]["kmeans_seed"], mass_meshes=1)
    problem = mass_phase.problem(mock_dir, sersic_run, other, LENS)
    elsewhere = fit(problem.dataset, problem.model.build(values))
    assert abs(elsewhere.log_evidence - written) > 1e-3


def test_a_mass_mesh_other_than_spix2s_carries_hyper_parameters_tuned_to_it(sersic_run, mock_dir):
    """With ``mass_mesh_tuning`` (quick) MASS's seed-1 mesh holds the hyper-parameters of
    a search of SPix2's ln ε on that mesh: the record's ln ε is SPix2's likelihood there,
    recomputed independently, at least the start's, and above SPix2's own values on that
    mesh; the seed-0 mesh (SPix2's) keeps SPix2's values; the paper profile tunes none."""
    assert (
        profile_settings("quick").mass_mesh_tuning,
        profile_settings("paper").mass_mesh_tuning,
    ) == (True, False)
    meshes = json.loads((sersic_run / "mass" / "result.json").read_text())["settings"]["meshes"]
    assert meshes[0]["mesh_tuning"] is None
    tuning = meshes[1]["mesh_tuning"]
    assert tuning["tuned"]
    assert 1 < tuning["n_calls"] <= mesh_tuning.TUNING_CALLS + 10
    spix2 = PhaseResult.read(sersic_run / "spix2")
    on_mesh = spix2_phase.problem(mock_dir, sersic_run, sersic_settings(kmeans_seed=1), LENS)
    at_spix2 = fit(on_mesh.dataset, on_mesh.model.build(spix2.max_likelihood)).log_evidence
    tuned = fit(
        on_mesh.dataset, on_mesh.model.build({**spix2.max_likelihood, **tuning["hyperparameters"]})
    ).log_evidence
    assert tuning["start_log_evidence"] == pytest.approx(at_spix2, abs=1e-6)
    assert tuning["log_evidence"] == pytest.approx(tuned, abs=1e-6)
    assert tuned > at_spix2 + 1.0
    assert set(tuning["hyperparameters"]) == {
        n for n in spix2.space.free_names if n.startswith(("mesh.", "regularization."))
    }
    # MASS's seed-1 problem holds them, in its space and in its source
    problem = mass_phase.problem(mock_dir, sersic_run, sersic_settings(kmeans_seed=1), LENS)
    for name, value in tuning["hyperparameters"].items():
        assert problem.space.parameter(name).value == value
    held = problem.model.source.source.regularization
    assert held.outer_coefficient == tuning["hyperparameters"]["regularization.outer_coefficient"]
    own = mass_phase.problem(mock_dir, sersic_run, sersic_settings(), LENS)
    assert "mesh_tuning" not in own.model.source.describe()
    for name in tuning["hyperparameters"]:
        assert own.space.parameter(name).value == spix2.max_likelihood[name]
    paper = mass_phase.problem(
        mock_dir, sersic_run, sersic_settings(kmeans_seed=1, mass_mesh_tuning=False), LENS
    )
    for name in tuning["hyperparameters"]:
        assert paper.space.parameter(name).value == spix2.max_likelihood[name]


def test_mass_mesh_jobs_pool_into_the_whole_phases_result(sersic_run, mock_dir):
    """MASS's meshes run as separate jobs (``--mesh k``) and pooled (``--pool-meshes``)
    give the whole phase's result: samples.csv and model.fits byte for byte, result.json
    equal but for the runtime; the pool refuses a mesh job missing, of another seed, of
    other settings or of inputs that changed since."""
    settings = sersic_settings()
    for mesh in (0, 1):
        run.run_phase("mass", mock_dir, sersic_run, settings, LENS, seed=1, threads=1, mesh=mesh)
        record = json.loads((sersic_run / f"mass_mesh{mesh}" / "result.json").read_text())
        assert record["settings"]["mesh"] == mesh
        assert record["settings"]["model"]["source"]["kmeans_seed"] == mesh
        assert record["sampler"]["seed"] == record["settings"]["mesh_seed"] == 1 + mesh
    arguments = ["phase", "mass", "--lens-dir", str(mock_dir), "--results", str(sersic_run)]
    slam = json.dumps(settings.to_dict())
    (sersic_run / "pooled").mkdir()  # a whole MASS run interrupted there left its checkpoint
    (sersic_run / "pooled" / "checkpoint-0123456789abcdef.pickle").write_bytes(b"x")
    pooled = [*arguments, "--seed", "1", "--slam", slam, "--pool-meshes", "--folder", "pooled"]
    assert main(pooled) == 0
    whole, joined = sersic_run / "mass", sersic_run / "pooled"
    for name in ("samples.csv", "model.fits"):
        assert (joined / name).read_bytes() == (whole / name).read_bytes()
    records = [json.loads((folder / "result.json").read_text()) for folder in (whole, joined)]
    for record in records:
        record["sampler"].pop("runtime_s")
    assert records[0] == records[1]
    assert [m["kmeans_seed"] for m in records[1]["settings"]["meshes"]] == [0, 1]
    assert not list(joined.glob("checkpoint-*"))
    assert recorded_cpu_seconds(joined) > 0.0  # the pool job recorded its process's CPU
    # a mesh whose peak check restarted it (seed + 1, twice the live points) is pooled:
    # its job started from the phase's seed
    result_file = sersic_run / "mass_mesh0" / "result.json"
    original = result_file.read_text()
    restarted = json.loads(original)
    restarted["sampler"]["seed"] = 2
    result_file.write_text(json.dumps(restarted))
    try:
        mesh_pool.pool_meshes(sersic_run, settings, seed=1, folder_name="restarted")
    finally:
        result_file.write_text(original)
    assert (
        json.loads((sersic_run / "restarted" / "result.json").read_text())["sampler"]["seed"] == 2
    )
    older = json.loads(original)
    del older["settings"]["mesh_seed"]  # a mesh result written before it was recorded
    result_file.write_text(json.dumps(older))
    try:
        with pytest.raises(mesh_pool.MeshPoolError, match="does not record the seed"):
            mesh_pool.pool_meshes(sersic_run, settings, seed=1, folder_name="refused")
    finally:
        result_file.write_text(original)
    # another seed, other settings, a missing mesh job, a changed input
    with pytest.raises(mesh_pool.MeshPoolError, match=r"sampled from seed 1, not 3"):
        mesh_pool.pool_meshes(sersic_run, settings, seed=3, folder_name="refused")
    other = sersic_settings(mass_source_pixels=40)
    with pytest.raises(mesh_pool.MeshPoolError, match="written with other slam settings"):
        mesh_pool.pool_meshes(sersic_run, other, seed=1, folder_name="refused")
    with pytest.raises(ValueError, match=r"mesh 2 of phase 'mass'.*mesh 0 to 1"):
        run.run_phase("mass", mock_dir, sersic_run, settings, LENS, seed=1, mesh=2)
    shutil.move(sersic_run / "mass_mesh1", sersic_run / "moved")
    with pytest.raises(mesh_pool.MeshPoolError, match=r"mass_mesh1/result.json not found"):
        mesh_pool.pool_meshes(sersic_run, settings, seed=1, folder_name="refused")
    shutil.move(sersic_run / "moved", sersic_run / "mass_mesh1")
    adapt = sersic_run / "spix1" / "adapt_image.fits"
    original = adapt.read_bytes()
    try:
        with fits.open(adapt) as hdus:
            hdus[0].data = hdus[0].data * 1.001
            hdus.writeto(adapt, overwrite=True)
        with pytest.raises(mesh_pool.MeshPoolError, match=r"adapt_image\.fits changed after"):
            mesh_pool.pool_meshes(sersic_run, settings, seed=1, folder_name="refused")
    finally:
        adapt.write_bytes(original)
    assert not (sersic_run / "refused").exists()


def test_mesh_tuning_is_a_deterministic_search_from_spix2s_values(
    sersic_run, mock_dir, monkeypatch
):
    """The search never returns worse than its start, gives the same values twice (a
    resumed MASS finds its checkpoint), returns the start when allowed one call, and
    refuses a problem that frees more than the hyper-parameters; a finished run's values
    are used as recorded, without searching again."""
    spix2 = PhaseResult.read(sersic_run / "spix2")
    on_mesh = spix2_phase.problem(mock_dir, sersic_run, sersic_settings(kmeans_seed=2), LENS)
    first = mesh_tuning.tuned_hyperparameters(on_mesh, spix2.max_likelihood, max_calls=40)
    again = mesh_tuning.tuned_hyperparameters(on_mesh, spix2.max_likelihood, max_calls=40)
    assert first == again
    assert first.log_evidence >= first.start_log_evidence
    assert first.n_calls <= 45
    alone = mesh_tuning.tuned_hyperparameters(on_mesh, spix2.max_likelihood, max_calls=1)
    assert alone.n_calls == 1
    assert alone.log_evidence == alone.start_log_evidence
    for name in first.describe()["hyperparameters"]:
        assert alone.values[name] == pytest.approx(spix2.max_likelihood[name], rel=1e-9)
    sp1 = spix1_phase.problem(mock_dir, sersic_run, sersic_settings(), LENS)
    with pytest.raises(ValueError, match="only SPix2's hyper-parameters can be tuned"):
        mesh_tuning.tuned_hyperparameters(
            sp1, PhaseResult.read(sersic_run / "spix1").max_likelihood
        )
    held = {**first.describe()["hyperparameters"]}

    def refuse(*args, **kwargs):
        raise AssertionError("searched again")

    monkeypatch.setattr(mass_phase, "tuned_hyperparameters", refuse)
    problem = mass_phase.problem(
        mock_dir, sersic_run, sersic_settings(kmeans_seed=2), LENS, hyperparameters=held
    )
    for name, value in held.items():
        assert problem.space.parameter(name).value == value


def test_mass_source_pixels_set_the_mass_meshes_alone(sersic_run, mock_dir):
    """``mass_source_pixels`` gives MASS's meshes their own k-means pixel count (with
    hyper-parameters tuned to it, quick), while LIGHT keeps ``source_pixels``; unset, MASS
    takes ``source_pixels``."""
    assert sersic_settings().mass_source_pixels is None
    assert profile_settings("quick").mass_source_pixels is None
    assert profile_settings("paper").mass_source_pixels is None
    assert sersic_settings().mass_pixels(60) == 60
    settings = sersic_settings(mass_source_pixels=90)
    assert settings.mass_pixels(60) == 90
    mass = mass_phase.problem(mock_dir, sersic_run, settings, LENS)
    light = light_phase.problem(mock_dir, sersic_run, settings, LENS)
    default = mass_phase.problem(mock_dir, sersic_run, sersic_settings(), LENS)
    assert mass.model.source.describe()["n_pixels"] == 90
    assert default.model.source.describe()["n_pixels"] == 60
    assert light.model.source.describe()["n_pixels"] == 60
    values = default.space.values(
        default.space.vector(PhaseResult.read(sersic_run / "mass").max_likelihood)
    )
    finer = fit(mass.dataset, mass.model.build(values))
    coarse = fit(default.dataset, default.model.build(values))
    assert (finer.source.fluxes.size, coarse.source.fluxes.size) == (90, 60)
    assert finer.log_evidence != pytest.approx(coarse.log_evidence)


def test_mass_meshes_sampled_side_by_side_draw_the_same_samples(sersic_run, mock_dir, tmp_path):
    """With ``n_processes: 2`` the two meshes' runs go to two one-thread processes side by
    side: the samples and evidence of one after the other in one process (``sersic_run``)
    to the last bit, and both runs' progress lines reach the phase log."""
    results = tmp_path / "results"
    shutil.copytree(sersic_run, results)
    shutil.rmtree(results / "mass")
    settings = sersic_settings()
    mass = dataclasses.replace(settings.samplers["mass"], n_processes=2)
    settings = dataclasses.replace(settings, samplers={**settings.samplers, "mass": mass})
    run.run_phase("mass", mock_dir, results, settings, LENS, seed=1, threads=1)
    side_by_side = pd.read_csv(results / "mass" / "samples.csv")
    one_process = pd.read_csv(sersic_run / "mass" / "samples.csv")
    pd.testing.assert_frame_equal(side_by_side, one_process, check_exact=True)
    first = json.loads((sersic_run / "mass" / "result.json").read_text())
    again = json.loads((results / "mass" / "result.json").read_text())
    assert again["log_evidence"] == first["log_evidence"]
    assert again["settings"]["meshes"] == first["settings"]["meshes"]
    log = (results / "mass" / "phase.log").read_text()
    assert "sampling the 2 runs 2 at a time, one process each" in log
    assert log.count("dynesty_static: done") == 2


def test_max_likelihood_problem_rebuilds_each_phases_written_fit(sersic_run, sp_run, mock_dir):
    """From result.json alone (settings, earlier phases' files, in MASS the mesh holding the
    best sample) the rebuilt problem refits every phase's model.fits to 1e-6 in ln ε."""
    folders = [sersic_run / phase for phase in PHASES] + [sp_run[0] / "sp"]
    for folder in folders:
        phase = PhaseResult.read(folder)
        problem, values = run.max_likelihood_problem(phase, mock_dir, folder.parent)
        assert problem.name == phase.phase
        written = fits.getheader(folder / records.MODEL_FILE)["LOGEVID"]
        refit = fit(problem.dataset, problem.model.build(values))
        assert refit.log_evidence == pytest.approx(written, abs=1e-6), folder


def test_arcs_support_runs_from_spix2_to_mass_and_refits_its_written_fits(
    sersic_run, mock_dir, tmp_path
):
    """``source_support: arcs`` on the capped chain: SP and SPix1 are the paper model's,
    SPix2 samples the arc threshold, LIGHT and MASS solve SPix2's support only, and each
    model.fits is refitted from result.json to 1e-6 in ln ε."""
    for phase in ("sp", "spix1"):
        shutil.copytree(sersic_run / phase, tmp_path / phase)
    settings = sersic_settings(source_support="arcs")
    for phase in ("spix2", "light", "mass"):
        run.run_phase(phase, mock_dir, tmp_path, settings, LENS, seed=1, threads=1)
    threshold = PhaseResult.read(tmp_path / "spix2").max_likelihood[models.ARC_THRESHOLD]
    assert 1e-3 <= threshold <= 0.3
    for phase in ("light", "mass"):
        result = PhaseResult.read(tmp_path / phase)
        assert result.max_likelihood[models.ARC_THRESHOLD] == threshold
        assert models.ARC_THRESHOLD not in result.space.free_names
        problem, values = run.max_likelihood_problem(result, mock_dir, tmp_path)
        refit = fit(problem.dataset, problem.model.build(values))
        written = fits.getheader(tmp_path / phase / records.MODEL_FILE)["LOGEVID"]
        assert refit.log_evidence == pytest.approx(written, abs=1e-6)
        assert refit.source.support is not None
        assert problem.model.describe()["source"]["source_support"] == "arcs"


@pytest.mark.parametrize(("chain", "phase"), [("sp_run", "sp"), ("sersic_run", "mass")])
def test_true_light_refit_scores_the_fit_against_a_fixed_lens_light(
    chain, phase, request, mock_dir
):
    """Fixing the lens light at the phase fit's own solution re-solves the same source
    (Δχ² = Δ ln ε = 0). Any other lens light raises χ² + sᵀHs, the only ln ε terms that
    change (same mass, mesh and regularization), so Δ ln ε < 0; that minimum over the
    source is convex in the lens light's scale c, so it grows from c = 1 to 0.8 to 0."""
    results = request.getfixturevalue(chain)
    results = results[0] if isinstance(results, tuple) else results
    problem, values = run.max_likelihood_problem(
        PhaseResult.read(results / phase), mock_dir, results
    )
    model = problem.model.build(values)
    own = fit(problem.dataset, model)
    own_light = own.native(own.lens_light_image)
    same = true_light_refit(problem.dataset, model, own_light)
    assert same.chi_squared == own.chi_squared
    assert same.log_evidence == own.log_evidence
    assert same.delta_chi_squared == pytest.approx(0.0, abs=1e-6 * own.chi_squared)
    assert same.delta_log_evidence == pytest.approx(0.0, abs=1e-6 * abs(own.log_evidence))
    assert same.n_lens_light_intensities == np.count_nonzero(own.lens_light_intensities) > 0
    assert same.lens_light_prior_coefficient is None  # these chains carry no prior
    warm = true_light_refit(
        problem.dataset, model, own_light, run.reference_passive_set(problem)
    )  # the sampler's warm start for the model's own fit: the same minimum
    assert warm.log_evidence == pytest.approx(own.log_evidence, rel=1e-10)
    assert warm.true_light_log_evidence == same.true_light_log_evidence
    dimmer = true_light_refit(problem.dataset, model, 0.8 * own_light)
    none = true_light_refit(problem.dataset, model, 0.0 * own_light)
    assert none.delta_log_evidence < dimmer.delta_log_evidence < 0.0
    with pytest.raises(ValueError, match="shape"):
        true_light_refit(problem.dataset, model, own_light[1:])
    with pytest.raises(ValueError, match="needs a model with a source"):
        true_light_refit(problem.dataset, dataclasses.replace(model, source=None), own_light)

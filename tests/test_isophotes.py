"""Tests of mgelens.isophotes (SPEC §9) on images whose isophotes are known exactly.

Truths used here, all independent of the contour/ellipse machinery under test:

* a single elliptical Gaussian or Sérsic: every isophote is the ellipse (q, φ) of the
  profile;
* "nested ellipses": I = exp(−a/h) with a(x, y) defined implicitly as the semi-major axis
  of the member of a family of ellipses with q(a), φ(a) varying smoothly (twist and
  flattening) that passes through (x, y) — the isophote of level L is exactly the ellipse
  a = −h ln L;
* "deformed ellipses": I = exp(−s/h), s = r/(ρ(ϑ) + ε cos 4ϑ) with ρ the unit ellipse's polar
  radius, so the isophote s = c is R(ϑ) = c ρ(ϑ) + cε cos 4ϑ: relative to the ellipse
  (a = c, q) its radial deviation is exactly a·ε cos 4ϑ, i.e. a₄/a = ε (> 0 disky) and
  all other harmonics vanish;
* a twisted three-Gaussian MGE, whose isophotes are found by bisection along rays of the
  analytic profile and whose ellipse is solved independently (scipy ``fsolve``) for zero
  a₀, a₂, b₂ of the radial deviation (a₁ = b₁ = 0 by point symmetry).
"""

import json
import logging
import math
from dataclasses import replace

import numba
import numpy as np
import pandas as pd
import pytest
from astropy.io import fits
from scipy import optimize

from mgelens.atomic import write_json
from mgelens.cli import main
from mgelens.ellipse_fit import (
    HARMONIC_NAMES,
    Ellipse,
    IsophoteError,
    fit_ellipse,
    fit_isophote,
    harmonic_deviations,
)
from mgelens.geometry import axis_ratio_and_angle_from, ell_comps_from, to_profile_frame
from mgelens.grid import pixel_centres
from mgelens.isophotes import (
    FLAG_ROUND,
    TABLE_COLUMNS,
    closed_contour,
    contour_generator,
    isophote_statistics,
    isophote_table,
    mass_shape_from,
    render_light,
    unwrap_position_angles,
)
from mgelens.light import Gaussian, Sersic
from mgelens.mass import SIE
from mgelens.plot import save_png
from mgelens.plot.isophotes import isophote_figure
from mgelens.summary import lens_summary, sample_table

PIXEL_SCALE = 0.05
POINT_SAMPLED = {"sub_size": 1, "sub_size_centre": 1}


def angle_difference(a, b):
    """Difference of axis angles (deg) reduced to [−90, 90)."""
    return (np.asarray(a) - np.asarray(b) + 90.0) % 180.0 - 90.0


def unit_ellipse_radius(theta, axis_ratio):
    """Polar radius of the ellipse with semi-major axis 1 at polar angle ``theta`` (rad)."""
    return axis_ratio / np.hypot(axis_ratio * np.cos(theta), np.sin(theta))


def grid(n=141):
    return pixel_centres((n, n), PIXEL_SCALE)


# --------------------------------------------------------------------------------------
# ellipse fit and Fourier analysis on exact curves


@pytest.mark.parametrize("angle", [0.0, 0.3, 37.0, 90.0, 179.7])
@pytest.mark.parametrize("arc", [2.0 * np.pi, 2.2])
def test_fit_ellipse_recovers_an_exact_ellipse(angle, arc):
    rng = np.random.default_rng(7)
    t = np.sort(rng.uniform(0.0, arc, 60))
    x0, y0, a, q = 0.31, -0.22, 1.7, 0.45
    phi = np.deg2rad(angle)
    u, v = a * np.cos(t), a * q * np.sin(t)
    x = x0 + u * np.cos(phi) - v * np.sin(phi)
    y = y0 + u * np.sin(phi) + v * np.cos(phi)
    fit = fit_ellipse(x, y)
    assert fit.x0 == pytest.approx(x0, abs=1e-9)
    assert fit.y0 == pytest.approx(y0, abs=1e-9)
    assert fit.semi_major == pytest.approx(a, rel=1e-9)
    assert fit.axis_ratio == pytest.approx(q, rel=1e-9)
    assert abs(angle_difference(fit.angle, angle)) < 1e-7
    assert 0.0 <= fit.angle < 180.0


def test_fit_ellipse_of_a_circle_and_degenerate_points():
    t = np.linspace(0.0, 2.0 * np.pi, 40)
    circle = fit_ellipse(2.0 + 0.5 * np.cos(t), -1.0 + 0.5 * np.sin(t))
    assert circle.axis_ratio == pytest.approx(1.0, abs=1e-9)
    assert circle.semi_major == pytest.approx(0.5, rel=1e-9)
    with pytest.raises(IsophoteError, match="at least 6"):
        fit_ellipse(np.arange(5.0), np.arange(5.0))
    with pytest.raises(IsophoteError):
        fit_ellipse(np.arange(10.0), 2.0 * np.arange(10.0) + 1.0)


def deformed_curve(ellipse, harmonics, n_points=3000, seed=3):
    """Vertices (x, y) of R(ϑ) = R_el(ϑ) + a Σ c_n {cos, sin}(nϑ), at random sorted ϑ."""
    theta = np.sort(np.random.default_rng(seed).uniform(0.0, 2.0 * np.pi, n_points))
    radius = ellipse.semi_major * unit_ellipse_radius(theta, ellipse.axis_ratio)
    for (kind, order), value in harmonics.items():
        wave = np.cos(order * theta) if kind == "cos" else np.sin(order * theta)
        radius = radius + ellipse.semi_major * value * wave
    phi = np.deg2rad(ellipse.angle)
    u, v = radius * np.cos(theta), radius * np.sin(theta)
    return (
        ellipse.x0 + u * np.cos(phi) - v * np.sin(phi),
        ellipse.y0 + u * np.sin(phi) + v * np.cos(phi),
    )


def test_harmonic_deviations_of_a_known_curve():
    ellipse = Ellipse(0.1, -0.05, 1.3, 0.7, 125.0)
    imposed = {("cos", 3): 0.004, ("sin", 3): -0.002, ("cos", 4): -0.011, ("sin", 4): 0.006}
    x, y = deformed_curve(ellipse, imposed)
    coefficients, errors = harmonic_deviations(x, y, ellipse)
    expected = dict.fromkeys(HARMONIC_NAMES, 0.0)
    expected.update({"a3": 0.004, "b3": -0.002, "a4": -0.011, "b4": 0.006})
    for name, value, error in zip(HARMONIC_NAMES, coefficients, errors, strict=True):
        assert value / ellipse.semi_major == pytest.approx(expected[name], abs=2e-6), name
        assert 0.0 <= error < 1e-5


@pytest.mark.parametrize("epsilon", [0.02, -0.02])
def test_fit_isophote_refines_the_ellipse_until_low_harmonics_vanish(epsilon):
    truth = Ellipse(-0.2, 0.15, 1.1, 0.55, 12.0)
    x, y = deformed_curve(truth, {("cos", 4): epsilon})
    fit = fit_isophote(x, y)
    assert fit.refined
    assert fit.ellipse.semi_major == pytest.approx(truth.semi_major, rel=1e-5)
    assert fit.ellipse.axis_ratio == pytest.approx(truth.axis_ratio, abs=1e-5)
    assert abs(angle_difference(fit.ellipse.angle, truth.angle)) < 1e-3
    assert (fit.ellipse.x0, fit.ellipse.y0) == pytest.approx((truth.x0, truth.y0), abs=1e-6)
    a4 = fit.harmonics[HARMONIC_NAMES.index("a4")] / fit.ellipse.semi_major
    assert a4 == pytest.approx(epsilon, abs=1e-5)
    assert np.all(np.abs(fit.harmonics[:5]) < 1e-6)
    # the direct conic fit alone is biased by the cos 4ϑ deformation: refining matters
    conic = fit_ellipse(x, y)
    assert abs(conic.axis_ratio - truth.axis_ratio) > 2e-3


# --------------------------------------------------------------------------------------
# images with exactly known isophotes


SINGLE_PROFILES = {
    "gaussian": lambda angle: Gaussian.from_major_axis((0.013, -0.07), 0.6, angle, 0.9),
    "sersic": lambda angle: Sersic((0.013, -0.07), ell_comps_from(0.55, angle), 1.0, 4.0),
}


@pytest.mark.parametrize("angle", [0.2, 37.0, 90.0, 179.8])
@pytest.mark.parametrize("kind", sorted(SINGLE_PROFILES))
def test_single_profile_isophotes(kind, angle):
    profile = SINGLE_PROFILES[kind](angle)
    q_true, angle_true = axis_ratio_and_angle_from(profile.ell_comps)
    image = render_light([profile], PIXEL_SCALE, **POINT_SAMPLED)
    table = isophote_table(image, PIXEL_SCALE, centre=(0.013, -0.07))
    assert list(table.columns) == list(TABLE_COLUMNS)
    assert len(table) == 40
    assert table["sma"].iloc[0] == pytest.approx(0.3, abs=0.01)
    assert table["sma"].iloc[-1] == pytest.approx(3.0, abs=0.01)
    assert np.max(np.abs(table["q"] - q_true)) < 0.005
    assert np.max(np.abs(angle_difference(table["pa"], angle_true))) < 0.5
    assert np.all((table["pa"] >= 0.0) & (table["pa"] < 180.0))
    assert np.max(np.hypot(table["x0"] - 0.013, table["y0"] + 0.07)) < 0.002
    statistics = isophote_statistics(table)
    assert statistics.delta_q_max < 0.005
    assert statistics.delta_pa_max < 0.5
    assert abs(statistics.a4_a_extreme) < 0.002


def twist_axis_ratio(a):
    return 0.75 - 0.2 * np.tanh((a - 1.2) / 0.6)


def twist_angle(a):
    return 40.0 + 30.0 * np.tanh((a - 1.2) / 0.7)


def nested_ellipse_semi_major(x, y, centre):
    """a(x, y) of the family {q(a), φ(a)} by bisection (the family must be nested)."""
    low, high = np.zeros_like(x), np.full_like(x, 20.0)
    for _ in range(60):
        a = 0.5 * (low + high)
        xp, yp = to_profile_frame(x, y, centre, 0.0)
        phi = np.deg2rad(twist_angle(a))
        u = xp * np.cos(phi) + yp * np.sin(phi)
        v = -xp * np.sin(phi) + yp * np.cos(phi)
        outside = np.hypot(u, v / twist_axis_ratio(a)) > a
        low, high = np.where(outside, a, low), np.where(outside, high, a)
    return 0.5 * (low + high)


def test_nested_ellipse_family_is_nested():
    a = np.linspace(0.05, 6.0, 600)[:, None]
    theta = np.linspace(0.0, 2.0 * np.pi, 721)[None, :]
    radius = a * unit_ellipse_radius(theta - np.deg2rad(twist_angle(a)), twist_axis_ratio(a))
    assert np.all(np.diff(radius, axis=0) > 0.0)


def test_twisted_flattening_isophotes_are_recovered():
    centre, scale = (0.02, -0.03), 0.5
    x, y = grid()
    image = np.exp(-nested_ellipse_semi_major(x, y, centre) / scale)
    table = isophote_table(image, PIXEL_SCALE, centre=centre)
    assert len(table) == 40
    a_true = -scale * np.log(table["level"].to_numpy())
    assert np.max(np.abs(table["sma"] - a_true)) < 0.005
    q_true, angle_true = twist_axis_ratio(a_true), twist_angle(a_true)
    assert np.max(np.abs(table["q"] - q_true)) < 0.01
    oriented = q_true < 0.9
    assert np.max(np.abs(angle_difference(table["pa"], angle_true)[oriented])) < 1.0
    statistics = isophote_statistics(table)
    inside = (table["sma"] >= 0.5) & (table["sma"] <= 2.5)
    assert statistics.delta_q_max == pytest.approx(np.ptp(q_true[inside]), abs=0.01)
    assert statistics.delta_pa_max == pytest.approx(np.ptp(angle_true[inside]), abs=1.0)
    assert statistics.delta_pa_max > 40.0


MGE = [
    Gaussian.from_major_axis((0.0, 0.0), 0.85, 10.0, 0.25, 4.0),
    Gaussian.from_major_axis((0.0, 0.0), 0.6, 55.0, 0.8, 1.0),
    Gaussian.from_major_axis((0.0, 0.0), 0.45, 100.0, 2.0, 0.2),
]


def mge_value(x, y):
    return sum(g.image(x, y) for g in MGE)


def ray_radii(level, angles):
    """Radius of the analytic MGE isophote of ``level`` along rays at ``angles`` (rad)."""
    low, high = np.zeros_like(angles), np.full_like(angles, 8.0)
    for _ in range(55):
        middle = 0.5 * (low + high)
        brighter = mge_value(middle * np.cos(angles), middle * np.sin(angles)) > level
        low, high = np.where(brighter, middle, low), np.where(brighter, high, middle)
    return 0.5 * (low + high)


def ray_truth(level, start):
    """(a, q, φ deg, a₄/a) of the ellipse with zero a₀, a₂, b₂ of the exact isophote."""
    theta = np.linspace(0.0, 2.0 * np.pi, 720, endpoint=False)

    def deviation(p):
        a, q, phi = p
        return ray_radii(level, theta + phi) - a * unit_ellipse_radius(theta, q)

    def low_harmonics(p):
        d = deviation(p)
        return [d.mean(), 2 * np.mean(d * np.cos(2 * theta)), 2 * np.mean(d * np.sin(2 * theta))]

    solution = optimize.fsolve(low_harmonics, start, xtol=1e-12)
    a4 = 2.0 * np.mean(deviation(solution) * np.cos(4.0 * theta)) / solution[0]
    return solution[0], solution[1], np.rad2deg(solution[2]) % 180.0, a4


def test_twisted_mge_matches_the_ray_traced_truth():
    image = render_light(MGE, PIXEL_SCALE, **POINT_SAMPLED)
    table = isophote_table(image, PIXEL_SCALE, centre=(0.0, 0.0))
    assert len(table) == 40
    for row in table.iloc[4::6].itertuples():
        start = (row.sma, row.q, np.deg2rad(row.pa))
        a, q, angle, a4 = ray_truth(row.level, start)
        assert row.sma == pytest.approx(a, abs=0.005)
        assert row.q == pytest.approx(q, abs=0.01)
        if q < 0.9:
            assert abs(angle_difference(row.pa, angle)) < 1.0
        assert row.a4_a == pytest.approx(a4, abs=0.002)
    assert isophote_statistics(table).delta_pa_max > 20.0


def deformed_image(axis_ratio, angle, epsilon, centre=(0.02, -0.03), scale=0.6):
    x, y = grid()
    u, v = to_profile_frame(x, y, centre, angle)
    theta = np.arctan2(v, u)
    s = np.hypot(u, v) / (unit_ellipse_radius(theta, axis_ratio) + epsilon * np.cos(4 * theta))
    return np.exp(-s / scale)


@pytest.mark.parametrize("epsilon", [0.015, -0.015])
@pytest.mark.parametrize(("axis_ratio", "angle"), [(0.7, 30.0), (0.5, 178.5)])
def test_boxy_and_disky_isophotes(epsilon, axis_ratio, angle):
    table = isophote_table(deformed_image(axis_ratio, angle, epsilon), PIXEL_SCALE)
    assert len(table) == 40
    assert np.max(np.abs(table["a4_a"] - epsilon)) < 0.002
    for column in ("b4_a", "a3_a", "b3_a"):
        assert np.max(np.abs(table[column])) < 0.002
    assert np.max(np.abs(table["q"] - axis_ratio)) < 0.005
    assert np.max(np.abs(angle_difference(table["pa"], angle))) < 0.5
    extreme = isophote_statistics(table).a4_a_extreme
    assert np.sign(extreme) == np.sign(epsilon)
    assert extreme == pytest.approx(epsilon, abs=0.002)


def test_round_isophotes_are_flagged_and_ignored_for_the_position_angle():
    image = render_light([Gaussian.from_major_axis((0.0, 0.0), 0.98, 20.0, 0.9)], PIXEL_SCALE)
    table = isophote_table(image, PIXEL_SCALE)
    assert len(table) == 40
    assert np.all(table["flag"] & FLAG_ROUND)
    statistics = isophote_statistics(table)
    assert statistics.n_isophotes_pa == 0
    assert math.isnan(statistics.delta_pa_max)
    assert statistics.to_dict()["delta_pa_max"] is None


# --------------------------------------------------------------------------------------
# statistics on hand-made tables


def test_unwrap_position_angles():
    angles = np.array([170.0, 178.0, 3.0, 12.0, 95.0, 150.0, 10.0])
    expected = [170.0, 178.0, 183.0, 192.0, 275.0, 330.0, 370.0]
    np.testing.assert_allclose(unwrap_position_angles(angles), expected)


def test_statistics_definitions():
    table = pd.DataFrame(
        {
            "sma": [0.4, 0.5, 0.9, 1.3, 1.7, 2.1, 2.5, 2.9],
            "q": [0.50, 0.80, 0.70, 0.97, 0.75, 0.72, 0.85, 0.30],
            "pa": [90.0, 175.0, 179.0, 60.0, 4.0, 9.0, 2.0, 90.0],
            "a4_a": [0.09, 0.010, -0.024, 0.003, 0.021, -0.005, 0.0, -0.08],
        }
    )
    assert math.isnan(isophote_statistics(table).a4_a_source_share)  # no column: undefined
    table["source_share"] = [0.9, 0.1, 0.35, 0.4, 0.2, 0.3, 0.05, 2.0]
    statistics = isophote_statistics(table)
    assert statistics.a4_a_source_share == pytest.approx(0.35)  # at a = 0.9″, a4/a −0.024
    assert statistics.n_isophotes == 6
    assert statistics.n_isophotes_pa == 5
    assert statistics.delta_q_max == pytest.approx(0.97 - 0.70)
    assert statistics.delta_pa_max == pytest.approx(189.0 - 175.0)
    assert statistics.a4_a_extreme == pytest.approx(-0.024)
    empty = isophote_statistics(table[table["sma"] > 10.0])
    assert empty.n_isophotes == 0
    undefined = (empty.delta_q_max, empty.delta_pa_max, empty.a4_a_extreme)
    assert all(math.isnan(v) for v in (*undefined, empty.a4_a_source_share))
    assert json.loads(json.dumps(empty.to_dict()))["a4_a_extreme"] is None


# --------------------------------------------------------------------------------------
# degenerate inputs: skipped with a logged reason, never a crash


def test_flat_and_empty_images_give_an_empty_table(caplog):
    caplog.set_level(logging.INFO, logger="mgelens.isophotes")
    flat = isophote_table(np.ones((81, 81)), PIXEL_SCALE)
    assert flat.empty
    assert list(flat.columns) == list(TABLE_COLUMNS)
    assert "cannot place isophote levels" in caplog.text
    empty = isophote_table(np.zeros((81, 81)), PIXEL_SCALE)
    assert empty.empty
    assert "no positive finite pixel" in caplog.text
    statistics = isophote_statistics(empty)
    assert statistics.n_isophotes == 0


def test_unusable_levels_are_skipped_with_a_reason(caplog):
    caplog.set_level(logging.INFO, logger="mgelens.isophotes")
    gaussian = Gaussian.from_major_axis((0.0, 0.0), 0.8, 30.0, 1.0)
    image = render_light([gaussian], PIXEL_SCALE, half_width=1.5)
    image[5:9, 5:9] = np.nan
    major = np.deg2rad(30.0)
    at_radius = [
        float(gaussian.image(r * np.cos(major), r * np.sin(major))) for r in (0.5, 1.0, 1.8, 5.0)
    ]
    levels = [2.0, -1.0, *at_radius]
    table = isophote_table(image, PIXEL_SCALE, centre=(0.0, 0.0), levels=levels)
    assert len(table) == 2
    np.testing.assert_allclose(table["sma"], [0.5, 1.0], atol=0.005)
    assert caplog.text.count("skipped") == 4
    assert "no contour at this level" in caplog.text
    assert "is not positive" in caplog.text
    assert "the contour is open" in caplog.text


def test_a_level_without_a_closed_contour_around_the_centre():
    galaxy = Gaussian.from_major_axis((0.0, 0.0), 0.8, 30.0, 0.6, 1.0)
    companion = Gaussian.from_major_axis((1.0, 0.5), 1.0, 0.0, 0.1, 3.0)
    image = render_light([galaxy, companion], PIXEL_SCALE, half_width=2.0)
    x, y = grid(81)
    with pytest.raises(IsophoteError, match="no closed contour around the centre"):
        closed_contour(contour_generator(image, PIXEL_SCALE, (0, 0)), 1.5, (0.0, 0.0))
    slope = 1.0 + 0.1 * x + 0.05 * y
    open_only = contour_generator(slope, PIXEL_SCALE, (0, 0))
    with pytest.raises(IsophoteError, match="open"):
        closed_contour(open_only, 1.0, (0.0, 0.0))
    table = isophote_table(slope, PIXEL_SCALE, centre=(0.0, 0.0), levels=[1.0, 1.05])
    assert table.empty


# --------------------------------------------------------------------------------------
# rendering, mass comparison, figure, command


def test_render_light_grid_flux_and_psf():
    gaussian = Gaussian.from_major_axis((0.1, -0.05), 0.7, 20.0, 0.3, 2.0)
    # uniform sub-grid: the midpoint rule integrates a resolved Gaussian spectrally
    uniform = render_light([gaussian], PIXEL_SCALE, half_width=3.0, sub_size_centre=4)
    assert uniform.shape == (121, 121)
    assert uniform.sum() == pytest.approx(gaussian.total_flux(PIXEL_SCALE), rel=1e-12)
    # adaptive (16×16 within 0.3″): per-pixel means differ from 4×4 by ~h²f''/24
    image = render_light([gaussian], PIXEL_SCALE, half_width=3.0)
    assert image.sum() == pytest.approx(gaussian.total_flux(PIXEL_SCALE), rel=1e-4)
    yy, xx = np.mgrid[:21, :21] - 10
    psf = np.exp(-(xx**2 + yy**2) / 2.0)
    blurred = render_light([gaussian], PIXEL_SCALE, half_width=3.0, psf=psf / psf.sum())
    assert blurred.sum() == pytest.approx(image.sum(), rel=1e-9)
    assert blurred.max() < image.max()
    x, y = grid(121)
    row, col = np.unravel_index(np.argmax(image), image.shape)
    assert (x[row, col], y[row, col]) == pytest.approx((0.1, -0.05), abs=1e-12)


def test_mass_shape_of_an_sie():
    """The SIE's tangential critical curve is its κ = ½ isodensity ellipse (|γ| = κ):
    semi-major axis 2θ_E/(1 + q), axis ratio q, angle φ; R_eff = 2θ_E√q/(1 + q)."""
    theta_e, q, angle = 1.2, 0.8, 135.0
    sie = SIE(centre=(0.013, -0.07), einstein_radius=theta_e, axis_ratio=q, angle=angle)
    shape = mass_shape_from([sie], axis_ratio_interval=(0.77, 0.83))
    ellipse = shape.critical_curve_ellipse
    assert ellipse.axis_ratio == pytest.approx(q, abs=0.002)
    assert abs(angle_difference(ellipse.angle, angle)) < 0.3
    assert ellipse.semi_major == pytest.approx(2 * theta_e / (1 + q), rel=2e-3)
    assert (ellipse.x0, ellipse.y0) == pytest.approx((0.013, -0.07), abs=1e-3)
    effective = 2 * theta_e * math.sqrt(q) / (1 + q)
    assert shape.critical_curve_einstein_radius == pytest.approx(effective, rel=2e-3)
    assert (shape.axis_ratio, shape.angle) == (q, angle)
    summary = shape.to_dict()
    assert summary["critical_curve_axis_ratio"] == ellipse.axis_ratio
    assert summary["axis_ratio_interval"] == (0.77, 0.83)


def test_mass_shape_without_a_closed_critical_curve(tmp_path):
    """An SIE whose critical curve (semi-major axis 2θ_E/(1 + q) = 5.6″) leaves the ±3″
    grid keeps its q and φ, has no critical-curve fields and says why; its summary row has
    NaN in those columns and its figure draws no curve (a sample is not stopped by it)."""
    sie = SIE(centre=(0.0, 0.0), einstein_radius=5.0, axis_ratio=0.8, angle=30.0)
    shape = mass_shape_from([sie], (0.75, 0.85), (25.0, 35.0))
    assert (shape.axis_ratio, shape.angle) == (0.8, 30.0)
    assert shape.critical_curve is None
    assert shape.critical_curve_ellipse is None
    assert shape.critical_curve_einstein_radius is None
    assert shape.critical_curve_note.startswith("no closed tangential critical curve within ±3")
    assert mass_shape_from([replace(sie, einstein_radius=1.0)]).critical_curve_note is None
    image = deformed_image(0.7, 30.0, 0.01)
    table = isophote_table(image, PIXEL_SCALE)
    path = tmp_path / "lens" / "isophotes.json"
    path.parent.mkdir()
    write_json(path, lens_summary("lens", isophote_statistics(table), shape))
    row = sample_table([path]).iloc[0]
    assert row["mass_axis_ratio"] == 0.8
    assert math.isnan(row["mass_critical_curve_einstein_radius"])
    assert math.isnan(row["mass_critical_curve_axis_ratio"])
    figure = isophote_figure(image, PIXEL_SCALE, table, shape)
    assert "critical curve" not in [line.get_label() for line in figure.axes[0].lines]


def test_isophote_figure(tmp_path):
    image = deformed_image(0.7, 30.0, 0.01)
    table = isophote_table(image, PIXEL_SCALE)
    sie = SIE(centre=(0.02, -0.03), einstein_radius=1.1, axis_ratio=0.75, angle=50.0)
    shape = mass_shape_from([sie], (0.72, 0.78), (48.0, 52.0))
    figure = isophote_figure(image, PIXEL_SCALE, table, shape, title="test", unit="e-/s")
    assert len(figure.axes) == 5  # image, q, PA, a4 and the image's colour bar
    shared = isophote_figure(image, PIXEL_SCALE, table.assign(source_share=0.1), shape)
    assert len(shared.axes) == 6  # and the source share under a4, with the a axis label
    assert shared.axes[4].get_xlabel() == "semi-major axis a [arcsec]"
    assert shared.axes[3].get_xlabel() == ""
    assert figure.axes[-1].get_ylabel() == "log₁₀ lens light [e-/s per pixel]"
    path = tmp_path / "figure.png"
    save_png(figure, path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["figure.png"]
    flat = np.ones((81, 81))
    flat_figure = isophote_figure(flat, PIXEL_SCALE, isophote_table(flat, PIXEL_SCALE))
    assert flat_figure.axes[-1].get_ylabel() == "log₁₀ lens light [data units per pixel]"


def test_isophotes_command(tmp_path, capsys):
    image = deformed_image(0.6, 120.0, -0.012, centre=(0.0, 0.0))
    fits.writeto(tmp_path / "lens.fits", image.astype(np.float32))
    yy, xx = np.mgrid[:11, :11] - 5
    fits.writeto(tmp_path / "psf.fits", np.exp(-(xx**2 + yy**2) / 2.0))
    out = tmp_path / "out"
    code = main(
        [
            "isophotes",
            str(tmp_path / "lens.fits"),
            "--pixel-scale",
            "0.05",
            "--centre",
            "0",
            "0",
            "--psf",
            str(tmp_path / "psf.fits"),
            "--lens",
            "J0000",
            "--summary",
            str(out / "summary.json"),
            "--figure",
            str(out / "isophotes.png"),
            "--out",
            str(out / "isophotes.csv"),
        ]
    )
    assert code == 0
    table = pd.read_csv(out / "isophotes.csv")
    assert list(table.columns) == list(TABLE_COLUMNS)
    assert len(table) == 40
    summary = json.loads((out / "summary.json").read_text())
    assert summary["lens"] == "J0000"
    assert summary["statistics"]["a4_a_extreme"] < 0.0
    assert summary["statistics"]["n_isophotes"] == int(
        ((table["sma"] >= 0.5) & (table["sma"] <= 2.5)).sum()
    )
    assert (out / "isophotes.png").stat().st_size > 10_000
    printed = capsys.readouterr().out
    assert "delta_q_max:" in printed
    assert "(boxy)" in printed
    assert (
        main(
            [
                "isophotes",
                str(tmp_path / "missing.fits"),
                "--pixel-scale",
                "0.05",
                "--out",
                str(out / "x.csv"),
            ]
        )
        == 1
    )


def test_isophotes_command_names_a_non_finite_image_and_runs_on_its_threads(tmp_path, caplog):
    image = deformed_image(0.6, 120.0, 0.0, centre=(0.0, 0.0))
    image[0, 0] = np.nan
    fits.writeto(tmp_path / "lens.fits", image)
    threads = numba.get_num_threads()
    try:
        arguments = ["isophotes", str(tmp_path / "lens.fits"), "--pixel-scale", "0.05"]
        code = main([*arguments, "--threads", "1", "--out", str(tmp_path / "x.csv")])
        assert numba.get_num_threads() == 1
    finally:
        numba.set_num_threads(threads)
    assert code == 1
    assert f"{tmp_path / 'lens.fits'}: 1 NaN or infinite pixel(s)" in caplog.text
    assert not (tmp_path / "x.csv").exists()


# --------------------------------------------------------------------------------------
# cross-check with photutils.isophote (optional dependency)

M1_TABLE = {
    "q": [
        0.83,
        0.77,
        0.83,
        0.90,
        0.65,
        0.64,
        0.77,
        0.50,
        1.00,
        0.79,
        0.48,
        0.62,
        0.41,
        0.18,
        0.78,
        0.22,
    ],
    "phi": [-19, -19, 71, -19, -70, 4, 56, -52, 0, -80, -2, -78, 28, 49, -73, -25],
    "lg_i": [
        0.86,
        0.91,
        0.29,
        0.30,
        -0.24,
        -0.48,
        -0.13,
        -0.75,
        -0.73,
        -0.76,
        -1.6,
        -1.4,
        -2.0,
        -2.2,
        -2.2,
        -2.4,
    ],
    "lg_sigma": [
        -1.8,
        -1.6,
        -1.4,
        -1.1,
        -1.0,
        -0.85,
        -0.75,
        -0.56,
        -0.25,
        -0.14,
        -0.13,
        0.0018,
        0.020,
        -0.19,
        0.43,
        -0.11,
    ],
}
"""SPEC §10.1, M1 = SDSSJ0252+0039: major-axis σ (arcsec), q, φ (deg), I (e⁻/s/pix)."""


def test_agreement_with_photutils_on_the_m1_lens_light():
    """SPEC §9.2 on the M1 mock lens light (8×8 over-sampling, Gaussian PSF σ = 1 pixel).

    q and PA must agree within |Δq| < 0.01 and |ΔPA| < 2° (q < 0.9). The disky/boxy
    coefficient — photutils ``b4``, the cos 4θ intensity harmonic over sma·|dI/da| — is
    not the same quantity as Bender's radial a₄/a: to first order b4 = a₄/a · 2⟨cos²4ϑ/ρ(ϑ)⟩
    (ρ the unit ellipse's polar radius; a factor 1.1–1.3 for q = 0.9–0.7), so the SPEC
    tolerance 0.003 only holds where |b4| < 0.01; beyond that the signs must agree.
    """
    isophote = pytest.importorskip("photutils.isophote")
    centre = (0.013, -0.070)
    gaussians = [
        Gaussian.from_major_axis(centre, q, phi, 10.0**lg_sigma, 10.0**lg_i)
        for q, phi, lg_i, lg_sigma in zip(*M1_TABLE.values(), strict=True)
    ]
    yy, xx = np.mgrid[:21, :21] - 10
    psf = np.exp(-(xx**2 + yy**2) / 2.0)
    image = render_light(gaussians, PIXEL_SCALE, 3.75, psf / psf.sum(), 8, 8)
    table = isophote_table(image, PIXEL_SCALE, centre=centre)
    centre_pixel = 0.5 * (image.shape[0] - 1)
    geometry = isophote.EllipseGeometry(
        x0=centre[0] / PIXEL_SCALE + centre_pixel,
        y0=centre[1] / PIXEL_SCALE + centre_pixel,
        sma=20.0,
        eps=1.0 - float(np.interp(1.0, table["sma"], table["q"])),
        pa=np.deg2rad(float(np.interp(1.0, table["sma"], table["pa"]))),
    )
    fitted = isophote.Ellipse(image, geometry=geometry).fit_image(
        sma0=20.0, minsma=8.0, maxsma=55.0, step=0.08
    )
    sma = np.asarray(fitted.sma) * PIXEL_SCALE
    used = (sma >= 0.5) & (sma <= 2.5) & (np.asarray(fitted.stop_code) == 0)
    assert used.sum() >= 15
    sma = sma[used]
    q_photutils = 1.0 - np.asarray(fitted.eps)[used]
    angle_photutils = np.rad2deg(np.asarray(fitted.pa)[used])
    b4 = np.asarray(fitted.b4)[used]
    q = np.interp(sma, table["sma"], table["q"])
    angle = np.interp(sma, table["sma"], table["pa"])
    a4 = np.interp(sma, table["sma"], table["a4_a"])
    assert np.max(np.abs(q - q_photutils)) < 0.01
    assert np.max(np.abs(angle_difference(angle, angle_photutils)[q < 0.9])) < 2.0
    small = np.abs(b4) < 0.01
    assert small.sum() >= 5
    assert np.max(np.abs(a4 - b4)[small]) < 0.003
    assert np.all(np.sign(a4[np.abs(b4) > 0.003]) == np.sign(b4[np.abs(b4) > 0.003]))

"""Tests of mgelens.mass against independent routes (SPEC §3).

Independent references used here:

* the elliptical-isodensity integrals (Schramm 1990; Keeton 2001, "A catalog of mass
  models", eq. for α of κ(ξ), ξ² = x′² + y′²/q²):
  α′_x = q x′ ∫₀¹ κ(ξ(u)) (1 − (1 − q²)u)^{−1/2} du,
  α′_y = q y′ ∫₀¹ κ(ξ(u)) (1 − (1 − q²)u)^{−3/2} du, ξ(u)² = u (x′² + y′²/(1 − (1 − q²)u));
* Tessore & Metcalf's ₂F₁ form, with scipy's complex ``hyp2f1`` and with ₂F₁ from its
  Euler integral (the anchor's rescaled-θ_E route);
* closed forms of the SIE, SIS and external shear.
"""

import numpy as np
import pytest
from scipy import integrate, special

from mgelens.geometry import from_profile_frame, to_profile_frame
from mgelens.mass import (
    EPL,
    SIE,
    ExternalShear,
    caustic,
    convergence_from,
    deflection_jacobian,
    deflections_from,
    einstein_radius_effective,
    jacobian_eigenvalues,
    magnification,
    ray_trace,
    tangential_critical_curve,
)

CENTRE = (0.13, -0.21)
QUERY_OFFSETS = np.array([[1.1, 0.4], [-0.3, 0.9], [-1.7, -0.6], [0.05, -0.02], [2.4, -1.9]])


def query_points(centre=CENTRE):
    """Query points (x, y) around ``centre``, near and far, in every quadrant."""
    return centre[0] + QUERY_OFFSETS[:, 0], centre[1] + QUERY_OFFSETS[:, 1]


def relative_error(actual, expected):
    """max |a − e| / |e| over points, for vector fields given as (x, y) pairs."""
    norm = np.hypot(*expected)
    return float(np.max(np.hypot(actual[0] - expected[0], actual[1] - expected[1]) / norm))


# --------------------------------------------------------------------------------------
# independent reference routes


def deflections_by_integration(profile, x, y):
    """EPL/SIE deflections from the isodensity integrals of κ (quad, tight tolerances).

    With κ(ξ) = (2 − t)/(1 + q) (θ_E/ξ)^t the factor u^{−t/2} of κ(ξ(u)) is handled as an
    algebraic weight; the rest, g(u) = (2 − t)/(1 + q) θ_E^t (x′² + y′²/d(u))^{−t/2},
    d(u) = 1 − (1 − q²)u, is smooth on [0, 1].
    """
    q, theta_e = profile.axis_ratio, profile.einstein_radius
    t = getattr(profile, "slope", 2.0) - 1.0
    norm = (2.0 - t) / (1.0 + q) * theta_e**t
    options = {"weight": "alg", "wvar": (-t / 2.0, 0.0), "epsabs": 0.0, "epsrel": 1e-13}

    def d(u):
        return 1.0 - (1.0 - q**2) * u

    def integral(xp, yp, power):
        def integrand(u):
            return norm * (xp**2 + yp**2 / d(u)) ** (-t / 2.0) / d(u) ** power

        return integrate.quad(integrand, 0.0, 1.0, **options)[0]

    xps, yps = to_profile_frame(x, y, profile.centre, profile.angle)
    alpha_x = [q * xp * integral(xp, yp, 0.5) for xp, yp in zip(xps, yps, strict=True)]
    alpha_y = [q * yp * integral(xp, yp, 1.5) for xp, yp in zip(xps, yps, strict=True)]
    return from_profile_frame(np.array(alpha_x), np.array(alpha_y), profile.angle)


def hyp2f1_euler(b, c, z):
    """₂F₁(1, b; c; z) for complex |z| < 1 from Euler's integral (needs c > b > 0)."""

    def part(s, imag):
        value = 1.0 / (1.0 - z * s)
        return value.imag if imag else value.real

    options = {"weight": "alg", "wvar": (b - 1.0, c - b - 1.0), "epsabs": 0.0, "epsrel": 1e-13}
    real = integrate.quad(part, 0.0, 1.0, args=(False,), **options)[0]
    imag = integrate.quad(part, 0.0, 1.0, args=(True,), **options)[0]
    norm = special.gamma(c) / (special.gamma(b) * special.gamma(c - b))
    return norm * (real + 1j * imag)


def _omega(profile, xp, yp, hyp2f1):
    """R and Ω(ϑ) = e^{iϑ} ₂F₁(1, t/2; 2 − t/2; −f e^{2iϑ}) in the profile frame."""
    q, t = profile.axis_ratio, profile.slope - 1.0
    f = (1.0 - q) / (1.0 + q)
    radius = np.hypot(q * xp, yp)
    phase = np.exp(1j * np.arctan2(yp, q * xp))
    hyper = np.array([hyp2f1(0.5 * t, 2.0 - 0.5 * t, -f * p**2) for p in np.atleast_1d(phase)])
    return radius, phase * hyper


def deflections_tessore_metcalf(profile, x, y):
    """T&M ₂F₁ form with b_TM = q θ_E (2/(1 + q))^{1/t}, scipy's complex ``hyp2f1``."""
    q, t = profile.axis_ratio, profile.slope - 1.0
    xp, yp = to_profile_frame(x, y, profile.centre, profile.angle)
    radius, omega = _omega(profile, xp, yp, lambda b, c, z: special.hyp2f1(1.0, b, c, z))
    b_tm = q * profile.einstein_radius * (2.0 / (1.0 + q)) ** (1.0 / t)
    alpha = 2.0 * b_tm / (1.0 + q) * (b_tm / radius) ** (t - 1.0) * omega
    return from_profile_frame(alpha.real, alpha.imag, profile.angle)


def deflections_anchor_route(profile, x, y):
    """Anchor route: θ_E·2√q/(1 + q), b = √q·that, ₂F₁ form, times ((1 + q)/2)^{t−1}."""
    q, t = profile.axis_ratio, profile.slope - 1.0
    xp, yp = to_profile_frame(x, y, profile.centre, profile.angle)
    radius, omega = _omega(profile, xp, yp, hyp2f1_euler)
    b = np.sqrt(q) * profile.einstein_radius * 2.0 * np.sqrt(q) / (1.0 + q)
    alpha = 2.0 * b / (1.0 + q) * (b / radius) ** (t - 1.0) * omega * ((1.0 + q) / 2.0) ** (t - 1.0)
    return from_profile_frame(alpha.real, alpha.imag, profile.angle)


def gradient_by_differences(function, x, y, step=1e-5):
    """Central-difference gradient of a scalar field."""
    return (
        (function(x + step, y) - function(x - step, y)) / (2.0 * step),
        (function(x, y + step) - function(x, y - step)) / (2.0 * step),
    )


def rotate(vx, vy, angle):
    """Rotate vectors counter-clockwise by ``angle`` degrees."""
    return from_profile_frame(vx, vy, angle)


# --------------------------------------------------------------------------------------
# deflections against the convergence


@pytest.mark.parametrize("axis_ratio", [0.3, 0.7])
def test_isodensity_integral_reproduces_sie_closed_form(axis_ratio):
    sie = SIE(CENTRE, 1.3, axis_ratio, 30.0)
    x, y = query_points()
    assert relative_error(deflections_by_integration(sie, x, y), sie.deflections(x, y)) < 1e-12


@pytest.mark.parametrize("angle", [0.0, 30.0, 117.0])
@pytest.mark.parametrize("slope", [1.5, 2.0, 2.5, 2.95])
@pytest.mark.parametrize("axis_ratio", [0.3, 0.7])
def test_epl_deflections_equal_integral_of_convergence(axis_ratio, slope, angle):
    epl = EPL(CENTRE, 1.2, axis_ratio, angle, slope)
    x, y = query_points()
    assert relative_error(epl.deflections(x, y), deflections_by_integration(epl, x, y)) < 1e-9


@pytest.mark.parametrize(
    "profile",
    [
        EPL(CENTRE, 1.2, 0.4, 117.0, 1.6),
        EPL(CENTRE, 0.9, 0.8, 30.0, 2.4),
        SIE(CENTRE, 1.1, 0.6, 75.0),
    ],
)
def test_deflections_are_gradient_of_potential(profile):
    x, y = query_points()
    gradient = gradient_by_differences(profile.potential, x, y)
    assert relative_error(gradient, profile.deflections(x, y)) < 1e-7


@pytest.mark.parametrize("axis_ratio", [0.3, 0.7, 0.95])
def test_epl_with_slope_two_equals_sie(axis_ratio):
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-3.0, 3.0, (2, 2000))
    epl = EPL(CENTRE, 1.4, axis_ratio, 117.0, 2.0)
    sie = SIE(CENTRE, 1.4, axis_ratio, 117.0)
    assert relative_error(epl.deflections(x, y), sie.deflections(x, y)) < 1e-10
    np.testing.assert_allclose(epl.convergence(x, y), sie.convergence(x, y), rtol=1e-13)


def test_round_profiles_reduce_to_sis():
    x, y = query_points()
    dx, dy = x - CENTRE[0], y - CENTRE[1]
    r = np.hypot(dx, dy)
    sis = (1.3 * dx / r, 1.3 * dy / r)
    assert relative_error(EPL(CENTRE, 1.3, 1.0, 40.0, 2.0).deflections(x, y), sis) < 1e-14
    assert relative_error(SIE(CENTRE, 1.3, 1.0, 40.0).deflections(x, y), sis) < 1e-5


@pytest.mark.parametrize("slope", [1.5, 2.0, 2.3])
def test_mean_convergence_inside_einstein_radius_of_round_epl_is_one(slope):
    """2/θ_E² ∫₀^θ_E κ r dr, integrated in s = ln(θ_E/r) (the integrand decays as e^{−(3−γ)s}).

    The push-out at r < 1e-8″ changes the result by ~(1e-8/θ_E)^{3−γ} ≤ 3e-6 here.
    """
    epl = EPL(CENTRE, 1.3, 1.0, 0.0, slope)
    direction = np.array([0.6, -0.8])

    def integrand(s):
        r = epl.einstein_radius * np.exp(-s)
        kappa = epl.convergence(CENTRE[0] + r * direction[0], CENTRE[1] + r * direction[1])
        return 2.0 * r**2 * kappa / epl.einstein_radius**2

    mean, _ = integrate.quad(integrand, 0.0, np.inf, epsabs=0.0, epsrel=1e-10, limit=200)
    assert mean == pytest.approx(1.0, abs=1e-5)


# --------------------------------------------------------------------------------------
# the three EPL routes of SPEC §3.1


def test_euler_integral_hyp2f1_matches_scipy():
    z = -0.54 * np.exp(2j * np.linspace(0.0, np.pi, 7))
    for b, c in [(0.15, 1.85), (0.5, 1.5), (0.75, 1.25)]:
        for value in z:
            assert hyp2f1_euler(b, c, value) == pytest.approx(
                special.hyp2f1(1.0, b, c, value), rel=1e-12
            )


@pytest.mark.parametrize("slope", [1.3, 1.5, 2.0, 2.5, 2.7, 2.95])
@pytest.mark.parametrize("axis_ratio", [0.3, 0.7, 1.0])
def test_series_hypergeometric_and_anchor_routes_agree(axis_ratio, slope):
    epl = EPL(CENTRE, 1.2, axis_ratio, 117.0, slope)
    # every quadrant of ϑ, near and far
    polar_angles = np.linspace(0.0, 2.0 * np.pi, 13, endpoint=False) + 0.01
    radii = np.where(np.arange(13) % 2 == 0, 0.3, 2.2)
    x = CENTRE[0] + radii * np.cos(polar_angles)
    y = CENTRE[1] + radii * np.sin(polar_angles)
    series = epl.deflections(x, y)
    assert relative_error(series, deflections_tessore_metcalf(epl, x, y)) < 1e-10
    assert relative_error(series, deflections_anchor_route(epl, x, y)) < 1e-10


@pytest.mark.parametrize("axis_ratio", [0.1, 0.2, 0.5, 0.9])
def test_series_truncation_holds_at_every_polar_angle(axis_ratio):
    """The series length is fixed per call from its worst case (ϑ = 0); check all ϑ."""
    polar_angles = np.linspace(0.0, 2.0 * np.pi, 721)
    x = CENTRE[0] + 1.3 * np.cos(polar_angles)
    y = CENTRE[1] + 1.3 * np.sin(polar_angles)
    for slope in (1.25, 2.0, 2.75, 2.95):
        epl = EPL(CENTRE, 1.2, axis_ratio, 117.0, slope)
        reference = deflections_tessore_metcalf(epl, x, y)
        assert relative_error(epl.deflections(x, y), reference) < 1e-10


# --------------------------------------------------------------------------------------
# conventions


@pytest.mark.parametrize("profile_type", ["epl", "sie"])
def test_rotation_convention(profile_type):
    """A profile at φ evaluated at c + R(φ)p equals the φ = 0 profile at c + p, rotated by φ."""
    angle = 117.0

    def make(phi):
        if profile_type == "epl":
            return EPL(CENTRE, 1.1, 0.5, phi, 2.3)
        return SIE(CENTRE, 1.1, 0.5, phi)

    px, py = QUERY_OFFSETS.T
    rx, ry = rotate(px, py, angle)
    rotated = make(angle).deflections(CENTRE[0] + rx, CENTRE[1] + ry)
    reference = rotate(*make(0.0).deflections(CENTRE[0] + px, CENTRE[1] + py), angle)
    assert relative_error(rotated, reference) < 1e-13
    np.testing.assert_allclose(
        make(angle).convergence(CENTRE[0] + rx, CENTRE[1] + ry),
        make(0.0).convergence(CENTRE[0] + px, CENTRE[1] + py),
        rtol=1e-13,
    )


def test_axis_ratio_convention_major_axis_along_angle():
    """κ is constant on η = const, the ellipse with semi-major η along φ and semi-minor qη."""
    q, angle, eta = 0.4, 30.0, 0.8
    epl = EPL(CENTRE, 1.2, q, angle, 2.2)
    u = np.linspace(0.0, 2.0 * np.pi, 9)
    ex, ey = rotate(eta * np.cos(u), q * eta * np.sin(u), angle)
    kappa = epl.convergence(CENTRE[0] + ex, CENTRE[1] + ey)
    np.testing.assert_allclose(kappa, 0.8 / 1.4 * (1.2 / eta) ** 1.2, rtol=1e-13)
    major = epl.convergence(
        CENTRE[0] + eta * np.cos(np.deg2rad(angle)), CENTRE[1] + eta * np.sin(np.deg2rad(angle))
    )
    assert major == pytest.approx(kappa[0], rel=1e-13)


def test_ell_comps_round_trip():
    epl = EPL.from_ell_comps(CENTRE, (0.0, 0.2), 1.2, 2.1)
    assert epl.axis_ratio == pytest.approx(0.8 / 1.2)
    assert epl.angle == pytest.approx(45.0)
    assert epl.ell_comps == pytest.approx((0.0, 0.2), abs=1e-15)
    sie = SIE.from_ell_comps(CENTRE, (-0.1, -0.05), 1.0)
    assert sie.ell_comps == pytest.approx((-0.1, -0.05))
    assert 90.0 < sie.angle < 180.0


def test_external_shear():
    shear = ExternalShear(0.05, -0.03)
    x, y = query_points()
    assert (
        relative_error(shear.deflections(x, y), gradient_by_differences(shear.potential, x, y))
        < 1e-9
    )
    np.testing.assert_allclose(shear.convergence(x, y), 0.0)
    a_xx, a_xy, a_yx, a_yy = deflection_jacobian([shear], x, y)
    np.testing.assert_allclose(
        [a_xx, a_xy, a_yx, a_yy], [[0.05] * 5, [-0.03] * 5, [-0.03] * 5, [-0.05] * 5]
    )
    assert shear.magnitude == pytest.approx(np.hypot(0.05, 0.03))
    assert shear.angle == pytest.approx(180.0 + 0.5 * np.rad2deg(np.arctan2(-0.03, 0.05)))
    assert ExternalShear(0.0, 0.1).angle == pytest.approx(45.0)


def test_sums_and_ray_tracing():
    profiles = [EPL(CENTRE, 1.2, 0.7, 30.0, 2.2), ExternalShear(0.04, 0.01)]
    x, y = query_points()
    alpha_x, alpha_y = deflections_from(profiles, x, y)
    epl_x, epl_y = profiles[0].deflections(x, y)
    np.testing.assert_allclose(alpha_x, epl_x + 0.04 * x + 0.01 * y, rtol=1e-15)
    np.testing.assert_allclose(alpha_y, epl_y + 0.01 * x - 0.04 * y, rtol=1e-15)
    beta_x, beta_y = ray_trace(profiles, x, y)
    np.testing.assert_allclose([beta_x, beta_y], [x - alpha_x, y - alpha_y])
    np.testing.assert_allclose(convergence_from(profiles, x, y), profiles[0].convergence(x, y))


def test_shapes_and_centre_push_out():
    epl = EPL(CENTRE, 1.2, 0.7, 30.0, 2.2)
    grid = np.zeros((3, 4))
    assert epl.deflections(grid, grid)[0].shape == (3, 4)
    assert epl.potential(grid, 0.0).shape == (3, 4)
    at_centre = epl.deflections(*CENTRE)
    assert np.shape(at_centre[0]) == ()
    np.testing.assert_allclose(at_centre, epl.deflections(CENTRE[0] + 1e-8, CENTRE[1]), rtol=1e-12)
    assert np.all(np.isfinite(epl.convergence(*CENTRE)))
    assert np.all(np.isfinite(SIE(CENTRE, 1.0, 0.5).deflections(*CENTRE)))


# --------------------------------------------------------------------------------------
# magnification and critical curves


def test_magnification_of_sis():
    sis = SIE(CENTRE, 1.3, 1.0)
    x, y = query_points()
    r = np.hypot(x - CENTRE[0], y - CENTRE[1])
    far = r > 0.2
    # SIS: μ = r/(r − θ_E); the q cap 0.99999 leaves ~1e-5 relative differences
    np.testing.assert_allclose(magnification([sis], x, y)[far], (r / (r - 1.3))[far], rtol=1e-4)
    exact = EPL(CENTRE, 1.3, 1.0, 0.0, 2.0)
    np.testing.assert_allclose(magnification([exact], x, y)[far], (r / (r - 1.3))[far], rtol=1e-7)


def test_jacobian_eigenvalues_of_sis():
    """SIS: λ_t = 1 − θ_E/r, λ_r = 1; the ±Δ/2 stencil errs by O((Δ/r)²)."""
    sis = [EPL((0.0, 0.0), 1.0, 1.0, 0.0, 2.0)]
    x, y, lambda_t, lambda_r = jacobian_eigenvalues(sis, grid_spacing=0.05, half_width=2.0)
    assert x.shape == (81, 81)
    np.testing.assert_allclose(x[0], np.linspace(-2.0, 2.0, 81), atol=1e-12)
    np.testing.assert_allclose(y[:, 0], np.linspace(-2.0, 2.0, 81), atol=1e-12)
    r = np.hypot(x, y)
    away = r > 0.8
    np.testing.assert_allclose(lambda_t[away], 1.0 - 1.0 / r[away], atol=1e-3)
    np.testing.assert_allclose(lambda_r[away], 1.0, atol=1e-3)


def test_critical_curve_and_caustic_of_sis():
    sis = [EPL((0.1, -0.05), 1.2, 1.0, 0.0, 2.0)]
    x, y = tangential_critical_curve(sis)
    assert (x[0], y[0]) == (x[-1], y[-1])
    np.testing.assert_allclose(np.hypot(x - 0.1, y + 0.05), 1.2, atol=1e-3)
    assert einstein_radius_effective(sis) == pytest.approx(1.2, rel=1e-3)
    beta_x, beta_y = caustic(sis)
    assert np.max(np.hypot(beta_x - 0.1, beta_y + 0.05)) < 1e-3


@pytest.mark.parametrize("axis_ratio", [0.5, 0.8])
def test_effective_einstein_radius_of_sie(axis_ratio):
    """SIE critical curve: κ = ½, i.e. η = 2θ_E/(1 + q), so θ_eff = θ_E·2√q/(1 + q) = θ_E^{LT}."""
    sie = SIE((0.05, 0.1), 1.1, axis_ratio, 60.0)
    effective = einstein_radius_effective([sie, ExternalShear()])
    assert effective == pytest.approx(
        1.1 * 2.0 * np.sqrt(axis_ratio) / (1.0 + axis_ratio), rel=2e-3
    )
    assert effective == pytest.approx(1.1, rel=0.06)


def test_missing_critical_curve_raises():
    with pytest.raises(ValueError, match="half_width"):
        tangential_critical_curve([SIE((0.0, 0.0), 2.0, 0.8)], half_width=1.0)


# --------------------------------------------------------------------------------------
# validation


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"slope": 1.2}, "slope"),
        ({"slope": 3.0}, "slope"),
        ({"slope": np.nan}, "slope"),
        ({"axis_ratio": 0.0}, "axis_ratio"),
        ({"axis_ratio": 1.01}, "axis_ratio"),
        ({"einstein_radius": -0.1}, "einstein_radius"),
        ({"centre": (0.0,)}, "centre"),
    ],
)
def test_epl_validation(kwargs, message):
    with pytest.raises(ValueError, match=message):
        EPL(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"axis_ratio": -0.5}, "axis_ratio"),
        ({"axis_ratio": 1.5}, "axis_ratio"),
        ({"einstein_radius": -1.0}, "einstein_radius"),
    ],
)
def test_sie_validation(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SIE(**kwargs)

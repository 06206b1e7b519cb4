"""Lens-light profiles of the mocks (SPEC §10.1): multi-Gaussian light
with each Gaussian's own q and φ (M1–M3), and light defined by its isophotes (the
population), whose q(a), PA(a) and a₄/a(a) are known by construction.

Conventions (SPEC §1.1, §2.1): (x, y) in arcsec, angles in degrees counter-clockwise
from +x, axis ratio q = minor/major; surface brightness in e⁻ s⁻¹ per image pixel.

* :class:`MGELight`: Gaussians with their own q and φ and the mgefit **major-axis** σ
  (built with :meth:`mgelens.light.Gaussian.from_major_axis`), used for M1–M3 from the
  tables of SPEC §10.1 (:data:`mgelens.mock_lenses.PAPER_MOCKS`).
* :class:`IsophoteLight`: light defined directly by its isophotes, so that the isophote
  shape versus radius — q(a), PA(a) and the Bender a₄/a — is known by construction (the
  population, :func:`mgelens.mock_lenses.population_lens`). See the class docstring for
  the exact meaning.
"""

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from math import exp, log, sqrt

import numpy as np
from numba import prange

from mgelens._jit import njit
from mgelens.grid import flat_points
from mgelens.light import Gaussian, sersic_constant

ISOPHOTE_TRUTH_RADII = np.geomspace(0.1, 3.0, 40)
"""Semi-major axes (arcsec) at which a mock records its true isophote shape."""

# --------------------------------------------------------------------------------------
# numba kernels


EXPONENT_CUTOFF = 100.0
"""Gaussian terms with exponent above this (e^−100 ≈ 4e−44) are dropped."""

_POINTS_PER_TASK = 1024
"""Consecutive points handled by one parallel task of the point kernels."""


@njit(parallel=True, fastmath=True)
def _gaussian_sum_kernel(x, y, centre_x, centre_y, a_xx, a_xy, a_yy, peak):
    """Σ_k I_k exp(−E_k) at points, E_k = a_xx dx² + a_xy dx dy + a_yy dy²."""
    out = np.zeros(x.size)
    for i in prange(x.size):
        total = 0.0
        for k in range(peak.size):
            dx = x[i] - centre_x[k]
            dy = y[i] - centre_y[k]
            exponent = a_xx[k] * dx * dx + a_xy[k] * dx * dy + a_yy[k] * dy * dy
            if exponent < EXPONENT_CUTOFF:
                total += peak[k] * exp(-exponent)
        out[i] = total
    return out


@njit(parallel=True, fastmath=True)
def _gaussian_sum_grid_kernel(x_axis, y_axis, segment, centre_x, centre_y, a_xx, a_xy, a_yy, peak):
    """Σ_k I_k exp(−E_k) on the outer grid of ``x_axis`` (uniform) and ``y_axis``.

    Along a row, E_k is quadratic in the node index, so over a segment of ``segment``
    nodes (one pixel's sub-pixels) exp(−E) follows the recurrence G ← G R, R ← R C
    (R = exp(−ΔE), C = exp(−2 a_xx h²)): two exponentials per segment instead of one per
    node, restarted every segment so rounding stays ~1e−15. Segments whose smallest E
    exceeds ``EXPONENT_CUTOFF`` are skipped; segments spanning more than 600 in E (very
    narrow Gaussians) use one exponential per node.
    """
    n_x = x_axis.size
    h = x_axis[1] - x_axis[0] if n_x > 1 else 1.0
    out = np.zeros((y_axis.size, n_x))
    for row in prange(y_axis.size):
        for k in range(peak.size):
            dy = y_axis[row] - centre_y[k]
            curvature = a_xx[k] * h * h
            decay = exp(-2.0 * curvature)
            for first in range(0, n_x, segment):
                count = min(segment, n_x - first)
                dx = x_axis[first] - centre_x[k]
                e0 = a_xx[k] * dx * dx + a_xy[k] * dx * dy + a_yy[k] * dy * dy
                slope = 2.0 * a_xx[k] * dx * h + a_xy[k] * dy * h
                vertex = min(max(-slope / (2.0 * curvature), 0.0), count - 1.0)
                e_min = e0 + vertex * slope + vertex * vertex * curvature
                if e_min > EXPONENT_CUTOFF:
                    continue
                last = count - 1.0
                e_max = max(e0, e0 + last * slope + last * last * curvature)
                if e_max - e_min < 600.0:
                    value = peak[k] * exp(-e0)
                    ratio = exp(-(slope + curvature))
                    for j in range(count):
                        out[row, first + j] += value
                        value *= ratio
                        ratio *= decay
                else:
                    for j in range(count):
                        e = e0 + j * slope + j * j * curvature
                        if e < EXPONENT_CUTOFF:
                            out[row, first + j] += peak[k] * exp(-e)
    return out


@njit(inline="always")
def _log_isophote_radius(u, cos_theta, sin_theta, table, u_min, inv_du):
    """ln ρ of isophote a = e^u at the sky direction (cos θ, sin θ).

    ``table`` rows hold (q, cos φ, sin φ, c) at u = u_min + k/inv_du (linear
    interpolation); ρ = q/sqrt(q² cos²ψ + sin²ψ) + c cos 4ψ with ψ = θ − φ(a).
    """
    t = (u - u_min) * inv_du
    k = min(max(int(np.floor(t)), 0), table.shape[0] - 2)
    f = min(max(t - k, 0.0), 1.0)
    q = table[k, 0] + f * (table[k + 1, 0] - table[k, 0])
    cos_phi = table[k, 1] + f * (table[k + 1, 1] - table[k, 1])
    sin_phi = table[k, 2] + f * (table[k + 1, 2] - table[k, 2])
    c4 = table[k, 3] + f * (table[k + 1, 3] - table[k, 3])
    norm = sqrt(cos_phi * cos_phi + sin_phi * sin_phi)
    c = (cos_theta * cos_phi + sin_theta * sin_phi) / norm
    s = (sin_theta * cos_phi - cos_theta * sin_phi) / norm
    c2 = c * c
    return log(q / sqrt(q * q * c2 + s * s) + c4 * (8.0 * c2 * c2 - 8.0 * c2 + 1.0))


@njit(inline="always")
def _semi_major_axis(dx, dy, guess, table, u_min, inv_du):
    """ln of the label a of the isophote through (dx, dy): root u of g = u + ln ρ − ln r.

    g′ ∈ [½, 3/2] (checked by :class:`IsophoteLight`), so the fixed-point step
    u ← ln r − ln ρ(u) contracts; it starts from ``guess`` (the previous point's root, or
    ln r when NaN) and is followed by secant steps until |g| < 1e−13. Returns −inf at
    the centre.
    """
    r = sqrt(dx * dx + dy * dy)
    if r < 1e-300:
        return -np.inf
    cos_theta = dx / r
    sin_theta = dy / r
    log_r = log(r)
    u0 = log_r if np.isnan(guess) else guess
    g0 = u0 + _log_isophote_radius(u0, cos_theta, sin_theta, table, u_min, inv_du) - log_r
    if abs(g0) < 1e-13:
        return u0
    u1 = u0 - g0
    for _ in range(60):
        g1 = u1 + _log_isophote_radius(u1, cos_theta, sin_theta, table, u_min, inv_du) - log_r
        if abs(g1) < 1e-13 or g1 == g0:
            break
        u0, u1, g0 = u1, u1 - g1 * (u1 - u0) / (g1 - g0), g1
    return u1


@njit(parallel=True)
def _isophote_label_kernel(x, y, centre_x, centre_y, table, u_min, inv_du):
    """ln a of the isophote through each point (−inf at the centre)."""
    n = x.size
    out = np.empty(n)
    for task in prange((n + _POINTS_PER_TASK - 1) // _POINTS_PER_TASK):
        guess = np.nan
        for i in range(task * _POINTS_PER_TASK, min(n, (task + 1) * _POINTS_PER_TASK)):
            u = _semi_major_axis(x[i] - centre_x, y[i] - centre_y, guess, table, u_min, inv_du)
            out[i] = u
            guess = u if np.isfinite(u) else np.nan
    return out


@njit(parallel=True)
def _isophote_light_kernel(x, y, centre_x, centre_y, table, u_min, inv_du, sersic):
    """Sérsic of the isophote label: I_e exp(−b_n[(a/R_e)^{1/n} − 1]) at each point.

    ``sersic`` = (I_e, ln R_e, 1/n, b_n).
    """
    n = x.size
    out = np.empty(n)
    for task in prange((n + _POINTS_PER_TASK - 1) // _POINTS_PER_TASK):
        guess = np.nan
        for i in range(task * _POINTS_PER_TASK, min(n, (task + 1) * _POINTS_PER_TASK)):
            u = _semi_major_axis(x[i] - centre_x, y[i] - centre_y, guess, table, u_min, inv_du)
            out[i] = sersic[0] * exp(-sersic[3] * (exp((u - sersic[1]) * sersic[2]) - 1.0))
            guess = u if np.isfinite(u) else np.nan
    return out


# --------------------------------------------------------------------------------------
# lens light


@dataclass(frozen=True)
class MGELight:
    """Lens light as a sum of elliptical Gaussians, each with its own q and φ.

    Attributes
    ----------
    gaussians : tuple of :class:`~mgelens.light.Gaussian`
        Anchor-form Gaussians (minor-axis ``sigma``); build mgefit tables (major-axis σ)
        with :meth:`from_table`.
    """

    gaussians: tuple[Gaussian, ...]

    @classmethod
    def from_table(
        cls,
        centre: tuple[float, float],
        axis_ratios: Sequence[float],
        angles: Sequence[float],
        log_intensities: Sequence[float],
        log_sigmas: Sequence[float],
    ) -> "MGELight":
        """From an mgefit table: q, φ (degrees), lg I (e⁻ s⁻¹ pix⁻¹), lg σ_major (arcsec).

        Each Gaussian is I exp[−(x′² + y′²/q²)/(2σ²)] (SPEC §10.1), i.e. the anchor form
        with minor-axis σ = q σ_table (:meth:`~mgelens.light.Gaussian.from_major_axis`).
        """
        rows = zip(axis_ratios, angles, log_intensities, log_sigmas, strict=True)
        return cls(
            tuple(
                Gaussian.from_major_axis(centre, q, phi, 10.0**lg_sigma, 10.0**lg_intensity)
                for q, phi, lg_intensity, lg_sigma in rows
            )
        )

    def _quadratic_forms(self) -> tuple[np.ndarray, ...]:
        """Per Gaussian: centre x, centre y, a_xx, a_xy, a_yy, I with the exponent
        E = a_xx dx² + a_xy dx dy + a_yy dy² = (q² x′² + y′²)/(2σ²)."""
        g = self.gaussians
        phi = np.deg2rad([gaussian.angle for gaussian in g])
        c, s = np.cos(phi), np.sin(phi)
        q2 = np.array([gaussian.axis_ratio for gaussian in g]) ** 2
        scale = 1.0 / (2.0 * np.array([gaussian.sigma for gaussian in g]) ** 2)
        return (
            np.array([gaussian.centre[0] for gaussian in g], dtype=float),
            np.array([gaussian.centre[1] for gaussian in g], dtype=float),
            (q2 * c * c + s * s) * scale,
            2.0 * c * s * (q2 - 1.0) * scale,
            (q2 * s * s + c * c) * scale,
            np.array([gaussian.intensity for gaussian in g], dtype=float),
        )

    def image(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Surface brightness (e⁻ s⁻¹ per pixel) at points (x, y), arcsec."""
        x_flat, y_flat, shape = flat_points(x, y)
        return _gaussian_sum_kernel(x_flat, y_flat, *self._quadratic_forms()).reshape(shape)

    def image_on_grid(
        self, x_axis: np.ndarray, y_axis: np.ndarray, segment: int = 16
    ) -> np.ndarray:
        """Surface brightness on the grid of 1D axes (``x_axis`` uniform), (n_y, n_x).

        Same values as :meth:`image` (to ~1e−14 relative) but with two exponentials per
        ``segment`` nodes of a row (see ``_gaussian_sum_grid_kernel``).
        """
        return _gaussian_sum_grid_kernel(
            np.ascontiguousarray(x_axis, dtype=float),
            np.ascontiguousarray(y_axis, dtype=float),
            int(segment),
            *self._quadratic_forms(),
        )

    def total_flux(self, pixel_scale: float) -> float:
        """Σ 2π I σ_major² q / Δ² = Σ 2π I σ² / (q Δ²): the pixel sum over the whole plane."""
        return float(sum(g.total_flux(pixel_scale) for g in self.gaussians))

    def to_dict(self) -> dict:
        return {
            "model": "mge",
            "form": "I exp(-(x'^2 + y'^2/q^2)/(2 sigma_major^2)); sigma = q sigma_major is "
            "the anchor (minor-axis) sigma",
            "gaussians": [
                {
                    "centre": list(g.centre),
                    "axis_ratio": g.axis_ratio,
                    "angle": g.angle,
                    "ell_comps": list(g.ell_comps),
                    "intensity": g.intensity,
                    "sigma_major": g.sigma_major,
                    "sigma": g.sigma,
                }
                for g in self.gaussians
            ],
        }


@dataclass(frozen=True)
class Transition:
    """Smooth change of a quantity with semi-major axis a (arcsec).

    value(a) = inner + (outer − inner) · ½[1 + tanh(ln(a/radius)/width)]: ``inner`` for
    a ≪ radius, ``outer`` for a ≫ radius, half-way at a = radius; ``width`` in ln a.
    """

    inner: float
    outer: float
    radius: float = 1.0
    width: float = 0.5

    def __post_init__(self):
        if not (self.radius > 0.0 and self.width > 0.0):
            raise ValueError(f"radius and width must be > 0, got {self.radius}, {self.width}")

    def __call__(self, semi_major_axis) -> np.ndarray:
        u = np.log(np.asarray(semi_major_axis, dtype=float) / self.radius) / self.width
        return self.inner + (self.outer - self.inner) * 0.5 * (1.0 + np.tanh(u))


NESTING_RANGE = (0.5, 1.5)
"""Allowed range of ∂ ln(a ρ)/∂ ln a at fixed sky angle (1 for self-similar isophotes):
positive means the isophotes nest; the margins keep them well apart and make the label
equation a contraction for its fixed-point step."""

TABLE_LOG_RANGE = (np.log(1e-6), np.log(1e3))
TABLE_SIZE = 2**14 + 1
"""The kernels interpolate q, φ, a₄/a linearly in ln a on this grid (Δ ln a ≈ 1.3e−3):
relative error ≲ 1e−6 against the formulas for transition widths ≥ 0.3."""


def _isophote_shape(psi, axis_ratio, a4_over_a):
    """ρ(ψ) = q/sqrt(q² cos²ψ + sin²ψ) + (a₄/a) cos 4ψ: polar radius over a (NumPy)."""
    q = axis_ratio
    return q / np.sqrt((q * np.cos(psi)) ** 2 + np.sin(psi) ** 2) + a4_over_a * np.cos(4 * psi)


@dataclass(frozen=True)
class IsophoteLight:
    """Lens light defined by its isophotes, whose shape is known at every radius.

    Construction. The isophote labelled a (its semi-major axis) is the closed curve whose
    polar radius about ``centre``, at angle ψ from its major axis, is

        R(ψ; a) = a ρ(ψ),  ρ(ψ) = q/sqrt(q² cos²ψ + sin²ψ) + c cos 4ψ,

    with q = q(a), major axis at PA φ(a) (degrees CCW from +x, so ψ = θ − φ(a) for the sky
    polar angle θ) and c = (a₄/a)(a); q, φ and c are :class:`Transition` functions of a.
    The first term is the ellipse of semi-axes a and q a; the second is the radial
    deviation a₄ cos 4ψ with a₄ = c a. The surface brightness is a Sérsic function of the
    label, I = I_e exp{−b_n[(a/R_e)^{1/n} − 1]}, with R_e measured along the major axis.

    Meaning of the recorded truth (Bender & Möllenhoff 1987, SPEC §9.1): the ellipse
    (centre, a, q, φ) is the best ellipse in the sense that the isophote's radial deviation
    from it, as a function of the polar angle ψ in the ellipse frame, has no harmonic of
    order 0, 1 or 2; that deviation is exactly a₄ cos 4ψ, so a₄/a = c, **positive = disky**
    (isophote pointed along the axes), negative = boxy. Fitters that define the best
    ellipse otherwise (a plain algebraic conic fit; photutils, whose ``b4`` is an
    intensity harmonic divided by the gradient) differ from these numbers by amounts of
    order 0.1 |a₄/a| in q and 10–30 % in a₄/a.

    Attributes
    ----------
    centre : (x, y) arcsec
    intensity : float
        I_e, e⁻ s⁻¹ per pixel at a = R_e.
    effective_radius : float
        R_e, arcsec along the major axis.
    sersic_index : float
        n.
    axis_ratio, angle, a4 : Transition
        q(a); φ(a) in degrees; a₄/a (a).
    """

    centre: tuple[float, float]
    intensity: float
    effective_radius: float
    sersic_index: float
    axis_ratio: Transition
    angle: Transition
    a4: Transition

    def __post_init__(self):
        if not (self.intensity > 0.0 and self.effective_radius > 0.0):
            raise ValueError("intensity and effective_radius must be > 0")
        if not 0.3 <= self.sersic_index <= 10.0:
            raise ValueError(f"sersic_index must be in [0.3, 10], got {self.sersic_index}")
        low, high = self.nesting()
        if low < NESTING_RANGE[0] or high > NESTING_RANGE[1]:
            raise ValueError(
                f"isophotes change too fast with radius: d ln(a rho)/d ln a spans "
                f"[{low:.3f}, {high:.3f}], allowed {NESTING_RANGE}; widen the transitions or "
                "reduce the changes of q, angle or a4"
            )

    @cached_property
    def _table(self) -> tuple[np.ndarray, float, float]:
        """(q, cos φ, sin φ, a₄/a) at u = ln a on a uniform grid, its u_min and 1/Δu."""
        u = np.linspace(TABLE_LOG_RANGE[0], TABLE_LOG_RANGE[1], TABLE_SIZE)
        a = np.exp(u)
        phi = np.deg2rad(self.angle(a))
        table = np.column_stack([self.axis_ratio(a), np.cos(phi), np.sin(phi), self.a4(a)])
        return table, float(u[0]), float(1.0 / (u[1] - u[0]))

    def nesting(self) -> tuple[float, float]:
        """(min, max) over a ∈ [10⁻³, 10²]″ and all directions of ∂ ln(a ρ)/∂ ln a.

        This is g′ of the label equation; 1 for self-similar isophotes, > 0 where
        isophotes nest. Computed from the exact formulas (not the table).
        """
        u = np.linspace(np.log(1e-3), np.log(1e2), 600)[:, None]
        theta = np.linspace(0.0, 2.0 * np.pi, 360, endpoint=False)[None, :]
        du = 1e-4
        upper = self._log_radius(u + du, theta)
        lower = self._log_radius(u - du, theta)
        slope = 1.0 + (upper - lower) / (2.0 * du)
        return float(slope.min()), float(slope.max())

    def _log_radius(self, u: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """ln ρ of isophote a = e^u at sky polar angle θ (radians), exact formulas."""
        a = np.exp(u)
        psi = theta - np.deg2rad(self.angle(a))
        return np.log(_isophote_shape(psi, self.axis_ratio(a), self.a4(a)))

    def semi_major_axis(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Label a (arcsec) of the isophote through each point (0 at the centre)."""
        x_flat, y_flat, shape = flat_points(x, y)
        table, u_min, inv_du = self._table
        u = _isophote_label_kernel(
            x_flat, y_flat, float(self.centre[0]), float(self.centre[1]), table, u_min, inv_du
        )
        return np.exp(u).reshape(shape)

    def profile(self, semi_major_axis) -> np.ndarray:
        """Surface brightness on the isophote of semi-major axis a (e⁻ s⁻¹ per pixel)."""
        a = np.asarray(semi_major_axis, dtype=float)
        n = self.sersic_index
        return self.intensity * np.exp(
            -sersic_constant(n) * ((a / self.effective_radius) ** (1.0 / n) - 1.0)
        )

    def image(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Surface brightness (e⁻ s⁻¹ per pixel) at points (x, y), arcsec."""
        x_flat, y_flat, shape = flat_points(x, y)
        table, u_min, inv_du = self._table
        n = self.sersic_index
        sersic = np.array(
            [self.intensity, np.log(self.effective_radius), 1.0 / n, sersic_constant(n)]
        )
        values = _isophote_light_kernel(
            x_flat,
            y_flat,
            float(self.centre[0]),
            float(self.centre[1]),
            table,
            u_min,
            inv_du,
            sersic,
        )
        return values.reshape(shape)

    def isophote_curve(self, semi_major_axis: float, n_points: int = 360):
        """(x, y) arcsec of ``n_points`` points of the true isophote a, equally spaced in ψ."""
        a = float(semi_major_axis)
        q, phi, c4 = self.axis_ratio(a), np.deg2rad(self.angle(a)), self.a4(a)
        psi = np.linspace(0.0, 2.0 * np.pi, n_points, endpoint=False)
        radius = a * _isophote_shape(psi, q, c4)
        return (
            self.centre[0] + radius * np.cos(psi + phi),
            self.centre[1] + radius * np.sin(psi + phi),
        )

    def isophote_table(self, radii: np.ndarray = ISOPHOTE_TRUTH_RADII) -> dict:
        """True isophote shape at semi-major axes ``radii``: q, PA in [0, 180), a₄/a, I."""
        radii = np.asarray(radii, dtype=float)
        return {
            "sma": radii.tolist(),
            "axis_ratio": self.axis_ratio(radii).tolist(),
            "angle": np.mod(self.angle(radii), 180.0).tolist(),
            "a4_over_a": self.a4(radii).tolist(),
            "intensity": self.profile(radii).tolist(),
        }

    def to_dict(self) -> dict:
        return {
            "model": "isophote",
            "form": "isophote a: R(psi) = a [q/sqrt(q^2 cos^2 psi + sin^2 psi) + c cos 4 psi], "
            "psi = polar angle from the major axis at angle(a); q, angle, c = a4/a smooth in "
            "a; I = intensity exp(-b_n ((a/effective_radius)^(1/n) - 1))",
            "a4_convention": "Bender & Moellenhoff: radial deviation from the best ellipse is "
            "a4 cos 4 psi (psi polar angle in the ellipse frame); a4/a > 0 disky, < 0 boxy",
            "transition": "value(a) = inner + (outer - inner) (1 + tanh(ln(a/radius)/width))/2",
            "centre": list(self.centre),
            "intensity": self.intensity,
            "effective_radius": self.effective_radius,
            "sersic_index": self.sersic_index,
            "axis_ratio": dataclasses.asdict(self.axis_ratio),
            "angle": dataclasses.asdict(self.angle),
            "a4_over_a": dataclasses.asdict(self.a4),
            "isophotes": self.isophote_table(),
        }

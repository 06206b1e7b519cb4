"""Mass profiles, ray tracing, magnification and critical curves (SPEC §3).

Conventions (SPEC §1.1, §2.1):

* Coordinates (x, y) in arcsec; angles φ in degrees counter-clockwise from +x; the major
  axis of an elliptical profile lies along φ.
* Profile frame x′ = (x − x_c) cos φ + (y − y_c) sin φ, y′ = −(x − x_c) sin φ + (y − y_c) cos φ;
  q = minor/major axis ratio; ``ell_comps = (e1, e2) = (f cos 2φ, f sin 2φ)``,
  f = (1 − q)/(1 + q).
* Deflection angles are in arcsec, the lensing potential in arcsec², convergence is
  dimensionless. Einstein radii follow the PyAutoGalaxy (paper) convention, SPEC §3.3.
* Lens equation (single plane): β = θ − Σ α_profile(θ).

Deflections of the EPL and SIE are numba kernels, parallel over points.
"""

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from math import atan, atanh, sqrt
from typing import Protocol

import contourpy
import numpy as np
from numba import prange

from mgelens._jit import njit
from mgelens.geometry import (
    axis_ratio_and_angle_from,
    ell_comps_from,
    to_profile_frame,
)

RADIAL_MINIMUM = 1e-8
"""Points closer than this (arcsec) to a profile centre are pushed out to it (anchor
``radial_minimum``)."""

SIE_MAX_AXIS_RATIO = 0.99999
"""The SIE closed form is singular at q = 1; q is capped at this value inside it."""

SERIES_RELATIVE_TOLERANCE = 1e-10
"""Relative truncation tolerance of the Tessore & Metcalf series (see ``_epl_series_ratios``)."""

SERIES_MAX_TERMS = 200

_CHUNK = 256
"""Points per parallel work item of the EPL kernel."""

SLOPE_RANGE = (1.2, 3.0)
"""Open interval of valid EPL slopes γ (κ ∝ η^{1−γ}; the mass inside η diverges at γ = 3)."""


class MassProfile(Protocol):
    """Anything with deflections, convergence and potential at (x, y) arcsec."""

    def deflections(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...

    def convergence(self, x: np.ndarray, y: np.ndarray) -> np.ndarray: ...

    def potential(self, x: np.ndarray, y: np.ndarray) -> np.ndarray: ...


# --------------------------------------------------------------------------------------
# numba kernels


@njit(inline="always")
def _pushed_offset(x, y, centre_x, centre_y):
    """Offset of (x, y) from the centre, pushed out to at least ``RADIAL_MINIMUM``."""
    dx = x - centre_x
    dy = y - centre_y
    r2 = dx * dx + dy * dy
    if r2 < RADIAL_MINIMUM * RADIAL_MINIMUM:
        if r2 == 0.0:
            return RADIAL_MINIMUM, 0.0
        stretch = RADIAL_MINIMUM / sqrt(r2)
        return dx * stretch, dy * stretch
    return dx, dy


@njit(parallel=True)
def _epl_deflections_kernel(
    x, y, centre_x, centre_y, cos_phi, sin_phi, q, t, scale, ratios, alpha_x, alpha_y
):
    """Tessore & Metcalf (2015) series deflections of the EPL, written into alpha_x/y.

    In the profile frame, with R e^{iϑ} = q x′ + i y′:
    α′_x + i α′_y = scale · R^{1−t} · Σ_{n=0}^{N} Ω_n, Ω_0 = e^{iϑ},
    Ω_n = ratios[n−1] · e^{2iϑ} · Ω_{n−1}, N = ratios.size, scale = 2 b^t/(1 + q).
    Points are processed in chunks so that the fixed-length series loop runs over
    contiguous buffers (SIMD across points).
    """
    n_points = x.size
    one_minus_t = 1.0 - t
    for chunk in prange((n_points + _CHUNK - 1) // _CHUNK):
        start = chunk * _CHUNK
        size = min(_CHUNK, n_points - start)
        w_re = np.empty(size)  # e^{2iϑ}
        w_im = np.empty(size)
        term_re = np.empty(size)  # Ω_n
        term_im = np.empty(size)
        sum_re = np.empty(size)  # Σ Ω_n
        sum_im = np.empty(size)
        amplitude = np.empty(size)  # scale · R^{1−t}
        for j in range(size):
            dx, dy = _pushed_offset(x[start + j], y[start + j], centre_x, centre_y)
            u = q * (dx * cos_phi + dy * sin_phi)
            v = -dx * sin_phi + dy * cos_phi
            radius = sqrt(u * u + v * v)
            c = u / radius
            s = v / radius
            w_re[j] = c * c - s * s
            w_im[j] = 2.0 * c * s
            term_re[j] = sum_re[j] = c
            term_im[j] = sum_im[j] = s
            amplitude[j] = scale * radius**one_minus_t
        for n in range(ratios.size):
            ratio = ratios[n]
            for j in range(size):
                re = ratio * (term_re[j] * w_re[j] - term_im[j] * w_im[j])
                im = ratio * (term_re[j] * w_im[j] + term_im[j] * w_re[j])
                term_re[j] = re
                term_im[j] = im
                sum_re[j] += re
                sum_im[j] += im
        for j in range(size):
            ax = amplitude[j] * sum_re[j]
            ay = amplitude[j] * sum_im[j]
            alpha_x[start + j] = ax * cos_phi - ay * sin_phi
            alpha_y[start + j] = ax * sin_phi + ay * cos_phi


@njit(parallel=True)
def _sie_deflections_kernel(
    x, y, centre_x, centre_y, cos_phi, sin_phi, q, factor, alpha_x, alpha_y
):
    """Closed-form SIE deflections (SPEC §3.1) for q < 1, written into alpha_x/y.

    α′_x = factor · arctan(s x′/ψ), α′_y = factor · artanh(s y′/ψ), s = sqrt(1 − q²),
    ψ = sqrt(q² x′² + y′²), factor = 2 θ_E q/((1 + q) s).
    """
    s = sqrt(1.0 - q * q)
    for i in prange(x.size):
        dx, dy = _pushed_offset(x[i], y[i], centre_x, centre_y)
        xp = dx * cos_phi + dy * sin_phi
        yp = -dx * sin_phi + dy * cos_phi
        psi = sqrt(q * q * xp * xp + yp * yp)
        ax = factor * atan(s * xp / psi)
        ay = factor * atanh(s * yp / psi)
        alpha_x[i] = ax * cos_phi - ay * sin_phi
        alpha_y[i] = ax * sin_phi + ay * cos_phi


# --------------------------------------------------------------------------------------
# helpers


def _epl_series_ratios(axis_ratio: float, t: float) -> np.ndarray:
    """Term ratios r_n = −f (2n − 2 + t)/(2n + 2 − t), n = 1..N, of the EPL series.

    Ω_n = r_n e^{2iϑ} Ω_{n−1}, so |Ω_n| = Π_{k≤n} |r_k| whatever ϑ, and |r_n| < f.
    |Ω(ϑ)| is smallest at ϑ = 0 (checked over 0.01 ≤ f ≤ 0.9, 0.2 < t < 1.8), where
    Ω(0) = 1 + Σ_n Π_{k≤n} r_k. N is the first n with
    |Ω_n| · max(1, f/(1 − f)) < ``SERIES_RELATIVE_TOLERANCE`` · Ω(0): this meets SPEC's
    per-point rule |Ω_N| < 1e−10 |Ω| at every ϑ and bounds the geometric tail
    (≤ |Ω_N| f/(1 − f)) below 1e−10 |Ω|. At most ``SERIES_MAX_TERMS`` − 1 ratios.
    """
    f = (1.0 - axis_ratio) / (1.0 + axis_ratio)
    n = np.arange(1, SERIES_MAX_TERMS)
    ratios = -f * (2.0 * n - 2.0 + t) / (2.0 * n + 2.0 - t)
    terms = np.cumprod(ratios)
    omega_min = 1.0 + terms.sum()
    tail_factor = max(1.0, f / (1.0 - f))
    converged = np.abs(terms) * tail_factor < SERIES_RELATIVE_TOLERANCE * omega_min
    n_terms = int(np.argmax(converged)) + 1 if converged.any() else ratios.size
    return ratios[:n_terms]


def _flat_pair(x, y) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
    """Broadcast x, y to one shape and return contiguous float64 1-D views plus that shape."""
    x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    return np.ascontiguousarray(x).ravel(), np.ascontiguousarray(y).ravel(), x.shape


def _run_deflection_kernel(kernel, x, y, *params) -> tuple[np.ndarray, np.ndarray]:
    """Call a ``kernel(x, y, *params, alpha_x, alpha_y)`` on arrays of any (broadcast) shape."""
    xf, yf, shape = _flat_pair(x, y)
    alpha_x = np.empty_like(xf)
    alpha_y = np.empty_like(xf)
    kernel(xf, yf, *params, alpha_x, alpha_y)
    return alpha_x.reshape(shape), alpha_y.reshape(shape)


def _pushed_offsets(x, y, centre) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised offsets from ``centre`` with the ``RADIAL_MINIMUM`` push-out."""
    dx = np.asarray(x, dtype=np.float64) - centre[0]
    dy = np.asarray(y, dtype=np.float64) - centre[1]
    r = np.hypot(dx, dy)
    stretch = RADIAL_MINIMUM / np.maximum(r, RADIAL_MINIMUM)
    inside = r < RADIAL_MINIMUM
    dx = np.where(inside, np.where(r == 0.0, RADIAL_MINIMUM, dx * stretch), dx)
    dy = np.where(inside, dy * stretch, dy)
    return dx, dy


def _validate_elliptical(einstein_radius: float, axis_ratio: float) -> None:
    if not einstein_radius >= 0.0:
        raise ValueError(f"einstein_radius must be >= 0 arcsec, got {einstein_radius}")
    if not 0.0 < axis_ratio <= 1.0:
        raise ValueError(f"axis_ratio must be in (0, 1], got {axis_ratio}")


def _frozen_centre(profile, centre) -> None:
    """Store ``centre`` as a tuple of two floats on a frozen dataclass."""
    if len(centre) != 2:
        raise ValueError(f"centre must be (x, y), got {centre!r}")
    object.__setattr__(profile, "centre", (float(centre[0]), float(centre[1])))


# --------------------------------------------------------------------------------------
# profiles


@dataclass(frozen=True)
class EPL:
    """Elliptical power-law mass profile (PyAutoGalaxy ``PowerLaw`` convention, SPEC §3.1).

    κ(η) = (3 − γ)/(1 + q) · (θ_E/η)^{γ−1}, η = sqrt(x′² + y′²/q²).

    Parameters
    ----------
    centre : (float, float)
        (x, y) of the mass centre, arcsec.
    einstein_radius : float
        θ_E in arcsec, PyAutoGalaxy convention (θ_E^{LT} = θ_E √q (2/(1+q))^{1/(γ−1)}).
    axis_ratio : float
        q = minor/major, 0 < q ≤ 1. Accurate to 1e-10 for q ≳ 0.1 (series capped at
        200 terms).
    angle : float
        Major-axis position angle φ, degrees counter-clockwise from +x.
    slope : float
        Logarithmic 3D density slope γ, 1.2 < γ < 3 (γ = 2 is the SIE).
    """

    centre: tuple[float, float] = (0.0, 0.0)
    einstein_radius: float = 1.0
    axis_ratio: float = 1.0
    angle: float = 0.0
    slope: float = 2.0

    def __post_init__(self):
        _frozen_centre(self, self.centre)
        _validate_elliptical(self.einstein_radius, self.axis_ratio)
        if not SLOPE_RANGE[0] < self.slope < SLOPE_RANGE[1]:
            raise ValueError(
                f"slope must be in ({SLOPE_RANGE[0]}, {SLOPE_RANGE[1]}), got {self.slope}"
            )

    @classmethod
    def from_ell_comps(
        cls,
        centre: tuple[float, float],
        ell_comps: tuple[float, float],
        einstein_radius: float,
        slope: float,
    ) -> "EPL":
        """Build from ``ell_comps = (e1, e2)`` (f capped at 0.999, SPEC §2.1)."""
        axis_ratio, angle = axis_ratio_and_angle_from(ell_comps)
        return cls(centre, einstein_radius, axis_ratio, angle, slope)

    @property
    def ell_comps(self) -> tuple[float, float]:
        """``(e1, e2) = (f cos 2φ, f sin 2φ)``."""
        return ell_comps_from(self.axis_ratio, self.angle)

    def to_dict(self) -> dict:
        """The record of this profile: ``{"type": class name, "parameters": fields}``
        (:func:`mass_from_dict` reads it back)."""
        return {"type": type(self).__name__, "parameters": dataclasses.asdict(self)}

    def convergence(self, x, y) -> np.ndarray:
        """Dimensionless convergence κ at (x, y) arcsec (any broadcastable shapes)."""
        q, t = self.axis_ratio, self.slope - 1.0
        dx, dy = _pushed_offsets(x, y, self.centre)
        xp, yp = to_profile_frame(dx, dy, (0.0, 0.0), self.angle)
        eta = np.sqrt(xp**2 + (yp / q) ** 2)
        return (2.0 - t) / (1.0 + q) * (self.einstein_radius / eta) ** t

    def deflections(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Deflection angles (α_x, α_y) in arcsec at (x, y) arcsec (Tessore & Metcalf series)."""
        q, t = self.axis_ratio, self.slope - 1.0
        b_tm = q * self.einstein_radius * (2.0 / (1.0 + q)) ** (1.0 / t)
        scale = 2.0 * b_tm**t / (1.0 + q)
        phi = np.deg2rad(self.angle)
        return _run_deflection_kernel(
            _epl_deflections_kernel,
            x,
            y,
            *self.centre,
            np.cos(phi),
            np.sin(phi),
            q,
            t,
            scale,
            _epl_series_ratios(q, t),
        )

    def potential(self, x, y) -> np.ndarray:
        """Lensing potential ψ = (x′α′_x + y′α′_y)/(3 − γ) in arcsec², ψ(centre) = 0."""
        alpha_x, alpha_y = self.deflections(x, y)
        dx, dy = _pushed_offsets(x, y, self.centre)
        return (dx * alpha_x + dy * alpha_y) / (3.0 - self.slope)


@dataclass(frozen=True)
class SIE:
    """Singular isothermal ellipsoid: the EPL with γ = 2, in closed form (SPEC §3.1).

    κ(η) = θ_E/((1 + q) η), η = sqrt(x′² + y′²/q²).

    Parameters
    ----------
    centre : (float, float)
        (x, y) of the mass centre, arcsec.
    einstein_radius : float
        θ_E in arcsec, PyAutoGalaxy convention (θ_E^{LT} = θ_E · 2√q/(1 + q)).
    axis_ratio : float
        q = minor/major, 0 < q ≤ 1; capped at 0.99999 inside the deflection formula.
    angle : float
        Major-axis position angle φ, degrees counter-clockwise from +x.
    """

    centre: tuple[float, float] = (0.0, 0.0)
    einstein_radius: float = 1.0
    axis_ratio: float = 1.0
    angle: float = 0.0

    def __post_init__(self):
        _frozen_centre(self, self.centre)
        _validate_elliptical(self.einstein_radius, self.axis_ratio)

    @classmethod
    def from_ell_comps(
        cls, centre: tuple[float, float], ell_comps: tuple[float, float], einstein_radius: float
    ) -> "SIE":
        """Build from ``ell_comps = (e1, e2)`` (f capped at 0.999, SPEC §2.1)."""
        axis_ratio, angle = axis_ratio_and_angle_from(ell_comps)
        return cls(centre, einstein_radius, axis_ratio, angle)

    @property
    def ell_comps(self) -> tuple[float, float]:
        """``(e1, e2) = (f cos 2φ, f sin 2φ)``."""
        return ell_comps_from(self.axis_ratio, self.angle)

    def to_dict(self) -> dict:
        """The record of this profile: ``{"type": class name, "parameters": fields}``
        (:func:`mass_from_dict` reads it back)."""
        return {"type": type(self).__name__, "parameters": dataclasses.asdict(self)}

    def convergence(self, x, y) -> np.ndarray:
        """Dimensionless convergence κ at (x, y) arcsec (any broadcastable shapes)."""
        q = self.axis_ratio
        dx, dy = _pushed_offsets(x, y, self.centre)
        xp, yp = to_profile_frame(dx, dy, (0.0, 0.0), self.angle)
        return self.einstein_radius / ((1.0 + q) * np.sqrt(xp**2 + (yp / q) ** 2))

    def deflections(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Deflection angles (α_x, α_y) in arcsec at (x, y) arcsec."""
        q = min(self.axis_ratio, SIE_MAX_AXIS_RATIO)
        factor = 2.0 * self.einstein_radius * q / ((1.0 + q) * np.sqrt(1.0 - q * q))
        phi = np.deg2rad(self.angle)
        return _run_deflection_kernel(
            _sie_deflections_kernel, x, y, *self.centre, np.cos(phi), np.sin(phi), q, factor
        )

    def potential(self, x, y) -> np.ndarray:
        """Lensing potential ψ = x′α′_x + y′α′_y in arcsec², ψ(centre) = 0."""
        alpha_x, alpha_y = self.deflections(x, y)
        dx, dy = _pushed_offsets(x, y, self.centre)
        return dx * alpha_x + dy * alpha_y


@dataclass(frozen=True)
class ExternalShear:
    """External shear about the origin (0, 0) (SPEC §3.2, lenstronomy ``SHEAR``).

    ψ = ½γ₁(x² − y²) + γ₂xy, so α_x = γ₁x + γ₂y, α_y = γ₂x − γ₁y; κ = 0.

    Parameters
    ----------
    gamma_1, gamma_2 : float
        Dimensionless shear components.
    """

    gamma_1: float = 0.0
    gamma_2: float = 0.0

    @property
    def magnitude(self) -> float:
        """γ_ext = sqrt(γ₁² + γ₂²)."""
        return float(np.hypot(self.gamma_1, self.gamma_2))

    @property
    def angle(self) -> float:
        """Shear angle ½ atan2(γ₂, γ₁) in degrees, in [0, 180)."""
        angle = 0.5 * float(np.rad2deg(np.arctan2(self.gamma_2, self.gamma_1)))
        return angle + 180.0 if angle < 0.0 else angle

    def to_dict(self) -> dict:
        """The record of this profile: ``{"type": class name, "parameters": fields}``
        (:func:`mass_from_dict` reads it back)."""
        return {"type": type(self).__name__, "parameters": dataclasses.asdict(self)}

    def convergence(self, x, y) -> np.ndarray:
        """Zero everywhere, with the broadcast shape of (x, y)."""
        return np.zeros(np.broadcast_shapes(np.shape(x), np.shape(y)))

    def deflections(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Deflection angles (α_x, α_y) in arcsec at (x, y) arcsec."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        return self.gamma_1 * x + self.gamma_2 * y, self.gamma_2 * x - self.gamma_1 * y

    def potential(self, x, y) -> np.ndarray:
        """Lensing potential in arcsec²."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        return 0.5 * self.gamma_1 * (x**2 - y**2) + self.gamma_2 * x * y


# --------------------------------------------------------------------------------------
# sums over profiles, lens equation, magnification


def deflections_from(profiles: Sequence[MassProfile], x, y) -> tuple[np.ndarray, np.ndarray]:
    """Total deflection (α_x, α_y) in arcsec of several profiles at (x, y) arcsec."""
    shape = np.broadcast_shapes(np.shape(x), np.shape(y))
    alpha_x, alpha_y = np.zeros(shape), np.zeros(shape)
    for profile in profiles:
        ax, ay = profile.deflections(x, y)
        alpha_x += ax
        alpha_y += ay
    return alpha_x, alpha_y


def ray_trace(profiles: Sequence[MassProfile], x, y) -> tuple[np.ndarray, np.ndarray]:
    """Source-plane positions β = θ − α(θ) in arcsec of image-plane positions (x, y)."""
    alpha_x, alpha_y = deflections_from(profiles, x, y)
    return np.asarray(x) - alpha_x, np.asarray(y) - alpha_y


def convergence_from(profiles: Sequence[MassProfile], x, y) -> np.ndarray:
    """Total dimensionless convergence of several profiles at (x, y) arcsec."""
    kappa = np.zeros(np.broadcast_shapes(np.shape(x), np.shape(y)))
    for profile in profiles:
        kappa += profile.convergence(x, y)
    return kappa


def deflection_jacobian(
    profiles: Sequence[MassProfile], x, y, step: float = 1e-4
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """∂α/∂θ by central differences of step ``step`` arcsec.

    Returns
    -------
    a_xx, a_xy, a_yx, a_yy : ndarray
        ∂α_x/∂x, ∂α_x/∂y, ∂α_y/∂x, ∂α_y/∂y (dimensionless), shape of (x, y).
    """
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    ax_right, ay_right = deflections_from(profiles, x + step, y)
    ax_left, ay_left = deflections_from(profiles, x - step, y)
    ax_up, ay_up = deflections_from(profiles, x, y + step)
    ax_down, ay_down = deflections_from(profiles, x, y - step)
    two_step = 2.0 * step
    return (
        (ax_right - ax_left) / two_step,
        (ax_up - ax_down) / two_step,
        (ay_right - ay_left) / two_step,
        (ay_up - ay_down) / two_step,
    )


def magnification(profiles: Sequence[MassProfile], x, y, step: float = 1e-4) -> np.ndarray:
    """Signed magnification μ = 1/det(I − ∂α/∂θ), derivatives by central differences."""
    a_xx, a_xy, a_yx, a_yy = deflection_jacobian(profiles, x, y, step)
    return 1.0 / ((1.0 - a_xx) * (1.0 - a_yy) - a_xy * a_yx)


# --------------------------------------------------------------------------------------
# critical curves and caustics (SPEC §3.4; plots and summaries only)


def jacobian_eigenvalues(
    profiles: Sequence[MassProfile], grid_spacing: float = 0.02, half_width: float = 3.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Tangential and radial eigenvalues of the lens Jacobian on a uniform square grid.

    The grid has nodes at k·``grid_spacing`` for |k·grid_spacing| ≤ ``half_width`` (arcsec)
    in x and y. Derivatives use a ±``grid_spacing``/2 central-difference stencil; with
    κ = ½ tr(∂α/∂θ) and |γ| from its symmetrised trace-free part,
    λ_t = 1 − κ − |γ| and λ_r = 1 − κ + |γ|.

    Returns
    -------
    x, y, lambda_t, lambda_r : ndarray (n, n)
        Native 2D arrays, row index increasing with y (SPEC §1.1).
    """
    n_half = round(half_width / grid_spacing)
    axis = np.arange(-n_half, n_half + 1) * grid_spacing
    x, y = np.meshgrid(axis, axis)
    a_xx, a_xy, a_yx, a_yy = deflection_jacobian(profiles, x, y, 0.5 * grid_spacing)
    kappa = 0.5 * (a_xx + a_yy)
    shear = np.hypot(0.5 * (a_xx - a_yy), 0.5 * (a_xy + a_yx))
    return x, y, 1.0 - kappa - shear, 1.0 - kappa + shear


def _polyline_length(line: np.ndarray) -> float:
    return float(np.sum(np.hypot(*np.diff(line, axis=0).T)))


def tangential_critical_curve(
    profiles: Sequence[MassProfile], grid_spacing: float = 0.02, half_width: float = 3.0
) -> tuple[np.ndarray, np.ndarray]:
    """Tangential critical curve: the longest closed zero contour of λ_t (marching squares).

    Returns
    -------
    x, y : ndarray (n_points,)
        Closed polyline in arcsec (last point equals the first).

    Raises
    ------
    ValueError
        If no closed zero contour of λ_t lies inside the grid (increase ``half_width``).
    """
    x, y, lambda_t, _ = jacobian_eigenvalues(profiles, grid_spacing, half_width)
    generator = contourpy.contour_generator(
        x[0], y[:, 0], lambda_t, line_type=contourpy.LineType.Separate
    )
    closed = [line for line in generator.lines(0.0) if np.array_equal(line[0], line[-1])]
    if not closed:
        raise ValueError(
            f"no closed tangential critical curve within ±{half_width} arcsec; increase half_width"
        )
    curve = max(closed, key=_polyline_length)
    return curve[:, 0].copy(), curve[:, 1].copy()


def caustic(
    profiles: Sequence[MassProfile], grid_spacing: float = 0.02, half_width: float = 3.0
) -> tuple[np.ndarray, np.ndarray]:
    """Tangential caustic: the tangential critical curve ray-traced to the source plane."""
    x, y = tangential_critical_curve(profiles, grid_spacing, half_width)
    return ray_trace(profiles, x, y)


def einstein_radius_effective(
    profiles: Sequence[MassProfile], grid_spacing: float = 0.02, half_width: float = 3.0
) -> float:
    """sqrt(area/π) in arcsec of the tangential critical curve (shoelace area)."""
    return circle_equivalent_radius(*tangential_critical_curve(profiles, grid_spacing, half_width))


def circle_equivalent_radius(x: np.ndarray, y: np.ndarray) -> float:
    """sqrt(area/π) of a closed polyline (last point equal to the first; shoelace area)."""
    area = 0.5 * abs(float(np.sum(x[:-1] * y[1:] - x[1:] * y[:-1])))
    return float(np.sqrt(area / np.pi))


MASS_PROFILES = {"SIE": SIE, "EPL": EPL, "ExternalShear": ExternalShear}
"""Mass profile classes by the ``type`` name of their records."""


def mass_from_dict(entry: dict):
    """The mass profile of a record written by its ``to_dict`` (extra keys ignored).

    Raises
    ------
    ValueError
        For an unknown ``type``.
    """
    if entry["type"] not in MASS_PROFILES:
        raise ValueError(
            f"unknown mass profile type {entry['type']!r}; known: {sorted(MASS_PROFILES)}"
        )
    parameters = dict(entry["parameters"])
    if "centre" in parameters:
        parameters["centre"] = tuple(parameters["centre"])
    return MASS_PROFILES[entry["type"]](**parameters)

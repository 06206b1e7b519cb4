"""Isophote analysis of the lens light: q(a), PA(a) and boxy/disky a₄/a (SPEC §9.1).

Method (per image):

1. **Levels** — ``n_levels`` (40) intensities log-spaced between the image values at
   0.3″ and 3.0″ from the centre along the major axis at each of these radii (the
   direction of the cos 2θ intensity harmonic on the circle; see :func:`isophote_levels`
   for why not along the inner major axis only).
2. **Contours** — marching squares (:mod:`contourpy`) on log₁₀ I with the pixel centres
   at their (x, y) arcsec positions (SPEC §1.1: row index increases with +y), after a
   cubic-spline interpolation onto a grid twice as fine. Marching squares interpolates
   linearly between nodes, which displaces a curved isophote by ≈ h²κ/8 (h the node
   spacing, κ the curvature); tracing log₁₀ I (closer to linear in r than I) on the
   finer grid cuts this bias about fivefold (q of a q = 0.5 Sérsic at a = 0.3″ good to
   0.002 instead of 0.01). Of the contours of a level, the largest closed one enclosing
   the centre is the isophote.
3. **Ellipse** — direct least-squares conic fit (Fitzgibbon, Pilu & Fisher 1999) in
   the numerically stable form of Halíř & Flusser (1998), on centred and scaled
   coordinates (:func:`fit_ellipse`).
4. **Fourier analysis** (Bender & Möllenhoff 1987) — in the ellipse frame the contour
   radius R(ϑ) at the polar angle ϑ (from the major axis, counter-clockwise) is
   resampled at 360 equally spaced ϑ and the deviation from the ellipse,
   δR = R − R_el, R_el = ab/sqrt((b cos ϑ)² + (a sin ϑ)²), is fitted by least squares with
   a₀ + Σ_{n=1}^{4} (a_n cos nϑ + b_n sin nϑ).
   **a₄/a > 0: disky; a₄/a < 0: boxy** — the sign of photutils' ``b4`` (its cos 4θ
   intensity term; checked with photutils 3.0, after the sign fix of photutils#1501).
   The two are not the same number: to first order b4 ≈ a₄/a · 2⟨cos² 4ϑ/ρ(ϑ)⟩, ρ the
   polar radius of the unit ellipse (a factor 1.1–1.3 for q = 0.9–0.7).
5. **Refinement** — the direct conic fit minimises an algebraic distance, so for a
   contour that is not an exact ellipse (boxy/disky, twisted) its ellipse leaves small
   first- and second-order harmonics in δR, which in turn leak into a₄ at second order.
   The ellipse is therefore refined by modified Newton iterations (central-difference
   Jacobian) on (x₀, y₀, a, e₁, e₂) until a₀, a₁, b₁, a₂, b₂ vanish: the reported
   ellipse is the one with respect to which the contour has no harmonics below n = 3,
   as for the best-fitting ellipse of Bender et al. and for photutils (whose iterations
   zero the n = 1, 2 intensity harmonics). On a cos 4ϑ-deformed ellipse with
   a₄/a = ±0.015 and q = 0.5 the conic fit alone is off by 0.01 in q and 0.0035 in a₄/a,
   the refined one by 0.002 and 0.0008. The conic fit is the starting point; if the
   iterations do not converge the conic ellipse is kept and the row is flagged
   :data:`FLAG_NOT_REFINED`.

Uncertainties: the Fourier covariance is the least-squares covariance (AᵀA)⁻¹ scaled by
the residual variance RSS/(N − 9), inflated by N/n_vertices when the N = 360 resampled
radii outnumber the independent contour vertices. Geometry errors follow from the
harmonics through the refinement Jacobian J = ∂(a₀, a₁, b₁, a₂, b₂)/∂(x₀, y₀, a, e₁, e₂):
Cov_p = J⁻¹ Cov_h J⁻ᵀ. On noise-free models these errors measure only the departure of
the contour from the truncated Fourier series.

Angles are degrees counter-clockwise from +x; PA of an ellipse is its major-axis angle
in [0, 180). ``ell_comps`` follow :mod:`mgelens.geometry`. Lengths are arcsec.
"""

import logging
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from functools import lru_cache

import contourpy
import numpy as np
import pandas as pd
from scipy import ndimage

from mgelens.convolve import convolve_image
from mgelens.geometry import axis_ratio_and_angle_from, ell_comps_from, to_profile_frame
from mgelens.grid import SubGrid, adaptive_sub_sizes, pixel_centres, sub_grid
from mgelens.light import Gaussian, MGESet
from mgelens.mass import tangential_critical_curve

logger = logging.getLogger(__name__)

N_ANGLES = 360
"""Equally spaced polar angles on which the contour radius is resampled."""
HARMONIC_NAMES = ("a0", "a1", "b1", "a2", "b2", "a3", "b3", "a4", "b4")
"""Order of the Fourier coefficients of δR(ϑ) returned by :func:`harmonic_deviations`."""
ROUND_AXIS_RATIO = 0.95
"""Isophotes rounder than this (q > 0.95) have no meaningful PA (SPEC §9.1 step 5)."""
STATISTICS_SMA_RANGE = (0.5, 2.5)
"""Semi-major-axis range (arcsec) of the per-lens statistics (SPEC §9.1 step 5)."""
LEVEL_SMA_RANGE = (0.3, 3.0)
"""Major-axis radii (arcsec) whose intensities bound the isophote levels (SPEC §9.1)."""
N_LEVELS = 40

FLAG_ROUND = 1
"""Table flag bit: q > :data:`ROUND_AXIS_RATIO`, PA ill-defined (ignored in PA statistics)."""
FLAG_NOT_REFINED = 2
"""Table flag bit: harmonic refinement did not converge; the direct conic ellipse is used."""

TABLE_COLUMNS = (
    "sma",
    "q",
    "q_err",
    "pa",
    "pa_err",
    "a4_a",
    "a4_a_err",
    "b4_a",
    "a3_a",
    "b3_a",
    "x0",
    "y0",
    "level",
    "flag",
)
"""Columns of :func:`isophote_table`, one row per isophote (see its docstring)."""

_MAX_NEWTON_ITERATIONS = 20
_HARMONIC_TOLERANCE = 1e-7
"""Refinement stops when max |a₀, a₁, b₁, a₂, b₂| < this × a."""
_STEP_POSITION = 1e-4
"""Finite-difference step of x₀, y₀ and a, in units of a."""
_STEP_ELL_COMPS = 1e-4
_MIN_CONTOUR_POINTS = 8
CONTOUR_UPSAMPLING = 2
"""Refinement of the pixel grid (cubic spline of log₁₀ I) before marching squares."""


class IsophoteError(ValueError):
    """An isophote (or the whole image) cannot be analysed; the message says why."""


# --------------------------------------------------------------------------------------
# ellipse geometry and the direct conic fit


@dataclass(frozen=True)
class Ellipse:
    """An ellipse in the (x, y) arcsec frame.

    Attributes
    ----------
    x0, y0 : float
        Centre, arcsec.
    semi_major : float
        Semi-major axis a, arcsec.
    axis_ratio : float
        q = b/a, 0 < q ≤ 1.
    angle : float
        Major-axis position angle, degrees counter-clockwise from +x, in [0, 180).
    """

    x0: float
    y0: float
    semi_major: float
    axis_ratio: float
    angle: float

    @property
    def semi_minor(self) -> float:
        return self.semi_major * self.axis_ratio

    def polar_radius(self, theta: np.ndarray) -> np.ndarray:
        """R_el(ϑ) = ab/sqrt((b cos ϑ)² + (a sin ϑ)²), ϑ in radians from the major axis."""
        a, b = self.semi_major, self.semi_minor
        return a * b / np.hypot(b * np.cos(theta), a * np.sin(theta))

    def points(self, n_points: int = 200) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) of ``n_points`` points along the ellipse, the last equal to the first."""
        t = np.linspace(0.0, 2.0 * np.pi, n_points)
        phi = np.deg2rad(self.angle)
        u, v = self.semi_major * np.cos(t), self.semi_minor * np.sin(t)
        return (
            self.x0 + u * np.cos(phi) - v * np.sin(phi),
            self.y0 + u * np.sin(phi) + v * np.cos(phi),
        )


def _reduced_angle(angle: float) -> float:
    """An axis angle in degrees reduced to [0, 180)."""
    reduced = math.fmod(angle, 180.0)
    reduced = reduced + 180.0 if reduced < 0.0 else reduced
    return 0.0 if reduced >= 180.0 else reduced


def ellipse_from_conic(coefficients: np.ndarray) -> Ellipse:
    """Centre, axes and orientation of the conic A x² + B xy + C y² + D x + E y + F = 0.

    Raises
    ------
    IsophoteError
        If the conic is not a real ellipse.
    """
    a, b, c, d, e, f = coefficients
    quadratic = np.array([[a, 0.5 * b], [0.5 * b, c]])
    if not np.linalg.det(quadratic) > 0.0:
        raise IsophoteError("the fitted conic is not an ellipse (B² − 4AC ≥ 0)")
    x0, y0 = np.linalg.solve(2.0 * quadratic, [-d, -e])
    constant = f + 0.5 * (d * x0 + e * y0)
    eigenvalues, eigenvectors = np.linalg.eigh(quadratic)
    if constant > 0.0:
        eigenvalues, constant = -eigenvalues[::-1], -constant
        eigenvectors = eigenvectors[:, ::-1]
    if not (eigenvalues[0] > 0.0 and constant < 0.0):
        raise IsophoteError("the fitted conic is an imaginary ellipse")
    semi_major = math.sqrt(-constant / eigenvalues[0])
    semi_minor = math.sqrt(-constant / eigenvalues[1])
    major = eigenvectors[:, 0]
    angle = _reduced_angle(math.degrees(math.atan2(major[1], major[0])))
    return Ellipse(float(x0), float(y0), semi_major, semi_minor / semi_major, angle)


def fit_ellipse(x: np.ndarray, y: np.ndarray) -> Ellipse:
    """Direct least-squares ellipse fit to points (Fitzgibbon et al. 1999).

    Minimises the algebraic distance Σ (A x² + B xy + C y² + D x + E y + F)² under the
    ellipse constraint 4AC − B² = 1, solved as in Halíř & Flusser (1998) (the scatter
    matrix split into quadratic and linear blocks, the linear part eliminated), on
    coordinates centred on their mean and scaled to unit RMS radius.

    Parameters
    ----------
    x, y : ndarray (n,)
        Points in arcsec (n ≥ 6). A closing point equal to the first may be included.

    Returns
    -------
    Ellipse

    Raises
    ------
    IsophoteError
        Too few points, or points that no real ellipse fits (e.g. collinear).
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if x.size < 6:
        raise IsophoteError(f"an ellipse fit needs at least 6 points, got {x.size}")
    x_mean, y_mean = x.mean(), y.mean()
    scale = math.sqrt(np.mean((x - x_mean) ** 2 + (y - y_mean) ** 2))
    if not scale > 0.0:
        raise IsophoteError("all points coincide")
    u, v = (x - x_mean) / scale, (y - y_mean) / scale
    quadratic = np.column_stack([u * u, u * v, v * v])
    linear = np.column_stack([u, v, np.ones_like(u)])
    s1, s2, s3 = quadratic.T @ quadratic, quadratic.T @ linear, linear.T @ linear
    try:
        reduce_linear = -np.linalg.solve(s3, s2.T)
    except np.linalg.LinAlgError as exc:
        raise IsophoteError("degenerate points (collinear)") from exc
    reduced = s1 + s2 @ reduce_linear
    constrained = np.array([0.5 * reduced[2], -reduced[1], 0.5 * reduced[0]])
    eigenvalues, eigenvectors = np.linalg.eig(constrained)
    eigenvectors = np.real(eigenvectors)
    condition = 4.0 * eigenvectors[0] * eigenvectors[2] - eigenvectors[1] ** 2
    candidates = np.flatnonzero((condition > 0.0) & (np.abs(np.imag(eigenvalues)) == 0.0))
    if candidates.size == 0:
        raise IsophoteError("no elliptical solution of the conic fit")
    quadratic_part = eigenvectors[:, candidates[0]]
    linear_part = reduce_linear @ quadratic_part
    ellipse = ellipse_from_conic(np.concatenate([quadratic_part, linear_part]))
    return Ellipse(
        x_mean + scale * ellipse.x0,
        y_mean + scale * ellipse.y0,
        scale * ellipse.semi_major,
        ellipse.axis_ratio,
        ellipse.angle,
    )


# --------------------------------------------------------------------------------------
# Fourier analysis of the radial deviations


@lru_cache(maxsize=4)
def _fourier_design(n_angles: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Polar angles, design matrix (n_angles, 9), its pseudo-inverse and diag((AᵀA)⁻¹)."""
    theta = 2.0 * np.pi * np.arange(n_angles) / n_angles
    columns = [np.ones_like(theta)]
    for n in range(1, 5):
        columns += [np.cos(n * theta), np.sin(n * theta)]
    design = np.column_stack(columns)
    normal_inverse = np.linalg.inv(design.T @ design)
    return theta, design, normal_inverse @ design.T, np.diag(normal_inverse).copy()


def _polar_radii(x: np.ndarray, y: np.ndarray, ellipse: Ellipse, theta: np.ndarray) -> np.ndarray:
    """Radius of the closed polygon (x, y) at polar angles ``theta`` in the ellipse frame.

    Raises
    ------
    IsophoteError
        If the polygon is not star-shaped about the ellipse centre (R(ϑ) multivalued) or
        does not wind around it.
    """
    u, v = to_profile_frame(x, y, (ellipse.x0, ellipse.y0), ellipse.angle)
    angles = np.arctan2(v, u)
    steps = (np.roll(angles, -1) - angles + np.pi) % (2.0 * np.pi) - np.pi
    if not (np.all(steps >= 0.0) or np.all(steps <= 0.0)):
        raise IsophoteError("contour is not star-shaped about its ellipse centre")
    if not abs(abs(steps.sum()) - 2.0 * np.pi) < 1e-6:
        raise IsophoteError("contour does not enclose its ellipse centre")
    return np.interp(theta, angles, np.hypot(u, v), period=2.0 * np.pi)


def harmonic_deviations(
    x: np.ndarray, y: np.ndarray, ellipse: Ellipse, n_angles: int = N_ANGLES
) -> tuple[np.ndarray, np.ndarray]:
    """Fourier coefficients of the contour's radial deviation from ``ellipse``.

    δR(ϑ) = R(ϑ) − R_el(ϑ) = a₀ + Σ_{n=1}^{4} (a_n cos nϑ + b_n sin nϑ), fitted by least
    squares on ``n_angles`` equally spaced polar angles ϑ of the ellipse frame
    (ϑ = 0 along the major axis, direction ``ellipse.angle``; counter-clockwise).

    Parameters
    ----------
    x, y : ndarray (n,)
        Vertices of a closed contour, arcsec, without a repeated closing vertex.
    ellipse : Ellipse
    n_angles : int

    Returns
    -------
    coefficients, errors : ndarray (9,)
        In the order of :data:`HARMONIC_NAMES`, arcsec. The errors are the least-squares
        1σ scaled by the residual variance, inflated by ``n_angles/n`` when ``n_angles``
        exceeds the number of vertices.

    Raises
    ------
    IsophoteError
        If R(ϑ) is not single-valued about the ellipse centre.
    """
    theta, design, pseudo_inverse, normal_diagonal = _fourier_design(n_angles)
    deviation = _polar_radii(x, y, ellipse, theta) - ellipse.polar_radius(theta)
    coefficients = pseudo_inverse @ deviation
    residual = deviation - design @ coefficients
    variance = residual @ residual / (n_angles - len(HARMONIC_NAMES))
    variance *= max(1.0, n_angles / x.size)
    return coefficients, np.sqrt(variance * normal_diagonal)


# --------------------------------------------------------------------------------------
# one isophote: conic fit, harmonic refinement, uncertainties


@dataclass(frozen=True)
class IsophoteFit:
    """Fitted ellipse and harmonics of one contour.

    Attributes
    ----------
    ellipse : Ellipse
        Refined ellipse (harmonics n ≤ 2 of δR vanish) or, if not ``refined``, the
        direct conic fit.
    harmonics, harmonic_errors : ndarray (9,)
        δR Fourier coefficients and 1σ errors in arcsec, order :data:`HARMONIC_NAMES`.
    axis_ratio_error : float
        1σ of q.
    angle_error : float
        1σ of the PA in degrees.
    refined : bool
    """

    ellipse: Ellipse
    harmonics: np.ndarray
    harmonic_errors: np.ndarray
    axis_ratio_error: float
    angle_error: float
    refined: bool


def _ellipse_from_parameters(parameters: np.ndarray) -> Ellipse:
    x0, y0, semi_major, e1, e2 = parameters
    axis_ratio, angle = axis_ratio_and_angle_from((e1, e2))
    return Ellipse(float(x0), float(y0), float(semi_major), axis_ratio, angle)


def _parameters_from_ellipse(ellipse: Ellipse) -> np.ndarray:
    e1, e2 = ell_comps_from(ellipse.axis_ratio, ellipse.angle)
    return np.array([ellipse.x0, ellipse.y0, ellipse.semi_major, e1, e2])


def _low_harmonics(x: np.ndarray, y: np.ndarray, parameters: np.ndarray) -> np.ndarray:
    """(a₀, a₁, b₁, a₂, b₂) of δR for the ellipse of ``parameters``."""
    return harmonic_deviations(x, y, _ellipse_from_parameters(parameters))[0][:5]


def _harmonic_jacobian(x: np.ndarray, y: np.ndarray, parameters: np.ndarray) -> np.ndarray:
    """∂(a₀, a₁, b₁, a₂, b₂)/∂(x₀, y₀, a, e₁, e₂) by central differences (5×5)."""
    steps = np.array([_STEP_POSITION] * 3 + [_STEP_ELL_COMPS] * 2)
    steps[:3] *= parameters[2]
    jacobian = np.empty((5, 5))
    for k, step in enumerate(steps):
        shift = np.zeros(5)
        shift[k] = step
        jacobian[:, k] = (
            _low_harmonics(x, y, parameters + shift) - _low_harmonics(x, y, parameters - shift)
        ) / (2.0 * step)
    return jacobian


def _refine(
    x: np.ndarray, y: np.ndarray, start: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Modified Newton iterations zeroing (a₀, a₁, b₁, a₂, b₂).

    The Jacobian is reused while the residual norm contracts at least fourfold per step
    and recomputed otherwise; steps are halved (up to three times) until the norm
    decreases. Returns the parameters and the last Jacobian, or None without convergence.
    """
    parameters = start.copy()
    residual = _low_harmonics(x, y, parameters)
    jacobian, fresh = _harmonic_jacobian(x, y, parameters), True
    for _ in range(_MAX_NEWTON_ITERATIONS):
        if np.max(np.abs(residual)) < _HARMONIC_TOLERANCE * parameters[2]:
            return parameters, jacobian
        step = np.linalg.solve(jacobian, -residual)
        norm = np.linalg.norm(residual)
        for damping in (1.0, 0.5, 0.25, 0.125):
            trial = parameters + damping * step
            if not (trial[2] > 0.0 and np.hypot(trial[3], trial[4]) < 1.0):
                continue
            try:
                trial_residual = _low_harmonics(x, y, trial)
            except IsophoteError:
                continue
            if np.linalg.norm(trial_residual) < norm:
                parameters, residual = trial, trial_residual
                break
        else:
            if fresh:
                return None
        if not np.linalg.norm(residual) < 0.25 * norm:
            jacobian, fresh = _harmonic_jacobian(x, y, parameters), True
        else:
            fresh = False
    return None


def _geometry_errors(jacobian: np.ndarray, low_errors: np.ndarray, ell_comps) -> tuple:
    """1σ of q and PA (deg) from Cov_p = J⁻¹ Cov_h J⁻ᵀ, p = (x₀, y₀, a, e₁, e₂)."""
    inverse = np.linalg.inv(jacobian)
    covariance = (inverse * low_errors**2) @ inverse.T
    e1, e2 = ell_comps
    f = max(math.hypot(e1, e2), 1e-12)
    d_q = -2.0 / (1.0 + f) ** 2 * np.array([e1 / f, e2 / f])
    d_angle = np.rad2deg(0.5 * np.array([-e2, e1]) / f**2)
    block = covariance[3:, 3:]
    return math.sqrt(d_q @ block @ d_q), math.sqrt(d_angle @ block @ d_angle)


def fit_isophote(x: np.ndarray, y: np.ndarray) -> IsophoteFit:
    """Ellipse, refinement and harmonic analysis of one closed contour.

    Parameters
    ----------
    x, y : ndarray (n,)
        Closed contour in arcsec (a repeated closing vertex is dropped).

    Returns
    -------
    IsophoteFit

    Raises
    ------
    IsophoteError
        Too few vertices, no elliptical conic, or a contour that is not star-shaped.
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if x[0] == x[-1] and y[0] == y[-1]:
        x, y = x[:-1], y[:-1]
    if x.size < _MIN_CONTOUR_POINTS:
        raise IsophoteError(f"contour has only {x.size} vertices")
    start = _parameters_from_ellipse(fit_ellipse(x, y))
    try:
        refined = _refine(x, y, start)
    except np.linalg.LinAlgError:
        refined = None
    if refined is None:
        parameters, jacobian = start, _harmonic_jacobian(x, y, start)
    else:
        parameters, jacobian = refined
    ellipse = _ellipse_from_parameters(parameters)
    harmonics, errors = harmonic_deviations(x, y, ellipse)
    try:
        q_error, angle_error = _geometry_errors(jacobian, errors[:5], parameters[3:])
    except np.linalg.LinAlgError:
        q_error = angle_error = math.nan
    return IsophoteFit(ellipse, harmonics, errors, q_error, angle_error, refined is not None)


# --------------------------------------------------------------------------------------
# images: levels, contours, the isophote table


def _pixel_position(x, y, shape, pixel_scale, origin) -> tuple[np.ndarray, np.ndarray]:
    """(row, col) fractional pixel indices of (x, y) arcsec (SPEC §1.1)."""
    n_y, n_x = shape
    col = (np.asarray(x) - origin[0]) / pixel_scale + (n_x - 1) / 2.0
    row = (np.asarray(y) - origin[1]) / pixel_scale + (n_y - 1) / 2.0
    return row, col


def brightest_pixel_centre(
    image: np.ndarray, pixel_scale: float, origin: tuple[float, float] = (0.0, 0.0)
) -> tuple[float, float]:
    """(x, y) arcsec of the brightest finite pixel."""
    row, col = np.unravel_index(np.nanargmax(image), image.shape)
    x, y = pixel_centres(image.shape, pixel_scale, origin)
    return float(x[row, col]), float(y[row, col])


def _sample(image, x, y, pixel_scale, origin) -> np.ndarray:
    """Bilinear image values at (x, y) arcsec; points outside take the nearest edge value."""
    row, col = _pixel_position(x, y, image.shape, pixel_scale, origin)
    return ndimage.map_coordinates(image, [row, col], order=1, mode="nearest")


def _major_axis_value(
    image: np.ndarray,
    pixel_scale: float,
    centre: tuple[float, float],
    radius: float,
    origin: tuple[float, float],
) -> float:
    """Mean image value at ±``radius`` from ``centre`` along the local major axis.

    The major axis is the direction θ_m of the cos 2θ harmonic of I on the circle of
    that radius (I is highest along the major axis of elliptical isophotes).
    """
    angles = np.linspace(0.0, 2.0 * np.pi, 72, endpoint=False)
    ring = _sample(
        image,
        centre[0] + radius * np.cos(angles),
        centre[1] + radius * np.sin(angles),
        pixel_scale,
        origin,
    )
    major = 0.5 * math.atan2(ring @ np.sin(2.0 * angles), ring @ np.cos(2.0 * angles))
    ends = np.array([radius, -radius])
    xs, ys = centre[0] + ends * math.cos(major), centre[1] + ends * math.sin(major)
    row, col = _pixel_position(xs, ys, image.shape, pixel_scale, origin)
    if np.any((row < 0) | (row > image.shape[0] - 1) | (col < 0) | (col > image.shape[1] - 1)):
        logger.info("the %.2f arcsec major-axis radius lies outside the image", radius)
    return float(_sample(image, xs, ys, pixel_scale, origin).mean())


def isophote_levels(
    image: np.ndarray,
    pixel_scale: float,
    centre: tuple[float, float],
    sma_range: tuple[float, float] = LEVEL_SMA_RANGE,
    n_levels: int = N_LEVELS,
    origin: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """Intensities log-spaced between the major-axis values at ``sma_range`` (SPEC §9.1).

    Each bound is the mean image value (bilinear) at ±a from ``centre`` along the major
    axis at that radius, the direction of the cos 2θ harmonic of I on the circle of
    radius a; beyond the image edge the edge value is used and a message is logged.
    SPEC §9.1 measures both bounds along the major axis of the brightest isophotes; in a
    twisted galaxy that direction is far from the outer major axis, and the faintest level
    would then lie at a ≫ 3″ (a = 4.6″ for a 30° twist with q → 0.55).

    Returns
    -------
    ndarray (n_levels,)
        Decreasing intensities (brightest, innermost isophote first), image units.

    Raises
    ------
    IsophoteError
        If the image does not decrease from the inner to the outer radius or the outer
        value is not positive (flat, empty or inverted image).
    """
    inner, outer = sma_range
    bright = _major_axis_value(image, pixel_scale, centre, inner, origin)
    faint = _major_axis_value(image, pixel_scale, centre, outer, origin)
    if not (np.isfinite(bright) and np.isfinite(faint) and bright > faint > 0.0):
        raise IsophoteError(
            f"cannot place isophote levels: I({inner}″) = {bright:.4g} and "
            f"I({outer}″) = {faint:.4g} along the major axis must satisfy I_in > I_out > 0 "
            "(flat, empty or inverted image?)"
        )
    return np.geomspace(bright, faint, n_levels)


def _polygon_area(x: np.ndarray, y: np.ndarray) -> float:
    """Signed shoelace area of a closed polygon (closing vertex repeated or not)."""
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _encloses(x: np.ndarray, y: np.ndarray, point: tuple[float, float]) -> bool:
    """Whether the closed polygon (x, y) contains ``point`` (crossing-number test)."""
    px, py = point
    x_next, y_next = np.roll(x, -1), np.roll(y, -1)
    straddles = (y > py) != (y_next > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = x + (py - y) * (x_next - x) / (y_next - y)
    return bool(np.count_nonzero(straddles & (x_cross > px)) % 2)


def contour_generator(
    image: np.ndarray, pixel_scale: float, origin: tuple[float, float]
) -> contourpy.ContourGenerator:
    """Marching-squares generator on log₁₀ I, cubic-spline interpolated to a finer grid.

    Pass it to :func:`closed_contour`. The grid is refined by :data:`CONTOUR_UPSAMPLING`
    (nodes at pixel centres and between them). Non-positive or non-finite pixels are
    filled with the nearest valid value for the spline and masked, together with every
    fine node next to them.
    """
    valid = np.isfinite(image) & (image > 0.0)
    nearest = ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
    log_image = np.log10(image[tuple(nearest)])
    n_y, n_x = image.shape
    rows = np.arange((n_y - 1) * CONTOUR_UPSAMPLING + 1) / CONTOUR_UPSAMPLING
    cols = np.arange((n_x - 1) * CONTOUR_UPSAMPLING + 1) / CONTOUR_UPSAMPLING
    fine = np.meshgrid(rows, cols, indexing="ij")
    fine_log = ndimage.map_coordinates(log_image, fine, order=3, mode="nearest")
    fine_invalid = ndimage.map_coordinates((~valid).astype(float), fine, order=1) > 0.0
    x = (cols - (n_x - 1) / 2.0) * pixel_scale + origin[0]
    y = (rows - (n_y - 1) / 2.0) * pixel_scale + origin[1]
    return contourpy.contour_generator(
        x, y, np.ma.masked_array(fine_log, mask=fine_invalid), line_type=contourpy.LineType.Separate
    )


def closed_contour(
    generator: contourpy.ContourGenerator, level: float, centre: tuple[float, float]
) -> np.ndarray:
    """The isophote of ``level``: the largest closed contour enclosing ``centre``.

    Parameters
    ----------
    generator : contourpy.ContourGenerator
        On log₁₀ of the image (see :func:`isophote_table`).
    level : float
        Intensity (image units, > 0).
    centre : (x, y) arcsec

    Returns
    -------
    ndarray (n, 2)
        (x, y) vertices, arcsec, closing vertex not repeated, consecutive duplicates removed.

    Raises
    ------
    IsophoteError
        No contour at this level, only open ones (the isophote leaves the image or a
        masked region), or no closed one around the centre.
    """
    if not level > 0.0:
        raise IsophoteError(f"level {level} is not positive")
    lines = generator.lines(math.log10(level))
    if not lines:
        raise IsophoteError("no contour at this level")
    closed = [line[:-1] for line in lines if len(line) > 3 and np.array_equal(line[0], line[-1])]
    around = [line for line in closed if _encloses(line[:, 0], line[:, 1], centre)]
    if not around:
        if len(closed) < len(lines):
            raise IsophoteError("the contour is open (it leaves the image or a masked region)")
        raise IsophoteError("no closed contour around the centre")
    line = max(around, key=lambda v: abs(_polygon_area(v[:, 0], v[:, 1])))
    keep = np.any(line != np.roll(line, 1, axis=0), axis=1)
    return line[keep]


def _table_row(fit: IsophoteFit, level: float) -> dict:
    ellipse, sma = fit.ellipse, fit.ellipse.semi_major
    coefficient = dict(zip(HARMONIC_NAMES, fit.harmonics / sma, strict=True))
    flag = (FLAG_ROUND if ellipse.axis_ratio > ROUND_AXIS_RATIO else 0) | (
        0 if fit.refined else FLAG_NOT_REFINED
    )
    return {
        "sma": sma,
        "q": ellipse.axis_ratio,
        "q_err": fit.axis_ratio_error,
        "pa": ellipse.angle,
        "pa_err": fit.angle_error,
        "a4_a": coefficient["a4"],
        "a4_a_err": fit.harmonic_errors[HARMONIC_NAMES.index("a4")] / sma,
        "b4_a": coefficient["b4"],
        "a3_a": coefficient["a3"],
        "b3_a": coefficient["b3"],
        "x0": ellipse.x0,
        "y0": ellipse.y0,
        "level": level,
        "flag": flag,
    }


def _empty_table() -> pd.DataFrame:
    columns = {name: pd.Series(dtype=float) for name in TABLE_COLUMNS}
    return pd.DataFrame(columns).astype({"flag": int})


def isophote_table(
    image: np.ndarray,
    pixel_scale: float,
    centre: tuple[float, float] | None = None,
    levels: Sequence[float] | None = None,
    origin: tuple[float, float] = (0.0, 0.0),
) -> pd.DataFrame:
    """Isophotes of an image: one fitted ellipse and its harmonics per intensity level.

    Parameters
    ----------
    image : ndarray (n_y, n_x)
        Native image (row index increasing with +y), e.g. a PSF-convolved lens-light
        model. Non-positive and non-finite pixels are excluded from the contours.
    pixel_scale : float
        Δ in arcsec per pixel.
    centre : (x, y) arcsec, optional
        Galaxy centre, used to pick the contours enclosing it and to place the levels;
        default the brightest pixel.
    levels : sequence of float, optional
        Intensities; default :func:`isophote_levels` (40 between the 0.3″ and 3.0″
        major-axis values).
    origin : (x, y) arcsec
        Grid origin (SPEC §1.1); (0, 0) puts it at the image centre.

    Returns
    -------
    pandas.DataFrame
        One row per isophote, sorted by ``sma``; columns :data:`TABLE_COLUMNS`:

        * ``sma`` — semi-major axis a of the fitted ellipse, arcsec;
        * ``q``, ``q_err`` — axis ratio b/a and its 1σ;
        * ``pa``, ``pa_err`` — major-axis angle, degrees CCW from +x in [0, 180), and 1σ;
        * ``a4_a``, ``a4_a_err`` — Bender a₄/a (cos 4ϑ; > 0 disky, < 0 boxy) and 1σ;
        * ``b4_a``, ``a3_a``, ``b3_a`` — sin 4ϑ, cos 3ϑ and sin 3ϑ coefficients over a;
        * ``x0``, ``y0`` — ellipse centre, arcsec;
        * ``level`` — intensity of the isophote, image units;
        * ``flag`` — bit set: :data:`FLAG_ROUND` (1), :data:`FLAG_NOT_REFINED` (2).

        Levels that cannot be analysed (no closed contour around the centre, contour
        leaving the image, degenerate ellipse) are skipped and the reason is logged.
        An image on which no levels can be placed gives an empty table (logged).
    """
    image = np.asarray(image, dtype=float)
    if image.ndim != 2:
        raise ValueError(f"image must be 2D, got shape {image.shape}")
    if not np.any(np.isfinite(image) & (image > 0.0)):
        logger.warning("no isophotes: the image has no positive finite pixel")
        return _empty_table()
    if centre is None:
        centre = brightest_pixel_centre(image, pixel_scale, origin)
    if levels is None:
        try:
            levels = isophote_levels(image, pixel_scale, centre, origin=origin)
        except IsophoteError as exc:
            logger.warning("no isophotes: %s", exc)
            return _empty_table()
    generator = contour_generator(image, pixel_scale, origin)
    rows = []
    for level in levels:
        try:
            contour = closed_contour(generator, float(level), centre)
            rows.append(_table_row(fit_isophote(contour[:, 0], contour[:, 1]), float(level)))
        except IsophoteError as exc:
            logger.info("isophote at level %.5g skipped: %s", level, exc)
    if not rows:
        logger.warning("no isophote could be fitted")
        return _empty_table()
    table = pd.DataFrame(rows, columns=list(TABLE_COLUMNS))
    return table.sort_values("sma", ignore_index=True)


# --------------------------------------------------------------------------------------
# per-lens statistics


def unwrap_position_angles(angles: np.ndarray) -> np.ndarray:
    """Axis angles (deg, mod 180) made continuous: each moved by k·180° to the value
    closest to the previous one (SPEC §9.1 step 5)."""
    unwrapped = np.asarray(angles, dtype=float).copy()
    for k in range(1, unwrapped.size):
        turns = np.round((unwrapped[k] - unwrapped[k - 1]) / 180.0)
        unwrapped[k] -= 180.0 * turns
    return unwrapped


@dataclass(frozen=True)
class IsophoteStatistics:
    """Per-lens isophote statistics over ``sma_min`` ≤ a ≤ ``sma_max`` (SPEC §9.1 step 5).

    Attributes
    ----------
    delta_q_max : float
        max q − min q (NaN without isophotes).
    delta_pa_max : float
        max PA − min PA in degrees after unwrapping along increasing a, over the
        isophotes with q ≤ ``round_axis_ratio`` (NaN if there are none).
    a4_a_extreme : float
        The a₄/a of largest absolute value, sign kept (> 0 disky, < 0 boxy).
    n_isophotes : int
        Isophotes in the range.
    n_isophotes_pa : int
        Of those, the ones used for ΔPA (not round).
    sma_min, sma_max : float
        The range, arcsec.
    round_axis_ratio : float
        q above which an isophote's PA is ignored.
    """

    delta_q_max: float
    delta_pa_max: float
    a4_a_extreme: float
    n_isophotes: int
    n_isophotes_pa: int
    sma_min: float = STATISTICS_SMA_RANGE[0]
    sma_max: float = STATISTICS_SMA_RANGE[1]
    round_axis_ratio: float = ROUND_AXIS_RATIO

    def to_dict(self) -> dict:
        """Plain-type dictionary for JSON, NaN written as None."""
        return {
            key: None if isinstance(value, float) and math.isnan(value) else value
            for key, value in asdict(self).items()
        }


def isophote_statistics(
    table: pd.DataFrame,
    sma_range: tuple[float, float] = STATISTICS_SMA_RANGE,
    round_axis_ratio: float = ROUND_AXIS_RATIO,
) -> IsophoteStatistics:
    """Δq_max, ΔPA_max and the extreme a₄/a of an :func:`isophote_table` (SPEC §9.1)."""
    inside = table[(table["sma"] >= sma_range[0]) & (table["sma"] <= sma_range[1])]
    inside = inside.sort_values("sma")
    q = inside["q"].to_numpy(dtype=float)
    a4 = inside["a4_a"].to_numpy(dtype=float)
    angles = inside.loc[inside["q"] <= round_axis_ratio, "pa"].to_numpy(dtype=float)
    unwrapped = unwrap_position_angles(angles)
    return IsophoteStatistics(
        delta_q_max=float(q.max() - q.min()) if q.size else math.nan,
        delta_pa_max=float(unwrapped.max() - unwrapped.min()) if unwrapped.size else math.nan,
        a4_a_extreme=float(a4[np.argmax(np.abs(a4))]) if a4.size else math.nan,
        n_isophotes=int(q.size),
        n_isophotes_pa=int(unwrapped.size),
        sma_min=float(sma_range[0]),
        sma_max=float(sma_range[1]),
        round_axis_ratio=float(round_axis_ratio),
    )


# --------------------------------------------------------------------------------------
# rendering a lens-light model


def render_light(
    profiles: Sequence,
    pixel_scale: float = 0.05,
    half_width: float = 3.5,
    psf: np.ndarray | None = None,
    sub_size: int = 4,
    sub_size_centre: int = 16,
    centre: tuple[float, float] = (0.0, 0.0),
    centre_radius: float = 0.3,
) -> np.ndarray:
    """Over-sampled (and optionally PSF-convolved) image of light profiles.

    Parameters
    ----------
    profiles : sequence
        Objects with ``image(x, y)`` (e.g. ``MGESet.gaussians(intensities)``, Sérsics).
    pixel_scale : float
        Δ, arcsec per pixel.
    half_width : float
        The square grid spans at least ±``half_width`` arcsec; its size is odd so that
        (0, 0) is a pixel centre (grid origin (0, 0), SPEC §1.1).
    psf : ndarray, optional
        Odd, unit-sum kernel; convolved with zero padding (SPEC §1.4).
    sub_size, sub_size_centre, centre, centre_radius
        Over-sampling as in the fits (SPEC §1.3): s×s sub-pixels averaged per pixel,
        ``sub_size_centre`` for pixels within ``centre_radius`` arcsec of ``centre``.

    Returns
    -------
    ndarray (n, n)
        Native image (row index increasing with +y), profile units per pixel.
    """
    n = 2 * math.ceil(half_width / pixel_scale - 1e-9) + 1
    x, y = (values.ravel() for values in pixel_centres((n, n), pixel_scale))
    sizes = adaptive_sub_sizes(x, y, centre, centre_radius, sub_size, sub_size_centre)
    grid = sub_grid(x, y, pixel_scale, sizes)
    image = sum(_binned_image(profile, grid) for profile in profiles).reshape(n, n)
    return image if psf is None else convolve_image(image, psf)


def _binned_image(profile, grid: SubGrid) -> np.ndarray:
    """Pixel means of a profile over ``grid``; Gaussians use the compiled MGE kernel."""
    if isinstance(profile, Gaussian):
        column = MGESet(profile.centre, profile.ell_comps, np.array([profile.sigma])).columns(grid)
        return profile.intensity * column[:, 0]
    return grid.bin(profile.image(grid.x, grid.y))


# --------------------------------------------------------------------------------------
# the mass model for comparison (SPEC §9.3)


@dataclass(frozen=True)
class MassShape:
    """Shape of the lens mass model to compare with the isophotes (SPEC §9.3).

    Attributes
    ----------
    axis_ratio, angle : float
        q and φ (deg CCW from +x) of the main mass profile.
    axis_ratio_interval, angle_interval : (float, float) or None
        Their 3σ intervals, when known.
    critical_curve : (ndarray, ndarray) or None
        Tangential critical curve (x, y) in arcsec.
    critical_curve_ellipse : Ellipse or None
        :func:`fit_ellipse` of the critical curve.
    critical_curve_einstein_radius : float or None
        Effective Einstein radius sqrt(area/π) of the critical curve, arcsec; not the
        profile's θ_E parameter (SPEC §3.4), from which it differs for elliptical
        power laws.
    """

    axis_ratio: float
    angle: float
    axis_ratio_interval: tuple[float, float] | None = None
    angle_interval: tuple[float, float] | None = None
    critical_curve: tuple[np.ndarray, np.ndarray] | None = None
    critical_curve_ellipse: Ellipse | None = None
    critical_curve_einstein_radius: float | None = None

    def to_dict(self) -> dict:
        """JSON-ready summary (without the critical-curve vertices)."""
        ellipse = self.critical_curve_ellipse
        return {
            "axis_ratio": self.axis_ratio,
            "angle": self.angle,
            "axis_ratio_interval": self.axis_ratio_interval,
            "angle_interval": self.angle_interval,
            "critical_curve_axis_ratio": None if ellipse is None else ellipse.axis_ratio,
            "critical_curve_angle": None if ellipse is None else ellipse.angle,
            "critical_curve_einstein_radius": self.critical_curve_einstein_radius,
        }


def mass_shape_from(
    profiles: Sequence,
    axis_ratio_interval: tuple[float, float] | None = None,
    angle_interval: tuple[float, float] | None = None,
    grid_spacing: float = 0.02,
    half_width: float = 3.0,
) -> MassShape:
    """:class:`MassShape` of a mass model whose first profile is elliptical (EPL, SIE).

    Computes the tangential critical curve (:func:`mgelens.mass.tangential_critical_curve`,
    all ``profiles`` including shear), its ellipse fit and effective Einstein radius.

    Raises
    ------
    ValueError
        If there is no closed tangential critical curve within ±``half_width``.
    """
    main = profiles[0]
    x, y = tangential_critical_curve(profiles, grid_spacing, half_width)
    return MassShape(
        axis_ratio=float(main.axis_ratio),
        angle=_reduced_angle(float(main.angle)),
        axis_ratio_interval=axis_ratio_interval,
        angle_interval=angle_interval,
        critical_curve=(x, y),
        critical_curve_ellipse=fit_ellipse(x, y),
        critical_curve_einstein_radius=math.sqrt(abs(_polygon_area(x[:-1], y[:-1])) / math.pi),
    )

"""One isophote contour -> its best ellipse and Fourier harmonics (SPEC §9.1 steps 3–5),
used by :func:`mgelens.isophotes.isophote_table`.

1. **Ellipse** — direct least-squares conic fit (Fitzgibbon, Pilu & Fisher 1999) in
   the numerically stable form of Halíř & Flusser (1998), on centred and scaled
   coordinates (:func:`fit_ellipse`).
2. **Fourier analysis** (Bender & Möllenhoff 1987) — in the ellipse frame the contour
   radius R(ϑ) at the polar angle ϑ (from the major axis, counter-clockwise) is
   resampled at 360 equally spaced ϑ and the deviation from the ellipse,
   δR = R − R_el, R_el = ab/sqrt((b cos ϑ)² + (a sin ϑ)²), is fitted by least squares with
   a₀ + Σ_{n=1}^{4} (a_n cos nϑ + b_n sin nϑ).
   **a₄/a > 0: disky; a₄/a < 0: boxy** — the sign of photutils' ``b4`` (its cos 4θ
   intensity term; checked with photutils 3.0, after the sign fix of photutils#1501).
   The two are not the same number: to first order b4 ≈ a₄/a · 2⟨cos² 4ϑ/ρ(ϑ)⟩, ρ the
   polar radius of the unit ellipse (a factor 1.1–1.3 for q = 0.9–0.7).
3. **Refinement** — the direct conic fit minimises an algebraic distance, so for a
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
   :data:`mgelens.isophotes.FLAG_NOT_REFINED`.

Uncertainties: the Fourier covariance is the least-squares covariance (AᵀA)⁻¹ scaled by
the residual variance RSS/(N − 9), inflated by N/n_vertices when the N = 360 resampled
radii outnumber the independent contour vertices. Geometry errors follow from the
harmonics through the refinement Jacobian J = ∂(a₀, a₁, b₁, a₂, b₂)/∂(x₀, y₀, a, e₁, e₂):
Cov_p = J⁻¹ Cov_h J⁻ᵀ. On noise-free models these errors measure only the departure of
the contour from the truncated Fourier series.

Angles are degrees counter-clockwise from +x; PA of an ellipse is its major-axis angle
in [0, 180). ``ell_comps`` follow :mod:`mgelens.geometry`. Lengths are arcsec.
"""

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from mgelens.geometry import axis_ratio_and_angle_from, ell_comps_from, to_profile_frame

N_ANGLES = 360
"""Equally spaced polar angles on which the contour radius is resampled."""
HARMONIC_NAMES = ("a0", "a1", "b1", "a2", "b2", "a3", "b3", "a4", "b4")
"""Order of the Fourier coefficients of δR(ϑ) returned by :func:`harmonic_deviations`."""
_MAX_NEWTON_ITERATIONS = 20
_HARMONIC_TOLERANCE = 1e-7
"""Refinement stops when max |a₀, a₁, b₁, a₂, b₂| < this × a."""
_STEP_POSITION = 1e-4
"""Finite-difference step of x₀, y₀ and a, in units of a."""
_STEP_ELL_COMPS = 1e-4
_MIN_CONTOUR_POINTS = 8


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


def reduced_angle(angle: float) -> float:
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
    angle = reduced_angle(math.degrees(math.atan2(major[1], major[0])))
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

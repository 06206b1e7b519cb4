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
3. **Ellipse and harmonics** of each contour (:func:`mgelens.ellipse_fit.fit_isophote`):
   the best ellipse in Bender & Möllenhoff's sense, a₄/a and the other harmonics, with
   their uncertainties.
4. **Statistics** per lens over 0.5–2.5″ (:func:`isophote_statistics`): Δq_max, ΔPA_max
   and the extreme a₄/a.

Angles are degrees counter-clockwise from +x; PA of an ellipse is its major-axis angle
in [0, 180). ``ell_comps`` follow :mod:`mgelens.geometry`. Lengths are arcsec.
"""

import logging
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace

import contourpy
import numpy as np
import pandas as pd
from scipy import ndimage

from mgelens.convolve import convolve_image
from mgelens.ellipse_fit import (
    HARMONIC_NAMES,
    Ellipse,
    IsophoteError,
    IsophoteFit,
    fit_ellipse,
    fit_isophote,
    reduced_angle,
)
from mgelens.grid import SubGrid, adaptive_sub_sizes, pixel_centres, sub_grid
from mgelens.light import Gaussian, MGESet
from mgelens.mass import tangential_critical_curve

logger = logging.getLogger(__name__)

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

CONTOUR_UPSAMPLING = 2
"""Refinement of the pixel grid (cubic spline of log₁₀ I) before marching squares."""


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
    a4_a_source_share : float
        The lensed-source share of the light around the isophote of the extreme a₄/a
        (:mod:`mgelens.source_share`): how much of the fitted light there is the source's.
        NaN when the table has no ``source_share`` column or it is undefined there.
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
    a4_a_source_share: float = math.nan
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
    """Δq_max, ΔPA_max and the extreme a₄/a of an :func:`isophote_table` (SPEC §9.1), and
    the source share at the extreme a₄/a if the table has the ``source_share`` column."""
    inside = table[(table["sma"] >= sma_range[0]) & (table["sma"] <= sma_range[1])]
    inside = inside.sort_values("sma")
    q = inside["q"].to_numpy(dtype=float)
    a4 = inside["a4_a"].to_numpy(dtype=float)
    angles = inside.loc[inside["q"] <= round_axis_ratio, "pa"].to_numpy(dtype=float)
    unwrapped = unwrap_position_angles(angles)
    extreme = int(np.argmax(np.abs(a4))) if a4.size else None
    share = (
        float(inside["source_share"].iloc[extreme])
        if extreme is not None and "source_share" in inside
        else math.nan
    )
    return IsophoteStatistics(
        delta_q_max=float(q.max() - q.min()) if q.size else math.nan,
        delta_pa_max=float(unwrapped.max() - unwrapped.min()) if unwrapped.size else math.nan,
        a4_a_extreme=float(a4[extreme]) if a4.size else math.nan,
        n_isophotes=int(q.size),
        n_isophotes_pa=int(unwrapped.size),
        a4_a_source_share=share,
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
    critical_curve_note : str or None
        Why the three critical-curve fields are None (no closed curve on the grid).
    """

    axis_ratio: float
    angle: float
    axis_ratio_interval: tuple[float, float] | None = None
    angle_interval: tuple[float, float] | None = None
    critical_curve: tuple[np.ndarray, np.ndarray] | None = None
    critical_curve_ellipse: Ellipse | None = None
    critical_curve_einstein_radius: float | None = None
    critical_curve_note: str | None = None

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
            "critical_curve_note": self.critical_curve_note,
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
    A mass without a closed tangential critical curve within ±``half_width`` (a sampler
    stopped among its prior draws, a barely lensing mass) still has its q and φ: the
    critical-curve fields are then None and ``critical_curve_note`` says why, so that one
    such lens leaves empty columns in the sample summary instead of stopping it.
    """
    main = profiles[0]
    shape = MassShape(
        axis_ratio=float(main.axis_ratio),
        angle=reduced_angle(float(main.angle)),
        axis_ratio_interval=axis_ratio_interval,
        angle_interval=angle_interval,
    )
    try:
        x, y = tangential_critical_curve(profiles, grid_spacing, half_width)
    except ValueError as exc:
        return replace(shape, critical_curve_note=str(exc))
    return replace(
        shape,
        critical_curve=(x, y),
        critical_curve_ellipse=fit_ellipse(x, y),
        critical_curve_einstein_radius=math.sqrt(abs(_polygon_area(x[:-1], y[:-1])) / math.pi),
    )

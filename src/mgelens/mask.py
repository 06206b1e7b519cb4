"""Masks and contaminant handling (SPEC §1.2).

Masks are boolean arrays of the native image shape ``(n_y, n_x)`` with **True = excluded**;
every function returns a new array. Geometric masks use the pixel centres of
:func:`mgelens.grid.pixel_centres` (arcsec, grid origin (0, 0) at the image centre) and are
inclusive: a pixel is used iff its centre lies within the boundary, with a tolerance of
:data:`RADIUS_TOLERANCE` so that centres exactly on a circle count despite rounding.

Contaminated pixels (neighbouring galaxies, stars) are not excluded but kept with a noise
scaled up by orders of magnitude (the SLACS cutouts mark them with noise = 1e8): the huge σ
removes them from χ², and their constant ln(2πσ²) terms cancel between models.
"""

import os
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from mgelens.grid import pixel_centres
from mgelens.imaging import Imaging
from mgelens.imaging_input import ImagingError, check_mask, check_positive, read_fits_mask

RADIUS_TOLERANCE = 1e-9
"""Arcsec added to radii so that pixel centres exactly on a circle are inside."""
SLACS_NOISE_THRESHOLD = 1e3
"""Noise above which a SLACS pixel is a contaminant sentinel (the sentinel is 1e8)."""
CONTAMINANT_NOISE_FACTOR = 1e8
"""Default noise multiplier for contaminated pixels."""


class MaskError(ValueError):
    """Invalid mask input; the message names the file (if any) and how to fix it."""


def validate_mask(mask: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Check that ``mask`` is a usable mask for an image of ``shape``; return a bool copy.

    Raises
    ------
    MaskError
        If the mask is not boolean, its shape differs from ``shape``, or it is empty
        (excludes every pixel).
    """
    with _mask_errors():
        return check_mask(mask, shape)


def circular(
    shape: tuple[int, int],
    pixel_scale: float,
    radius: float,
    centre: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """Circular mask: a pixel is used iff its centre is within ``radius`` of ``centre``.

    Parameters
    ----------
    shape : (int, int)
        Native image shape ``(n_y, n_x)``.
    pixel_scale : float
        Arcsec/pixel.
    radius : float
        Arcsec, > 0; inclusive (distance ≤ radius + 1e-9″).
    centre : (float, float)
        Circle centre (x, y) in arcsec.

    Returns
    -------
    ndarray of bool (n_y, n_x)
        True = excluded.
    """
    radius = _positive(radius, "radius (arcsec)")
    distance = _distances(shape, pixel_scale, centre)
    mask = distance > radius + RADIUS_TOLERANCE
    with _mask_errors(f"circular mask of radius {radius}″ centred at {tuple(centre)}″: "):
        return check_mask(mask, shape)


def largest_inside_radius(
    shape: tuple[int, int], pixel_scale: float, centre: tuple[float, float] = (0.0, 0.0)
) -> float:
    """Radius (arcsec) of the largest circle about ``centre`` inside the image: the
    distance from ``centre`` to the nearest outer edge of the image's border pixels
    (negative if ``centre`` lies outside the image)."""
    half_y, half_x = (0.5 * n * pixel_scale for n in shape)
    return float(min(half_x - abs(centre[0]), half_y - abs(centre[1])))


def annular(
    shape: tuple[int, int],
    pixel_scale: float,
    inner_radius: float,
    outer_radius: float,
    centre: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """Annular mask: used iff ``inner_radius ≤ distance ≤ outer_radius`` (both inclusive).

    Parameters
    ----------
    shape : (int, int)
        Native image shape ``(n_y, n_x)``.
    pixel_scale : float
        Arcsec/pixel.
    inner_radius, outer_radius : float
        Arcsec, 0 ≤ inner < outer.
    centre : (float, float)
        Annulus centre (x, y) in arcsec.

    Returns
    -------
    ndarray of bool (n_y, n_x)
        True = excluded.
    """
    outer_radius = _positive(outer_radius, "outer_radius (arcsec)")
    if not 0.0 <= inner_radius < outer_radius:
        raise MaskError(
            f"annulus radii must satisfy 0 <= inner_radius < outer_radius, got "
            f"{inner_radius}″ and {outer_radius}″; swap or correct them"
        )
    distance = _distances(shape, pixel_scale, centre)
    mask = (distance < inner_radius - RADIUS_TOLERANCE) | (
        distance > outer_radius + RADIUS_TOLERANCE
    )
    prefix = f"annular mask {inner_radius}″–{outer_radius}″ centred at {tuple(centre)}″: "
    with _mask_errors(prefix):
        return check_mask(mask, shape)


def from_fits(
    path: str | os.PathLike,
    invert: bool = False,
    shape: tuple[int, int] | None = None,
    hdu: int = 0,
) -> np.ndarray:
    """Read a mask from a FITS image.

    By default **nonzero = excluded** and 0 = used (the convention of
    :meth:`mgelens.imaging.Imaging.to_fits`); ``invert=True`` reads files in which nonzero
    marks the used pixels (e.g. a "fit region" image).

    Parameters
    ----------
    path : path
        FITS file; the first HDU with a 2D image is used if ``hdu`` has none.
    invert : bool
        Treat nonzero as used instead of excluded.
    shape : (int, int), optional
        Expected shape (e.g. ``imaging.shape``); checked if given.
    hdu : int
        HDU to read.

    Returns
    -------
    ndarray of bool (n_y, n_x)
        True = excluded.

    Raises
    ------
    MaskError
        Naming the file: unreadable, NaN/inf values, wrong shape or empty mask.
    """
    with _mask_errors():
        mask = read_fits_mask(path, invert=invert, hdu=hdu)
    with _mask_errors(f"{path}: "):
        return check_mask(mask, mask.shape if shape is None else shape)


def read_contaminant_circles(path: str | os.PathLike) -> tuple[tuple[float, float, float], ...]:
    """Contaminant circles from a text file: one ``x y radius`` per line (arcsec; centre in
    the coordinates of :func:`mgelens.grid.pixel_centres`, +x right and +y up from the image
    centre); ``#`` starts a comment, blank lines are skipped. For neighbours that the
    input's noise map does not mark (e.g. a compact object at the mask's edge): the fit
    treats these pixels as it treats the SLACS sentinels (:func:`contaminants`).

    Raises
    ------
    MaskError
        Naming the file (and the line): unreadable, a line that is not three numbers, a
        non-finite value or a radius ≤ 0, or no circle at all.
    """
    try:
        lines = Path(path).read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise MaskError(
            f"{path}: cannot read the contaminant circles ({exc}); give a text file of "
            "`x y radius` lines in arcsec"
        ) from exc
    circles = []
    for number, line in enumerate(lines, start=1):
        content = line.split("#", 1)[0].split()
        if not content:
            continue
        try:
            x, y, radius = (float(value) for value in content)
        except ValueError:
            raise MaskError(
                f"{path}, line {number}: {line.strip()!r} is not `x y radius` (three numbers "
                "in arcsec)"
            ) from None
        if not (np.isfinite([x, y, radius]).all() and radius > 0.0):
            raise MaskError(
                f"{path}, line {number}: {line.strip()!r} needs finite numbers and a radius > 0"
            )
        circles.append((x, y, radius))
    if not circles:
        raise MaskError(
            f"{path}: no contaminant circle; add `x y radius` lines (arcsec) or remove the file "
            "from the sample sheet"
        )
    return tuple(circles)


def contaminant_regions_from_noise(
    noise_map: np.ndarray, threshold: float = SLACS_NOISE_THRESHOLD
) -> np.ndarray:
    """Pixels whose noise exceeds ``threshold`` (SLACS contaminant sentinels, noise = 1e8).

    Parameters
    ----------
    noise_map : ndarray (n_y, n_x)
        1-sigma noise (data units).
    threshold : float
        Noise above which a pixel is a sentinel (data units).

    Returns
    -------
    ndarray of bool (n_y, n_x)
        True = contaminated (a region, not a mask: these pixels stay in the fit).
    """
    noise_map = np.asarray(noise_map, dtype=np.float64)
    if noise_map.ndim != 2:
        raise MaskError(f"noise_map must be 2D (n_y, n_x), got shape {noise_map.shape}")
    return noise_map > threshold


def contaminants(
    imaging: Imaging,
    regions: np.ndarray | Iterable[np.ndarray | tuple[float, float, float]],
    factor: float = CONTAMINANT_NOISE_FACTOR,
) -> Imaging:
    """Imaging whose noise is multiplied by ``factor`` inside the union of ``regions``.

    Parameters
    ----------
    imaging : Imaging
        The data set (unchanged).
    regions : ndarray of bool, or iterable of (ndarray of bool or (x, y, radius))
        Contaminated areas: bool arrays of ``imaging.shape`` with True = contaminated, or
        circles given as centre (x, y) and radius in arcsec (inclusive, like
        :func:`circular`). A single bool array is accepted as one region.
    factor : float
        Noise multiplier (> 0).

    Returns
    -------
    Imaging
        A new data set; the mask is unchanged, so contaminated pixels stay in the fit with
        a negligible weight.
    """
    if isinstance(regions, np.ndarray):
        regions = [regions]
    union = np.zeros(imaging.shape, dtype=bool)
    for region in regions:
        union |= _contaminant_region(region, imaging.shape, imaging.pixel_scale)
    factor = _positive(factor, "factor")
    return imaging.with_noise_scaled(union, factor)


def _contaminant_region(
    region: np.ndarray | tuple[float, float, float], shape: tuple[int, int], pixel_scale: float
) -> np.ndarray:
    """A contaminant region (bool array or (x, y, radius) circle) as a bool array."""
    if isinstance(region, np.ndarray):
        if region.dtype != bool or region.shape != tuple(shape):
            raise MaskError(
                f"contaminant region must be a bool array of shape {tuple(shape)} "
                f"(True = contaminated), got dtype {region.dtype} and shape {region.shape}"
            )
        return region
    try:
        x, y, radius = (float(value) for value in region)
    except (TypeError, ValueError) as exc:
        raise MaskError(
            f"contaminant region {region!r} must be a bool array of shape {tuple(shape)} or a "
            "circle (x, y, radius) in arcsec"
        ) from exc
    radius = _positive(radius, "contaminant circle radius (arcsec)")
    inside = _distances(shape, pixel_scale, (x, y)) <= radius + RADIUS_TOLERANCE
    if not inside.any():
        raise MaskError(
            f"contaminant circle {region!r} covers no pixel of the {tuple(shape)} image; give "
            "(x, y) in arcsec from the image centre, not in pixel indices"
        )
    return inside


def _distances(
    shape: tuple[int, int], pixel_scale: float, centre: tuple[float, float]
) -> np.ndarray:
    """Distance (arcsec) of every pixel centre from ``centre``."""
    if np.shape(shape) != (2,) or not all(isinstance(n, int | np.integer) and n > 0 for n in shape):
        raise MaskError(f"shape must be two positive integers (n_y, n_x), got {shape!r}")
    pixel_scale = _positive(pixel_scale, "pixel_scale (arcsec/pixel)")
    x, y = pixel_centres((int(shape[0]), int(shape[1])), pixel_scale)
    return np.hypot(x - centre[0], y - centre[1])


def _positive(value: float, label: str) -> float:
    """``value`` as a finite float > 0, else MaskError."""
    with _mask_errors():
        return check_positive(value, label)


@contextmanager
def _mask_errors(prefix: str = "") -> Iterator[None]:
    """Re-raise :class:`ImagingError` from the shared checks as :class:`MaskError`."""
    try:
        yield
    except ImagingError as exc:
        raise MaskError(f"{prefix}{exc}") from exc

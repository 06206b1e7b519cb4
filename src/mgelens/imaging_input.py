"""Reading and validating the inputs of an imaging data set (SPEC §1).

The checks that :class:`mgelens.imaging.Imaging` applies to its arrays, and the readers of
its files: FITS images, PSFs and masks, and the pixel scale and brightness unit from a FITS
header or an ``info.json``. Every invalid input raises :class:`ImagingError`, whose message
names the file (if any), the problem and how to fix it. Images keep the orientation and
dtype in which astropy reads them; masks are boolean with **True = excluded**; a PSF is
returned normalised to unit sum. Log records go to the ``mgelens.imaging`` logger.
"""

import json
import logging
import os
import warnings
from pathlib import Path

import numpy as np
from astropy.io import fits
from astropy.utils.exceptions import AstropyUserWarning
from astropy.wcs import WCS, FITSFixedWarning
from astropy.wcs.utils import proj_plane_pixel_scales

logger = logging.getLogger("mgelens.imaging")
"""Named after :mod:`mgelens.imaging`: these messages concern the imaging data set."""

PIXSCALE_KEY = "PIXSCALE"
"""FITS header keyword of the pixel scale (arcsec/pixel)."""
PSF_SUM_TOLERANCE = 1e-6
"""A PSF whose sum differs from 1 by more than this is renormalised."""
PIXEL_SCALE_RTOL = 1e-6
"""Relative difference above which an explicit and a header pixel scale disagree."""
PSF_NEGATIVE_FRACTION = 0.05
"""Largest depth of a PSF's negative entries, as a fraction of its peak, that is accepted
(a PSF is a non-negative kernel; background-subtracted empirical PSFs dip slightly below
zero in their noise). The SLACS PSFs have no negative entry and the mocks' Gaussians
none; a PSF beyond this is a wrong file, HDU or sign."""


class ImagingError(ValueError):
    """Invalid imaging input; the message names the file (if any) and how to fix it.

    Attributes
    ----------
    component : str or None
        The offending part of the data set (``"data"``, ``"noise_map"``, ``"psf"``,
        ``"mask"``, ``"pixel_scale"``), when the error concerns one of them.
    """

    def __init__(self, message: str, component: str | None = None):
        super().__init__(message)
        self.component = component


def check_mask(mask: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Validate a mask (bool, True = excluded) for an image of ``shape``; return a copy.

    Raises
    ------
    ImagingError
        If the mask is not boolean, has another shape, or excludes every pixel.
    """
    mask = np.asarray(mask)
    if mask.dtype != bool:
        raise ImagingError(
            f"mask must be a boolean array (True = excluded), got dtype {mask.dtype}; "
            "convert a 0/1 array with `mask != 0` if 1 marks excluded pixels",
            component="mask",
        )
    if mask.shape != tuple(shape):
        raise ImagingError(
            f"mask has shape {mask.shape} but the image has shape {tuple(shape)}; "
            "build the mask on the image grid (e.g. mgelens.mask.circular(imaging.shape, ...))",
            component="mask",
        )
    if mask.all():
        raise ImagingError(
            "mask is empty: it excludes every pixel (no unmasked pixel left); enlarge the "
            "radius, check the centre, or check the True = excluded convention",
            component="mask",
        )
    return mask.copy()


def check_positive(value: float, label: str) -> float:
    """Return ``value`` as a finite float > 0.

    Raises
    ------
    ImagingError
        Mentioning ``label`` if ``value`` is not a number, not finite or not > 0.
    """
    try:
        number = float(value)
    except (TypeError, ValueError) as exc:
        raise ImagingError(f"{label} must be a number, got {value!r}") from exc
    if not (np.isfinite(number) and number > 0.0):
        raise ImagingError(f"{label} must be finite and > 0, got {value!r}")
    return number


def read_fits_image(path: str | os.PathLike, hdu: int = 0) -> tuple[np.ndarray, fits.Header]:
    """Read a 2D image and its header from a FITS file.

    Parameters
    ----------
    path : path
        The FITS file.
    hdu : int
        HDU to read; if it holds no 2D image, the first HDU that does is used (logged).

    Returns
    -------
    image : ndarray (n_y, n_x)
        The image with the file's dtype (often big-endian).
    header : astropy.io.fits.Header
        Header of the HDU read.

    Raises
    ------
    ImagingError
        Naming the file: missing, not FITS, corrupt or truncated, ``hdu`` out of range,
        or no 2D image in any HDU.
    """
    path = Path(path)
    if not path.is_file():
        what = "is a directory, not a file" if path.is_dir() else "not found"
        raise ImagingError(f"{path}: FITS file {what}; check the path and the file name")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", AstropyUserWarning)
        try:
            with fits.open(path, memmap=False) as hdul:
                index = _image_hdu_index(hdul, hdu, path)
                image, header = np.array(hdul[index].data), hdul[index].header.copy()
        except (OSError, TypeError, ValueError) as exc:
            if isinstance(exc, ImagingError):
                raise
            raise _unreadable(path, str(exc)) from exc
    problems = [str(w.message) for w in caught if issubclass(w.category, AstropyUserWarning)]
    if problems:
        raise _unreadable(path, "; ".join(problems))
    for other in caught:
        warnings.warn_explicit(other.message, other.category, other.filename, other.lineno)
    return image, header


def read_psf(path: str | os.PathLike, hdu: int = 0) -> np.ndarray:
    """Read a PSF from FITS, validated and normalised to unit sum as :class:`Imaging` does.

    Raises
    ------
    ImagingError
        Naming the file, if it cannot be read or the PSF is even-sized, non-finite or has
        a non-positive sum.
    """
    psf, _ = read_fits_image(path, hdu)
    try:
        return normalised_psf(as_image(psf, "psf"), str(path))
    except ImagingError as exc:
        raise ImagingError(f"{path}: {exc}", component="psf") from exc


def read_fits_mask(path: str | os.PathLike, invert: bool = False, hdu: int = 0) -> np.ndarray:
    """Read a mask image: nonzero = excluded (or nonzero = used if ``invert``).

    Returns
    -------
    ndarray of bool (n_y, n_x)
        True = excluded.

    Raises
    ------
    ImagingError
        Naming the file when it cannot be read or holds NaN/inf.
    """
    values, _ = read_fits_image(path, hdu)
    n_bad = int((~np.isfinite(values)).sum()) if values.dtype.kind == "f" else 0
    if n_bad:
        raise ImagingError(
            f"{path}: mask file holds {n_bad} NaN/inf values; write 0 for used and nonzero "
            "for excluded pixels",
            component="mask",
        )
    excluded = values != 0
    return ~excluded if invert else excluded


def _image_hdu_index(hdul: fits.HDUList, hdu: int, path: Path) -> int:
    """Index of the HDU to read: ``hdu`` if it holds a 2D image, else the first that does."""
    if not 0 <= hdu < len(hdul):
        raise ImagingError(
            f"{path}: has {len(hdul)} HDU(s), so hdu={hdu} does not exist; "
            f"pass hdu= between 0 and {len(hdul) - 1}"
        )
    if _is_2d_image(hdul[hdu]):
        return hdu
    for index, candidate in enumerate(hdul):
        if _is_2d_image(candidate):
            logger.info("%s: HDU %d holds no 2D image; reading HDU %d", path, hdu, index)
            return index
    shapes = [None if h.data is None else h.data.shape for h in hdul]
    raise ImagingError(
        f"{path}: no 2D image in any HDU (data shapes per HDU: {shapes}); "
        "store the image as a 2D array (n_y, n_x)"
    )


def _is_2d_image(hdu: fits.PrimaryHDU | fits.ImageHDU) -> bool:
    return hdu.is_image and hdu.data is not None and hdu.data.ndim == 2


def _unreadable(path: Path, reason: str) -> ImagingError:
    return ImagingError(
        f"{path}: not a readable FITS file (corrupt or truncated?): {reason}; "
        "re-create or re-download it"
    )


def as_image(array: np.ndarray, label: str) -> np.ndarray:
    """Native-endian float64 2D copy of ``array``."""
    kind = np.asarray(array).dtype.kind
    if kind not in "biuf":
        raise ImagingError(
            f"{label} must be a real numeric array, got dtype kind {kind!r}", component=label
        )
    image = np.array(array, dtype=np.float64)
    if image.ndim != 2:
        raise ImagingError(
            f"{label} must be a 2D image (n_y, n_x), got shape {image.shape}; "
            "select the image plane (e.g. cube[0]) before building the Imaging",
            component=label,
        )
    return image


def normalised_psf(psf: np.ndarray, name: str) -> np.ndarray:
    """Validate an odd-sized, finite, positive-sum PSF without deep negative entries
    (:data:`PSF_NEGATIVE_FRACTION`) and normalise it to unit sum."""
    if psf.shape[0] % 2 == 0 or psf.shape[1] % 2 == 0:
        raise ImagingError(
            f"psf must have an odd size in both axes so that its centre is a pixel, got "
            f"shape {psf.shape}; crop or pad it to an odd size around the peak",
            component="psf",
        )
    n_bad = int((~np.isfinite(psf)).sum())
    if n_bad:
        raise ImagingError(
            f"psf has {n_bad} NaN/inf values; replace them (e.g. with 0) or use another PSF",
            component="psf",
        )
    total = float(psf.sum())
    if total <= 0.0:
        raise ImagingError(
            f"psf sums to {total:.6g} <= 0; a PSF needs a positive total, check that the "
            "right file and HDU were given",
            component="psf",
        )
    peak = float(psf.max())
    if psf.min() < -PSF_NEGATIVE_FRACTION * peak:  # peak > 0 since the total is
        raise ImagingError(
            f"psf has negative entries down to {psf.min():.4g} against a peak of {peak:.4g} "
            f"(more than {PSF_NEGATIVE_FRACTION:g} of the peak); a PSF is a non-negative "
            "kernel: check the file, the HDU and the sign, or set its noise pixels to 0",
            component="psf",
        )
    if abs(total - 1.0) > PSF_SUM_TOLERANCE:
        label = f" of {name}" if name else ""
        logger.info("PSF%s sums to %.9g, not 1: normalised to unit sum", label, total)
        return psf / total
    return psf


def check_unmasked_values(data: np.ndarray, noise_map: np.ndarray, used: np.ndarray) -> None:
    """Raise unless data and noise are finite and noise > 0 at the ``used`` pixels."""
    fix = (
        "exclude those pixels (mask.fits, nonzero = excluded, or a smaller mask) or repair the file"
    )
    _raise_if_any(~np.isfinite(data) & used, "data", "NaN/inf values", fix)
    _raise_if_any(~np.isfinite(noise_map) & used, "noise_map", "NaN/inf values", fix)
    _raise_if_any(
        (noise_map <= 0) & used,
        "noise_map",
        "values <= 0",
        "exclude those pixels or give them a huge noise (e.g. 1e8) to remove them from χ²",
    )


def _raise_if_any(bad: np.ndarray, label: str, problem: str, fix: str) -> None:
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise ImagingError(
            f"{label} has {int(bad.sum())} {problem} at unmasked pixels (first at row {row}, "
            f"col {col}), which the fit uses (masked pixels may hold anything); {fix}",
            component=label,
        )


def checked_pixel_scale(value: float, label: str) -> float:
    try:
        return check_positive(value, f"{label} (arcsec/pixel)")
    except ImagingError as exc:
        raise ImagingError(str(exc), component="pixel_scale") from exc


def header_pixel_scale(header: fits.Header, path: Path) -> float | None:
    """Pixel scale (arcsec/pixel) from ``PIXSCALE`` or a celestial WCS; None if neither."""
    if PIXSCALE_KEY in header:
        return checked_pixel_scale(header[PIXSCALE_KEY], f"{path}: header {PIXSCALE_KEY}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FITSFixedWarning)
            wcs = WCS(header)
    except (ValueError, KeyError) as exc:
        logger.warning("%s: header WCS not usable (%s); ignoring it", path, exc)
        return None
    if not wcs.has_celestial:
        return None
    scales = proj_plane_pixel_scales(wcs.celestial) * 3600.0
    if not np.isclose(scales[0], scales[1], rtol=PIXEL_SCALE_RTOL, atol=0.0):
        raise ImagingError(
            f"{path}: WCS pixels are not square ({scales[0]:.6g}″ × {scales[1]:.6g}″); "
            "mgelens needs square pixels, resample the image first"
        )
    return checked_pixel_scale(scales[0], f"{path}: WCS pixel scale")


def resolve_pixel_scale(explicit: float | None, from_header: float | None, path: Path) -> float:
    """The explicit pixel scale if given (warning on disagreement), else the header's."""
    if explicit is None:
        if from_header is None:
            raise ImagingError(
                f"{path}: no pixel scale: the header has neither {PIXSCALE_KEY} nor a "
                "celestial WCS; pass pixel_scale=<arcsec/pixel>, give the folder an "
                "info.json with pixel_scale_arcsec, or set the lens's `pixel_scale` column "
                "in the sample sheet (mgelens phase --pixel-scale)",
                component="pixel_scale",
            )
        return from_header
    scale = checked_pixel_scale(explicit, "pixel_scale")
    if from_header is not None and abs(scale - from_header) > PIXEL_SCALE_RTOL * from_header:
        logger.warning(
            "%s: header pixel scale %.9g arcsec differs from pixel_scale=%.9g; using the latter",
            path,
            from_header,
            scale,
        )
    return scale


def read_info(path: Path, pixel_scale_given: bool) -> dict:
    """The content of an ``info.json`` ({} if absent or not a JSON object).

    An unreadable file is an error only when the pixel scale must come from it; otherwise
    it is logged and ignored (it then gives no brightness unit).
    """
    if not path.is_file():
        return {}
    try:
        info = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        if pixel_scale_given:
            logger.warning("%s: cannot read JSON (%s); its brightness unit is not used", path, exc)
            return {}
        raise ImagingError(
            f"{path}: cannot read JSON ({exc}); fix the file or pass pixel_scale="
        ) from exc
    return info if isinstance(info, dict) else {}


def info_unit(info: dict) -> str:
    """The brightness unit of ``info["units"]``: its text before the first "(", stripped."""
    units = info.get("units")
    return units.split("(", 1)[0].strip() if isinstance(units, str) else ""


def info_pixel_scale(info: dict, path: Path) -> float | None:
    """``pixel_scale_arcsec`` of the ``info.json`` at ``path`` (logged), or None if absent."""
    value = info.get("pixel_scale_arcsec")
    if value is None:
        return None
    scale = checked_pixel_scale(value, f"{path}: pixel_scale_arcsec")
    logger.info("%s: pixel scale %.9g arcsec/pixel taken from %s", path.parent, scale, path.name)
    return scale

"""Imaging data sets: image, noise map, PSF, pixel scale and mask (SPEC §1).

Arrays keep the orientation in which astropy reads the FITS file (shape ``(n_y, n_x)``,
row index increasing with +y, see :mod:`mgelens.grid`). Masks are boolean with
**True = excluded**. Data and noise map share one brightness unit (e⁻ s⁻¹ pixel⁻¹ for the
SLACS cutouts); the PSF is a dimensionless kernel of unit sum.

Folder layout read by :meth:`Imaging.from_folder` and written by :meth:`Imaging.to_fits`::

    data.fits        image (BUNIT = brightness unit when known)
    noise_map.fits   1-sigma noise, same unit as data
    psf.fits         odd-sized kernel, unit sum
    mask.fits        optional, uint8, nonzero = excluded
    info.json        optional; ``pixel_scale_arcsec`` is used when no pixel scale is given

Every file written carries the pixel scale (arcsec/pixel) in the ``PIXSCALE`` keyword.
"""

import dataclasses
import json
import logging
import os
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from astropy.io import fits
from astropy.utils.exceptions import AstropyUserWarning
from astropy.wcs import WCS, FITSFixedWarning
from astropy.wcs.utils import proj_plane_pixel_scales

from mgelens.atomic import write_fits

logger = logging.getLogger(__name__)

DATA_FILE = "data.fits"
NOISE_MAP_FILE = "noise_map.fits"
PSF_FILE = "psf.fits"
MASK_FILE = "mask.fits"
INFO_FILE = "info.json"
PIXSCALE_KEY = "PIXSCALE"
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


@dataclass(frozen=True, eq=False, repr=False)
class Imaging:
    """An imaging data set on a regular grid of square pixels.

    Inputs are validated and stored as read-only native-endian float64 copies (the mask as
    a read-only bool copy); the caller's arrays are never modified.

    Parameters
    ----------
    data : ndarray (n_y, n_x)
        Image in a brightness unit per pixel (e.g. e⁻ s⁻¹).
    noise_map : ndarray (n_y, n_x)
        1-sigma noise in the unit of ``data``; finite and > 0 at every unmasked pixel.
    psf : ndarray (k_y, k_x)
        Odd-sized, finite kernel with positive sum, whose negative entries (if any) are
        shallower than :data:`PSF_NEGATIVE_FRACTION` of its peak. A sum differing from 1
        by more than 1e-6 is normalised to unit sum (logged at INFO level).
    pixel_scale : float
        Pixel size in arcsec/pixel, > 0.
    mask : ndarray of bool (n_y, n_x) or None
        True = excluded. None means every pixel is used. At least one pixel must be used.
    name : str
        Label of the data set (e.g. the lens name).
    unit : str
        Brightness unit of ``data`` and ``noise_map`` (FITS ``BUNIT``), "" if unknown.

    Raises
    ------
    ImagingError
        For non-2D or non-numeric arrays, mismatched shapes, an even-sized, non-finite,
        non-positive or too negative PSF, a bad pixel scale or mask, NaN/inf in data or
        noise at unmasked pixels, or noise <= 0 at unmasked pixels. Masked pixels may hold
        any value.
    """

    data: np.ndarray
    noise_map: np.ndarray
    psf: np.ndarray
    pixel_scale: float
    mask: np.ndarray | None = None
    name: str = ""
    unit: str = ""

    def __post_init__(self) -> None:
        data = _as_image(self.data, "data")
        noise_map = _as_image(self.noise_map, "noise_map")
        if noise_map.shape != data.shape:
            raise ImagingError(
                f"noise_map has shape {noise_map.shape} but data has shape {data.shape}; "
                "both must cover the same pixels (same cutout)",
                component="noise_map",
            )
        mask = None if self.mask is None else check_mask(self.mask, data.shape)
        psf = _normalised_psf(_as_image(self.psf, "psf"), self.name)
        pixel_scale = _checked_pixel_scale(self.pixel_scale, "pixel_scale")
        used = np.ones(data.shape, dtype=bool) if mask is None else ~mask
        _check_unmasked_values(data, noise_map, used)
        for field, value in (("data", data), ("noise_map", noise_map), ("psf", psf)):
            value.setflags(write=False)
            object.__setattr__(self, field, value)
        if mask is not None:
            mask.setflags(write=False)
        object.__setattr__(self, "mask", mask)
        object.__setattr__(self, "pixel_scale", pixel_scale)
        object.__setattr__(self, "name", str(self.name))
        object.__setattr__(self, "unit", str(self.unit))

    def __repr__(self) -> str:
        n_used = self.data.size if self.mask is None else int((~self.mask).sum())
        return (
            f"Imaging(name={self.name!r}, shape={self.shape}, pixel_scale={self.pixel_scale}, "
            f"psf_shape={self.psf.shape}, n_unmasked={n_used}, unit={self.unit!r})"
        )

    @property
    def shape(self) -> tuple[int, int]:
        """Native image shape ``(n_y, n_x)`` in pixels."""
        return self.data.shape

    @property
    def signal_to_noise_map(self) -> np.ndarray:
        """``data / noise_map`` per pixel (dimensionless); 0 where noise <= 0 or non-finite."""
        valid = np.isfinite(self.noise_map) & (self.noise_map > 0)
        return np.divide(self.data, self.noise_map, out=np.zeros(self.shape), where=valid)

    def with_mask(self, mask: np.ndarray | None) -> "Imaging":
        """A copy with ``mask`` (bool, True = excluded; None = use every pixel)."""
        return dataclasses.replace(self, mask=mask)

    def with_noise_scaled(self, region: np.ndarray, factor: float) -> "Imaging":
        """A copy whose noise map is multiplied by ``factor`` inside ``region``.

        Parameters
        ----------
        region : ndarray of bool (n_y, n_x)
            True where the noise is scaled (e.g. contaminating objects).
        factor : float
            Multiplier (> 0, finite); 1e8 effectively removes the pixels from χ².
        """
        region = np.asarray(region)
        if region.dtype != bool or region.shape != self.shape:
            raise ImagingError(
                f"noise-scaling region must be a bool array of shape {self.shape}, got "
                f"dtype {region.dtype} and shape {region.shape}; build it on the image grid"
            )
        factor = check_positive(factor, "noise scaling factor")
        return dataclasses.replace(
            self, noise_map=np.where(region, self.noise_map * factor, self.noise_map)
        )

    @classmethod
    def from_fits(
        cls,
        data_path: str | os.PathLike,
        noise_map_path: str | os.PathLike,
        psf_path: str | os.PathLike,
        pixel_scale: float | None = None,
        hdu: int = 0,
        name: str = "",
        mask_path: str | os.PathLike | None = None,
        mask_from: Callable[[tuple[int, int], float], np.ndarray] | None = None,
        unit: str = "",
    ) -> "Imaging":
        """Read an imaging data set from FITS files.

        Parameters
        ----------
        data_path, noise_map_path, psf_path : path
            FITS files of the image, its 1-sigma noise map and the PSF.
        pixel_scale : float, optional
            Arcsec/pixel. Wins over the data header; if omitted, the data header's
            ``PIXSCALE`` keyword (arcsec) or its celestial WCS is used.
        hdu : int
            HDU holding the images; if it has no 2D image the first HDU with one is used.
        name : str
            Label of the data set.
        mask_path : path, optional
            FITS mask, nonzero = excluded (see :func:`read_fits_mask`).
        mask_from : callable, optional
            ``mask_from(shape, pixel_scale)`` -> bool mask (True = excluded), combined with
            the mask file: e.g. a fit's circle, so that only the pixels the fit uses must
            hold finite data and a positive noise.
        unit : str
            Brightness unit to use when the data header has no ``BUNIT`` ("" = unknown).

        Raises
        ------
        ImagingError
            Naming the offending file: missing, not FITS or corrupt, without a 2D image,
            invalid content (see :class:`Imaging`), or no pixel scale available.
        """
        paths = {
            "data": Path(data_path),
            "noise_map": Path(noise_map_path),
            "psf": Path(psf_path),
            "mask": None if mask_path is None else Path(mask_path),
        }
        data, header = read_fits_image(paths["data"], hdu)
        noise_map, _ = read_fits_image(paths["noise_map"], hdu)
        psf, _ = read_fits_image(paths["psf"], hdu)
        mask = None if paths["mask"] is None else read_fits_mask(paths["mask"])
        header_scale = _header_pixel_scale(header, paths["data"])
        scale = _resolve_pixel_scale(pixel_scale, header_scale, paths["data"])
        if mask_from is not None:
            region = mask_from(np.shape(data), scale)
            if mask is None:
                mask = region
            elif np.shape(mask) == np.shape(region):  # else the check names the mask file
                mask = mask | region
        unit = str(header.get("BUNIT", "")).strip() or unit
        try:
            return cls(data, noise_map, psf, scale, mask=mask, name=name, unit=unit)
        except ImagingError as exc:
            source = paths.get(exc.component)
            if source is None:
                raise
            raise ImagingError(f"{source}: {exc}", component=exc.component) from exc

    @classmethod
    def from_folder(
        cls,
        folder: str | os.PathLike,
        pixel_scale: float | None = None,
        hdu: int = 0,
        name: str | None = None,
        mask_from: Callable[[tuple[int, int], float], np.ndarray] | None = None,
    ) -> "Imaging":
        """Read ``data.fits``, ``noise_map.fits``, ``psf.fits`` (and ``mask.fits``) of a folder.

        This is the layout of ``shared/data/slacs/<lens>/`` and of :meth:`to_fits`.

        Parameters
        ----------
        folder : path
            The folder.
        pixel_scale : float, optional
            Arcsec/pixel. If omitted, ``pixel_scale_arcsec`` of a sibling ``info.json`` is
            used (logged), else the data header (see :meth:`from_fits`). The brightness
            unit is the data header's ``BUNIT``, else the ``units`` of ``info.json`` up to
            its first parenthesis (``"electrons/s (HST ...)"`` → ``electrons/s``).
        hdu : int
            HDU holding the images (see :meth:`from_fits`).
        name : str, optional
            Label; defaults to the folder name.
        mask_from : callable, optional
            Extra mask from the shape and pixel scale (see :meth:`from_fits`).
        """
        folder = Path(folder)
        if not folder.is_dir():
            raise ImagingError(
                f"{folder}: imaging folder not found; expected a folder holding "
                f"{DATA_FILE}, {NOISE_MAP_FILE} and {PSF_FILE}"
            )
        info = _read_info(folder / INFO_FILE, pixel_scale is not None)
        if pixel_scale is None:
            pixel_scale = _info_pixel_scale(info, folder / INFO_FILE)
        mask_path = folder / MASK_FILE
        return cls.from_fits(
            folder / DATA_FILE,
            folder / NOISE_MAP_FILE,
            folder / PSF_FILE,
            pixel_scale=pixel_scale,
            hdu=hdu,
            name=folder.resolve().name if name is None else name,
            mask_path=mask_path if mask_path.is_file() else None,
            mask_from=mask_from,
            unit=_info_unit(info),
        )

    def to_fits(self, folder: str | os.PathLike) -> Path:
        """Write the data set in the folder layout of :meth:`from_folder`.

        Each file is written under a temporary name in ``folder`` and then moved into place
        (``os.replace``), so readers never see a half-written file. ``PIXSCALE`` is written
        with full float precision, so data, noise, PSF, mask and pixel scale round-trip
        exactly. Without a mask, a stale ``mask.fits`` in ``folder`` is removed.

        Returns
        -------
        Path
            The folder (created if needed).
        """
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        _write_fits_image(folder / DATA_FILE, self.data, self.pixel_scale, self.unit)
        _write_fits_image(folder / NOISE_MAP_FILE, self.noise_map, self.pixel_scale, self.unit)
        _write_fits_image(folder / PSF_FILE, self.psf, self.pixel_scale)
        if self.mask is None:
            (folder / MASK_FILE).unlink(missing_ok=True)
        else:
            _write_fits_image(folder / MASK_FILE, self.mask.astype(np.uint8), self.pixel_scale)
        return folder


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
        return _normalised_psf(_as_image(psf, "psf"), str(path))
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


def _as_image(array: np.ndarray, label: str) -> np.ndarray:
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


def _normalised_psf(psf: np.ndarray, name: str) -> np.ndarray:
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


def _check_unmasked_values(data: np.ndarray, noise_map: np.ndarray, used: np.ndarray) -> None:
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


def _checked_pixel_scale(value: float, label: str) -> float:
    try:
        return check_positive(value, f"{label} (arcsec/pixel)")
    except ImagingError as exc:
        raise ImagingError(str(exc), component="pixel_scale") from exc


def _header_pixel_scale(header: fits.Header, path: Path) -> float | None:
    """Pixel scale (arcsec/pixel) from ``PIXSCALE`` or a celestial WCS; None if neither."""
    if PIXSCALE_KEY in header:
        return _checked_pixel_scale(header[PIXSCALE_KEY], f"{path}: header {PIXSCALE_KEY}")
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
    return _checked_pixel_scale(scales[0], f"{path}: WCS pixel scale")


def _resolve_pixel_scale(explicit: float | None, from_header: float | None, path: Path) -> float:
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
    scale = _checked_pixel_scale(explicit, "pixel_scale")
    if from_header is not None and abs(scale - from_header) > PIXEL_SCALE_RTOL * from_header:
        logger.warning(
            "%s: header pixel scale %.9g arcsec differs from pixel_scale=%.9g; using the latter",
            path,
            from_header,
            scale,
        )
    return scale


def _read_info(path: Path, pixel_scale_given: bool) -> dict:
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


def _info_unit(info: dict) -> str:
    """The brightness unit of ``info["units"]``: its text before the first "(", stripped."""
    units = info.get("units")
    return units.split("(", 1)[0].strip() if isinstance(units, str) else ""


def _info_pixel_scale(info: dict, path: Path) -> float | None:
    """``pixel_scale_arcsec`` of the ``info.json`` at ``path`` (logged), or None if absent."""
    value = info.get("pixel_scale_arcsec")
    if value is None:
        return None
    scale = _checked_pixel_scale(value, f"{path}: pixel_scale_arcsec")
    logger.info("%s: pixel scale %.9g arcsec/pixel taken from %s", path.parent, scale, path.name)
    return scale


def _exact_float_card(key: str, value: float, comment: str) -> fits.Card:
    """A header card holding ``value`` with all 17 significant digits (exact round trip)."""
    return fits.Card.fromstring(f"{key:<8}= {repr(float(value)).upper():>20} / {comment}")


def _write_fits_image(path: Path, image: np.ndarray, pixel_scale: float, unit: str = "") -> None:
    """Write ``image`` to ``path`` atomically, with ``PIXSCALE`` (and ``BUNIT`` if known)."""
    header = fits.Header([_exact_float_card(PIXSCALE_KEY, pixel_scale, "[arcsec/pixel]")])
    if unit:
        header["BUNIT"] = unit
    write_fits(path, fits.PrimaryHDU(data=image, header=header))

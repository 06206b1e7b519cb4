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

The checks of the arrays and the readers of the files are in :mod:`mgelens.imaging_input`.
"""

import dataclasses
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from astropy.io import fits

from mgelens.atomic import write_fits
from mgelens.imaging_input import (
    PIXSCALE_KEY,
    ImagingError,
    as_image,
    check_mask,
    check_positive,
    check_unmasked_values,
    checked_pixel_scale,
    header_pixel_scale,
    info_pixel_scale,
    info_unit,
    normalised_psf,
    read_fits_image,
    read_fits_mask,
    read_info,
    resolve_pixel_scale,
)

DATA_FILE = "data.fits"
NOISE_MAP_FILE = "noise_map.fits"
PSF_FILE = "psf.fits"
MASK_FILE = "mask.fits"
INFO_FILE = "info.json"


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
        shallower than :data:`~mgelens.imaging_input.PSF_NEGATIVE_FRACTION` of its peak. A
        sum differing from 1 by more than 1e-6 is normalised to unit sum (logged at INFO
        level).
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
        data = as_image(self.data, "data")
        noise_map = as_image(self.noise_map, "noise_map")
        if noise_map.shape != data.shape:
            raise ImagingError(
                f"noise_map has shape {noise_map.shape} but data has shape {data.shape}; "
                "both must cover the same pixels (same cutout)",
                component="noise_map",
            )
        mask = None if self.mask is None else check_mask(self.mask, data.shape)
        psf = normalised_psf(as_image(self.psf, "psf"), self.name)
        pixel_scale = checked_pixel_scale(self.pixel_scale, "pixel_scale")
        used = np.ones(data.shape, dtype=bool) if mask is None else ~mask
        check_unmasked_values(data, noise_map, used)
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
            FITS mask, nonzero = excluded (see :func:`~mgelens.imaging_input.read_fits_mask`).
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
        header_scale = header_pixel_scale(header, paths["data"])
        scale = resolve_pixel_scale(pixel_scale, header_scale, paths["data"])
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
        info = read_info(folder / INFO_FILE, pixel_scale is not None)
        if pixel_scale is None:
            pixel_scale = info_pixel_scale(info, folder / INFO_FILE)
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
            unit=info_unit(info),
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


def _exact_float_card(key: str, value: float, comment: str) -> fits.Card:
    """A header card holding ``value`` with all 17 significant digits (exact round trip)."""
    return fits.Card.fromstring(f"{key:<8}= {repr(float(value)).upper():>20} / {comment}")


def _write_fits_image(path: Path, image: np.ndarray, pixel_scale: float, unit: str = "") -> None:
    """Write ``image`` to ``path`` atomically, with ``PIXSCALE`` (and ``BUNIT`` if known)."""
    header = fits.Header([_exact_float_card(PIXSCALE_KEY, pixel_scale, "[arcsec/pixel]")])
    if unit:
        header["BUNIT"] = unit
    write_fits(path, fits.PrimaryHDU(data=image, header=header))

"""FITS products of a phase: ``model.fits`` and SPix1's ``adapt_image.fits``.

``model.fits`` is multi-extension (:data:`MODEL_EXTENSIONS`): an empty primary HDU with
the provenance (phase, lens, figures of merit), then one image per quantity, each with
``EXTNAME`` and ``BUNIT``. Image-plane arrays are native 2D in the data's orientation
(row index increases with +y, SPEC §1.1) and zero outside the mask. The source-plane
reconstruction is a regular grid described by ``PIXSCALE`` (arcsec/pixel) and
``XCENTRE``/``YCENTRE`` (arcsec, the grid's central point), like the mocks' ``source.fits``.

Brightness is in the data unit per image pixel (e.g. e⁻ s⁻¹ pix⁻¹); the normalised
residuals (data − model)/σ are dimensionless (``BUNIT = ''``).
"""

from pathlib import Path

import numpy as np
from astropy.io import fits

from mgelens import mass as mass_module
from mgelens.atomic import write_fits
from mgelens.fit import FitResult, MGESource
from mgelens.grid import pixel_centres

MODEL_EXTENSIONS = {
    "MODEL": "model image: lens light + lensed source, PSF-convolved",
    "LENS": "lens light model, PSF-convolved",
    "LENSED": "lensed source model, PSF-convolved",
    "RESID": "residuals data - model",
    "NRESID": "normalized residuals (data - model) / noise",
    "SRCPLANE": "source-plane reconstruction (unlensed source)",
}
"""EXTNAME of each image extension of ``model.fits`` and what it holds."""

SOURCE_PLANE_SHAPE = (151, 151)
"""Pixels of the source-plane reconstruction grid."""


def _image_hdu(name: str, image: np.ndarray, unit: str, header: fits.Header | None = None):
    hdu = fits.ImageHDU(np.asarray(image, dtype=np.float64), header=header, name=name)
    hdu.header["BUNIT"] = (unit, "dimensionless" if unit == "" else "per image pixel")
    hdu.header["CONTENT"] = MODEL_EXTENSIONS.get(name, name)
    return hdu


def _grid_header(pixel_scale: float, centre: tuple[float, float]) -> fits.Header:
    header = fits.Header()
    header["PIXSCALE"] = (float(pixel_scale), "[arcsec/pixel]")
    header["XCENTRE"] = (float(centre[0]), "[arcsec] x of the array centre")
    header["YCENTRE"] = (float(centre[1]), "[arcsec] y of the array centre")
    return header


def source_plane_image(
    result: FitResult,
    shape: tuple[int, int] = SOURCE_PLANE_SHAPE,
    window: tuple[tuple[float, float], float] | None = None,
) -> tuple[np.ndarray, float, tuple[float, float]]:
    """Source-plane image of a fit with its pixel scale (arcsec) and centre (x, y arcsec).

    Pixelized sources are interpolated (natural neighbour) over their mesh's extent. An
    MGE source is evaluated at the grid points over the extent of the ray-traced unmasked
    pixel centres. ``window`` = (centre, half-width), arcsec, renders that square instead
    (a zoom, :func:`mgelens.overview.source_window`).
    """
    centre, half_width = (None, None) if window is None else window
    if result.source is not None:
        image, extent = result.source.image(shape, half_width, centre)
    else:
        image, extent = _mge_source_image(result, shape, centre, half_width)
    pixel_scale = (extent[1] - extent[0]) / shape[1]
    centre = (0.5 * (extent[0] + extent[1]), 0.5 * (extent[2] + extent[3]))
    return image, pixel_scale, centre


def _mge_source_image(
    result: FitResult,
    shape: tuple[int, int],
    centre: tuple[float, float] | None = None,
    half_width: float | None = None,
):
    source = result.model.source
    if not isinstance(source, MGESource):
        raise TypeError("the fit has neither a pixelized nor an MGE source")
    if centre is None or half_width is None:
        dataset = result.dataset
        x, y = pixel_centres(dataset.mask.shape, dataset.imaging.pixel_scale)
        bx, by = mass_module.ray_trace(result.model.mass, x[~dataset.mask], y[~dataset.mask])
        centre = (0.5 * (bx.min() + bx.max()), 0.5 * (by.min() + by.max()))
        half_width = 0.5 * max(np.ptp(bx), np.ptp(by)) * 1.05
    pixel_scale = 2.0 * half_width / shape[1]
    gx, gy = pixel_centres(shape, pixel_scale, origin=centre)
    intensities = result.source_light_intensities
    image = np.zeros(shape)
    start = 0
    for mge in source.sets:
        image += mge.image(gx, gy, intensities[start : start + mge.n_gaussians])
        start += mge.n_gaussians
    extent = (
        centre[0] - half_width,
        centre[0] + half_width,
        centre[1] - half_width,
        centre[1] + half_width,
    )
    return image, extent


def write_model_fits(path: str | Path, result: FitResult, provenance: dict) -> None:
    """Write ``model.fits`` of a fit (extensions :data:`MODEL_EXTENSIONS`) atomically.

    Parameters
    ----------
    path : path
        Output file.
    result : FitResult
        The maximum-likelihood fit of the phase.
    provenance : dict
        Short ``{KEY: value}`` cards for the primary header (keys ≤ 8 characters).
    """
    imaging = result.dataset.imaging
    unit = imaging.unit
    primary = fits.PrimaryHDU()
    for key, value in provenance.items():
        primary.header[key] = value
    primary.header["LOGLIKE"] = (result.log_likelihood, "ln L of the max-likelihood fit")
    primary.header["LOGEVID"] = (result.log_evidence, "ln evidence (= ln L without pixels)")
    primary.header["CHI2"] = (result.chi_squared, "chi-squared over the mask")
    primary.header["NPIXMASK"] = (int(result.dataset.data.size), "unmasked image pixels")
    primary.header["SOLVER"] = (
        "nnls" if result.solution.positive_only else "cholesky",
        "linear solver (nnls = non-negative)",
    )
    image_header = _grid_header(imaging.pixel_scale, (0.0, 0.0))
    images = {
        "MODEL": result.model_image,
        "LENS": result.lens_light_image,
        "LENSED": result.lensed_source_image,
        "RESID": result.residuals,
    }
    hdus = [primary]
    hdus += [_image_hdu(n, result.native(v), unit, image_header) for n, v in images.items()]
    hdus.append(_image_hdu("NRESID", result.native(result.normalized_residuals), "", image_header))
    source, pixel_scale, centre = source_plane_image(result)
    hdus.append(_image_hdu("SRCPLANE", source, unit, _grid_header(pixel_scale, centre)))
    write_fits(path, fits.HDUList(hdus))


def write_adapt_image(path: str | Path, result: FitResult) -> None:
    """Write the adapt image: the fit's PSF-convolved lensed source, native, zero outside
    the mask (SPEC §4.1; floored at 1 % only where it is used)."""
    imaging = result.dataset.imaging
    hdu = fits.PrimaryHDU(
        result.native(result.lensed_source_image),
        header=_grid_header(imaging.pixel_scale, (0.0, 0.0)),
    )
    hdu.header["BUNIT"] = (imaging.unit, "per image pixel")
    hdu.header["CONTENT"] = "adapt image: lensed source model, PSF-convolved"
    write_fits(path, hdu)


def read_adapt_image(path: str | Path, mask: np.ndarray) -> np.ndarray:
    """The adapt image of ``path`` over the unmasked pixels of ``mask`` (slim order)."""
    image = np.asarray(fits.getdata(path), dtype=np.float64)
    if image.shape != mask.shape:
        raise ValueError(
            f"{path}: adapt image has shape {image.shape} but the mask has {mask.shape}; "
            "rerun the spix1 phase with the same data"
        )
    adapt = image[~mask]
    if not np.any(adapt > 0):
        raise ValueError(f"{path}: the adapt image has no positive pixel inside the mask")
    return adapt

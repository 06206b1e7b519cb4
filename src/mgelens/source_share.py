"""Share of the lensed-source model in the light along each lens-light isophote.

A fit splits the data into lens light and lensed source, and the data alone do not fix
the split (issue #32): the pixelized source may spread a glow of its outer cells over the
whole mask, and the lens light is then the data minus that glow. Where the glow is a
sizeable part of the light, the lens light's isophotes (q, PA, a₄/a; SPEC §9.1) describe
the split as much as the galaxy. This module measures, per isophote, how much of the
fitted light there is the source's:

    share(a) = Σ LENSED / Σ LENS

summed over the fit's pixels in the elliptical annulus |r_ell − a| ≤ Δ (Δ the pixel
scale) around the isophote's ellipse (its centre x0, y0, axis ratio q and major-axis
angle PA: r_ell = √(u² + (v/q)²) with u, v along the major and minor axes). LENSED and
LENS are the PSF-convolved lensed-source and lens-light images of a phase's
``model.fits``; the fit's pixels are those where the model is non-zero (``model.fits``
holds zeros outside the fit's mask). An isophote whose annulus has under half its pixels
in the fit (mask edge, masked contaminants) gets NaN.

Coordinates follow SPEC §1.1 (x, y arcsec, row index increasing with +y, ``origin`` the
array centre's position); angles are degrees CCW from +x.
"""

import numpy as np
import pandas as pd

from mgelens.geometry import to_profile_frame
from mgelens.grid import pixel_centres

MIN_FITTED_FRACTION = 0.5
"""An annulus needs at least this fraction of its pixels inside the fit."""


def source_share(
    table: pd.DataFrame,
    lens: np.ndarray,
    lensed: np.ndarray,
    model: np.ndarray,
    pixel_scale: float,
    origin: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """Lensed-source over lens-light model summed around each isophote of ``table``.

    Parameters
    ----------
    table : pandas.DataFrame
        :func:`mgelens.isophotes.isophote_table` rows (``sma``, ``q``, ``pa``, ``x0``,
        ``y0``), in the same arcsec frame as the images.
    lens, lensed, model : ndarray (n_y, n_x)
        Lens-light, lensed-source and total model images of one fit (``model.fits``
        LENS, LENSED, MODEL); ``model`` is zero outside the fit's pixels.
    pixel_scale : float
        Δ, arcsec per pixel: the annulus half-width.
    origin : (x, y) arcsec
        Position of the array centre (SPEC §1.1).

    Returns
    -------
    ndarray (len(table),)
        share(a) ≥ 0, NaN where the annulus is less than half inside the fit or the lens
        light there sums to zero.
    """
    lens, lensed, model = (np.asarray(image, dtype=float) for image in (lens, lensed, model))
    if not lens.shape == lensed.shape == model.shape or lens.ndim != 2:
        raise ValueError(
            f"lens, lensed and model images must be 2D of one shape: "
            f"{lens.shape}, {lensed.shape}, {model.shape}"
        )
    x, y = pixel_centres(lens.shape, pixel_scale, origin)
    fitted = np.isfinite(model) & (model != 0.0)
    shares = np.full(len(table), np.nan)
    for k, row in enumerate(table.itertuples(index=False)):
        u, v = to_profile_frame(x, y, (row.x0, row.y0), row.pa)
        annulus = np.abs(np.hypot(u, v / row.q) - row.sma) <= pixel_scale
        inside = annulus & fitted
        if inside.sum() < MIN_FITTED_FRACTION * annulus.sum() or not inside.any():
            continue
        light = lens[inside].sum()
        if light > 0.0:
            shares[k] = lensed[inside].sum() / light
    return shares

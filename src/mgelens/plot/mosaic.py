"""Mosaic of every lens's normalised residuals with its fit-quality flag.

One panel per lens: (data − model)/σ of its MASS ``model.fits`` (NRESID) on a diverging
scale of ±:data:`LIMIT` σ, with (x, y) arcsec axes (+x right, +y up, SPEC §1.1), zoomed on
the fitted pixels; contours of the lensed-source model at :data:`SOURCE_LEVELS` times the
noise (σ = RESID / NRESID; pixels outside the 1σ contour are the ones the quality statistic
uses, :mod:`mgelens.quality`); the light-model label and the quality state (``ok``,
``FLAG`` with the worst block marked, or ``n/a`` when not measured) in the corners, and
``LENSING`` top left when the lensing check flags the mass model. One colour bar for all
panels.
"""

import math
import os
from dataclasses import dataclass

import numpy as np
from astropy.io import fits
from matplotlib.figure import Figure

from mgelens.grid import pixel_centres

LIMIT = 3.5
"""Colour-scale limit in σ."""
SOURCE_LEVELS = (1.0, 10.0)
"""Lensed-source contours, in units of the noise."""
MAX_COLUMNS = 8


@dataclass(frozen=True)
class MosaicPanel:
    """What one panel shows.

    Attributes
    ----------
    lens, light_model : str
    nresid : ndarray (n_y, n_x)
        Normalised residuals, zero outside the mask.
    source_snr : ndarray (n_y, n_x)
        Lensed-source model over the noise (NaN where unknown).
    pixel_scale : float
        Arcsec per pixel.
    quality : dict
        ``mgelens quality`` record (``measured``, ``flag``, ``worst_x``, ``worst_y``,
        ``lensing``).
    """

    lens: str
    light_model: str
    nresid: np.ndarray
    source_snr: np.ndarray
    pixel_scale: float
    quality: dict

    @property
    def state(self) -> str:
        if not self.quality.get("measured"):
            return "n/a"
        return "FLAG" if self.quality.get("flag") else "ok"

    @property
    def lensing_flag(self) -> bool:
        return bool(self.quality.get("lensing", {}).get("flag", False))


def read_panel(model_path: str | os.PathLike, lens: str, light_model: str, quality: dict):
    """A :class:`MosaicPanel` from a phase's ``model.fits`` and its quality record."""
    with fits.open(model_path) as hdus:
        nresid = np.array(hdus["NRESID"].data, dtype=float)
        resid = np.array(hdus["RESID"].data, dtype=float)
        lensed = np.array(hdus["LENSED"].data, dtype=float)
        pixel_scale = float(hdus["NRESID"].header["PIXSCALE"])
    with np.errstate(divide="ignore", invalid="ignore"):
        noise = np.where(nresid != 0.0, resid / nresid, np.nan)
        snr = lensed / noise
    return MosaicPanel(lens, light_model, nresid, snr, pixel_scale, quality)


def _half_width(panel: MosaicPanel) -> float:
    """Arcsec half-width that holds every fitted (non-zero) pixel."""
    x, y = pixel_centres(panel.nresid.shape, panel.pixel_scale)
    fitted = panel.nresid != 0.0
    if not fitted.any():
        return 0.5 * panel.pixel_scale * max(panel.nresid.shape)
    return float(max(np.abs(x[fitted]).max(), np.abs(y[fitted]).max())) + panel.pixel_scale


def residual_mosaic(panels: list[MosaicPanel]) -> Figure:
    """The mosaic figure, panels in the given order; a note if there is none."""
    n = len(panels)
    columns = max(1, min(MAX_COLUMNS, math.ceil(math.sqrt(n))))
    rows = max(1, math.ceil(n / columns))
    figure = Figure(figsize=(2.4 * columns + 0.8, 2.4 * rows + 0.3), layout="constrained")
    axes = np.atleast_1d(figure.subplots(rows, columns, squeeze=False)).ravel()
    image = None
    for ax, panel in zip(axes, panels, strict=False):
        n_y, n_x = panel.nresid.shape
        half_x, half_y = 0.5 * n_x * panel.pixel_scale, 0.5 * n_y * panel.pixel_scale
        extent = (-half_x, half_x, -half_y, half_y)
        image = ax.imshow(
            panel.nresid, origin="lower", extent=extent, cmap="RdBu_r", vmin=-LIMIT, vmax=LIMIT
        )
        if np.any(np.isfinite(panel.source_snr)):
            ax.contour(
                np.nan_to_num(panel.source_snr, nan=0.0),
                levels=SOURCE_LEVELS,
                origin="lower",
                extent=extent,
                colors=("0.3", "k"),
                linewidths=(0.6, 0.8),
            )
        if panel.state == "FLAG":
            ax.plot(panel.quality["worst_x"], panel.quality["worst_y"], "x", color="m", ms=9)
        width = _half_width(panel)
        ax.set_xlim(-width, width)
        ax.set_ylim(-width, width)
        colour = {"ok": "tab:green", "FLAG": "tab:red", "n/a": "0.4"}[panel.state]
        ax.set_title(panel.lens, fontsize=9)
        ax.text(0.03, 0.03, panel.light_model, transform=ax.transAxes, fontsize=8, va="bottom")
        ax.text(
            0.97,
            0.97,
            panel.state,
            transform=ax.transAxes,
            ha="right",
            va="top",
            fontsize=8,
            color=colour,
            fontweight="bold",
        )
        if panel.lensing_flag:
            ax.text(
                0.03,
                0.97,
                "LENSING",
                transform=ax.transAxes,
                va="top",
                fontsize=8,
                color="tab:red",
                fontweight="bold",
            )
        ax.tick_params(labelsize=7)
        ax.set_xlabel("x [arcsec]", fontsize=7)
        ax.set_ylabel("y [arcsec]", fontsize=7)
    for ax in axes[n:]:
        ax.set_axis_off()
    if image is None:
        axes[0].text(0.5, 0.5, "no lens", transform=axes[0].transAxes, ha="center")
    else:
        figure.colorbar(image, ax=axes[:n].tolist(), label="(data − model)/σ [σ]", shrink=0.9)
    return figure

"""The paper's Figures 5–7: lens-light error and residuals of one lens-light model on the
mocks (:mod:`mgelens.mock_study`).

One column per fit. Row 1: the relative difference (model − true)/true of the
PSF-convolved lens light inside the fit mask, on a ±20 % scale. Row 2: the normalised
residuals (data − model)/σ on a ±3.5 scale, with contours of the data minus the fitted
lens light (the lensed source as that fit leaves it). Arcsec axes, +x right, +y up.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure

from mgelens.grid import pixel_centres
from mgelens.mock_study import MODEL_LABELS
from mgelens.plot.overview import image_extent

RELATIVE_LIMIT = 0.20
RESIDUAL_LIMIT = 3.5
CONTOUR_FRACTIONS = (0.1, 0.3, 0.6)
"""Contour levels of data − lens light, as fractions of its maximum inside the mask."""


@dataclass(frozen=True)
class LightPanel:
    """The images of one fit's column.

    Attributes
    ----------
    label : str
        Column title (lens id and mock).
    relative : ndarray
        (model − true)/true lens light, NaN outside the fit.
    residuals : ndarray
        Normalised residuals, NaN outside the fit.
    source : ndarray
        Data minus the fitted lens light, NaN outside the fit.
    pixel_scale : float
        Arcsec per pixel.
    radius : float
        Mask radius, arcsec (the panels show ±1.1 × radius).
    """

    label: str
    relative: np.ndarray
    residuals: np.ndarray
    source: np.ndarray
    pixel_scale: float
    radius: float


def lens_light_figure(model: str, panels: Sequence[LightPanel]) -> Figure:
    """Figure of the fits of lens-light ``model`` (a key of ``MODEL_LABELS``), one column
    per panel."""
    n = len(panels)
    figure = Figure(figsize=(3.4 * n + 1.2, 6.6), layout="constrained")
    axes = figure.subplots(2, n, squeeze=False, sharex=True, sharey=True)
    top = bottom = None
    for column, panel in enumerate(panels):
        extent = image_extent(panel.relative.shape, panel.pixel_scale)
        top = axes[0, column].imshow(
            panel.relative, origin="lower", extent=extent, cmap="RdBu_r",
            vmin=-RELATIVE_LIMIT, vmax=RELATIVE_LIMIT,
        )  # fmt: skip
        bottom = axes[1, column].imshow(
            panel.residuals, origin="lower", extent=extent, cmap="RdBu_r",
            vmin=-RESIDUAL_LIMIT, vmax=RESIDUAL_LIMIT,
        )  # fmt: skip
        finite = np.isfinite(panel.source)
        peak = float(np.nanmax(panel.source)) if finite.any() else 0.0
        if peak > 0:
            x, y = pixel_centres(panel.source.shape, panel.pixel_scale)
            axes[1, column].contour(
                x, y, np.where(finite, panel.source, 0.0),
                levels=[f * peak for f in CONTOUR_FRACTIONS], colors="k", linewidths=0.6,
            )  # fmt: skip
        axes[0, column].set_title(panel.label, fontsize=10)
        limit = 1.1 * panel.radius
        for ax in axes[:, column]:
            ax.set_xlim(-limit, limit)
            ax.set_ylim(-limit, limit)
            ax.set_xlabel("x [arcsec]")
    axes[0, 0].set_ylabel("y [arcsec]")
    axes[1, 0].set_ylabel("y [arcsec]")
    if top is not None:
        bar = figure.colorbar(top, ax=axes[0, :].tolist(), shrink=0.9)
        bar.set_label("lens light (model − true)/true")
        bar = figure.colorbar(bottom, ax=axes[1, :].tolist(), shrink=0.9)
        bar.set_label("(data − model)/σ")
    figure.suptitle(
        f"{MODEL_LABELS.get(model, model)}: lens-light error (top),\nnormalised residuals "
        "with contours of data − lens light (bottom)",
        fontsize=10,
    )
    return figure

"""Per-lens overview figure (the paper's Fig. 1): one phase's maximum-likelihood fit.

Six panels (2×3), drawn from an :class:`~mgelens.overview.Overview` (no computation, no
file reading):

1. **data** — asinh stretch (linear below about the median noise σ̃ of the fitted pixels,
   logarithmic above); contaminant pixels (inside the fit circle but ignored by the fit:
   noise at the 1e8 sentinel or excluded by ``mask.fits``) as a flat grey overlay; the
   fit circle dashed.
2. **lens light ⊗ PSF** — the lens-light model, same asinh stretch as the data.
3. **source plane** — the reconstruction (linear scale; blank outside the mesh) with the
   Voronoi cell edges of a pixelized source (none for the SP phase's MGE source) and the
   tangential caustic; the cells held at zero off the source's support (``source_support:
   arcs``) under a grey veil.
4. **normalised residuals** (data − model)/σ — diverging map fixed at ±3.5 σ,
   contaminants grey as in panel 1.
5. **lens-light contours** — log-spaced isophote levels of the lens-light model, each MGE
   set's (or Sérsic's) axis ratio q and position angle drawn as an ellipse with its
   major axis (size :attr:`~mgelens.overview.LightComponent.semi_major`, at most the fit
   radius), its q and PA in the legend; the point set marked with a cross.
6. **lensed source ⊗ PSF** — asinh stretch (linear below σ̃), with the tangential
   critical curve.

A mass model without a closed tangential critical curve within ±3″ (SPEC §3.4) gets a
note in panels 3 and 6 instead of the curves.

Image-plane panels show the fit circle and a margin around it. Every image is drawn with
``imshow(..., origin="lower")`` and an (x, y) arcsec extent from the pixel edges of the
grid (SPEC §1.1): +x to the right, +y up. Pixels outside the fit's mask are blank.
"""

import matplotlib
import numpy as np
from matplotlib import colors
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Patch

from mgelens.ellipse_fit import Ellipse
from mgelens.grid import pixel_centres
from mgelens.overview import LightComponent, Overview

RESIDUAL_LIMIT = 3.5
"""Colour limits ±3.5 σ of the normalised-residual panel."""
N_CONTOURS = 10
"""Number of lens-light contour levels."""
CONTOUR_RANGE = 1e-4
"""The faintest contour level is at least this fraction of the lens light's peak."""
MARGIN = 1.08
"""Image-plane panels show ±MARGIN × the fit radius about the fit circle's centre."""
CONTAMINANT_COLOUR = "0.55"
OFF_SUPPORT_ALPHA = 0.6
"""Opacity of the grey veil over the source cells held at zero off the support."""
CRITICAL_COLOUR = "cyan"
COMPONENT_COLOURS = ("tab:red", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink")


def image_extent(shape: tuple[int, int], pixel_scale: float) -> tuple[float, float, float, float]:
    """``imshow`` extent (x_min, x_max, y_min, y_max) arcsec of a native image: the outer
    pixel edges of the grid of :func:`mgelens.grid.pixel_centres` (origin (0, 0))."""
    x, y = pixel_centres(shape, pixel_scale)
    half = 0.5 * pixel_scale
    return (x[0, 0] - half, x[0, -1] + half, y[0, 0] - half, y[-1, 0] + half)


def brightness_label(unit: str) -> str:
    """Colour-bar label of a brightness image: the data unit per image pixel."""
    return f"{unit} per pixel" if unit else "data units per pixel"


def _fitted_pixels(overview: Overview) -> np.ndarray:
    return np.isfinite(overview.normalized_residuals) & ~overview.contaminants


def _asinh_norm(image: np.ndarray, used: np.ndarray, width: float) -> colors.AsinhNorm:
    values = image[used]
    return colors.AsinhNorm(
        linear_width=width,
        vmin=float(np.percentile(values, 0.5)),
        vmax=float(np.max(values)),
    )


def asinh_ticks(norm: colors.AsinhNorm, spacing: float = 0.08) -> list[float]:
    """Colour-bar ticks of an asinh stretch: 0 and ±{1, 2, 5}·10^k within the limits, the
    rounder first, none closer than ``spacing`` (fraction of the bar) to one kept."""
    candidates = [0.0] + [
        sign * mantissa * 10.0**power
        for mantissa in (1.0, 2.0, 5.0)
        for power in range(-4, 6)
        for sign in (1.0, -1.0)
    ]
    kept: list[float] = []
    for value in candidates:
        if not norm.vmin <= value <= norm.vmax:
            continue
        position = float(norm(value))
        if all(abs(position - float(norm(other))) >= spacing for other in kept):
            kept.append(value)
    return sorted(kept)


def _image(ax: Axes, figure: Figure, image, extent, norm, cmap, title: str, label: str):
    shown = ax.imshow(
        image,
        origin="lower",
        extent=extent,
        norm=norm,
        cmap=matplotlib.colormaps[cmap].with_extremes(bad="white"),
        interpolation="nearest",
    )
    ax.set_title(title)
    ax.set_xlabel("x [arcsec]")
    ax.set_ylabel("y [arcsec]")
    bar = figure.colorbar(shown, ax=ax, shrink=0.9, label=label)
    if isinstance(norm, colors.AsinhNorm):
        ticks = asinh_ticks(norm)
        bar.set_ticks(ticks, labels=[f"{t:g}" for t in ticks])
    return shown


def _contaminants(ax: Axes, overview: Overview, extent) -> None:
    """Contaminant pixels as a flat grey layer (the layer's unmasked pixels)."""
    if not overview.contaminants.any():
        return
    layer = np.ma.masked_array(np.ones(overview.contaminants.shape), ~overview.contaminants)
    ax.imshow(
        layer,
        origin="lower",
        extent=extent,
        cmap=colors.ListedColormap([CONTAMINANT_COLOUR]),
        interpolation="nearest",
        gid="contaminants",
    )
    patch = Patch(color=CONTAMINANT_COLOUR, label="ignored (σ = 1e8, contaminants, mask.fits)")
    ax.legend(handles=[patch], loc="lower left", fontsize="x-small", framealpha=0.8)


def _fit_circle(ax: Axes, overview: Overview, colour: str) -> None:
    ax.add_patch(
        Circle(
            overview.mask_centre,
            overview.mask_radius,
            fill=False,
            color=colour,
            linestyle="--",
            linewidth=0.8,
        )
    )
    half = MARGIN * overview.mask_radius
    ax.set_xlim(overview.mask_centre[0] - half, overview.mask_centre[0] + half)
    ax.set_ylim(overview.mask_centre[1] - half, overview.mask_centre[1] + half)


def _curve(ax: Axes, curve, label: str) -> None:
    """Draw a critical curve or caustic, or say that the mass model has none."""
    if curve is None:
        ax.text(
            0.5,
            0.95,
            f"no {label}: no closed tangential critical curve within ±3″",
            fontsize="x-small",
            ha="center",
            va="top",
            bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": CRITICAL_COLOUR},
            transform=ax.transAxes,
        )
        return
    ax.plot(*curve, color=CRITICAL_COLOUR, linewidth=1.0, label=label)
    ax.legend(loc="upper right", fontsize="x-small", framealpha=0.6)


def _source_panel(ax: Axes, figure: Figure, overview: Overview, label: str) -> None:
    source = overview.source
    low = min(0.0, float(np.nanmin(source.image)))
    norm = colors.Normalize(vmin=low, vmax=float(np.nanmax(source.image)))
    kind = "Voronoi mesh" if source.mesh_edges is not None else "MGE"
    _image(ax, figure, source.image, source.extent, norm, "inferno", f"source ({kind})", label)
    if source.mesh_edges is not None:
        ax.add_collection(
            LineCollection(source.mesh_edges, colors="white", linewidths=0.25, alpha=0.5)
        )
    off_support = source.off_support
    veiled = off_support is not None and bool(np.any(off_support & np.isfinite(source.image)))
    if veiled:
        layer = np.ma.masked_array(
            np.ones(off_support.shape), ~(off_support & np.isfinite(source.image))
        )
        ax.imshow(
            layer,
            origin="lower",
            extent=source.extent,
            cmap=colors.ListedColormap([CONTAMINANT_COLOUR]),
            alpha=OFF_SUPPORT_ALPHA,
            interpolation="nearest",
            gid="off_support",
        )
    _curve(ax, overview.caustic, "caustic")
    if veiled:
        handles, _ = ax.get_legend_handles_labels()
        veil = Patch(
            color=CONTAMINANT_COLOUR,
            alpha=OFF_SUPPORT_ALPHA,
            label="held at zero (off the arcs' support)",
        )
        ax.legend(handles=[*handles, veil], loc="upper right", fontsize="x-small", framealpha=0.6)
    ax.set_xlim(source.extent[0], source.extent[1])
    ax.set_ylim(source.extent[2], source.extent[3])


def contour_levels(image: np.ndarray) -> np.ndarray:
    """:data:`N_CONTOURS` log-spaced levels from the 5th percentile of the positive finite
    values (at least :data:`CONTOUR_RANGE` × the peak) to just below the peak; none if no
    value is positive."""
    positive = image[np.isfinite(image) & (image > 0.0)]
    if positive.size == 0:
        return np.empty(0)
    peak = float(positive.max())
    low = max(float(np.percentile(positive, 5.0)), CONTOUR_RANGE * peak)
    return np.geomspace(low, peak, N_CONTOURS + 1)[:-1]


def component_text(component: LightComponent) -> str:
    """Legend text of a lens-light component: ``set k: q=…, PA=…°``."""
    text = f"{component.label}: q={component.axis_ratio:.2f}, PA={component.angle:.0f}°"
    return text if component.semi_major > 0 or component.point else f"{text} (no flux)"


def _contour_panel(ax: Axes, figure: Figure, overview: Overview, label: str) -> None:
    x, y = pixel_centres(overview.lens_light.shape, overview.pixel_scale)
    levels = contour_levels(overview.lens_light)
    if levels.size:
        norm = colors.LogNorm(vmin=levels[0] / 4.0, vmax=levels[-1])
        light = overview.lens_light
        positive = np.ma.masked_where(~(np.isfinite(light) & (light > 0.0)), light)
        lines = ax.contour(x, y, positive, levels=levels, cmap="Greys", norm=norm)
        figure.colorbar(lines, ax=ax, shrink=0.9, label=label, format="%.3g")
    else:
        ax.text(0.5, 0.9, "no positive lens light", ha="center", transform=ax.transAxes)
    for k, component in enumerate(overview.components):
        colour = COMPONENT_COLOURS[k % len(COMPONENT_COLOURS)]
        text = component_text(component)
        if component.point:
            ax.plot(*component.centre, marker="x", color=colour, markersize=8, label=text)
            continue
        size = min(component.semi_major, overview.mask_radius)
        ellipse = Ellipse(*component.centre, size, component.axis_ratio, component.angle)
        phi = np.deg2rad(component.angle)
        ends = size * np.array([-1.0, 1.0])
        ax.plot(*ellipse.points(), color=colour, linewidth=1.2, label=text)
        ax.plot(
            component.centre[0] + ends * np.cos(phi),
            component.centre[1] + ends * np.sin(phi),
            color=colour,
            linewidth=0.8,
            linestyle=":",
        )
    ax.legend(loc="lower right", fontsize="x-small", framealpha=0.8)
    sersic = any(c.kind == "sersic" for c in overview.components)
    ax.set_title(f"lens-light contours and {'Sérsics' if sersic else 'MGE sets'}")
    ax.set_xlabel("x [arcsec]")
    ax.set_ylabel("y [arcsec]")
    ax.set_aspect("equal")


def overview_figure(overview: Overview) -> Figure:
    """The six-panel overview of one fit (see the module docstring)."""
    figure = Figure(figsize=(15.5, 9.5), layout="constrained")
    axes = figure.subplots(2, 3)
    extent = image_extent(overview.data.shape, overview.pixel_scale)
    used = _fitted_pixels(overview)
    width = float(np.median(overview.noise_map[used]))
    norm = _asinh_norm(overview.data, used, width)
    label = brightness_label(overview.unit)

    _image(axes[0, 0], figure, overview.data, extent, norm, "viridis", "data", label)
    _contaminants(axes[0, 0], overview, extent)
    _fit_circle(axes[0, 0], overview, "white")

    _image(
        axes[0, 1], figure, overview.lens_light, extent, norm, "viridis", "lens light ⊗ PSF", label
    )
    _fit_circle(axes[0, 1], overview, "0.3")

    _source_panel(axes[0, 2], figure, overview, label)

    residual_norm = colors.Normalize(-RESIDUAL_LIMIT, RESIDUAL_LIMIT)
    _image(
        axes[1, 0],
        figure,
        overview.normalized_residuals,
        extent,
        residual_norm,
        "RdBu_r",
        "normalised residuals (data − model)/σ",
        "σ",
    )
    _contaminants(axes[1, 0], overview, extent)
    _fit_circle(axes[1, 0], overview, "0.3")

    _contour_panel(axes[1, 1], figure, overview, label)
    _fit_circle(axes[1, 1], overview, "0.3")

    lensed_norm = _asinh_norm(overview.lensed_source, used, width)
    _image(
        axes[1, 2], figure, overview.lensed_source, extent, lensed_norm, "viridis",
        "lensed source ⊗ PSF", label,
    )  # fmt: skip
    _curve(axes[1, 2], overview.critical_curve, "critical curve")
    _fit_circle(axes[1, 2], overview, "0.3")
    figure.suptitle(overview.title)
    return figure

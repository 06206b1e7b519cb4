"""Per-lens isophote figure (`fig:isophotes_example`, SPEC §9.3).

Left: the lens-light image (log stretch, ``origin="lower"``, x/y in arcsec) with a subset
of the isophotes, their fitted ellipses and, when given, the tangential critical curve and
its ellipse. Right: q(a), PA(a) and a₄/a(a) against the semi-major axis a, with the
mass model's q and φ (and their 3σ intervals), the critical-curve ellipse's q and PA, the
effective Einstein radius and the statistics range 0.5″–2.5″ marked.
"""

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from mgelens.ellipse_fit import Ellipse, IsophoteError
from mgelens.grid import pixel_centres
from mgelens.isophotes import (
    ROUND_AXIS_RATIO,
    STATISTICS_SMA_RANGE,
    MassShape,
    closed_contour,
    contour_generator,
    unwrap_position_angles,
)

LIGHT_COLOUR = "tab:blue"
MASS_COLOUR = "tab:red"
CRITICAL_COLOUR = "tab:green"


def _nearest_turn(angle: float, reference: float) -> float:
    """``angle`` moved by a multiple of 180° to lie within ±90° of ``reference``."""
    return angle - 180.0 * np.round((angle - reference) / 180.0)


def _show_image(
    ax: Axes,
    image: np.ndarray,
    pixel_scale: float,
    table: pd.DataFrame,
    mass: MassShape | None,
    centre: tuple[float, float],
    half_width: float,
    n_isophotes: int,
    origin: tuple[float, float],
):
    """Draw the image panel; returns the image artist (for its colour bar)."""
    x, y = pixel_centres(image.shape, pixel_scale, origin)
    positive = image[np.isfinite(image) & (image > 0.0)]
    if len(table):
        floor = table["level"].min() / 3.0
    else:
        floor = positive.min() if positive.size else 1.0
    shown = np.log10(np.clip(np.nan_to_num(image, nan=floor), floor, None))
    half = 0.5 * pixel_scale
    artist = ax.imshow(
        shown,
        origin="lower",
        cmap="gray_r",
        extent=(x[0, 0] - half, x[0, -1] + half, y[0, 0] - half, y[-1, 0] + half),
    )
    if len(table):
        generator = contour_generator(image, pixel_scale, origin)
        table = table.iloc[np.unique(np.linspace(0, len(table) - 1, n_isophotes).astype(int))]
    for row in table.itertuples():
        try:
            contour = closed_contour(generator, row.level, (row.x0, row.y0))
        except IsophoteError:
            continue
        ax.plot(*np.vstack([contour, contour[:1]]).T, color=LIGHT_COLOUR, linewidth=0.8)
        ex, ey = Ellipse(row.x0, row.y0, row.sma, row.q, row.pa).points()
        ax.plot(ex, ey, color="tab:orange", linewidth=0.8, linestyle="--")
    if mass is not None and mass.critical_curve is not None:
        ax.plot(*mass.critical_curve, color=CRITICAL_COLOUR, linewidth=1.2, label="critical curve")
        if mass.critical_curve_ellipse is not None:
            ax.plot(*mass.critical_curve_ellipse.points(), color=CRITICAL_COLOUR, linestyle=":")
        ax.legend(loc="upper right", fontsize="small")
    ax.set_xlim(centre[0] - half_width, centre[0] + half_width)
    ax.set_ylim(centre[1] - half_width, centre[1] + half_width)
    ax.set_aspect("equal")
    ax.set_xlabel("x [arcsec]")
    ax.set_ylabel("y [arcsec]")
    return artist


def _mark_radii(ax: Axes, mass: MassShape | None) -> None:
    """Shade a outside the statistics range; mark the Einstein radius."""
    ax.axvspan(0.0, STATISTICS_SMA_RANGE[0], color="0.92", zorder=0)
    ax.axvspan(STATISTICS_SMA_RANGE[1], 1e3, color="0.92", zorder=0)
    if mass is not None and mass.critical_curve_einstein_radius is not None:
        ax.axvline(
            mass.critical_curve_einstein_radius,
            color=CRITICAL_COLOUR,
            linestyle="-.",
            linewidth=1.0,
            label="Einstein radius",
        )


def _plot_axis_ratio(ax: Axes, table: pd.DataFrame, mass: MassShape | None) -> None:
    ax.errorbar(
        table["sma"],
        table["q"],
        yerr=table["q_err"],
        fmt="o",
        markersize=3,
        color=LIGHT_COLOUR,
        label="light isophotes",
    )
    if mass is not None:
        ax.axhline(mass.axis_ratio, color=MASS_COLOUR, label="mass model")
        if mass.axis_ratio_interval is not None:
            ax.axhspan(*mass.axis_ratio_interval, color=MASS_COLOUR, alpha=0.2)
        if mass.critical_curve_ellipse is not None:
            ax.axhline(
                mass.critical_curve_ellipse.axis_ratio,
                color=CRITICAL_COLOUR,
                linestyle="--",
                label="critical curve",
            )
    ax.set_ylabel("q = b/a")


def _plot_angle(ax: Axes, table: pd.DataFrame, mass: MassShape | None) -> None:
    oriented = table[table["q"] <= ROUND_AXIS_RATIO]
    angles = unwrap_position_angles(oriented["pa"].to_numpy())
    ax.errorbar(
        oriented["sma"], angles, yerr=oriented["pa_err"], fmt="o", markersize=3, color=LIGHT_COLOUR
    )
    reference = float(np.median(angles)) if angles.size else 90.0
    if mass is not None:
        shift = _nearest_turn(mass.angle, reference) - mass.angle
        ax.axhline(mass.angle + shift, color=MASS_COLOUR)
        if mass.angle_interval is not None:
            ax.axhspan(
                mass.angle_interval[0] + shift,
                mass.angle_interval[1] + shift,
                color=MASS_COLOUR,
                alpha=0.2,
            )
        if mass.critical_curve_ellipse is not None:
            ax.axhline(
                _nearest_turn(mass.critical_curve_ellipse.angle, reference),
                color=CRITICAL_COLOUR,
                linestyle="--",
            )
    ax.set_ylabel("PA [deg]")


def _plot_a4(ax: Axes, table: pd.DataFrame) -> None:
    ax.axhline(0.0, color="0.5", linewidth=0.8)
    ax.errorbar(
        table["sma"],
        table["a4_a"],
        yerr=table["a4_a_err"],
        fmt="o",
        markersize=3,
        color=LIGHT_COLOUR,
    )
    ax.set_ylabel("a₄/a (> 0 disky)")


def _plot_source_share(ax: Axes, table: pd.DataFrame) -> None:
    ax.plot(table["sma"], table["source_share"], "o", markersize=3, color=LIGHT_COLOUR)
    ax.set_ylim(bottom=0.0)
    ax.set_ylabel("lensed source /\nlens light")


def isophote_figure(
    image: np.ndarray,
    pixel_scale: float,
    table: pd.DataFrame,
    mass: MassShape | None = None,
    centre: tuple[float, float] | None = None,
    half_width: float = 3.0,
    n_isophotes: int = 8,
    origin: tuple[float, float] = (0.0, 0.0),
    title: str | None = None,
    unit: str = "",
) -> Figure:
    """The per-lens isophote figure.

    Parameters
    ----------
    image : ndarray (n_y, n_x)
        Lens-light image (row index increasing with +y), e.g. the PSF-convolved model,
        possibly with noise added for display.
    pixel_scale : float
        Δ, arcsec per pixel.
    table : pandas.DataFrame
        :func:`mgelens.isophotes.isophote_table` of the image.
    mass : MassShape, optional
        Mass-model q, φ (3σ intervals), critical curve and Einstein radius.
    centre : (x, y) arcsec, optional
        Centre of the image panel; default the centre of the innermost isophote.
    half_width : float
        The image panel shows ±``half_width`` arcsec around ``centre``.
    n_isophotes : int
        Number of isophotes (and ellipses) drawn on the image.
    origin : (x, y) arcsec
        Grid origin of ``image`` (SPEC §1.1).
    title : str, optional
    unit : str
        Brightness unit of ``image`` per pixel, for the colour bar ("" = data units).

    Returns
    -------
    matplotlib.figure.Figure
    """
    if centre is None:
        centre = (
            (float(table["x0"].iloc[0]), float(table["y0"].iloc[0])) if len(table) else (0.0, 0.0)
        )
    with_share = "source_share" in table
    figure = Figure(figsize=(11.0, 7.0 if with_share else 5.5), layout="constrained")
    grid = figure.add_gridspec(4 if with_share else 3, 2, width_ratios=(1.15, 1.0))
    image_ax = figure.add_subplot(grid[:, 0])
    q_ax = figure.add_subplot(grid[0, 1])
    profile_axes = [q_ax] + [figure.add_subplot(grid[k, 1], sharex=q_ax) for k in (1, 2)]
    if with_share:
        profile_axes.append(figure.add_subplot(grid[3, 1], sharex=q_ax))
    pa_ax, a4_ax = profile_axes[1:3]
    artist = _show_image(
        image_ax, image, pixel_scale, table, mass, centre, half_width, n_isophotes, origin
    )
    figure.colorbar(
        artist,
        ax=image_ax,
        shrink=0.8,
        label=f"log₁₀ lens light [{unit or 'data units'} per pixel]",
    )
    _plot_axis_ratio(q_ax, table, mass)
    _plot_angle(pa_ax, table, mass)
    _plot_a4(a4_ax, table)
    if with_share:
        _plot_source_share(profile_axes[3], table)
    upper = float(table["sma"].max()) * 1.05 if len(table) else 3.0
    for ax in profile_axes:
        _mark_radii(ax, mass)
        ax.set_xlim(0.0, upper)
    for ax in profile_axes[:-1]:
        ax.tick_params(labelbottom=False)
    profile_axes[-1].set_xlabel("semi-major axis a [arcsec]")
    q_ax.legend(fontsize="small")
    if title is not None:
        figure.suptitle(title)
    return figure

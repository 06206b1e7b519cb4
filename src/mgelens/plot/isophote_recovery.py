"""A mock's fitted isophotes against its true ones (:mod:`mgelens.isophote_recovery`).

Top row: q(a), PA(a) and a₄/a(a) of the fitted lens light (markers) and of the true lens
light (line), each measured by the same isophote analysis, with the tolerance band about
the truth over the compared range 0.5–2.5″ and the range outside it shaded. Bottom row:
fitted − true at the comparison radii with the tolerances dashed. The semi-major axis a
is in arcsec on a log axis.
"""

from dataclasses import asdict

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.ticker import FixedLocator, FormatStrFormatter, NullFormatter

from mgelens.isophote_recovery import ISOPHOTE_TOLERANCES, IsophoteTolerances
from mgelens.isophotes import ROUND_AXIS_RATIO, STATISTICS_SMA_RANGE, unwrap_position_angles

SMA_TICKS = (0.1, 0.2, 0.3, 0.5, 1.0, 2.0, 3.0, 5.0)
"""Labelled semi-major axes (arcsec) on the log axis."""
FIT_COLOUR = "tab:blue"
TRUE_COLOUR = "black"

_QUANTITIES = (
    ("q", "axis_ratio", "q = b/a", ""),
    ("pa", "angle", "PA [deg]", "°"),
    ("a4_a", "a4_over_a", "a₄/a", ""),
)
"""(table column and profile prefix, tolerance field, axis label, unit) per panel column."""


def _oriented(table: pd.DataFrame, column: str) -> pd.DataFrame:
    """The table's rows for ``column``: PA only where the isophote is not round."""
    if column != "pa":
        return table
    return table[table["q"] <= ROUND_AXIS_RATIO]


def _angles_near(angles: np.ndarray, reference: float) -> np.ndarray:
    """Unwrapped axis angles moved as a whole by k·180° to start within ±90° of ``reference``."""
    unwrapped = unwrap_position_angles(angles)
    if unwrapped.size:
        unwrapped -= 180.0 * np.round((unwrapped[0] - reference) / 180.0)
    return unwrapped


def isophote_recovery_figure(
    fitted: pd.DataFrame,
    true: pd.DataFrame,
    profile: pd.DataFrame,
    lens: str,
    tolerances: IsophoteTolerances = ISOPHOTE_TOLERANCES,
) -> Figure:
    """Fitted against true isophote profiles of one mock (see the module docstring).

    ``fitted`` and ``true`` are isophote tables (:func:`mgelens.isophotes.isophote_table`);
    ``profile`` is their :func:`~mgelens.isophote_recovery.compare_isophotes`.
    """
    figure = Figure(figsize=(12.0, 6.0), layout="constrained")
    axes = figure.subplots(2, 3, sharex=True, height_ratios=(2, 1))
    limits = asdict(tolerances)
    inside = (profile["sma"] >= STATISTICS_SMA_RANGE[0]) & (
        profile["sma"] <= STATISTICS_SMA_RANGE[1]
    )
    for k, (column, field, label, unit) in enumerate(_QUANTITIES):
        top, bottom = axes[0, k], axes[1, k]
        true_rows, fit_rows = _oriented(true, column), _oriented(fitted, column)
        true_values = true_rows[column].to_numpy(dtype=float)
        fit_values = fit_rows[column].to_numpy(dtype=float)
        band = profile[f"{column}_true"].to_numpy(dtype=float)
        if column == "pa":
            reference = float(np.nanmedian(band)) if np.isfinite(band).any() else 90.0
            true_values = _angles_near(true_values, reference)
            fit_values = _angles_near(fit_values, reference)
            band = band - 180.0 * np.round((band - reference) / 180.0)
        top.plot(true_rows["sma"], true_values, color=TRUE_COLOUR, label="true lens light")
        top.plot(
            fit_rows["sma"],
            fit_values,
            "o",
            markersize=3,
            color=FIT_COLOUR,
            label="fitted lens light",
        )
        top.fill_between(
            profile["sma"][inside],
            (band - limits[field])[inside],
            (band + limits[field])[inside],
            color=TRUE_COLOUR,
            alpha=0.15,
            linewidth=0,
            label=f"truth ± {limits[field]:g}{unit}",
        )
        top.set_ylabel(label)
        error = profile[f"{column}_error"].to_numpy(dtype=float)
        bottom.plot(profile["sma"], error, "o-", markersize=3, color=FIT_COLOUR)
        for sign in (-1.0, 1.0):
            bottom.axhline(sign * limits[field], color=TRUE_COLOUR, linestyle="--", linewidth=0.8)
        bottom.axhline(0.0, color="0.6", linewidth=0.6)
        bottom.set_ylabel("fitted − true [deg]" if column == "pa" else "fitted − true")
        bottom.set_xlabel("semi-major axis a [arcsec]")
        for ax in (top, bottom):
            ax.set_xscale("log")
            ax.xaxis.set_major_locator(FixedLocator(SMA_TICKS))
            ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.axvspan(1e-3, STATISTICS_SMA_RANGE[0], color="0.92", zorder=0)
            ax.axvspan(STATISTICS_SMA_RANGE[1], 1e3, color="0.92", zorder=0)
    sma = pd.concat([fitted["sma"], true["sma"]])
    if len(sma):
        axes[0, 0].set_xlim(0.8 * sma.min(), 1.25 * sma.max())
    axes[0, 0].legend(loc="best", fontsize="small")
    figure.suptitle(f"{lens}: isophotes of the fitted lens light against the truth")
    return figure

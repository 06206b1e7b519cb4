"""Our Einstein radii against published SLACS models (SPEC §3.3, :mod:`mgelens.published`).

Two panels of a :func:`mgelens.summary.lens_table`: our θ_E^LT (MASS posterior median with
1σ errors, converted from θ_E^AG) against Bolton et al. 2008's b_SIE, and against Shajib et
al. 2021's imaging-only power-law θ_E (with their 1σ errors). Each panel has the 1:1 line,
a ±5 % band, the names of lenses off by more than 10 %, fits flagged by the residuals
(``quality_flag``) circled in red and by the lensing check (``lensing_flag``) boxed in
orange, and the least-squares slope of
y = a·x (:func:`mgelens.published.slope_through_origin`). A panel without published values
says so.
"""

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from mgelens.published import slope_text, slope_through_origin

BAND = 0.05
"""Half-width of the shaded band about 1:1 (fraction)."""
OUTLIER = 0.10
"""Relative difference beyond which a lens is named."""
FLAG_MARKERS = (
    ("quality_flag", "o", "tab:red", "residuals flagged"),
    ("lensing_flag", "s", "tab:orange", "lensing flagged"),
)
"""(table column, marker, colour, legend label) of the flagged fits' outlines."""
PANELS = (
    ("bolton_b_sie", None, r"Bolton et al. 2008 $b_{\rm SIE}$ [arcsec]"),
    (
        "shajib_theta_e",
        "shajib_theta_e",
        r"Shajib et al. 2021 $\theta_{\rm E}$ (imaging only) [arcsec]",
    ),
)


def _panel(ax: Axes, table: pd.DataFrame, column: str, errors: str | None, label: str) -> None:
    ax.set_xlabel(label)
    ax.set_ylabel(r"mgelens $\theta_{\rm E}^{\rm LT}$ [arcsec]")
    rows = table[np.isfinite(table[column]) & np.isfinite(table["theta_e_lt"])]
    if rows.empty:
        ax.text(0.5, 0.5, "no published values", transform=ax.transAxes, ha="center")
        return
    x, y = rows[column].to_numpy(float), rows["theta_e_lt"].to_numpy(float)
    lo, hi = 0.9 * min(x.min(), y.min()), 1.1 * max(x.max(), y.max())
    line = np.array([lo, hi])
    ax.fill_between(line, (1 - BAND) * line, (1 + BAND) * line, color="0.85", label="±5 %")
    ax.plot(line, line, color="k", linewidth=0.8, label="1:1")
    xerr = None
    if errors is not None:
        xerr = rows[[f"{errors}_err_lo", f"{errors}_err_hi"]].to_numpy(float).T
    yerr = rows[["theta_e_lt_err_lo", "theta_e_lt_err_hi"]].to_numpy(float).T
    ax.errorbar(x, y, xerr=xerr, yerr=yerr, fmt="o", markersize=4, color="tab:blue")
    for flag, marker, colour, name in FLAG_MARKERS:
        if flag in rows:
            flagged = rows[flag].fillna(False).to_numpy(bool)
            if flagged.any():
                ax.plot(x[flagged], y[flagged], marker, mfc="none", mec=colour, ms=9, label=name)
    for lens, xi, yi in zip(rows["lens"], x, y, strict=True):
        if abs(yi / xi - 1.0) > OUTLIER:
            ax.annotate(lens, (xi, yi), textcoords="offset points", xytext=(4, 4), fontsize=7)
    ax.text(
        0.04,
        0.96,
        f"y = a·x: {slope_text(*slope_through_origin(x, y))}",
        transform=ax.transAxes,
        va="top",
        fontsize=9,
    )
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_aspect("equal")
    # upper left, under the slope: above the band, where only overestimates would lie
    ax.legend(loc="upper left", bbox_to_anchor=(0.02, 0.91), fontsize=8)


def einstein_radius_figure(table: pd.DataFrame) -> Figure:
    """The two comparison panels of a lens table with published columns.

    ``table`` needs ``lens``, ``theta_e_lt`` with ``theta_e_lt_err_lo``/``_err_hi``,
    ``bolton_b_sie``, ``shajib_theta_e`` and ``shajib_theta_e_err_lo``/``_err_hi``.
    """
    figure = Figure(figsize=(10.0, 5.0), layout="constrained")
    for ax, (column, errors, label) in zip(figure.subplots(1, 2), PANELS, strict=True):
        _panel(ax, table, column, errors, label)
    return figure

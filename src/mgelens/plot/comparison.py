"""Our Einstein radii and slopes against published SLACS models (SPEC §3.3,
:mod:`mgelens.published`).

Two panels of a :func:`mgelens.summary.lens_table`: our θ_E^LT (MASS posterior median with
1σ errors, converted from θ_E^AG) against Bolton et al. 2008's b_SIE, and against Shajib et
al. 2021's imaging-only power-law θ_E (with their 1σ errors). Each panel has the 1:1 line,
a ±5 % band, the names of lenses off by more than 10 %, fits flagged by the residuals
(``quality_flag``) circled in red, by the lensing check (``lensing_flag``) boxed in
orange, singly imaged ones (``singly_imaged_flag``) in purple diamonds, lenses whose
MASS did not converge (``mass_converged`` false) in grey crosses and those whose MASS
interval a prior bound cuts (``prior_edge``) in brown triangles, and the least-squares
slope of
y = a·x (:func:`mgelens.published.slope_through_origin`). A panel without published values
says so. :func:`slope_figure` sets our γ against Shajib's in the same way, naming the
lenses whose slopes differ by more than :data:`mgelens.published.SLOPE_TENSION` combined
errors.
"""

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from mgelens.published import SLOPE_TENSION, slope_differences, slope_text, slope_through_origin
from mgelens.search.results import names_a_prior_edge

BAND = 0.05
"""Half-width of the shaded band about 1:1 (fraction)."""
OUTLIER = 0.10
"""Relative difference beyond which a lens is named."""
FLAG_MARKERS = (
    ("quality_flag", "o", "tab:red", "residuals flagged"),
    ("lensing_flag", "s", "tab:orange", "lensing flagged"),
    ("singly_imaged_flag", "D", "tab:purple", "singly imaged"),
    ("mass_unconverged", "X", "tab:gray", "MASS not converged"),
    ("at_prior_edge", "^", "tab:brown", "MASS at a prior bound"),
)
"""(flag, marker, colour, legend label) of the flagged fits' outlines: a table column,
``mass_unconverged`` (``mass_converged`` false) or ``at_prior_edge`` (``prior_edge``
names a parameter)."""
PANELS = (
    ("bolton_b_sie", None, r"Bolton et al. 2008 $b_{\rm SIE}$ [arcsec]"),
    (
        "shajib_theta_e",
        "shajib_theta_e",
        r"Shajib et al. 2021 $\theta_{\rm E}$ (imaging only) [arcsec]",
    ),
)


def _outline_flagged(ax: Axes, rows: pd.DataFrame, x: np.ndarray, y: np.ndarray) -> None:
    """Outline the points of fits flagged by each of :data:`FLAG_MARKERS`."""
    if "mass_converged" in rows:
        rows = rows.assign(mass_unconverged=rows["mass_converged"].eq(False))
    if "prior_edge" in rows:
        rows = rows.assign(at_prior_edge=names_a_prior_edge(rows["prior_edge"]))
    for flag, marker, colour, name in FLAG_MARKERS:
        if flag in rows:
            flagged = rows[flag].fillna(False).to_numpy(bool)
            if flagged.any():
                ax.plot(x[flagged], y[flagged], marker, mfc="none", mec=colour, ms=9, label=name)


def _square_with_note(ax: Axes, lo: float, hi: float, note: str, fontsize: int) -> None:
    """Equal axes over [lo, hi] on both, and ``note`` in the upper left corner."""
    ax.text(0.04, 0.96, note, transform=ax.transAxes, va="top", fontsize=fontsize)
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_aspect("equal")


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
    _outline_flagged(ax, rows, x, y)
    for lens, xi, yi in zip(rows["lens"], x, y, strict=True):
        if abs(yi / xi - 1.0) > OUTLIER:
            ax.annotate(lens, (xi, yi), textcoords="offset points", xytext=(4, 4), fontsize=7)
    _square_with_note(ax, lo, hi, f"y = a·x: {slope_text(*slope_through_origin(x, y))}", 9)
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


SLOPE_RANGE = (1.5, 2.7)
"""Smallest γ range of the slope figure's axes (widened to hold every point)."""


def slope_figure(table: pd.DataFrame) -> Figure:
    """Our MASS γ (median, 1σ) against Shajib et al. 2021's imaging-only γ (1σ), with the
    1:1 line, the flagged fits outlined as in :func:`einstein_radius_figure`, the lenses
    in tension named (:func:`mgelens.published.slope_differences`) and the mean
    difference printed; "no published slopes" when the table has none.

    ``table`` needs ``lens``, ``slope`` with ``slope_err_lo``/``_err_hi`` and
    ``shajib_gamma`` with ``shajib_gamma_err_lo``/``_err_hi``.
    """
    figure = Figure(figsize=(5.5, 5.0), layout="constrained")
    ax = figure.subplots()
    ax.set_xlabel(r"Shajib et al. 2021 $\gamma$ (imaging only)")
    ax.set_ylabel(r"mgelens $\gamma$ (MASS)")
    differences = slope_differences(table)
    if differences.empty:
        ax.text(0.5, 0.5, "no published slopes", transform=ax.transAxes, ha="center")
        return figure
    rows = table.loc[differences.index]
    x, y = rows["shajib_gamma"].to_numpy(float), rows["slope"].to_numpy(float)
    lo = min(SLOPE_RANGE[0], x.min() - 0.1, y.min() - 0.1)
    hi = max(SLOPE_RANGE[1], x.max() + 0.1, y.max() + 0.1)
    ax.plot([lo, hi], [lo, hi], color="k", linewidth=0.8, label="1:1")
    xerr = rows[["shajib_gamma_err_lo", "shajib_gamma_err_hi"]].to_numpy(float).T
    yerr = rows[["slope_err_lo", "slope_err_hi"]].to_numpy(float).T
    ax.errorbar(x, y, xerr=xerr, yerr=yerr, fmt="o", markersize=4, color="tab:blue")
    _outline_flagged(ax, rows, x, y)
    for (lens, tension, difference, sigma), xi, yi in zip(
        differences[["lens", "tension", "difference", "sigma"]].itertuples(index=False),
        x,
        y,
        strict=True,
    ):
        if tension:
            text = f"{lens} ({difference / sigma:+.1f}σ)"
            ax.annotate(text, (xi, yi), textcoords="offset points", xytext=(4, 4), fontsize=7)
    note = (
        f"mean γ − γ_Shajib = {differences['difference'].mean():+.3f} ({len(rows)} "
        f"{'lens' if len(rows) == 1 else 'lenses'}); named: beyond {SLOPE_TENSION:g}σ"
    )
    _square_with_note(ax, lo, hi, note, 8)
    ax.legend(loc="lower right", fontsize=8)
    return figure

"""Sample histograms of the isophote statistics (the paper's three panels).

Panels: Δq_max, ΔPA_max (degrees) and max |a₄/a| over 0.5″ ≤ a ≤ 2.5″, one entry per lens
of a :func:`mgelens.summary.sample_table`; the complexity thresholds and |a₄/a| = 0.02 are
drawn as dashed lines. The title gives the fraction of complex lenses and the a₄ panel the
fraction below 0.02, each next to the paper's (SPEC §11: ≈ 40 % of 35 complex, 32 of 35
with max |a₄/a| < 0.02).
"""

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from mgelens.summary import DELTA_PA_THRESHOLD, DELTA_Q_THRESHOLD, complex_fraction

A4_THRESHOLD = 0.02
"""max |a₄/a| below which the paper counts a lens as neither boxy nor disky."""
PAPER_COMPLEX_FRACTION = 0.40
"""The paper's fraction of complex lenses (Δq_max > 0.1 or ΔPA_max > 10°), of 35."""
PAPER_A4_BELOW = (32, 35)
"""The paper's lenses with max |a₄/a| < :data:`A4_THRESHOLD`, of those measured."""

PANELS = (
    ("delta_q_max", "max Δq"),
    ("delta_pa_max", "max ΔPA [deg]"),
    ("abs_a4_a_max", "max |a₄/a|"),
)


def _histogram(ax: Axes, values: np.ndarray, label: str, threshold: float | None) -> None:
    values = values[np.isfinite(values)]
    if values.size:
        ax.hist(values, bins="auto", color="tab:blue", edgecolor="white")
    else:
        ax.text(0.5, 0.5, "no data", transform=ax.transAxes, ha="center", va="center")
    if threshold is not None:
        ax.axvline(threshold, color="tab:red", linestyle="--", linewidth=1.0)
    ax.set_xlabel(label)
    ax.set_ylabel("lenses")
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))  # counts


def histogram_figure(
    table: pd.DataFrame,
    delta_q_threshold: float = DELTA_Q_THRESHOLD,
    delta_pa_threshold: float = DELTA_PA_THRESHOLD,
) -> Figure:
    """Histograms of Δq_max, ΔPA_max and max |a₄/a| of a sample table.

    Parameters
    ----------
    table : pandas.DataFrame
        :func:`mgelens.summary.sample_table`.
    delta_q_threshold, delta_pa_threshold : float
        Complexity thresholds (ΔPA in degrees), drawn and used for the quoted fraction.

    Returns
    -------
    matplotlib.figure.Figure
    """
    figure = Figure(figsize=(11.0, 3.6), layout="constrained")
    axes = figure.subplots(1, 3)
    thresholds = (delta_q_threshold, delta_pa_threshold, A4_THRESHOLD)
    for ax, (column, label), threshold in zip(axes, PANELS, thresholds, strict=True):
        _histogram(ax, table[column].to_numpy(dtype=float), label, threshold)
    measured = int(np.count_nonzero(table["n_isophotes"] > 0))
    fraction = complex_fraction(table, delta_q_threshold, delta_pa_threshold)
    if measured:
        figure.suptitle(
            f"Δq > {delta_q_threshold:g} or ΔPA > {delta_pa_threshold:g}°: "
            f"{round(fraction * measured)}/{measured} lenses ({100.0 * fraction:.0f} %); "
            f"paper ≈ {100.0 * PAPER_COMPLEX_FRACTION:.0f} % of 35"
        )
    else:
        figure.suptitle("no lens with isophotes")
    a4 = table["abs_a4_a_max"].to_numpy(dtype=float)
    a4 = a4[np.isfinite(a4)]
    below, total = PAPER_A4_BELOW
    axes[2].set_title(
        f"max |a₄/a| < {A4_THRESHOLD:g}: {np.count_nonzero(a4 < A4_THRESHOLD)}/{a4.size}"
        f" (paper {below}/{total})",
        fontsize="medium",
    )
    return figure

"""ln ε against the mass slope (the paper's Appendix A figure; :mod:`mgelens.smoothness`).

One panel per source scheme of an :func:`mgelens.smoothness.appendix_a_table`: natural
neighbour + cross regularization, and nearest cell + neighbour regularization. Each
panel holds one curve per edge rule, ln ε − ln ε(γ_true) against γ − γ_true, with the
largest and the 95th-percentile jump in its legend. The schemes' ln ε differ by a
constant of no interest, so each curve is shown relative to its own value at the truth.
"""

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from mgelens.smoothness import SCHEMES, jump_summary

SCHEME_TITLES = {
    "natural_neighbour": "natural neighbour + cross regularization",
    "nearest": "nearest cell + neighbour regularization",
}
EDGE_RULE_STYLES = {
    "anchor": {"color": "tab:blue", "linestyle": "-"},
    "continuous": {"color": "tab:orange", "linestyle": "--"},
}


def smoothness_figure(table: pd.DataFrame, true_slope: float, label: str = "") -> Figure:
    """The figure of an Appendix A ``table`` scanned about ``true_slope``; ``label``
    (e.g. the mock's name) goes into the title."""
    summary = jump_summary(table).set_index(["scheme", "edge_rule"])
    schemes = [scheme for scheme in SCHEMES if scheme in set(table["scheme"])]
    figure = Figure(figsize=(5.2 * len(schemes), 4.2), layout="constrained")
    axes = figure.subplots(1, len(schemes), squeeze=False)[0]
    for ax, scheme in zip(axes, schemes, strict=True):
        for edge_rule, rows in table[table["scheme"] == scheme].groupby("edge_rule", sort=False):
            slope = rows["slope"].to_numpy(float)
            values = rows["log_evidence"].to_numpy(float)
            at_truth = values[np.argmin(np.abs(slope - true_slope))]
            jumps = summary.loc[(scheme, edge_rule)]
            ax.plot(
                slope - true_slope,
                values - at_truth,
                linewidth=1.0,
                label=(
                    f"{edge_rule} edges: largest jump {jumps['max_jump']:.2f}, "
                    f"95th pct. {jumps['p95_jump']:.2f}"
                ),
                **EDGE_RULE_STYLES.get(edge_rule, {}),
            )
        ax.axvline(0.0, color="0.6", linewidth=0.6)
        ax.xaxis.set_major_locator(MaxNLocator(5))
        ax.set_title(SCHEME_TITLES.get(scheme, scheme), fontsize=10)
        ax.set_xlabel(r"$\gamma - \gamma_{\rm true}$")
        ax.set_ylabel(r"$\ln\varepsilon - \ln\varepsilon(\gamma_{\rm true})$")
        ax.legend(fontsize=8, loc="lower center")
    title = r"Evidence against the slope, other parameters at the truth"
    figure.suptitle(f"{label}: {title}" if label else title, fontsize=11)
    return figure

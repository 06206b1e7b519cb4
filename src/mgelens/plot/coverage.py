"""Coverage figure (:mod:`mgelens.coverage`): the pull (median − truth)/σ of every mock
and mass parameter, σ the 1σ half-width on the side of the truth, with ±1 and ±3 marked,
mocks whose 3σ interval misses the truth in red and named, and the targets listed."""

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from mgelens.coverage import PARAMETERS

PULL_LIMIT = 10.0
"""Pulls beyond ±this are drawn at the limit (with a triangle) so the bulk stays legible."""

LABELS = {
    "mass.centre_x": "x",
    "mass.centre_y": "y",
    "mass.einstein_radius": "θ_E",
    "mass.axis_ratio": "q",
    "mass.angle": "φ",
    "mass.slope": "γ",
    "shear.gamma_1": "γ₁",
    "shear.gamma_2": "γ₂",
}


def coverage_figure(rows: pd.DataFrame, targets: pd.DataFrame, title: str = "") -> Figure:
    """Pulls per parameter (rows of :func:`~mgelens.coverage.coverage_rows`) and the
    targets (:func:`~mgelens.coverage.target_table`) as text."""
    figure = Figure(figsize=(11.0, 5.5), layout="constrained")
    ax = figure.add_subplot()
    names = [name for name in PARAMETERS if (rows["parameter"] == name).any()]
    rng = np.random.default_rng(0)
    for k, name in enumerate(names):
        part = rows[rows["parameter"] == name]
        pulls = part["pull"].to_numpy(dtype=float)
        shown = np.clip(pulls, -PULL_LIMIT, PULL_LIMIT)
        x = k + rng.uniform(-0.18, 0.18, len(part))
        missed = ~part["within_3sigma"].astype(bool).to_numpy()
        clipped = np.abs(pulls) > PULL_LIMIT
        for mask, colour in ((~missed, "tab:blue"), (missed, "tab:red")):
            ax.scatter(x[mask & ~clipped], shown[mask & ~clipped], s=14, color=colour)
            ax.scatter(x[mask & clipped], shown[mask & clipped], s=30, marker="^", color=colour)
        for xi, yi, lens in zip(x[missed], shown[missed], part["lens"][missed], strict=True):
            ax.annotate(
                lens,
                (xi, yi),
                xytext=(4, 2),
                textcoords="offset points",
                fontsize="x-small",
                color="tab:red",
            )
    for level, style in ((1.0, ":"), (3.0, "--")):
        for sign in (-1.0, 1.0):
            ax.axhline(sign * level, color="0.4", linestyle=style, linewidth=0.8)
    ax.axhline(0.0, color="0.6", linewidth=0.6)
    ax.set_xticks(range(len(names)), [LABELS[name] for name in names])
    ax.set_xlim(-0.6, len(names) - 0.4)
    ax.set_ylim(-PULL_LIMIT - 0.8, PULL_LIMIT + 0.8)
    ax.set_ylabel("(median − truth) / σ₁  [σ₁ = 1σ half-width toward the truth]")
    ax.set_xlabel("mass parameter (red: truth outside the 3σ interval)")
    lines = [
        f"{'✓' if row.met else '✗'} {row.target}: {row.fraction:.0%} "
        f"(goal {row.goal:.0%}, n={row.n})"
        for row in targets.itertuples()
    ]
    ax.text(1.01, 1.0, "\n".join(lines), transform=ax.transAxes, va="top", fontsize="small")
    lenses = rows["lens"].nunique()
    heading = f"Posterior coverage over {lenses} mock{'s' if lenses != 1 else ''}"
    seconds = rows.drop_duplicates("lens").get("chain_seconds")
    if seconds is not None and np.isfinite(seconds.to_numpy(dtype=float)).any():
        heading += f" (median chain {np.nanmedian(seconds.to_numpy(dtype=float)) / 60:.0f} min)"
    figure.suptitle(title or heading)
    return figure

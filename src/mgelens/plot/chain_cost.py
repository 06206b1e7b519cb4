"""Chain-cost figure (:mod:`mgelens.chain_cost`): each lens's CPU minutes as a bar split by
SLaM phase, the median of the complete chains marked, the sample's figures in the title."""

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from mgelens.chain_cost import CHAIN_PHASES

PHASE_LABELS = {"sp": "SP", "spix1": "SPix1", "spix2": "SPix2", "light": "LIGHT (all candidates)",
                "mass": "MASS"}  # fmt: skip


def cost_figure(table: pd.DataFrame, sample: dict) -> Figure:
    """Horizontal bars of :func:`~mgelens.chain_cost.cost_table` (CPU minutes per phase,
    stacked; a phase without a benchmark file adds nothing and its lens is marked
    "incomplete"; a lens with a job whose CPU time is Snakemake's sampled lower bound, not
    the job's own record, is marked "CPU ≥") with
    :func:`~mgelens.chain_cost.sample_cost`'s figures in the title."""
    height = 1.6 + 0.28 * max(len(table), 1)
    figure = Figure(figsize=(10.0, height), layout="constrained")
    ax = figure.add_subplot()
    y = np.arange(len(table))[::-1]
    left = np.zeros(len(table))
    for phase in CHAIN_PHASES:
        minutes = table[f"{phase}_cpu_s"].to_numpy(dtype=float) / 60.0
        minutes = np.nan_to_num(minutes)
        ax.barh(y, minutes, left=left, label=PHASE_LABELS[phase])
        left += minutes
    labels = [
        lens + ("" if complete else " (incomplete)") + ("" if exact else " (CPU ≥)")
        for lens, complete, exact in zip(
            table["lens"],
            table["complete"].astype(bool),
            table["cpu_exact"].astype(bool),
            strict=True,
        )
    ]
    ax.set_yticks(y, labels, fontsize="small")
    ax.set_xlabel("CPU time of the SLaM chain (core-minutes)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    if sample.get("n_complete"):
        ax.axvline(sample["median_cpu_min"], color="k", ls="--", lw=1)
        ax.set_title(
            f"{sample['n_complete']} complete chains of {sample['n_lenses']}: median "
            f"{sample['median_cpu_min']:.1f}, largest {sample['max_cpu_min']:.1f} "
            f"core-minutes ({sample['max_lens']}); in all {sample['total_cpu_h']:.2f} "
            f"core-hours.\nThe {sample['n_lenses']} lenses at the median (dashed): "
            f"{sample['projected_wall_h']:.1f} h on {sample['cores']} cores",
            fontsize="medium",
        )
    else:
        ax.set_title(f"no complete chain among {sample['n_lenses']} lenses", fontsize="medium")
    return figure

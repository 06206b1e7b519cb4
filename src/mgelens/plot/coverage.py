"""Coverage figure (:mod:`mgelens.coverage`): where each mock's truth lies against its
posterior intervals, per mass parameter, on a scale whose ±1 and ±3 are the 1σ and 3σ
limits on the truth's side (:func:`~mgelens.coverage.interval_pulls`), mocks whose 3σ
interval misses the truth in red and named, mocks whose fit a quality check flags drawn
open, and the targets listed."""

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from mgelens.coverage import FITS_UNFLAGGED, PARAMETERS, interval_pulls, known_flags
from mgelens.quality import NO_FLAG

PULL_LIMIT = 10.0
"""Pulls beyond ±this are drawn at the limit (with a triangle) so the bulk stays legible."""

LABEL_STEP_POINTS = 8.0
"""Vertical step (points) between the names of misses drawn at the same limit."""

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


def pull_axis_limit(pulls: np.ndarray) -> float:
    """Half-range of the pull axis: the largest |pull| shown (at most :data:`PULL_LIMIT`)
    plus a margin, and never less than 4 so that the ±3 lines always show."""
    largest = np.nanmax(np.abs(pulls), initial=0.0)
    return max(4.0, min(largest, PULL_LIMIT) + 0.8)


def target_line(row) -> str:
    """One target of :func:`~mgelens.coverage.target_table` as text: the count of mocks
    that pass, not a rounded percentage (18 of 19 is 94.7 %, short of a 95 % goal)."""
    fraction = f"{row.fraction:.1%}" if row.n else "no mocks"
    return (
        f"{'✓' if row.met else '✗'} {row.target}: {row.passed} of {row.n} ({fraction}; "
        f"goal ≥ {row.goal:.0%})"
    )


def target_text(targets: pd.DataFrame) -> str:
    """The targets of :func:`~mgelens.coverage.target_table` as lines of
    :func:`target_line`; those of :func:`~mgelens.coverage.targets_by_fits` over the
    unflagged fits under a heading of their own."""
    fits = targets["fits"] if "fits" in targets else pd.Series("", index=targets.index)
    lines = [target_line(row) for row in targets[fits != FITS_UNFLAGGED].itertuples()]
    unflagged = targets[fits == FITS_UNFLAGGED]
    if not unflagged.empty:
        lines += ["", f"Fits that no quality check flags ({unflagged['n'].max()} mocks):"]
        lines += [target_line(row) for row in unflagged.itertuples()]
    return "\n".join(lines)


def flagged_rows(rows: pd.DataFrame) -> np.ndarray:
    """Whether a quality check flags each row's fit (:func:`~mgelens.coverage.known_flags`;
    False where the mock has no quality record)."""
    flags = known_flags(rows)
    return (flags.notna() & (flags != NO_FLAG)).fillna(False).to_numpy(dtype=bool)


def chain_time_text(mocks: pd.DataFrame) -> str:
    """ " (median chain N CPU min)" over one row per mock, from ``chain_cpu_seconds`` where
    any is known (the cost on a shared host), else " (median chain N min)" of the
    wall-clock ``chain_seconds``; "" without either."""
    for column, unit in (("chain_cpu_seconds", "CPU min"), ("chain_seconds", "min")):
        seconds = mocks[column].to_numpy(dtype=float) if column in mocks else np.array([])
        if np.isfinite(seconds).any():
            return f" (median chain {np.nanmedian(seconds) / 60:.0f} {unit})"
    return ""


def coverage_figure(rows: pd.DataFrame, targets: pd.DataFrame, title: str = "") -> Figure:
    """Pulls per parameter (rows of :func:`~mgelens.coverage.coverage_rows`, with their
    quality ``flags`` if known) and the targets (:func:`~mgelens.coverage.target_table`
    or :func:`~mgelens.coverage.targets_by_fits`) as text."""
    figure = Figure(figsize=(11.0, 5.5), layout="constrained")
    ax = figure.add_subplot()
    names = [name for name in PARAMETERS if (rows["parameter"] == name).any()]
    all_pulls = interval_pulls(rows)
    all_flagged = flagged_rows(rows)
    rng = np.random.default_rng(0)
    for k, name in enumerate(names):
        of_name = (rows["parameter"] == name).to_numpy()
        part, pulls, flagged = rows[of_name], all_pulls[of_name], all_flagged[of_name]
        shown = np.clip(pulls, -PULL_LIMIT, PULL_LIMIT)
        x = k + rng.uniform(-0.18, 0.18, len(part))
        missed = ~part["within_3sigma"].astype(bool).to_numpy()
        clipped = np.abs(pulls) > PULL_LIMIT
        colours = np.where(missed, "tab:red", "tab:blue")
        faces = np.where(flagged, "none", colours)
        for shape, size, drawn in (("o", 14, ~clipped), ("^", 30, clipped)):
            ax.scatter(
                x[drawn], shown[drawn], s=size, marker=shape, facecolors=faces[drawn],
                edgecolors=colours[drawn],
            )  # fmt: skip
        stacked = {-1.0: 0, 1.0: 0}
        for xi, yi, lens, beyond in zip(
            x[missed], shown[missed], part["lens"][missed], clipped[missed], strict=True
        ):
            # names of misses clipped at the same limit are stacked toward the axis centre
            rank = stacked[np.sign(yi)] if beyond else 0
            stacked[np.sign(yi)] += int(beyond)
            ax.annotate(
                lens,
                (xi, yi),
                xytext=(5, 3 - np.sign(yi) * LABEL_STEP_POINTS * rank),
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
    limit = pull_axis_limit(all_pulls)
    ax.set_ylim(-limit, limit)
    ax.set_ylabel(
        "median − truth, in the posterior's intervals\n(±1, ±3: its 1σ, 3σ limits toward the truth)"
    )
    legend = "red: truth outside the 3σ interval"
    if all_flagged.any():
        legend += "; open: a quality check flags the fit"
    ax.set_xlabel(f"mass parameter ({legend})")
    ax.text(1.01, 1.0, target_text(targets), transform=ax.transAxes, va="top", fontsize="small")
    lenses = rows["lens"].nunique()
    heading = f"Posterior coverage over {lenses} mock{'s' if lenses != 1 else ''}"
    heading += chain_time_text(rows.drop_duplicates("lens"))
    figure.suptitle(title or heading)
    return figure

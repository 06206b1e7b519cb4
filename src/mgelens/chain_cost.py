"""What each lens's SLaM chain cost (issue #28): CPU and wall-clock time per phase from the
rules' Snakemake ``benchmark:`` files, likelihood calls from the phases' records.

A lens's folder ``results/<lens>/`` holds ``benchmarks/<phase>.tsv`` for every phase job
(Snakemake's columns: ``s`` wall-clock seconds, ``cpu_time`` CPU seconds, ``max_rss`` MB,
…) and ``<phase>/result.json`` with the sampler's ``n_calls``. The chain's phases are SP,
SPix1, SPix2, every LIGHT candidate (``light_x6_point`` …, or ``light`` where the sheet
pins the model) and MASS (:data:`CHAIN_PHASES`); rule ``choose_light``, the mock's
simulation and the analysis rules are not part of it. A benchmark file records the last
run of its job: a phase resumed after an interruption counts its last run only.
"""

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

CHAIN_PHASES = ("sp", "spix1", "spix2", "light", "mass")
"""The SLaM phases, in order; a benchmark file ``<phase>*.tsv`` whose stem starts with one
of them (before any ``_``) belongs to it (``light_x6_point`` to ``light``)."""

BENCHMARK_COLUMNS = ("s", "cpu_time", "max_rss")
"""Columns of a Snakemake benchmark file that the costs read."""

START_FILE = "start.json"
"""SP's start record (:mod:`mgelens.pipeline.sp_start`): its search's calls count among
SP's (also where a rerun of SP reused the record instead of searching again)."""


@dataclass(frozen=True)
class JobCost:
    """One phase job of a lens's chain.

    Attributes
    ----------
    job : str
        The benchmark file's stem: the phase's folder (``sp``, ``light_x6_point`` …).
    phase : str
        Its phase (:data:`CHAIN_PHASES`).
    wall_s, cpu_s : float
        Wall-clock and CPU seconds (``s``, ``cpu_time``).
    max_rss_mb : float
        Peak resident memory (MB).
    calls : float
        Likelihood calls of its sampler, and for SP of its start search; NaN where the
        phase's ``result.json`` is absent.
    """

    job: str
    phase: str
    wall_s: float
    cpu_s: float
    max_rss_mb: float
    calls: float


def phase_of(job: str) -> str | None:
    """The chain phase of a benchmark stem, or None for a job outside the chain."""
    phase = job.split("_")[0]
    return phase if phase in CHAIN_PHASES else None


def _benchmark(path: Path) -> dict[str, float]:
    """Sums of :data:`BENCHMARK_COLUMNS` (max for ``max_rss``) over the rows of one
    benchmark file (one row per repeat)."""
    try:
        table = pd.read_csv(path, sep="\t")
    except (OSError, ValueError) as error:
        raise ValueError(f"{path}: not a Snakemake benchmark file ({error})") from error
    missing = [name for name in BENCHMARK_COLUMNS if name not in table.columns]
    if missing or table.empty:
        raise ValueError(
            f"{path}: a Snakemake benchmark file needs a row with columns "
            f"{', '.join(BENCHMARK_COLUMNS)} (missing: {', '.join(missing) or 'rows'}); "
            "delete it and rerun the phase to record it again"
        )
    values = table[list(BENCHMARK_COLUMNS)].apply(pd.to_numeric, errors="coerce")
    return {
        "s": float(values["s"].sum()),
        "cpu_time": float(values["cpu_time"].sum()),
        "max_rss": float(values["max_rss"].max()),
    }


def _calls(lens_folder: Path, job: str) -> float:
    """Sampler calls in ``<job>/result.json`` (plus SP's start search); NaN without it."""
    record = lens_folder / job / "result.json"
    if not record.is_file():
        return np.nan
    try:
        calls = float(json.loads(record.read_text())["sampler"]["n_calls"])
        start = lens_folder / job / START_FILE
        if job == "sp" and start.is_file():
            calls += float(json.loads(start.read_text())["start"]["n_calls"])
    except (json.JSONDecodeError, KeyError, TypeError) as error:
        raise ValueError(f"{record}: no sampler calls to read ({error!r})") from error
    return calls


def job_costs(lens_folder: Path) -> list[JobCost]:
    """The chain's jobs of one lens folder (``results/<lens>``) with a benchmark file, in
    the order of :data:`CHAIN_PHASES`, then by name.

    Raises
    ------
    ValueError
        For a benchmark file or a phase record that cannot be read, naming it.
    """
    lens_folder = Path(lens_folder)
    costs = []
    for path in sorted((lens_folder / "benchmarks").glob("*.tsv")):
        phase = phase_of(path.stem)
        if phase is None:
            continue
        measured = _benchmark(path)
        costs.append(
            JobCost(
                path.stem,
                phase,
                measured["s"],
                measured["cpu_time"],
                measured["max_rss"],
                _calls(lens_folder, path.stem),
            )
        )
    return sorted(costs, key=lambda cost: (CHAIN_PHASES.index(cost.phase), cost.job))


def chain_seconds(lens_folder: Path) -> float:
    """Wall-clock seconds of a lens's chain (the sum over :func:`job_costs`); NaN with no
    benchmark file."""
    costs = job_costs(lens_folder)
    return float(sum(cost.wall_s for cost in costs)) if costs else np.nan


COST_COLUMNS = (
    "lens",
    *(f"{phase}_cpu_s" for phase in CHAIN_PHASES),
    *(f"{phase}_calls" for phase in CHAIN_PHASES),
    "chain_cpu_min",
    "chain_wall_min",
    "max_rss_mb",
    "complete",
)
"""Columns of :func:`cost_table`: per phase its CPU seconds and likelihood calls (a phase
with several jobs, the LIGHT candidates, sums them; NaN for a phase without a benchmark
file), the chain's CPU and wall-clock minutes over the jobs found, the largest peak
memory, and whether every phase has a benchmark file."""


def cost_row(lens: str, costs: list[JobCost]) -> dict:
    """One row of :func:`cost_table` from one lens's :func:`job_costs`."""
    row: dict = {"lens": lens}
    for phase in CHAIN_PHASES:
        jobs = [cost for cost in costs if cost.phase == phase]
        row[f"{phase}_cpu_s"] = sum(cost.cpu_s for cost in jobs) if jobs else np.nan
        row[f"{phase}_calls"] = sum(cost.calls for cost in jobs) if jobs else np.nan
    row["chain_cpu_min"] = sum(cost.cpu_s for cost in costs) / 60.0 if costs else np.nan
    row["chain_wall_min"] = sum(cost.wall_s for cost in costs) / 60.0 if costs else np.nan
    row["max_rss_mb"] = max((cost.max_rss_mb for cost in costs), default=np.nan)
    row["complete"] = all(any(c.phase == phase for c in costs) for phase in CHAIN_PHASES)
    return row


def cost_table(lens_folders: list[Path]) -> pd.DataFrame:
    """One row per lens folder (``results/<lens>``, named by the folder), columns
    :data:`COST_COLUMNS`."""
    rows = [cost_row(Path(folder).name, job_costs(Path(folder))) for folder in lens_folders]
    return pd.DataFrame(rows, columns=list(COST_COLUMNS))


def sample_cost(table: pd.DataFrame, cores: int) -> dict:
    """The sample's figures over its complete chains (rows of :func:`cost_table` with
    ``complete``): their number, median and largest CPU minutes per lens (and that lens),
    their total CPU hours, and the projected wall-clock hours of the whole table's lenses
    on ``cores`` cores, n_lenses × median / cores: what the sample takes if every core is
    kept busy and the other lenses cost the median."""
    if cores < 1:
        raise ValueError(f"cores must be at least 1, got {cores}")
    complete = table[table["complete"].astype(bool)]
    minutes = complete["chain_cpu_min"].to_numpy(dtype=float)
    if minutes.size == 0:
        return {"n_complete": 0, "n_lenses": len(table)}
    median = float(np.median(minutes))
    largest = int(np.argmax(minutes))
    return {
        "n_complete": int(minutes.size),
        "n_lenses": len(table),
        "median_cpu_min": median,
        "max_cpu_min": float(minutes[largest]),
        "max_lens": str(complete["lens"].iloc[largest]),
        "total_cpu_h": float(minutes.sum() / 60.0),
        "projected_wall_h": len(table) * median / 60.0 / cores,
        "cores": cores,
    }

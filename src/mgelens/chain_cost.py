"""What each lens's SLaM chain cost (issue #28): CPU and wall-clock seconds of its phase
jobs from the rules' Snakemake ``benchmark:`` files, likelihood calls from the phases'
records.

A phase job's benchmark file ``results/<lens>/benchmarks/<job>.tsv`` (Snakemake's
columns: ``s`` wall-clock seconds, ``cpu_time`` CPU seconds, ``max_rss`` MB, …) sits
beside its folder ``results/<lens>/<job>/`` (the pool job's: ``mass/``) with
``result.json`` (the sampler's ``n_calls``). A chain's jobs are SP, SPix1, SPix2, its
LIGHT job (``light`` where the sheet pins the model, else every candidate
``light_x6_point`` …) and MASS (``mass``, or its mesh jobs ``mass_mesh<k>`` and the job
that pools them, ``mass_pool``)
(:data:`CHAIN_PHASES`); the workflow passes exactly those (rule ``chain_cost``), so files
left from another configuration do not count. A benchmark file records the last run of
its job: a phase resumed after an interruption counts that run's time only, while its
sampler's calls include the runs before (they are checkpointed). A job's CPU seconds
are those its process recorded in ``<job>/cost.json`` (:mod:`mgelens.pipeline.job_cost`,
exact); where the folder has no such record of its result (a job of an older version),
the benchmark file's ``cpu_time``, which Snakemake samples (every 0.5 s for its first
15 s, then every 30 s) and so misses up to 30 s of the job's last stretch: a lower bound.
``cpu_exact`` says which. The wall seconds are the benchmark file's, exact.
"""

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from mgelens.pipeline.job_cost import recorded_cpu_seconds
from mgelens.pipeline.mesh_pool import POOL_JOB
from mgelens.pipeline.sp_start import START_FILE
from mgelens.search.results import RESULT_FILE

CHAIN_PHASES = ("sp", "spix1", "spix2", "light", "mass")
"""The SLaM phases, in order; a job whose name starts with one of them (before any
``_``) belongs to it (``light_x6_point`` to ``light``)."""

BENCHMARK_COLUMNS = ("s", "cpu_time", "max_rss")
"""Columns of a Snakemake benchmark file that the costs read (Snakemake writes NA where it
could not sample the process: a job shorter than its first sample)."""


@dataclass(frozen=True)
class JobCost:
    """One phase job of a lens's chain.

    Attributes
    ----------
    lens : str
        The lens folder's name.
    job : str
        The benchmark file's stem: the phase's folder (``sp``, ``light_x6_point`` …).
    phase : str
        Its phase (:data:`CHAIN_PHASES`).
    wall_s, cpu_s : float
        Wall-clock seconds (``s``) and CPU seconds (the job's ``cost.json``, else
        ``cpu_time``); NaN where Snakemake wrote NA and the job recorded none.
    max_rss_mb : float
        Peak resident memory (MB; NaN where Snakemake wrote NA).
    calls : float
        Likelihood calls of its sampler, and for SP of its start search; NaN where the
        phase's ``result.json`` is absent.
    cpu_exact : bool
        Whether ``cpu_s`` is the job's own record (exact) rather than Snakemake's sampled
        ``cpu_time`` (a lower bound).
    """

    lens: str
    job: str
    phase: str
    wall_s: float
    cpu_s: float
    max_rss_mb: float
    calls: float
    cpu_exact: bool


def phase_of(job: str) -> str | None:
    """The chain phase of a benchmark stem, or None for a job outside the chain."""
    phase = job.split("_")[0]
    return phase if phase in CHAIN_PHASES else None


def _benchmark(path: Path, columns: Sequence[str]) -> pd.DataFrame:
    """``columns`` of one benchmark file as numbers (one row per repeat; NA → NaN)."""
    fix = "delete it and rerun its phase to measure it again"
    try:
        table = pd.read_csv(path, sep="\t")
    except (OSError, ValueError) as error:
        raise ValueError(f"{path}: not a Snakemake benchmark file ({error}); {fix}") from error
    missing = [name for name in columns if name not in table.columns]
    if missing or table.empty:
        raise ValueError(
            f"{path}: a Snakemake benchmark file needs a row with columns "
            f"{', '.join(columns)} (missing: {', '.join(missing) or 'rows'}); {fix}"
        )
    return table[list(columns)].apply(pd.to_numeric, errors="coerce")


def _read_json(path: Path, job: str) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as error:
        raise ValueError(f"{path}: cannot be read ({error}); rerun phase {job}") from error


def _calls(lens_folder: Path, job: str) -> float:
    """Sampler calls in ``<job>/result.json``; NaN without the record, none for the job
    that pools MASS's mesh jobs (:data:`~mgelens.pipeline.mesh_pool.POOL_JOB`, whose
    calls are theirs). Where SP's record
    says it started from the search (``sp_start: search``), the calls of its start record
    (:data:`~mgelens.pipeline.sp_start.START_FILE`) count among SP's, also where a rerun of
    SP reused the record instead of searching again."""
    if job == POOL_JOB:
        return 0.0
    path = lens_folder / job / RESULT_FILE
    if not path.is_file():
        return np.nan
    record = _read_json(path, job)
    try:
        calls = float(record["sampler"]["n_calls"])
        searched = job == "sp" and record["settings"]["slam"]["sp_start"] == "search"
    except (KeyError, TypeError, ValueError) as error:
        raise ValueError(
            f"{path}: no sampler calls or SP start setting to read ({error!r}); rerun phase {job}"
        ) from error
    start = lens_folder / job / START_FILE
    if searched and start.is_file():
        start_record = _read_json(start, job)
        try:
            calls += float(start_record["start"]["n_calls"])
        except (KeyError, TypeError, ValueError) as error:
            raise ValueError(
                f"{start}: no start-search calls to read ({error!r}); delete it and rerun phase sp"
            ) from error
    return calls


def job_cost(benchmark: Path) -> JobCost:
    """The cost of the phase job whose benchmark file is ``benchmark``
    (``results/<lens>/benchmarks/<job>.tsv``).

    Raises
    ------
    ValueError
        For a job outside the chain, or a benchmark file or phase record that cannot be
        read, naming the file and the fix.
    """
    benchmark = Path(benchmark)
    phase = phase_of(benchmark.stem)
    if phase is None:
        raise ValueError(
            f"{benchmark}: not a benchmark file of a SLaM phase job (its name must start "
            f"with one of {', '.join(CHAIN_PHASES)})"
        )
    values = _benchmark(benchmark, BENCHMARK_COLUMNS)
    lens_folder = benchmark.parent.parent
    # the pool job writes MASS's folder; every other job the folder of its name
    folder = "mass" if benchmark.stem == POOL_JOB else benchmark.stem
    recorded = recorded_cpu_seconds(lens_folder / folder)
    return JobCost(
        lens_folder.name,
        benchmark.stem,
        phase,
        float(values["s"].sum(min_count=1)),
        float(values["cpu_time"].sum(min_count=1)) if recorded is None else recorded,
        float(values["max_rss"].max()),
        _calls(lens_folder, benchmark.stem),
        recorded is not None,
    )


def chain_seconds(lens_folder: Path, cpu: bool = False) -> float:
    """Seconds of a lens's chain, wall-clock or (``cpu``) CPU (:func:`job_cost`), summed
    over every phase job with a benchmark file in ``lens_folder/benchmarks/`` (other jobs
    left out); NaN with none, or where one of them is unmeasured. A job resumed after an
    interruption counts its last run."""
    files = sorted(Path(lens_folder, "benchmarks").glob("*.tsv"))
    costs = [job_cost(path) for path in files if phase_of(path.stem)]
    return _total([cost.cpu_s if cpu else cost.wall_s for cost in costs])


COST_COLUMNS = (
    "lens",
    *(f"{phase}_cpu_s" for phase in CHAIN_PHASES),
    *(f"{phase}_calls" for phase in CHAIN_PHASES),
    "chain_cpu_min",
    "chain_wall_min",
    "max_rss_mb",
    "complete",
    "cpu_exact",
)
"""Columns of :func:`cost_table`: per phase its CPU seconds and likelihood calls (a phase
with several jobs, the LIGHT candidates, sums them; NaN for a phase without a job or with
an unmeasured one), the chain's CPU and wall-clock minutes (NaN if a job's are
unmeasured), the largest peak memory, whether every phase has a job with its CPU time
measured, and whether every job's CPU time is its own record (:attr:`JobCost.cpu_exact`)
rather than Snakemake's sampled lower bound."""


def _total(values: Sequence[float]) -> float:
    """Sum of ``values``; NaN if there are none or one is NaN."""
    return float(np.sum(values)) if len(values) else np.nan


def cost_row(lens: str, costs: Sequence[JobCost]) -> dict:
    """One row of :func:`cost_table` from one lens's jobs (:func:`job_cost`)."""
    row: dict = {"lens": lens}
    for phase in CHAIN_PHASES:
        jobs = [cost for cost in costs if cost.phase == phase]
        row[f"{phase}_cpu_s"] = _total([cost.cpu_s for cost in jobs])
        row[f"{phase}_calls"] = _total([cost.calls for cost in jobs])
    row["chain_cpu_min"] = _total([cost.cpu_s for cost in costs]) / 60.0
    row["chain_wall_min"] = _total([cost.wall_s for cost in costs]) / 60.0
    memory = [cost.max_rss_mb for cost in costs if np.isfinite(cost.max_rss_mb)]
    row["max_rss_mb"] = max(memory, default=np.nan)
    row["complete"] = all(np.isfinite(row[f"{phase}_cpu_s"]) for phase in CHAIN_PHASES)
    row["cpu_exact"] = all(cost.cpu_exact for cost in costs)
    return row


def cost_table(benchmarks: Sequence[Path]) -> pd.DataFrame:
    """One row per lens (benchmark files ``results/<lens>/benchmarks/<job>.tsv`` grouped
    by lens folder, in the order of their first file), columns :data:`COST_COLUMNS`."""
    jobs: dict[Path, list[JobCost]] = {}
    for path in benchmarks:
        jobs.setdefault(Path(path).parent.parent, []).append(job_cost(Path(path)))
    rows = [cost_row(folder.name, costs) for folder, costs in jobs.items()]
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

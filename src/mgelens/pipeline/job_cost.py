"""What a phase job's own process cost, recorded by the job itself (issue #28).

Snakemake's ``benchmark:`` files give a job's wall-clock seconds exactly but sample its
CPU time (every 0.5 s for the first 15 s, then every 30 s), so their ``cpu_time`` misses up
to 30 s of each job's last stretch. A phase job (``mgelens phase``) therefore writes, after
its result, ``cost.json`` into its folder: the process's CPU seconds from the kernel's
accounting (``getrusage``: user + system time of every thread since the process started,
numba's threads included, and of the child processes it waited for: a likelihood pool's
workers), its wall-clock seconds from the command's start, its peak
resident memory, and the SHA-256 of the ``result.json`` it wrote. It records that run
only: a phase resumed from its checkpoint counts the run that finished it, as its
benchmark file does.

:func:`recorded_cpu_seconds` reads it back for :mod:`mgelens.chain_cost`, and only where it
belongs to the folder's result: a ``cost.json`` whose digest is not that of the folder's
``result.json`` was left by an earlier run. (Not file times: Snakemake touches a job's
outputs after it ends.)
"""

import json
import resource
import time
from pathlib import Path

from mgelens.atomic import write_json
from mgelens.search.results import RESULT_FILE, file_sha256

COST_FILE = "cost.json"
"""The record's name in the job's folder (``results/<lens>/<job>/``)."""


def process_cost(started: float) -> dict:
    """This process's cost so far: ``cpu_s`` (user + system CPU seconds of all its threads
    and of its terminated, waited-for children), ``wall_s`` (seconds since ``started``, a
    :func:`time.perf_counter` value) and ``max_rss_mb`` (its own peak resident memory, MB
    of 2²⁰ bytes; Linux reports kB)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return {
        "cpu_s": usage.ru_utime + usage.ru_stime + children.ru_utime + children.ru_stime,
        "wall_s": time.perf_counter() - started,
        "max_rss_mb": usage.ru_maxrss / 1024.0,
    }


def write_job_cost(folder: Path, started: float) -> None:
    """Write :func:`process_cost` and the digest of ``folder/result.json``, which the job
    has written, to ``folder/cost.json`` (atomically)."""
    folder = Path(folder)
    record = {**process_cost(started), "result_sha256": file_sha256(folder / RESULT_FILE)}
    write_json(folder / COST_FILE, record)


def recorded_cpu_seconds(folder: Path) -> float | None:
    """The CPU seconds of the job that wrote ``folder``'s ``result.json``, or None where
    ``folder`` has no ``cost.json``, no result, or a ``cost.json`` of another result.

    Raises
    ------
    ValueError
        For a ``cost.json`` that cannot be read, naming the file and the fix.
    """
    path, result = Path(folder) / COST_FILE, Path(folder) / RESULT_FILE
    if not path.is_file() or not result.is_file():
        return None
    try:
        record = json.loads(path.read_text())
        seconds, digest = float(record["cpu_s"]), str(record["result_sha256"])
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise ValueError(
            f"{path}: no CPU seconds and result digest to read ({error!r}); delete it (the "
            "chain cost then takes the benchmark file's sampled CPU time) or rerun the phase"
        ) from error
    return seconds if digest == file_sha256(result) else None

"""Small timing helpers shared by the benchmark scripts (run them from the repo root)."""

import resource
import time

import numba
import numpy as np


def median_time(func, repeats: int = 7, warmup: int = 1) -> float:
    """Median wall time of ``func()`` in seconds after ``warmup`` untimed calls."""
    for _ in range(warmup):
        func()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def peak_memory_mb() -> float:
    """Peak resident memory of this process so far, in MB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def report(name: str, value: float, unit: str = "s") -> None:
    """Print one figure as ``name: value`` (seconds unless ``unit`` says otherwise)."""
    print(f"{name}: {value:.4g}" + ("" if unit == "s" else f"  # {unit}"))


def set_threads(n: int = 2) -> None:
    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))

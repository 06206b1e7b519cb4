"""Small timing helpers shared by the benchmark scripts (run them from the repo root)."""

import resource
import time
import tracemalloc

import numpy as np

from mgelens.memory import keep_freed_memory
from mgelens.threads import limit_threads


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
    """n numba threads, one BLAS thread (mgelens's thread policy, mgelens.threads), and
    the phase jobs' malloc thresholds (mgelens.memory)."""
    limit_threads(n)
    keep_freed_memory()


def timings(function, repeats: int) -> tuple[float, float, float]:
    """Median and minimum wall time and median process CPU time (s) after one warm-up.

    CPU time sums all threads; on a machine shared with other jobs it is a steadier figure
    than wall time.
    """
    function()
    wall, cpu = [], []
    for _ in range(repeats):
        start_wall, start_cpu = time.perf_counter(), time.process_time()
        function()
        wall.append(time.perf_counter() - start_wall)
        cpu.append(time.process_time() - start_cpu)
    return float(np.median(wall)), float(np.min(wall)), float(np.median(cpu))


def report_timings(name: str, function, repeats: int) -> None:
    """Print ``name`` (median wall), ``name_min`` and ``name_cpu`` of ``function()``."""
    median, minimum, cpu = timings(function, repeats)
    print(f"{name}: {median:.4f}")
    print(f"{name}_min: {minimum:.4f}")
    print(f"{name}_cpu: {cpu:.4f}")


def peak_traced_mb(function) -> float:
    """Peak memory (MB) traced by ``tracemalloc`` during one ``function()`` call."""
    tracemalloc.start()
    function()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / 1e6


def host_yardstick_ms(repeats: int = 5) -> float:
    """Median CPU ms, on one thread, of a fixed workload shaped like a real lens's
    likelihood call: 60 real FFT round trips of a 135² frame and the weighted Gram of
    190 columns over 11,289 pixels. Printed beside per-call figures so that figures from
    different hosts can be compared (hosts of our kind differ by 2–2.5×,
    docs/benchmarks.md); the workload does not depend on mgelens's code, so a code change
    does not move it."""
    import scipy.fft
    from scipy.linalg import blas

    rng = np.random.default_rng(0)
    frames = rng.random((60, 135, 135))
    columns = rng.random((190, 11289)).T  # Fortran-ordered (11289, 190), as dsyrk takes

    def workload():
        spectrum = scipy.fft.rfft2(frames, workers=1)
        scipy.fft.irfft2(spectrum, s=frames.shape[1:], workers=1)
        blas.dsyrk(1.0, columns.T, trans=0, lower=0)

    return 1e3 * timings(workload, repeats)[2]

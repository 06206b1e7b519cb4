"""Thread policy: numba kernels run in parallel, BLAS runs single-threaded.

The parallel kernels (curvature tiles, light columns, interpolation) call BLAS from each
numba thread; a multi-threaded BLAS underneath oversubscribes the cores, and switching
OpenBLAS's thread count per call costs ~35 ms. So every entry point that chooses a thread
count (a phase job, ``mgelens simulate``, the benchmarks) calls :func:`limit_threads` once,
and the kernels check :func:`blas_threads` instead of switching.
"""

import contextlib
import functools

import numba
from threadpoolctl import ThreadpoolController


@functools.cache
def _controller() -> ThreadpoolController:
    """One controller per process: building one scans the loaded libraries (~6 ms)."""
    import scipy.linalg  # noqa: F401  (load scipy's BLAS before scanning, as numba uses it)

    return ThreadpoolController()


def limit_threads(threads: int) -> None:
    """Use ``threads`` numba threads and OpenMP threads, and one BLAS thread.

    scipy.fft follows numba's count (:mod:`mgelens.convolve` passes
    ``workers=numba.get_num_threads()``): with all cores as FFT workers, two one-thread
    phase jobs side by side each ran on ~1.4 cores and took 1.7× longer per call.

    Snakemake sets ``OMP_NUM_THREADS`` and friends but not numba's thread count, and
    libraries loaded before those variables were read ignore them, so all are set here.

    Raises
    ------
    ValueError
        If ``threads`` < 1.
    """
    if threads < 1:
        raise ValueError(f"threads must be >= 1, got {threads}")
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    _controller().limit(limits=threads, user_api="openmp")
    _controller().limit(limits=1, user_api="blas")


def blas_threads() -> int:
    """Largest thread count of the loaded BLAS libraries (~10 µs)."""
    return max(
        (lib["num_threads"] for lib in _controller().select(user_api="blas").info()), default=1
    )


def single_threaded_blas():
    """Context manager around BLAS calls made from parallel numba threads.

    It limits BLAS to one thread for its duration, and does nothing when BLAS already runs
    one thread (the :func:`limit_threads` policy) or numba runs one thread.
    """
    if numba.get_num_threads() == 1 or blas_threads() == 1:
        return contextlib.nullcontext()
    return _controller().limit(limits=1, user_api="blas")

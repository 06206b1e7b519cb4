"""Memory policy of long likelihood loops: keep freed memory in the process (glibc).

A likelihood evaluation allocates and frees arrays of a few MB (light columns, blur work
arrays, the curvature matrix). glibc's malloc serves such sizes from ``mmap`` or returns
the top of its heap to the system once more than ``M_TRIM_THRESHOLD`` is free, and both
thresholds adapt to the process's past allocations. After numba compiled the kernels in
the process (a fresh clone, an edited kernel: the first phase jobs of a workflow), every
evaluation then maps fresh pages, and the sampling runs markedly slower than in a process
that loaded the kernels from numba's cache. Fixed thresholds remove this
(docs/design_notes.md, "Freed memory").
"""

import ctypes
import ctypes.util
import functools
import logging

logger = logging.getLogger(__name__)

M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
"""``mallopt`` parameter numbers (glibc's malloc.h)."""
MMAP_THRESHOLD_BYTES = 32 * 1024 * 1024
"""Allocations below this come from the heap: glibc's largest accepted value on 64-bit."""
TRIM_THRESHOLD_BYTES = 1024 * 1024 * 1024
"""Free memory at the top of the heap kept for reuse before any is returned (1 GB)."""


@functools.cache
def keep_freed_memory() -> bool:
    """Fix glibc's malloc thresholds (:data:`MMAP_THRESHOLD_BYTES`,
    :data:`TRIM_THRESHOLD_BYTES`) for the rest of the process.

    Call once at the start of a job that evaluates a likelihood many times. The process
    then keeps up to its peak heap after arrays are freed. Returns whether the thresholds
    were set; ``False`` without glibc (macOS, musl), where nothing changes.
    """
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError, TypeError):
        logger.debug("no glibc mallopt: malloc thresholds left as they are")
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    mmap_set = mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) == 1
    trim_set = mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES) == 1
    return mmap_set and trim_set

"""numba configuration shared by every module with compiled kernels.

``njit`` is ``numba.njit`` with ``cache=True`` unless the environment variable
``MGELENS_NUMBA_CACHE=0`` turns caching off (useful on shared or NFS file
systems where concurrent cache writes race, numba#4807). ``NUMBA_DISABLE_JIT=1``
is honoured by numba itself. Keep each kernel and the kernels it calls in one
module: numba's cache is invalidated only when the defining file changes.
"""

import os

import numba

CACHE = os.environ.get("MGELENS_NUMBA_CACHE", "1") != "0"


def njit(*args, **kwargs):
    """``numba.njit`` with mgelens's caching policy (see module docstring)."""
    kwargs.setdefault("cache", CACHE)
    return numba.njit(*args, **kwargs)

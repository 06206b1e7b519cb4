"""The phase jobs' malloc policy (mgelens.memory): freed arrays are reused, not re-faulted."""

import platform
import subprocess
import sys

import pytest

ROUND_TRIPS = """
import resource, sys
import numpy as np
if sys.argv[1] == "keep":
    from mgelens.memory import keep_freed_memory
    assert keep_freed_memory()
big = np.ones(1 << 17)  # 1 MB, freed: glibc's dynamic mmap threshold rises to 1 MB
del big
def round_trip():  # like a likelihood evaluation: ten 512 kB work arrays, then freed
    arrays = [np.ones(1 << 16) for _ in range(10)]
    del arrays
round_trip()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(50):
    round_trip()
print((resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 50)
"""


def faults_per_round_trip(mode: str) -> float:
    output = subprocess.run(
        [sys.executable, "-c", ROUND_TRIPS, mode], capture_output=True, text=True, check=True
    )
    return float(output.stdout)


@pytest.mark.skipif(
    platform.system() != "Linux" or platform.libc_ver()[0] != "glibc",
    reason="mallopt thresholds are glibc's",
)
def test_freed_work_arrays_are_reused_without_page_faults():
    """With glibc's adaptive thresholds the freed heap top (5 MB) is returned to the
    system after every round trip, so each one faults its 1,280 pages in again; with
    keep_freed_memory() they are reused."""
    assert faults_per_round_trip("default") > 500
    assert faults_per_round_trip("keep") < 10

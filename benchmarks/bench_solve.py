"""Linear solves and log determinants of a real inversion (SPEC §6–7).

The system is configuration R of ``bench_likelihood.py``: 70 MGE + 1500 k-means source
unknowns of a mock lens in a 3.0″ mask, adaptive cross regularization. Prints the median
times of the non-negative solve (fnnls), the unconstrained Cholesky solve, ln det H by sparse LU and
ln det(F_SS + H) by dense Cholesky, the NNLS bookkeeping, and peak memory (the traced
Python/numpy peak of one fnnls call and the process peak RSS).

Run from the repository root: ``python benchmarks/bench_solve.py``. BLAS threads follow
OPENBLAS_NUM_THREADS / OMP_NUM_THREADS.
"""

import os

import numpy as np
from bench_likelihood import inversion_system
from common import median_time, peak_memory_mb, peak_traced_mb, report, set_threads

from mgelens.inversion.evidence import log_det_cholesky, log_det_regularization
from mgelens.inversion.nnls import reconstruction_positive_only
from mgelens.inversion.solve import reconstruction_positive_negative


def main() -> None:
    set_threads(2)
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
        print(f"{name}: {os.environ.get(name, 'unset')}")
    Q, D, H, fixed_zero, n_light = inversion_system()
    free = ~fixed_zero
    Q, D = Q[np.ix_(free, free)], D[free]  # the edge pixels are fixed at zero (SPEC §6.3)
    n = D.size
    result = reconstruction_positive_only(Q, D)
    print(
        f"n_unknowns: {n}  negative_unconstrained: {int(np.sum(np.linalg.solve(Q, D) <= 0))}"
        f"  zero_nnls: {int(np.sum(result.x == 0))}  outer_iterations: {result.n_iterations}"
    )
    report(f"fnnls_{n}_s", median_time(lambda: reconstruction_positive_only(Q, D)))
    report(f"cholesky_{n}_s", median_time(lambda: reconstruction_positive_negative(Q, D)))
    report(f"logdet_sparse_H_{H.shape[0]}_s", median_time(lambda: log_det_regularization(H)))
    source_block = Q[n_light:, n_light:]
    report(
        f"logdet_dense_FH_{source_block.shape[0]}_s",
        median_time(lambda: log_det_cholesky(source_block)),
    )
    report("fnnls_traced_peak_mb", peak_traced_mb(lambda: reconstruction_positive_only(Q, D)), "MB")
    report("peak_memory_mb", peak_memory_mb(), "MB")


if __name__ == "__main__":
    main()

"""Speed and memory of the source-plane mesh and its interpolation weights (SPEC §4.3–4.4).

A 1500-point mesh (uniform in a unit disc, like a k-means mesh of N_pix = 1500) and
180,000 queries (16 sub-pixels × 11,300 image pixels, uniform in the same disc, so ≈ 1 %
fall outside the convex hull). Prints ``name: value`` lines: median wall time in seconds
of several calls after a warm-up call (which also triggers numba compilation or loads it
from the cache), the minimum (``_min``) and the median process CPU time summed over threads
(``_cpu``, steadier than wall time on a shared machine); then the mean row length, the peak
memory traced by ``tracemalloc`` during one weights call (outputs included) and the process
peak RSS.

Run from the repository root: ``python benchmarks/bench_interpolate.py [--threads 2]``.
"""

import argparse
import resource
import time

import numba
import numpy as np
from common import peak_traced_mb, report_timings

from mgelens.source.interpolate import natural_neighbour_weights, nearest_cell_weights
from mgelens.source.mesh import VoronoiMesh

N_MESH = 1500
N_QUERIES = 16 * 11_300


def random_disc(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """n points uniform in the unit disc (arcsec)."""
    r = np.sqrt(rng.random(n))
    theta = 2.0 * np.pi * rng.random(n)
    return r * np.cos(theta), r * np.sin(theta)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--threads", type=int, default=2, help="numba threads")
    parser.add_argument("--repeats", type=int, default=15, help="timed calls per figure")
    args = parser.parse_args()
    numba.set_num_threads(args.threads)

    rng = np.random.default_rng(1)
    mx, my = random_disc(rng, N_MESH)
    qx, qy = random_disc(rng, N_QUERIES)
    mesh = VoronoiMesh.from_points(mx, my)

    start = time.perf_counter()
    natural_neighbour_weights(mesh, qx[:10], qy[:10])
    nearest_cell_weights(mesh, qx[:10], qy[:10])
    print(f"first_call_compile_or_cache_load_s: {time.perf_counter() - start:.2f}")
    print(f"numba_threads: {numba.get_num_threads()}")
    print(f"n_mesh: {N_MESH}")
    print(f"n_queries: {N_QUERIES}")
    report_timings("voronoi_mesh_1500_s", lambda: VoronoiMesh.from_points(mx, my), args.repeats)
    report_timings(
        "nn_weights_180k_queries_s",
        lambda: natural_neighbour_weights(mesh, qx, qy),
        args.repeats,
    )
    report_timings(
        "nearest_cell_180k_queries_s", lambda: nearest_cell_weights(mesh, qx, qy), args.repeats
    )
    indptr, _, _ = natural_neighbour_weights(mesh, qx, qy)
    print(f"nn_mean_row_length: {indptr[-1] / N_QUERIES:.2f}")
    peak = peak_traced_mb(lambda: natural_neighbour_weights(mesh, qx, qy))
    print(f"nn_weights_peak_traced_mb: {peak:.1f}")
    print(f"process_peak_rss_mb: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3:.0f}")


if __name__ == "__main__":
    main()

"""Speed of the k-means source-mesh centres (SPEC §4.1), rebuilt at every SPix2 likelihood
call because the weight hyper-parameters move the centres.

Two masks at 0.05″: M1's 1.8″ (4,053 pixel centres) and a real SLACS cutout's 3.0″
(11,277), weights from a ring-shaped adapt image (floor 0.1, power 2), 5 Lloyd
iterations, one thread. Prints the median wall time of ``kmeans_centres`` for 500 and
1,500 centres, and, from the same seeds, of its two steps (the compiled k-means++ seeding
and Lloyd iterations) and of scikit-learn's Lloyd iterations, with the weighted inertia of
both results; then the same for the systematic seeding along a Hilbert curve
(``seeding="systematic"``: its seeding step, the whole call and its inertia).

Run from the repository root: ``python benchmarks/bench_kmeans.py``.
"""

from functools import partial

import numpy as np
from common import median_time, report, set_threads
from sklearn.cluster import KMeans

from mgelens.grid import pixel_centres
from mgelens.source.image_mesh import (
    KMEANS_TOLERANCE,
    SEEDING_POINTS_PER_CELL,
    _grid_geometry,
    _kmeans_plusplus,
    _lloyd,
    kmeans_centres,
    kmeans_weights,
    systematic_seeding,
)


def weighted_inertia(points, weights, centres) -> float:
    distance = ((points[:, None, :] - centres[None, :, :]) ** 2).sum(axis=2)
    return float(np.sum(weights * distance.min(axis=1)))


def bench_mask(shape: tuple[int, int], radius: float) -> None:
    """Figures of one circular mask of ``radius`` arcsec on a ``shape`` grid of 0.05″."""
    x, y = pixel_centres(shape, 0.05)
    used = np.hypot(x, y) < radius
    x, y = x[used], y[used]
    adapt = np.exp(-((np.hypot(x, y) - 1.2) ** 2) / (2 * 0.2**2)) + 0.01
    weights = kmeans_weights(adapt, weight_floor=0.1, weight_power=2.0)
    points = np.column_stack([x, y])
    tag = f"r{radius:g}"
    report(f"{tag}_n_points", x.size, "pixel centres")
    grid = _grid_geometry(points, len(points), SEEDING_POINTS_PER_CELL)
    tolerance = KMEANS_TOLERANCE * float(np.mean(np.var(points, axis=0)))
    for n in (500, 1500):
        trials = 2 + int(np.log(n))
        uniforms = np.random.default_rng(0).random(1 + (n - 1) * trials)
        seeds = _kmeans_plusplus(points, weights, n, trials, uniforms, grid)
        kmeans = KMeans(n_clusters=n, init=seeds, n_init=1, max_iter=5)
        report(f"{tag}_kmeans_{n}_s", median_time(partial(kmeans_centres, x, y, weights, n)))
        report(
            f"{tag}_seeding_{n}_s",
            median_time(partial(_kmeans_plusplus, points, weights, n, trials, uniforms, grid)),
        )
        report(
            f"{tag}_lloyd_{n}_s",
            median_time(partial(_lloyd, points, weights, seeds, 5, tolerance)),
        )
        report(
            f"{tag}_lloyd_{n}_scikit_learn_s",
            median_time(partial(kmeans.fit, points, sample_weight=weights), repeats=3),
        )
        ours = _lloyd(points, weights, seeds, 5, tolerance)
        theirs = kmeans.fit(points, sample_weight=weights).cluster_centers_
        report(f"{tag}_inertia_{n}", weighted_inertia(points, weights, ours), "arcsec^2")
        report(
            f"{tag}_inertia_{n}_scikit_learn",
            weighted_inertia(points, weights, theirs),
            "arcsec^2",
        )
        systematic = partial(kmeans_centres, x, y, weights, n, seeding="systematic")
        report(f"{tag}_kmeans_{n}_systematic_s", median_time(systematic))
        report(
            f"{tag}_seeding_{n}_systematic_s",
            median_time(partial(systematic_seeding, points, weights, n, 0)),
        )
        centres = np.column_stack(systematic())
        report(
            f"{tag}_inertia_{n}_systematic",
            weighted_inertia(points, weights, centres),
            "arcsec^2",
        )


def main() -> None:
    set_threads(1)
    bench_mask((151, 151), 1.8)
    bench_mask((201, 201), 3.0)


if __name__ == "__main__":
    main()

"""Speed of the k-means source-mesh centres (SPEC §4.1), rebuilt at every SPix2 likelihood
call because the weight hyper-parameters move the centres.

An M1-like setting: the 4053 pixel centres inside a 1.8″ mask at 0.05″, weights from a
ring-shaped adapt image (floor 0.1, power 2), 5 Lloyd iterations. Prints the median wall
time of ``kmeans_centres`` (compiled k-means++ seeding + scikit-learn's Lloyd iterations)
for 500 and 1500 centres, and of scikit-learn's own ``KMeans`` (its seeding loops in
Python) for comparison, with the weighted inertia of both.

Run from the repository root: ``python benchmarks/bench_kmeans.py``.
"""

import warnings

import numpy as np
from common import median_time, report, set_threads
from sklearn.cluster import KMeans

from mgelens.grid import pixel_centres
from mgelens.source.image_mesh import kmeans_centres, kmeans_weights


def weighted_inertia(x, y, weights, cx, cy) -> float:
    distance = (x[:, None] - cx) ** 2 + (y[:, None] - cy) ** 2
    return float(np.sum(weights * distance.min(axis=1)))


def main() -> None:
    set_threads(1)
    x, y = pixel_centres((151, 151), 0.05)
    used = np.hypot(x, y) < 1.8
    x, y = x[used], y[used]
    adapt = np.exp(-((np.hypot(x, y) - 1.2) ** 2) / (2 * 0.2**2)) + 0.01
    weights = kmeans_weights(adapt, weight_floor=0.1, weight_power=2.0)
    points = np.column_stack([x, y])
    print(f"n_points: {x.size}")
    for n in (500, 1500):
        ours = kmeans_centres(x, y, weights, n, seed=0)
        report(f"kmeans_{n}_s", median_time(lambda n=n: kmeans_centres(x, y, weights, n, 0)))

        def reference(n=n):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                kmeans = KMeans(n_clusters=n, random_state=0, n_init=1, max_iter=5)
                return kmeans.fit(points, sample_weight=weights).cluster_centers_

        report(f"kmeans_{n}_scikit_learn_s", median_time(reference, repeats=3))
        theirs = reference()
        report(f"kmeans_{n}_inertia", weighted_inertia(x, y, weights, *ours), "arcsec^2")
        report(
            f"kmeans_{n}_scikit_learn_inertia",
            weighted_inertia(x, y, weights, theirs[:, 0], theirs[:, 1]),
            "arcsec^2",
        )


if __name__ == "__main__":
    main()

"""Image-plane centres of the source mesh (SPEC §4.1).

The centres are chosen once in the image plane and ray traced to the source plane
with the current mass model at every likelihood evaluation:

* :func:`overlay_centres`, a regular grid over the mask (magnification adaptive, SPix1);
* :func:`kmeans_centres`, weighted k-means on the unmasked pixel centres with weights
  from the adapt image (brightness adaptive, SPix2, L, M).

SPix2 runs k-means in every likelihood evaluation, so both of its steps are compiled and
find near points through a bucket grid (:func:`_bucket_grid`) instead of comparing every
point with every centre.
"""

import numpy as np

from mgelens._jit import njit
from mgelens.grid import pixel_centres
from mgelens.source.schemes import KMEANS_SEEDINGS

ADAPT_MINIMUM_FRACTION = 0.01


def mask_extent_centre(mask: np.ndarray, pixel_scale: float) -> tuple[float, float]:
    """Midpoint (x, y) of the extent of the unmasked pixel centres, arcsec."""
    x, y = pixel_centres(mask.shape, pixel_scale)
    xs, ys = x[~mask], y[~mask]
    return 0.5 * (xs.min() + xs.max()), 0.5 * (ys.min() + ys.max())


def overlay_centres(
    mask: np.ndarray, pixel_scale: float, shape: tuple[int, int] = (34, 34)
) -> tuple[np.ndarray, np.ndarray]:
    """Overlay grid points that fall on unmasked pixels (SPEC §4.1, anchor ``Overlay``).

    The grid of ``shape`` = (n_y, n_x) has spacing ((E_y + Δ)/n_y, (E_x + Δ)/n_x), with
    E the extents of the unmasked pixel centres, is centred on the middle of those
    extents and uses the pixel-centre convention of SPEC §1.1. A point is kept iff the
    data pixel containing it is unmasked. Returns (x, y) arcsec, row-major order.
    """
    n_y, n_x = shape
    x, y = pixel_centres(mask.shape, pixel_scale)
    xs, ys = x[~mask], y[~mask]
    spacing_y = (ys.max() - ys.min() + pixel_scale) / n_y
    spacing_x = (xs.max() - xs.min() + pixel_scale) / n_x
    centre = mask_extent_centre(mask, pixel_scale)
    gx = (np.arange(n_x) - (n_x - 1) / 2.0) * spacing_x + centre[0]
    gy = (np.arange(n_y) - (n_y - 1) / 2.0) * spacing_y + centre[1]
    ox, oy = (a.ravel() for a in np.meshgrid(gx, gy))
    n_rows, n_cols = mask.shape
    cols = np.floor(ox / pixel_scale + n_cols / 2.0).astype(np.int64)
    rows = np.floor(oy / pixel_scale + n_rows / 2.0).astype(np.int64)
    inside = (rows >= 0) & (rows < n_rows) & (cols >= 0) & (cols < n_cols)
    keep = np.zeros(ox.size, dtype=bool)
    keep[inside] = ~mask[rows[inside], cols[inside]]
    return ox[keep], oy[keep]


def floored_adapt_image(adapt_image: np.ndarray) -> np.ndarray:
    """Adapt image with values below 1 % of its maximum raised to 1 % (SPEC §4.1)."""
    adapt_image = np.asarray(adapt_image, dtype=float)
    peak = adapt_image.max()
    if not peak > 0.0:
        raise ValueError("the adapt image has no positive pixel; cannot weight k-means")
    return np.maximum(adapt_image, ADAPT_MINIMUM_FRACTION * peak)


def kmeans_weights(
    adapt_image: np.ndarray, weight_floor: float, weight_power: float, scheme: str = "2023"
) -> np.ndarray:
    """k-means sample weights from the (floored) adapt image Ξ (SPEC §4.1 step 2).

    ``scheme="2023"`` (default, paper era): W = [(Ξ − min Ξ)/(max Ξ − min Ξ) + W_floor·max Ξ]^p;
    ``scheme="2024"``: W = max((|Ξ|/max Ξ)^p, W_floor).
    """
    xi = floored_adapt_image(adapt_image)
    if scheme == "2023":
        span = xi.max() - xi.min()
        scaled = (xi - xi.min()) / span if span > 0 else np.zeros_like(xi)
        return (scaled + weight_floor * xi.max()) ** weight_power
    if scheme == "2024":
        return np.maximum((np.abs(xi) / xi.max()) ** weight_power, weight_floor)
    raise ValueError(f"unknown k-means weight scheme {scheme!r}; use '2023' or '2024'")


SEEDING_POINTS_PER_CELL = 8.0
"""Points per cell of the seeding's bucket grid."""

LLOYD_CENTRES_PER_CELL = 2.0
"""Centres per cell of the Lloyd iterations' bucket grid."""

KMEANS_TOLERANCE = 1e-4
"""Lloyd stops once the centres' total squared shift is at most this fraction of the mean
variance of the point coordinates (scikit-learn's ``tol`` default and definition)."""


def kmeans_centres(
    x: np.ndarray,
    y: np.ndarray,
    weights: np.ndarray,
    n_pixels: int,
    seed: int = 0,
    max_iter: int = 5,
    seeding: str = "kmeans++",
    curve_order: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted k-means centres of the pixel centres (x, y), arcsec (SPEC §4.1).

    Deliberately not converged (anchor: scikit-learn's ``KMeans(n_init=1, max_iter=5)``):
    what matters is that fixed inputs and a fixed ``seed`` give the identical mesh
    throughout a search.

    ``seeding="kmeans++"`` is the anchor's algorithm: scikit-learn's weighted greedy
    k-means++ seeding (first centre drawn ∝ weight, each next one the best of 2 + ln k
    candidates drawn ∝ weight × squared distance; :func:`_kmeans_plusplus`), then at most
    ``max_iter`` weighted Lloyd iterations with scikit-learn's stopping rules and its
    relocation of empty clusters (:func:`_lloyd`). Only the random stream differs from
    scikit-learn's, and centres agree with scikit-learn's Lloyd iterations from the same
    seeds to rounding, except where a pixel lies at equal distance from two centres
    (ties go to the lower index). Its centres jump when the weights change by a part in
    10⁴: each draw's pick moves, and every later draw follows from it.

    ``seeding="systematic"`` starts Lloyd from a stratified draw instead
    (:func:`systematic_seeding`): the points in Hilbert-curve order, the k starting centres
    at equal steps of the cumulative √weight, the steps' offset drawn from ``seed``. A
    small change of the weights moves a few starting centres by a pixel or so, and the
    mesh follows them smoothly (docs/slam.md, "k-means seeding"). ``curve_order`` is
    :func:`hilbert_order` of the points, computed here when not given (a caller that
    clusters the same points many times passes it once computed).

    Raises
    ------
    ValueError
        If ``n_pixels`` exceeds the number of points, the weights are not finite,
        non-negative and not all zero, or ``seeding`` is not one of
        :data:`KMEANS_SEEDINGS`.
    """
    if n_pixels > x.size:
        raise ValueError(
            f"k-means asks for {n_pixels} source pixels but the mask has only {x.size} pixels"
        )
    weights = np.asarray(weights, dtype=float)
    if not np.all(np.isfinite(weights)) or np.any(weights < 0) or not weights.sum() > 0:
        raise ValueError("k-means weights must be finite, non-negative and not all zero")
    points = np.column_stack([x, y]).astype(float)
    if seeding == "systematic":
        initial = points[systematic_seeding(points, weights, n_pixels, seed, curve_order)]
    elif seeding == "kmeans++":
        trials = 2 + int(np.log(n_pixels))
        uniforms = np.random.default_rng(seed).random(1 + (n_pixels - 1) * trials)
        grid = _grid_geometry(points, len(points), SEEDING_POINTS_PER_CELL)
        initial = _kmeans_plusplus(points, weights, n_pixels, trials, uniforms, grid)
    else:
        raise ValueError(f"unknown k-means seeding {seeding!r}; use one of {KMEANS_SEEDINGS}")
    tolerance = KMEANS_TOLERANCE * float(np.mean(np.var(points, axis=0)))
    centres = _lloyd(points, weights, initial, max_iter, tolerance)
    return centres[:, 0].copy(), centres[:, 1].copy()


HILBERT_ORDER = 16
"""Bits per axis of the grid on which :func:`hilbert_order` places the points."""


def hilbert_index(ix: np.ndarray, iy: np.ndarray, order: int) -> np.ndarray:
    """Distance along the Hilbert curve of order ``order`` (a 2^order × 2^order grid) of
    the integer cells (ix, iy), each in [0, 2^order). Consecutive distances are cells
    that share an edge; the curve starts at (0, 0) and ends at (2^order − 1, 0)."""
    x = np.asarray(ix, dtype=np.int64).copy()
    y = np.asarray(iy, dtype=np.int64).copy()
    distance = np.zeros(x.shape, dtype=np.int64)
    side = 1 << (order - 1)
    while side > 0:
        rx = (x & side) > 0
        ry = (y & side) > 0
        distance += side * side * ((3 * rx) ^ ry)
        flip = rx & ~ry  # the quadrant's copy of the curve is reflected, then transposed
        x = np.where(flip, side - 1 - x, x)
        y = np.where(flip, side - 1 - y, y)
        x, y = np.where(~ry, y, x), np.where(~ry, x, y)
        side //= 2
    return distance


def hilbert_order(points: np.ndarray) -> np.ndarray:
    """Indices that sort ``points`` (n, 2) along a Hilbert curve over their bounding box
    (a 2^16 grid per axis; points sharing a cell keep their order)."""
    low = points.min(axis=0)
    extent = np.maximum(points.max(axis=0) - low, np.finfo(float).tiny)
    last = (1 << HILBERT_ORDER) - 1
    cells = np.floor((points - low) / extent * last).astype(np.int64)
    return np.argsort(hilbert_index(cells[:, 0], cells[:, 1], HILBERT_ORDER), kind="stable")


def systematic_seeding(
    points: np.ndarray,
    weights: np.ndarray,
    k: int,
    seed: int,
    curve_order: np.ndarray | None = None,
) -> np.ndarray:
    """Indices of k distinct points (n, 2) drawn systematically ∝ √``weights``.

    Along the Hilbert order of the points (``curve_order``, :func:`hilbert_order` of
    ``points`` when not given), centre j is the point
    where the cumulative √weight first reaches (j + u)/k of the total, with one offset u
    in [0, 1) from ``numpy.random.default_rng(seed)``. The curve keeps near points near
    in the order, so every stretch of the image gets centres in proportion to its
    √weight, and a small change of the weights moves only the picks near the change. The
    square root is the density of centres that minimises the weighted squared distance
    in two dimensions (high-resolution quantization: density ∝ w^(d/(d+2))); drawn ∝ w,
    the starts crowd the bright arcs, and 5 Lloyd iterations leave the weighted inertia
    60 % above k-means++'s on a 3″ mask (benchmarks/bench_kmeans.py). A point picked
    twice passes the later pick on to the next points along the curve.
    """
    order = hilbert_order(points) if curve_order is None else curve_order
    cumulative = np.cumsum(np.sqrt(weights[order]))
    offset = np.random.default_rng(seed).random()
    targets = (np.arange(k) + offset) / k * cumulative[-1]
    picks = np.minimum(np.searchsorted(cumulative, targets, side="right"), len(order) - 1)
    steps = np.arange(k)
    picks = np.maximum.accumulate(picks - steps) + steps  # strictly increasing
    picks = np.minimum(picks, len(order) - k + steps)  # and inside the order
    return order[picks]


@njit
def _bucket_grid(points, x0, y0, cell, nx, ny):
    """Points (n, 2) sorted into the cells of a grid: (cell of each point, start, order).

    Cell (i, j) spans [x0 + i·cell, x0 + (i+1)·cell) × [y0 + j·cell, …) and has index
    j·nx + i; ``order[start[c]:start[c+1]]`` are the indices of the points in cell c in
    increasing order. Points outside the grid go to its edge cells.
    """
    n = points.shape[0]
    cells = np.empty(n, dtype=np.int64)
    for i in range(n):
        cells[i] = _cell_of(points[i, 0], points[i, 1], x0, y0, cell, nx, ny)
    start = np.zeros(nx * ny + 1, dtype=np.int64)
    for i in range(n):
        start[cells[i] + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, dtype=np.int64)
    for i in range(n):
        order[fill[cells[i]]] = i
        fill[cells[i]] += 1
    return cells, start, order


@njit
def _cell_of(x, y, x0, y0, cell, nx, ny):
    """Index of the grid cell holding (x, y), clamped to the grid."""
    i = min(max(int((x - x0) / cell), 0), nx - 1)
    j = min(max(int((y - y0) / cell), 0), ny - 1)
    return j * nx + i


def _grid_geometry(corners, count, per_cell):
    """Origin, cell size and shape (x0, y0, cell, nx, ny) of a bucket grid over the
    bounding box of ``corners`` (m, 2) with about ``per_cell`` of ``count`` evenly spread
    items per cell."""
    low, high = corners.min(axis=0), corners.max(axis=0)
    extent = np.maximum(high - low, 1e-9 * max(float((high - low).max()), 1e-12))
    cell = float(np.sqrt(extent[0] * extent[1] * per_cell / count))
    nx, ny = (int(e / cell) + 1 for e in high - low)
    return float(low[0]), float(low[1]), cell, nx, ny


@njit
def _kmeans_plusplus(points, weights, k, trials, uniforms, grid):
    """Greedy weighted k-means++ seeding (scikit-learn's algorithm): (k, 2) centres.

    ``uniforms`` holds the 1 + (k − 1)·trials uniform draws in [0, 1) it consumes;
    ``grid`` = (x0, y0, cell, nx, ny) is a bucket grid over the points. A candidate's
    potential Σ w·min(closest, d²) is the current potential minus what the points it
    would take over gain (:func:`_gain`).
    """
    n = points.shape[0]
    x0, y0, cell, nx, ny = grid
    cells, start, order = _bucket_grid(points, x0, y0, cell, nx, ny)
    centres = np.empty((k, 2))
    cumulative = np.cumsum(weights)
    first = min(np.searchsorted(cumulative, uniforms[0] * cumulative[-1]), n - 1)
    draw = 1
    centres[0] = points[first]
    closest = np.empty(n)
    farthest = np.zeros(nx * ny)  # the largest `closest` in each cell
    for i in range(n):
        closest[i] = (points[i, 0] - centres[0, 0]) ** 2 + (points[i, 1] - centres[0, 1]) ** 2
        farthest[cells[i]] = max(farthest[cells[i]], closest[i])
    candidate_x = np.empty(trials)
    candidate_y = np.empty(trials)
    potentials = np.empty(trials)
    for c in range(1, k):
        total = 0.0
        for i in range(n):
            total += weights[i] * closest[i]
            cumulative[i] = total
        reach = np.sqrt(farthest.max())
        for t in range(trials):
            pick = min(np.searchsorted(cumulative, uniforms[draw] * cumulative[-1]), n - 1)
            draw += 1
            candidate_x[t], candidate_y[t] = points[pick, 0], points[pick, 1]
            potentials[t] = cumulative[-1] - _gain(
                points, weights, closest, farthest, candidate_x[t], candidate_y[t], reach,
                grid, start, order, False,
            )  # fmt: skip
        best = 0
        for t in range(1, trials):  # the first of equal potentials, as a strict < over trials
            if potentials[t] < potentials[best]:
                best = t
        centres[c, 0], centres[c, 1] = candidate_x[best], candidate_y[best]
        _gain(
            points, weights, closest, farthest, candidate_x[best], candidate_y[best], reach,
            grid, start, order, True,
        )  # fmt: skip
    return centres


@njit
def _gain(points, weights, closest, farthest, cx, cy, reach, grid, start, order, update):
    """Σ w·(closest − d²) over the points nearer to (cx, cy) than to their closest centre;
    with ``update`` their ``closest`` becomes d² and ``farthest`` follows.

    Only cells within ``reach`` (√ of the largest ``closest``) of (cx, cy) and nearer to it
    than their own ``farthest`` can hold such points.
    """
    x0, y0, cell, nx, ny = grid
    i_low = max(int((cx - reach - x0) / cell), 0)
    i_high = min(int((cx + reach - x0) / cell), nx - 1)
    j_low = max(int((cy - reach - y0) / cell), 0)
    j_high = min(int((cy + reach - y0) / cell), ny - 1)
    gain = 0.0
    for j in range(j_low, j_high + 1):
        dy = max(y0 + j * cell - cy, cy - (y0 + (j + 1) * cell), 0.0)
        for i in range(i_low, i_high + 1):
            c = j * nx + i
            dx = max(x0 + i * cell - cx, cx - (x0 + (i + 1) * cell), 0.0)
            if dx * dx + dy * dy >= farthest[c]:
                continue
            largest = 0.0
            for slot in range(start[c], start[c + 1]):
                p = order[slot]
                d = (points[p, 0] - cx) ** 2 + (points[p, 1] - cy) ** 2
                if d < closest[p]:
                    gain += weights[p] * (closest[p] - d)
                    if update:
                        closest[p] = d
                largest = max(largest, closest[p])
            if update:
                farthest[c] = largest
    return gain


def _lloyd(points, weights, centres, max_iter, tolerance):
    """At most ``max_iter`` weighted Lloyd iterations from ``centres`` (k, 2): new centres.

    scikit-learn's rules: stop when no label changed or the total squared centre shift is
    at most ``tolerance``; a cluster of zero weight takes the point farthest from its
    centre (the farthest for the lowest-numbered empty cluster), which leaves its old
    cluster.
    """
    k = len(centres)
    labels = np.full(len(points), -1, dtype=np.int64)
    box = np.vstack([points.min(axis=0), points.max(axis=0)])
    for _ in range(max_iter):
        corners = np.vstack([box, centres])
        grid = _grid_geometry(corners, k, LLOYD_CENTRES_PER_CELL)
        new_labels, distances = _nearest_centres(points, centres, *grid)
        new_centres = _weighted_means(points, weights, new_labels, distances, centres)
        shift = float(np.sum((new_centres - centres) ** 2))
        centres = new_centres
        if np.array_equal(new_labels, labels) or shift <= tolerance:
            break
        labels = new_labels
    return centres


@njit
def _nearest_centres(points, centres, x0, y0, cell, nx, ny):
    """Label (index of the nearest centre, the lowest of equals) and squared distance of
    every point; the grid (x0, y0, cell, nx, ny) covers points and centres.

    Cells are searched in square rings around the point's cell; once the best distance
    is below r·cell after ring r, no centre in a farther ring can be as near.
    """
    n = points.shape[0]
    _, start, order = _bucket_grid(centres, x0, y0, cell, nx, ny)
    labels = np.empty(n, dtype=np.int64)
    distances = np.empty(n)
    rings = max(nx, ny)
    for p in range(n):
        px, py = points[p, 0], points[p, 1]
        home = _cell_of(px, py, x0, y0, cell, nx, ny)
        ci, cj = home % nx, home // nx
        best, best_label = np.inf, -1
        for r in range(rings + 1):
            for j in range(max(cj - r, 0), min(cj + r, ny - 1) + 1):
                edge_row = j == cj - r or j == cj + r
                step = 1 if edge_row else 2 * r  # inner rows: only the ring's two ends
                for i in range(ci - r, ci + r + 1, step):
                    if i < 0 or i >= nx:
                        continue
                    c = j * nx + i
                    for slot in range(start[c], start[c + 1]):
                        m = order[slot]
                        d = (px - centres[m, 0]) ** 2 + (py - centres[m, 1]) ** 2
                        if d < best or (d == best and m < best_label):
                            best, best_label = d, m
            if best < (r * cell) ** 2:
                break
        labels[p] = best_label
        distances[p] = best
    return labels, distances


@njit
def _weighted_means(points, weights, labels, distances, centres):
    """Weighted mean of each cluster's points, (k, 2), after scikit-learn's relocation of
    clusters of zero weight (see :func:`_lloyd`). A cluster whose weight is still zero
    stays where it was, or on the point it was relocated to."""
    k = centres.shape[0]
    means = centres.copy()
    sums = np.zeros((k, 2))
    totals = np.zeros(k)
    for p in range(points.shape[0]):
        c = labels[p]
        sums[c, 0] += weights[p] * points[p, 0]
        sums[c, 1] += weights[p] * points[p, 1]
        totals[c] += weights[p]
    empty = np.nonzero(totals == 0.0)[0]
    if empty.size > 0:
        farthest = np.argsort(-distances, kind="mergesort")[: empty.size]
        for e in range(empty.size):
            p, new, old = farthest[e], empty[e], labels[farthest[e]]
            sums[old, 0] -= weights[p] * points[p, 0]
            sums[old, 1] -= weights[p] * points[p, 1]
            totals[old] -= weights[p]
            sums[new, 0] = weights[p] * points[p, 0]
            sums[new, 1] = weights[p] * points[p, 1]
            totals[new] = weights[p]
            means[new] = points[p]
    for c in range(k):
        if totals[c] > 0.0:
            means[c, 0], means[c, 1] = sums[c, 0] / totals[c], sums[c, 1] / totals[c]
    return means

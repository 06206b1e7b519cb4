"""Image-plane mesh centres (SPEC §4.1) and border relocation (§4.2)."""

import numpy as np
import pytest
from sklearn.cluster import KMeans

from mgelens.grid import pixel_centres, sub_grid
from mgelens.source.border import (
    _farthest_crossings,
    _ray_side_distance,
    border_pixels,
    border_sub_pixels,
    relocate_to_border,
)
from mgelens.source.image_mesh import (
    SEEDING_POINTS_PER_CELL,
    _grid_geometry,
    _kmeans_plusplus,
    _lloyd,
    _nearest_centres,
    floored_adapt_image,
    hilbert_index,
    hilbert_order,
    kmeans_centres,
    kmeans_weights,
    overlay_centres,
    systematic_seeding,
)


@pytest.mark.parametrize(("radius", "count", "spacing"), [(1.8, 904, 0.10735), (1.6, 856, 0.09559)])
def test_overlay_matches_spec_numbers(radius, count, spacing):
    x, y = pixel_centres((151, 151), 0.05)
    mask = np.hypot(x, y) > radius
    ox, oy = overlay_centres(mask, 0.05, (34, 34))
    assert ox.size == count
    assert np.diff(np.unique(np.round(ox, 8)))[0] == pytest.approx(spacing, abs=1e-5)
    # every kept point lies on an unmasked pixel
    cols = np.floor(ox / 0.05 + 151 / 2).astype(int)
    rows = np.floor(oy / 0.05 + 151 / 2).astype(int)
    assert not mask[rows, cols].any()


def test_kmeans_weight_schemes():
    adapt = np.array([0.0, 0.5, 1.0, 2.0])
    floored = floored_adapt_image(adapt)
    assert floored[0] == pytest.approx(0.02)
    w2023 = kmeans_weights(adapt, weight_floor=0.1, weight_power=2.0)
    scaled = (floored - 0.02) / (2.0 - 0.02)
    assert np.allclose(w2023, (scaled + 0.1 * 2.0) ** 2)
    assert np.allclose(kmeans_weights(adapt, 0.3, 0.0), 1.0)  # p = 0: uniform
    w2024 = kmeans_weights(adapt, weight_floor=0.2, weight_power=1.0, scheme="2024")
    assert np.allclose(w2024, np.maximum(floored / 2.0, 0.2))
    with pytest.raises(ValueError, match="scheme"):
        kmeans_weights(adapt, 0.1, 1.0, scheme="1999")
    with pytest.raises(ValueError, match="positive"):
        floored_adapt_image(np.zeros(3))


def test_kmeans_is_deterministic_and_follows_the_weights():
    x, y = pixel_centres((40, 40), 0.05)
    x, y = x.ravel(), y.ravel()
    bright = np.exp(-((x - 0.3) ** 2 + y**2) / (2 * 0.1**2))
    weights = kmeans_weights(bright, weight_floor=0.0, weight_power=3.0)
    a = kmeans_centres(x, y, weights, 60, seed=1)
    b = kmeans_centres(x, y, weights, 60, seed=1)
    assert np.array_equal(a[0], b[0])
    assert np.array_equal(a[1], b[1])
    # centres concentrate where the weights are: most within 0.3" of the bright spot
    near = np.hypot(a[0] - 0.3, a[1]) < 0.3
    assert near.mean() > 0.6
    with pytest.raises(ValueError, match="only"):
        kmeans_centres(x[:10], y[:10], weights[:10], 20)


def weighted_inertia(x, y, weights, cx, cy):
    distance = (x[:, None] - cx) ** 2 + (y[:, None] - cy) ** 2
    return float(np.sum(weights * distance.min(axis=1)))


def test_compiled_kmeans_plusplus_matches_scikit_learn_quality():
    """The numba seeding is scikit-learn's algorithm with another random stream: after the
    same 5 Lloyd iterations the weighted inertia matches scikit-learn's on average, and
    the seeds are distinct data points."""
    x, y = pixel_centres((61, 61), 0.05)
    used = np.hypot(x, y) < 1.4
    x, y = x[used], y[used]
    bright = np.exp(-((np.hypot(x, y) - 0.9) ** 2) / (2 * 0.15**2)) + 0.02
    weights = kmeans_weights(bright, weight_floor=0.1, weight_power=2.0)
    ours, reference = [], []
    for seed in range(6):
        ours.append(weighted_inertia(x, y, weights, *kmeans_centres(x, y, weights, 150, seed)))
        kmeans = KMeans(n_clusters=150, random_state=seed, n_init=1, max_iter=5)
        centres = kmeans.fit(np.column_stack([x, y]), sample_weight=weights).cluster_centers_
        reference.append(weighted_inertia(x, y, weights, centres[:, 0], centres[:, 1]))
    # (a weighted random start instead of k-means++ is 4.7 % worse; seed scatter 0.4 %)
    assert np.mean(ours) == pytest.approx(np.mean(reference), rel=0.015)
    points = np.column_stack([x, y])
    trials = 2 + int(np.log(150))
    uniforms = np.random.default_rng(0).random(1 + 149 * trials)
    grid = _grid_geometry(points, len(points), SEEDING_POINTS_PER_CELL)
    seeds = _kmeans_plusplus(points, weights, 150, trials, uniforms, grid)
    assert len(np.unique(seeds, axis=0)) == 150
    assert all((points == seed).all(axis=1).any() for seed in seeds)


@pytest.mark.parametrize("order", [1, 2, 4, 6])
def test_hilbert_index_walks_every_cell_once_in_edge_sharing_steps(order):
    side = 1 << order
    ix, iy = (a.ravel() for a in np.meshgrid(np.arange(side), np.arange(side)))
    distance = hilbert_index(ix, iy, order)
    assert np.array_equal(np.sort(distance), np.arange(side * side))
    path = np.empty((side * side, 2), dtype=int)
    path[distance] = np.column_stack([ix, iy])
    assert np.all(np.abs(np.diff(path, axis=0)).sum(axis=1) == 1)
    assert tuple(path[0]) == (0, 0)
    assert tuple(path[-1]) == (side - 1, 0)
    # the lower-left quadrant is the first stretch of the curve
    quadrant = distance // (side * side // 4)
    assert np.array_equal(np.unique(quadrant[(ix < side // 2) & (iy < side // 2)]), [0])


def seeding_lens():
    x, y = pixel_centres((81, 81), 0.05)
    used = np.hypot(x, y) < 1.8
    x, y = x[used], y[used]
    ring = np.exp(-((np.hypot(x - 0.1, y + 0.05) - 1.0) ** 2) / (2 * 0.12**2))
    return x, y, ring


def test_systematic_seeding_places_centres_in_proportion_to_the_root_weight():
    """Each stretch of the Hilbert order (hence each aligned block of the image) holds
    within one of k times its share of the √weight; the picks are k distinct points."""
    x, y, ring = seeding_lens()
    weights = kmeans_weights(ring, weight_floor=0.05, weight_power=2.0)
    points = np.column_stack([x, y])
    k = 300
    picks = systematic_seeding(points, weights, k, seed=3)
    assert len(np.unique(picks)) == k
    density = np.sqrt(weights)
    rank = np.empty(len(points), dtype=int)
    rank[hilbert_order(points)] = np.arange(len(points))
    for stretch in np.array_split(np.arange(len(points)), 7):
        inside = np.isin(rank, stretch)
        expected = k * density[inside].sum() / density.sum()
        assert abs(np.isin(picks, np.nonzero(inside)[0]).sum() - expected) <= 1.0
    # centres left of x = 0 against the √weight there (a half-plane is not one stretch)
    left = x < 0
    share = density[left].sum() / density.sum()
    assert left[picks].mean() == pytest.approx(share, abs=0.03)
    arcs = np.abs(np.hypot(x - 0.1, y + 0.05) - 1.0) < 0.15
    assert arcs[picks].mean() == pytest.approx(density[arcs].sum() / density.sum(), abs=0.03)
    assert weights[arcs].sum() / weights.sum() > arcs[picks].mean() + 0.1  # not ∝ weight


def test_systematic_seeding_passes_a_heavy_points_extra_picks_along_the_curve():
    x, y, _ring = seeding_lens()
    points = np.column_stack([x, y])
    weights = np.full(x.size, 1e-6)
    weights[100] = 1.0  # one point holds a fifth of the √weight: about 10 of 50 picks
    picks = systematic_seeding(points, weights, 50, seed=0)
    assert len(np.unique(picks)) == 50
    rank = np.empty(len(points), dtype=int)
    rank[hilbert_order(points)] = np.arange(len(points))
    heavy = int(50 / (1.0 + 1e-3 * (x.size - 1))) - 1
    assert heavy >= 8
    # it keeps one and hands the others on to the points that follow it along the curve
    assert set(range(rank[100], rank[100] + heavy)) <= set(rank[picks])


def test_systematic_mesh_moves_little_when_the_weights_change_slightly():
    """A 10⁻⁴ change of the weight floor moves a few systematic starts and the mesh by a
    small fraction of a cell; the anchor's k-means++ moves most of its centres by a cell
    or more (the cause of SPix2's spikes in ln ε, docs/slam.md)."""
    x, y, ring = seeding_lens()
    k = 250
    cell = np.sqrt(np.pi * 1.8**2 / k)

    def moved(seeding):
        meshes = [
            np.column_stack(
                kmeans_centres(x, y, kmeans_weights(ring, floor, 1.5), k, seed=2, seeding=seeding)
            )
            for floor in (0.2, 0.2 * (1 + 1e-4))
        ]
        nearest = np.hypot(*(meshes[0][:, None, :] - meshes[1][None, :, :]).T).min(axis=0)
        return np.median(nearest) / cell, np.mean(nearest > 0.5 * cell), nearest.max() / cell

    # measured: systematic 1e-6, 0 and 0.17 cells; k-means++ 0.29, 20 % and 0.82
    systematic, anchor = moved("systematic"), moved("kmeans++")
    assert systematic[0] < 0.01
    assert systematic[1] == 0.0
    assert systematic[2] < 0.5
    assert anchor[0] > 0.1
    assert anchor[1] > 0.1


def test_systematic_mesh_is_as_tight_as_the_anchors_and_seeded():
    """After the same 5 Lloyd iterations the systematic start's weighted inertia is within
    a few per cent of k-means++'s (drawn ∝ weight instead of √weight it was 10 % above
    on this lens); a fixed seed repeats the mesh, another seed moves it."""
    x, y, ring = seeding_lens()
    weights = kmeans_weights(ring, weight_floor=0.1, weight_power=2.0)
    inertia = {
        seeding: np.mean(
            [
                weighted_inertia(
                    x, y, weights, *kmeans_centres(x, y, weights, 200, s, seeding=seeding)
                )
                for s in range(4)
            ]
        )
        for seeding in ("kmeans++", "systematic")
    }
    assert inertia["systematic"] == pytest.approx(inertia["kmeans++"], rel=0.03)
    a, b = (kmeans_centres(x, y, weights, 200, 5, seeding="systematic") for _ in range(2))
    assert np.array_equal(a[0], b[0])
    assert np.array_equal(a[1], b[1])
    other = kmeans_centres(x, y, weights, 200, 6, seeding="systematic")
    assert not np.allclose(a[0], other[0])
    with pytest.raises(ValueError, match="seeding"):
        kmeans_centres(x, y, weights, 200, seeding="random")


@pytest.mark.parametrize("iterations", [1, 2, 5])
def test_lloyd_iterations_equal_scikit_learns_from_the_same_seeds(iterations):
    """Away from ties (random points and weights) the compiled Lloyd iterations give
    scikit-learn's centres to rounding, whatever the spread of the centres (a dense
    cluster and sparse outskirts exercise the bucket grid's ring search)."""
    rng = np.random.default_rng(7)
    points = np.vstack([rng.normal(0.4, 0.3, (2500, 2)), rng.uniform(-3.0, 3.0, (1500, 2))])
    weights = rng.uniform(0.01, 1.0, len(points)) * (1 + 20 * (np.hypot(*points.T) < 0.8))
    seeds = points[rng.choice(len(points), 300, replace=False)]
    ours = _lloyd(points, weights, seeds, iterations, 0.0)
    kmeans = KMeans(n_clusters=300, init=seeds, n_init=1, max_iter=iterations, tol=0.0)
    theirs = kmeans.fit(points, sample_weight=weights).cluster_centers_
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-12)


def test_nearest_centres_match_brute_force_and_break_ties_to_the_lower_index():
    x, y = pixel_centres((60, 60), 0.05)
    points = np.column_stack([x.ravel(), y.ravel()])
    rng = np.random.default_rng(2)
    # centres on pixel centres: many points lie at equal distances from two of them
    centres = points[rng.choice(len(points), 90, replace=False)][::-1].copy()
    corners = np.vstack([points.min(axis=0), points.max(axis=0), centres])
    labels, distances = _nearest_centres(points, centres, *_grid_geometry(corners, 90, 2.0))
    brute = ((points[:, None, :] - centres[None]) ** 2).sum(axis=2)
    np.testing.assert_array_equal(labels, np.argmin(brute, axis=1))  # argmin: first minimum
    np.testing.assert_array_equal(distances, brute.min(axis=1))
    assert (np.sum(brute == brute.min(axis=1)[:, None], axis=1) > 1).sum() > 50


def test_an_empty_cluster_takes_the_point_farthest_from_its_centre():
    """Two centres on the same point: the second cluster gets no point and is moved, as in
    scikit-learn, onto the point farthest from its centre, which leaves its cluster."""
    points = np.array([[0.0, 0.0], [0.1, 0.0], [1.0, 0.0], [5.0, 0.0]])
    weights = np.array([1.0, 1.0, 1.0, 2.0])
    seeds = np.array([[0.0, 0.0], [0.0, 0.0], [5.0, 0.0]])
    centres = _lloyd(points, weights, seeds, 1, 0.0)
    # cluster 0 holds points 0-2; point 2 is the farthest from its centre (1.0)
    np.testing.assert_allclose(centres, [[0.05, 0.0], [1.0, 0.0], [5.0, 0.0]], atol=1e-15)
    kmeans = KMeans(n_clusters=3, init=seeds, n_init=1, max_iter=1, tol=0.0)
    theirs = kmeans.fit(points, sample_weight=weights).cluster_centers_
    np.testing.assert_allclose(centres, theirs, atol=1e-12)


def anchor_border_pixels(mask):
    """Brute force of the anchor's border: an unmasked pixel with a masked 8-neighbour
    from which one of the four axis directions reaches the array edge through masked
    pixels only."""
    border = []
    rows, cols = np.nonzero(~mask)
    padded = np.pad(mask, 1, constant_values=True)
    for k, (r, c) in enumerate(zip(rows, cols, strict=True)):
        if not padded[r : r + 3, c : c + 3].any():
            continue
        if (
            mask[:r, c].all()
            or mask[r + 1 :, c].all()
            or mask[r, :c].all()
            or mask[r, c + 1 :].all()
        ):
            border.append(k)
    return border


@pytest.mark.parametrize("inner", [0.0, 0.35])
def test_border_pixels_and_their_outermost_sub_pixels(inner):
    x, y = pixel_centres((21, 21), 0.1)
    r = np.hypot(x, y)
    mask = (r > 0.75) | (r < inner)
    pixels = border_pixels(mask)
    assert pixels.tolist() == anchor_border_pixels(mask)
    # the exterior edge only: of the 56 pixels with a masked 8-neighbour on the outer
    # edge, the 16 that touch it only diagonally are left out, and so is the annulus's
    # inner edge
    assert pixels.size == 40
    assert r[~mask][pixels].min() > 0.6
    used = ~mask
    grid = sub_grid(x[used], y[used], 0.1, 4)
    border = border_sub_pixels(mask, grid.x, grid.y, 4, (0.0, 0.0))
    assert np.sort(border // 16).tolist() == pixels.tolist()  # one per border pixel
    r_sub = np.hypot(grid.x, grid.y)
    for index in border:
        own = r_sub[index // 16 * 16 : (index // 16 + 1) * 16]
        assert r_sub[index] == own.max()
    # in order along the mask edge (polar angle), the sides of the border polygon
    assert np.all(np.diff(np.arctan2(grid.y[border], grid.x[border])) > 0)


def test_relocation_pulls_outliers_onto_the_border_only():
    angles = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    bx, by = np.cos(angles), np.sin(angles)  # unit-circle border around the origin
    px = np.array([0.2, 0.9, 3.0, -2.0, 0.0])
    py = np.array([0.1, 0.0, 0.0, 2.0, -1.5])
    new_x, new_y = relocate_to_border(px, py, bx, by)
    r_new = np.hypot(new_x, new_y)
    assert np.allclose(new_x[:2], px[:2])
    assert np.allclose(new_y[:2], py[:2])
    assert np.allclose(r_new[2:], 1.0, atol=2e-4)
    # moved radially: direction kept
    assert np.allclose(np.arctan2(new_y[2:], new_x[2:]), np.arctan2(py[2:], px[2:]))
    assert px[2] == 3.0  # inputs untouched


def regular_polygon_radius(theta: np.ndarray, n_sides: int) -> np.ndarray:
    """Distance from the centre of the regular n-gon with vertices at angles 2πk/n on the
    unit circle to its boundary in direction θ."""
    half = np.pi / n_sides
    offset = (theta % (2 * half)) - half  # angle from the nearest side's normal
    return np.cos(half) / np.cos(offset)


@pytest.mark.parametrize("reverse", [False, True])
def test_polygon_rule_moves_points_onto_the_border_polygon(reverse):
    n = 12
    angles = 2 * np.pi * np.arange(n) / n
    bx, by = np.cos(angles), np.sin(angles)
    if reverse:  # clockwise order describes the same polygon
        bx, by = bx[::-1], by[::-1]
    rng = np.random.default_rng(2)
    theta = rng.uniform(-np.pi, np.pi, 500)
    r = rng.uniform(0.0, 3.0, 500)
    px, py = r * np.cos(theta), r * np.sin(theta)
    new_x, new_y = relocate_to_border(px, py, bx, by, rule="polygon")
    boundary = regular_polygon_radius(theta, n)
    outside = r > boundary
    np.testing.assert_allclose(np.hypot(new_x, new_y)[outside], boundary[outside], rtol=1e-12)
    np.testing.assert_allclose(np.arctan2(new_y, new_x)[outside], theta[outside], atol=1e-12)
    np.testing.assert_array_equal(new_x[~outside], px[~outside])
    # the anchor's rule leaves points between the polygon and the vertex radius 1 alone
    anchor_x, anchor_y = relocate_to_border(px, py, bx, by)
    assert np.all(np.hypot(anchor_x, anchor_y) <= 1.0 + 1e-12)
    assert np.any(np.hypot(anchor_x, anchor_y)[outside] > boundary[outside] + 1e-3)


def test_polygon_rule_on_a_polygon_that_is_not_star_shaped_takes_the_farthest_crossing():
    # a square with a notch whose walls fold back in angle, seen from the mean vertex
    bx = np.array([1.0, 1.0, -0.2, 0.9, -1.0, -1.0, 1.0])
    by = np.array([-1.0, 1.0, 1.0, 0.2, 1.0, -1.0, -1.0])[:-1]
    bx = bx[:-1]
    px, py = np.array([0.3, 5.0, 0.0]), np.array([5.0, 0.5, -4.0])
    ox, oy = bx.mean(), by.mean()
    expected = []
    for x, y in zip(px, py, strict=True):
        u = np.array([x - ox, y - oy]) / np.hypot(x - ox, y - oy)
        crossings = []
        for k in range(bx.size):
            a = np.array([bx[k], by[k]])
            e = np.array([bx[(k + 1) % bx.size], by[(k + 1) % by.size]]) - a
            s, t = np.linalg.solve(np.column_stack([u, -e]), a - np.array([ox, oy]))
            if s > 0 and 0 <= t <= 1:
                crossings.append(s)
        expected.append(max(crossings))
    new_x, new_y = relocate_to_border(px, py, bx, by, rule="polygon")
    np.testing.assert_allclose(np.hypot(new_x - ox, new_y - oy), expected, rtol=1e-12)


def test_farthest_crossings_equal_the_broadcast_of_every_side_bit_for_bit():
    """The compiled loop over a polygon's sides gives the farthest crossing per ray to the
    last bit of the (rays × sides) broadcast of `_ray_side_distance`, on polygons that
    fold back and cross themselves, with a side along a ray and rays of zero length."""
    rng = np.random.default_rng(3)
    for trial in range(60):
        n = int(rng.integers(3, 120))
        theta = rng.uniform(0.0, 2.0 * np.pi, n)
        if trial % 2:
            theta.sort()
        radius = rng.uniform(0.2, 2.0, n)
        vx, vy = radius * np.cos(theta), radius * np.sin(theta)
        if trial % 7 == 0:
            vx[:2], vy[:2] = 0.0, [0.5, 1.0]  # a side along the ray towards +y
        dx, dy = rng.normal(size=500), rng.normal(size=500)
        dx[:2], dy[:2] = 0.0, [0.0, 1.0]
        with np.errstate(divide="ignore", invalid="ignore"):
            expected = _ray_side_distance(dx[:, None], dy[:, None], vx, vy, np.arange(n)).max(
                axis=1
            )
            farthest = _farthest_crossings(dx, dy, vx, vy)
        assert np.array_equal(farthest, expected)
        assert np.isfinite(farthest[2:]).any()


def test_polygon_rule_is_continuous_and_the_nearest_point_rule_is_not():
    """A point circling outside an elliptical border in steps of 1e−4 rad: its relocated
    position moves by O(step) under the polygon rule; under the anchor's rule it jumps
    whenever its nearest border point changes."""
    angles = np.linspace(-np.pi, np.pi, 80, endpoint=False)
    bx, by = 2.0 * np.cos(angles), np.sin(angles)
    theta = np.arange(0.0, 2.0, 1e-4)
    px, py = 3.0 * np.cos(theta), 3.0 * np.sin(theta)
    jumps = {}
    for rule in ("nearest_point", "polygon"):
        new_x, new_y = relocate_to_border(px, py, bx, by, rule=rule)
        jumps[rule] = np.hypot(np.diff(new_x), np.diff(new_y)).max()
    assert jumps["nearest_point"] > 0.01
    assert jumps["polygon"] < 3e-4


def test_an_unknown_border_rule_is_refused():
    with pytest.raises(ValueError, match="border rule"):
        relocate_to_border(np.zeros(3), np.zeros(3), np.ones(4), np.ones(4), rule="radial")


def reference_greedy_seeding(points, weights, k, trials, uniforms):
    """Greedy weighted k-means++ written plainly: one numpy pass per candidate."""
    n = len(points)
    cumulative = np.cumsum(weights)
    first = min(np.searchsorted(cumulative, uniforms[0] * cumulative[-1]), n - 1)
    centres, draw = [points[first]], 1
    closest = np.sum((points - points[first]) ** 2, axis=1)
    for _ in range(1, k):
        cumulative = np.cumsum(weights * closest)
        best = None
        for _ in range(trials):
            pick = min(np.searchsorted(cumulative, uniforms[draw] * cumulative[-1]), n - 1)
            draw += 1
            candidate = np.minimum(closest, np.sum((points - points[pick]) ** 2, axis=1))
            potential = np.sum(weights * candidate)
            if best is None or potential < best[0]:
                best = (potential, pick, candidate)
        centres.append(points[best[1]])
        closest = best[2]
    return np.array(centres)


def test_compiled_kmeans_plusplus_is_the_plain_greedy_algorithm():
    """All candidates of a step are scored in one pass over the points; the centres are
    those of the plain one-pass-per-candidate algorithm (random weights: no ties)."""
    rng = np.random.default_rng(5)
    points = rng.uniform(-1.5, 1.5, (700, 2))
    weights = rng.uniform(0.01, 1.0, 700)
    k = 90
    trials = 2 + int(np.log(k))
    uniforms = rng.random(1 + (k - 1) * trials)
    grid = _grid_geometry(points, len(points), SEEDING_POINTS_PER_CELL)
    np.testing.assert_array_equal(
        _kmeans_plusplus(points, weights, k, trials, uniforms, grid),
        reference_greedy_seeding(points, weights, k, trials, uniforms),
    )

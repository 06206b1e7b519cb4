"""Natural-neighbour (Sibson) and nearest-cell weights, cross points (SPEC §4.4, §5.3).

The reference is a brute-force Sibson interpolant that knows nothing of Delaunay triangles
or Watson's formula: the Voronoi cell of the query in the diagram with the query inserted
is a big box clipped by the perpendicular bisectors between the query and every mesh point;
the weight of mesh point j is the area of that cell inside j's old Voronoi cell (the cell
clipped by the bisectors between j and every other mesh point) over the cell's area.
"""

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from mgelens.source.interpolate import (
    MIN_TASK_SIZE,
    SLAB_SLOTS_PER_QUERY,
    cross_points,
    natural_neighbour_weights,
    nearest_cell_weights,
)
from mgelens.source.mesh import RING_POINTS, RING_RADIUS, MeshError, VoronoiMesh

# ----------------------------------------------------------------- brute-force Sibson oracle


def clip(polygon: list, normal: np.ndarray, offset: float) -> list:
    """Sutherland–Hodgman: the part of a convex polygon with normal · p ≤ offset."""
    kept = []
    for i, p in enumerate(polygon):
        q = polygon[(i + 1) % len(polygon)]
        fp, fq = normal @ p - offset, normal @ q - offset
        if fp <= 0.0:
            kept.append(p)
        if fp * fq < 0.0:
            kept.append(p + fp / (fp - fq) * (q - p))
    return kept


def polygon_area(polygon: list) -> float:
    if len(polygon) < 3:
        return 0.0
    p = np.array(polygon)
    return 0.5 * float(
        np.dot(p[:, 0], np.roll(p[:, 1], -1)) - np.dot(p[:, 1], np.roll(p[:, 0], -1))
    )


def closer_to(polygon: list, site: np.ndarray, others: np.ndarray) -> list:
    """Part of ``polygon`` closer to ``site`` than to any of ``others``.

    Bisectors are applied nearest first and stop once they are farther from ``site`` than
    every polygon vertex, after which none can cut.
    """
    others = others[np.argsort(((others - site) ** 2).sum(axis=1))]
    for other in others:
        if not polygon:
            break
        reach = max(np.linalg.norm(p - site) for p in polygon)
        if np.linalg.norm(other - site) > 2.0 * reach:
            break
        polygon = clip(polygon, other - site, 0.5 * (other @ other - site @ site))
    return polygon


def brute_force_sibson(points: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Dense Sibson weights of ``query`` (inside the hull) by polygon clipping."""
    size = 100.0 * np.ptp(points, axis=0).max()
    box = [query + size * np.array(corner) for corner in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    cell = closer_to(box, query, points)
    area = polygon_area(cell)
    reach = max(np.linalg.norm(p - query) for p in cell)
    weights = np.zeros(len(points))
    for j in np.flatnonzero(np.linalg.norm(points - query, axis=1) <= 2.0 * reach):
        others = np.delete(points, j, axis=0)
        weights[j] = polygon_area(closer_to(cell, points[j], others)) / area
    return weights


# ----------------------------------------------------------------------------------- helpers


def random_disc(seed: int, n: int, radius: float = 1.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    r = radius * np.sqrt(rng.random(n))
    theta = 2 * np.pi * rng.random(n)
    return np.column_stack([r * np.cos(theta), r * np.sin(theta)])


def mesh_of(points: np.ndarray) -> VoronoiMesh:
    return VoronoiMesh.from_points(points[:, 0], points[:, 1])


def dense(mesh: VoronoiMesh, queries: np.ndarray, weights=natural_neighbour_weights) -> np.ndarray:
    indptr, indices, values = weights(mesh, queries[:, 0], queries[:, 1])
    out = np.zeros((len(queries), mesh.n_points))
    rows = np.repeat(np.arange(len(queries)), np.diff(indptr))
    out[rows, indices] = values
    return out


def inside_hull(points: np.ndarray, queries: np.ndarray, margin: float) -> np.ndarray:
    """Queries at least ``margin`` inside the convex hull of ``points``."""
    equations = ConvexHull(points).equations
    distance = queries @ equations[:, :2].T + equations[:, 2]
    return queries[(distance <= -margin).all(axis=1)]


@pytest.fixture(scope="module")
def mesh() -> VoronoiMesh:
    return mesh_of(random_disc(11, 400))


# ------------------------------------------------------------------------------------- tests


@pytest.mark.parametrize(("seed", "n_points"), [(0, 30), (1, 60), (2, 120), (3, 200)])
def test_weights_match_brute_force_sibson(seed, n_points):
    points = random_disc(seed, n_points)
    queries = inside_hull(points, random_disc(seed + 100, 60), margin=0.1)[:12]
    assert len(queries) >= 8
    ours = dense(mesh_of(points), queries)
    for q, row in zip(queries, ours, strict=True):
        np.testing.assert_allclose(row, brute_force_sibson(points, q), rtol=0, atol=1e-10)


def test_weights_reproduce_linear_functions(mesh):
    queries = inside_hull(mesh.points, random_disc(5, 4000), margin=1e-3)
    weights = dense(mesh, queries)
    np.testing.assert_allclose(weights @ mesh.points, queries, rtol=0, atol=1e-12)
    linear = 2.0 + 3.0 * mesh.points[:, 0] - 5.0 * mesh.points[:, 1]
    np.testing.assert_allclose(
        weights @ linear, 2.0 + 3.0 * queries[:, 0] - 5.0 * queries[:, 1], rtol=0, atol=1e-11
    )


def test_rows_are_sorted_positive_and_sum_to_one(mesh):
    queries = random_disc(6, 5000, radius=1.2)  # some outside the hull
    indptr, indices, values = natural_neighbour_weights(mesh, queries[:, 0], queries[:, 1])
    assert (indptr.dtype, indices.dtype, values.dtype) == (np.int64, np.int64, np.float64)
    assert indptr[0] == 0
    assert indptr[-1] == len(indices) == len(values)
    assert (np.diff(indptr) >= 1).all()
    assert ((indices >= 0) & (indices < mesh.n_points)).all()
    assert (values > 0).all()
    rows = np.repeat(np.arange(len(queries)), np.diff(indptr))
    np.testing.assert_allclose(np.bincount(rows, weights=values), 1.0, rtol=0, atol=1e-12)
    same_row = rows[1:] == rows[:-1]
    assert (np.diff(indices)[same_row] > 0).all()


def test_weights_are_continuous_in_the_query_position(mesh):
    rng = np.random.default_rng(7)
    queries = inside_hull(mesh.points, random_disc(8, 2000), margin=1e-3)
    steps = 1e-7 * rng.normal(size=queries.shape)
    change = np.abs(dense(mesh, queries + steps) - dense(mesh, queries))
    assert change.max() < 1e-4


@pytest.mark.parametrize("fraction", [0.5, 0.3])
def test_weights_are_continuous_across_triangle_edges(mesh, fraction):
    interior = ~mesh.edge_pixels[mesh.edges].any(axis=1)
    a, b = (mesh.points[mesh.edges[interior, k]] for k in (0, 1))
    on_edge = a + fraction * (b - a)  # Watson's formula is singular exactly here
    normal = np.column_stack([a[:, 1] - b[:, 1], b[:, 0] - a[:, 0]])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    on = dense(mesh, on_edge)
    for side in (1e-7, -1e-7):
        assert np.abs(dense(mesh, on_edge + side * normal) - on).max() < 1e-4
    # The singular case averages the weights at x ± 1e-5·(edge length): linear precision
    # survives up to the round-off of those nearly singular points, and the weights stay
    # within the O(1e-5²) averaging error of the exact ones.
    np.testing.assert_allclose(on @ mesh.points, on_edge, rtol=0, atol=1e-10)
    for i in range(0, len(on_edge), max(1, len(on_edge) // 8)):
        np.testing.assert_allclose(on[i], brute_force_sibson(mesh.points, on_edge[i]), atol=1e-6)


def test_symmetric_lattice_cell_centre_splits_evenly():
    x, y = np.meshgrid(np.arange(6) * 0.1, np.arange(6) * 0.1)
    lattice = VoronoiMesh.from_points(x.ravel(), y.ravel())
    centres = np.array([[0.25, 0.25], [0.15, 0.35], [0.05, 0.05]])  # co-circular cavities
    weights = dense(lattice, centres)
    np.testing.assert_allclose(np.sort(weights, axis=1)[:, -4:], 0.25, rtol=0, atol=1e-8)
    np.testing.assert_allclose(weights @ lattice.points, centres, rtol=0, atol=1e-12)
    midpoints = np.array([[0.25, 0.2], [0.3, 0.15]])
    for q, row in zip(midpoints, dense(lattice, midpoints), strict=True):
        np.testing.assert_allclose(row, brute_force_sibson(lattice.points, q), atol=1e-8)


def test_query_on_a_mesh_point_gets_weight_one(mesh):
    jitter = 1e-14 * np.random.default_rng(9).normal(size=mesh.points.shape)
    for queries in (mesh.points, mesh.points + jitter):
        indptr, indices, values = natural_neighbour_weights(mesh, queries[:, 0], queries[:, 1])
        np.testing.assert_array_equal(indptr, np.arange(mesh.n_points + 1))
        np.testing.assert_array_equal(indices, np.arange(mesh.n_points))
        np.testing.assert_array_equal(values, 1.0)


def test_query_outside_the_hull_gets_its_nearest_point(mesh):
    queries = random_disc(10, 3000, radius=3.0)
    outside = queries[np.linalg.norm(queries, axis=1) > 1.0]
    weights = dense(mesh, outside)
    nearest = np.argmin(((outside[:, None, :] - mesh.points[None]) ** 2).sum(axis=2), axis=1)
    np.testing.assert_array_equal(weights, np.eye(mesh.n_points)[nearest])


def test_nearest_cell_weights_pick_the_closest_point(mesh):
    queries = random_disc(12, 5000, radius=1.5)
    indptr, indices, values = nearest_cell_weights(mesh, queries[:, 0], queries[:, 1])
    nearest = np.argmin(((queries[:, None, :] - mesh.points[None]) ** 2).sum(axis=2), axis=1)
    np.testing.assert_array_equal(indptr, np.arange(len(queries) + 1))
    np.testing.assert_array_equal(indices, nearest)
    np.testing.assert_array_equal(values, 1.0)


def test_long_rows_overflowing_the_first_pass_are_recomputed():
    rng = np.random.default_rng(13)
    theta = np.sort(2 * np.pi * rng.random(60))
    radius = 1.0 + 1e-3 * rng.random(60)
    ring = np.column_stack([radius * np.cos(theta), radius * np.sin(theta)])
    points = np.vstack([ring, [[0.6, 0.0]]])
    wide = mesh_of(points)
    queries = np.column_stack([-0.5 + 0.05 * rng.random(1024), 0.01 * rng.random(1024)])
    indptr, indices, values = natural_neighbour_weights(wide, queries[:, 0], queries[:, 1])
    assert np.diff(indptr).mean() > SLAB_SLOTS_PER_QUERY
    for i in range(0, len(queries), 97):
        one = natural_neighbour_weights(wide, queries[i : i + 1, 0], queries[i : i + 1, 1])
        np.testing.assert_array_equal(indices[indptr[i] : indptr[i + 1]], one[1])
        np.testing.assert_array_equal(values[indptr[i] : indptr[i + 1]], one[2])
    np.testing.assert_allclose(
        brute_force_sibson(points, queries[0]), dense(wide, queries[:1])[0], atol=1e-10
    )


def test_results_do_not_depend_on_the_split_into_thread_tasks(mesh):
    queries = random_disc(14, 5 * MIN_TASK_SIZE, radius=1.1)  # several tasks
    for weights in (natural_neighbour_weights, nearest_cell_weights):
        indptr, indices, values = weights(mesh, queries[:, 0], queries[:, 1])
        pieces = [weights(mesh, q[:, 0], q[:, 1]) for q in np.array_split(queries, 7)]
        offsets = np.cumsum([0] + [p[0][-1] for p in pieces[:-1]])
        joined = np.concatenate([p[0][:-1] + o for p, o in zip(pieces, offsets, strict=True)])
        np.testing.assert_array_equal(indptr, np.append(joined, indptr[-1]))
        np.testing.assert_array_equal(indices, np.concatenate([p[1] for p in pieces]))
        np.testing.assert_array_equal(values, np.concatenate([p[2] for p in pieces]))


def test_too_many_neighbours_and_bad_queries_raise(mesh):
    with pytest.raises(MeshError, match="more than 3 natural neighbours"):
        natural_neighbour_weights(mesh, np.array([0.01]), np.array([0.02]), max_neighbours=3)
    with pytest.raises(ValueError, match="at least 3"):
        natural_neighbour_weights(mesh, np.array([0.0]), np.array([0.0]), max_neighbours=2)
    with pytest.raises(MeshError, match="non-finite"):
        natural_neighbour_weights(mesh, np.array([0.0, np.nan]), np.array([0.0, 0.0]))
    indptr, indices, values = natural_neighbour_weights(mesh, np.empty(0), np.empty(0))
    assert indptr.tolist() == [0]
    assert len(indices) == len(values) == 0


@pytest.mark.parametrize(("offset", "delta"), [("anchor", 0.5), ("paper", np.sqrt(0.5))])
def test_cross_points_sit_on_an_axis_aligned_cross(mesh, offset, delta):
    cross = cross_points(mesh, offset).reshape(mesh.n_points, 4, 2)
    step = delta * np.sqrt(mesh.areas)
    p = mesh.points
    np.testing.assert_allclose(cross[:, 0], p + np.column_stack([step, 0 * step]), atol=1e-15)
    np.testing.assert_allclose(cross[:, 1], p - np.column_stack([step, 0 * step]), atol=1e-15)
    np.testing.assert_allclose(cross[:, 2], p + np.column_stack([0 * step, step]), atol=1e-15)
    np.testing.assert_allclose(cross[:, 3], p - np.column_stack([0 * step, step]), atol=1e-15)


def test_cross_points_reject_an_unknown_offset(mesh):
    with pytest.raises(ValueError, match="anchor"):
        cross_points(mesh, "dual")


# ------------------------------------------------------------- the continuous edge rule


def continuous_mesh_of(points: np.ndarray) -> VoronoiMesh:
    return VoronoiMesh.from_points(points[:, 0], points[:, 1], edge_rule="continuous")


@pytest.mark.parametrize("seed", [0, 1])
def test_continuous_rule_is_sibson_over_the_ringed_mesh_without_the_ring(seed):
    points = random_disc(seed, 60)
    mesh = continuous_mesh_of(points)
    ring = mesh.ringed.points[mesh.n_points :]
    assert len(ring) == RING_POINTS
    centre = points.mean(axis=0)
    np.testing.assert_allclose(
        np.hypot(*(ring - centre).T), RING_RADIUS * np.hypot(*(points - centre).T).max()
    )
    rng = np.random.default_rng(seed)
    queries = rng.uniform(-1.6, 1.6, (40, 2))  # inside and outside the hull of the points
    weights = dense(mesh, queries)
    for query, row in zip(queries, weights, strict=True):
        expected = brute_force_sibson(mesh.ringed.points, query)[: mesh.n_points]
        np.testing.assert_allclose(row, expected / expected.sum(), atol=1e-10)


def test_continuous_rule_keeps_plain_sibson_weights_away_from_the_hull(mesh):
    points = mesh.points
    queries = inside_hull(points, random_disc(5, 3000), margin=0.15)
    continuous = continuous_mesh_of(points)
    np.testing.assert_allclose(dense(continuous, queries), dense(mesh, queries), atol=1e-12)


def test_continuous_rule_weights_change_smoothly_across_the_hull(mesh):
    """A query walking out through the hull in steps of 1e−4: the anchor's rows jump to the
    nearest point at the crossing, the continuous rule's rows change by O(step)."""
    continuous = continuous_mesh_of(mesh.points)
    hull = ConvexHull(mesh.points)
    a, b = mesh.points[hull.simplices[0]]
    normal = hull.equations[0, :2]  # outward
    queries = 0.5 * (a + b) + (np.arange(1000)[:, None] - 500) * 1e-4 * normal
    anchor_steps = np.abs(np.diff(dense(mesh, queries), axis=0)).max(axis=1)
    continuous_rows = dense(continuous, queries)
    continuous_steps = np.abs(np.diff(continuous_rows, axis=0)).max(axis=1)
    assert np.all(continuous_rows >= 0)
    assert np.allclose(continuous_rows.sum(axis=1), 1.0)
    assert anchor_steps.max() > 0.3
    assert continuous_steps.max() < 0.01


def test_continuous_rule_weights_change_smoothly_as_a_point_leaves_the_hull():
    """A hull vertex moves inwards through the hull edge of its two neighbours: fixed
    queries around it, inside and outside the hull, see continuous weights: halving the
    step halves the largest change of a weight (Lipschitz), while the anchor's rows jump
    by the same amount at any step."""
    points = random_disc(3, 80)
    hull = ConvexHull(points).vertices
    k = hull[0]
    a, b = points[hull[-1]], points[hull[1]]
    foot = a + np.dot(points[k] - a, b - a) / np.dot(b - a, b - a) * (b - a)
    paths = [points[k] + np.linspace(0.0, 1.3, n)[:, None] * (foot - points[k]) for n in (400, 799)]
    queries = points[k] + 0.3 * (foot - points[k]) + 0.03 * random_disc(4, 50)
    queries = np.vstack(
        [queries, foot + 0.02 * (foot - points[k]) / np.linalg.norm(foot - points[k])]
    )
    steps = {}
    for rule in ("anchor", "continuous"):
        for path in paths:
            rows = []
            for position in path:
                moved = points.copy()
                moved[k] = position
                mesh = VoronoiMesh.from_points(moved[:, 0], moved[:, 1], edge_rule=rule)
                rows.append(dense(mesh, queries))
            steps[rule, len(path)] = np.abs(np.diff(np.array(rows), axis=0)).max()
    assert steps["anchor", 799] > 0.2
    assert steps["anchor", 799] > 0.9 * steps["anchor", 400]
    assert steps["continuous", 799] < 0.6 * steps["continuous", 400]
    assert steps["continuous", 799] < 0.05


def test_continuous_rule_outside_the_ring_falls_back_to_the_nearest_point(mesh):
    continuous = continuous_mesh_of(mesh.points)
    far = np.array([[40.0, 1.0], [-3.0, -60.0]])
    rows = dense(continuous, far)
    nearest = np.argmin(np.linalg.norm(mesh.points[None] - far[:, None], axis=2), axis=1)
    np.testing.assert_array_equal(rows[np.arange(2), nearest], 1.0)
    assert np.count_nonzero(rows) == 2

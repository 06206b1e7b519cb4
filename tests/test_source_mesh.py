"""Voronoi mesh of the source-plane centres (SPEC §4.3)."""

import numpy as np
import pytest
from scipy.spatial import ConvexHull, Voronoi

from mgelens.source.mesh import (
    AREA_PERCENTILE,
    EDGE_RULES,
    MeshError,
    VoronoiMesh,
    triangle_doubled_areas,
    voronoi_cell_areas,
)


def random_disc(seed: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    r = np.sqrt(rng.random(n))
    theta = 2 * np.pi * rng.random(n)
    return r * np.cos(theta), r * np.sin(theta)


def lattice(n_x: int, n_y: int, dx: float, dy: float) -> tuple[np.ndarray, np.ndarray]:
    x, y = np.meshgrid(np.arange(n_x) * dx - 0.3, np.arange(n_y) * dy + 0.1)
    return x.ravel(), y.ravel()


def shoelace(polygon: np.ndarray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


@pytest.fixture(scope="module")
def random_mesh() -> VoronoiMesh:
    return VoronoiMesh.from_points(*random_disc(3, 300))


def test_lattice_cells_have_the_lattice_cell_area():
    x, y = lattice(9, 7, 0.3, 0.2)
    mesh = VoronoiMesh.from_points(x, y)
    interior = ~mesh.edge_pixels
    raw = voronoi_cell_areas(mesh.points, mesh.simplices, mesh.circumcentres)
    np.testing.assert_allclose(raw[interior], 0.06, rtol=1e-12)
    # all bounded areas are equal, so the 90th percentile (and every area) is 0.06
    np.testing.assert_allclose(mesh.areas, 0.06, rtol=1e-12)


def test_lattice_edge_pixels_are_the_boundary_rows_and_columns():
    x, y = lattice(9, 7, 0.3, 0.2)
    mesh = VoronoiMesh.from_points(x, y)
    on_border = np.isclose(x, x.min()) | np.isclose(x, x.max())
    on_border |= np.isclose(y, y.min()) | np.isclose(y, y.max())
    np.testing.assert_array_equal(mesh.edge_pixels, on_border)


def test_bounded_areas_match_scipy_voronoi_shoelace(random_mesh):
    voronoi = Voronoi(random_mesh.points)
    raw = voronoi_cell_areas(random_mesh.points, random_mesh.simplices, random_mesh.circumcentres)
    for j in range(random_mesh.n_points):
        region = voronoi.regions[voronoi.point_region[j]]
        assert (-1 in region) == random_mesh.edge_pixels[j]
        if -1 not in region:
            assert raw[j] == pytest.approx(shoelace(voronoi.vertices[region]), rel=1e-12)


def test_areas_follow_the_percentile_rule(random_mesh):
    raw = voronoi_cell_areas(random_mesh.points, random_mesh.simplices, random_mesh.circumcentres)
    bounded = ~random_mesh.edge_pixels
    # the anchor's rule: unbounded cells enter the percentile as −1
    cap = np.percentile(np.where(bounded, raw, -1.0), AREA_PERCENTILE)
    assert cap < np.percentile(raw[bounded], AREA_PERCENTILE)
    areas = random_mesh.areas
    np.testing.assert_array_equal(areas[random_mesh.edge_pixels], cap)
    assert areas.max() == cap
    below = bounded & (raw < cap)
    np.testing.assert_array_equal(areas[below], raw[below])
    assert (areas[bounded & (raw >= cap)] == cap).all()


def test_edge_pixels_are_the_convex_hull_vertices(random_mesh):
    hull = np.zeros(random_mesh.n_points, dtype=bool)
    hull[ConvexHull(random_mesh.points).vertices] = True
    np.testing.assert_array_equal(random_mesh.edge_pixels, hull)


@pytest.mark.parametrize(
    "points", [random_disc(3, 300), random_disc(4, 40), lattice(9, 7, 0.3, 0.2)]
)
def test_edge_count_obeys_euler_formula(points):
    mesh = VoronoiMesh.from_points(*points)
    n, h = mesh.n_points, int(mesh.edge_pixels.sum())
    assert len(mesh.edges) == 3 * n - 3 - h
    assert len(mesh.simplices) == 2 * n - 2 - h


def test_edges_and_csr_adjacency_are_consistent(random_mesh):
    edges = random_mesh.edges
    assert edges.dtype == np.int64
    assert (edges[:, 0] < edges[:, 1]).all()
    assert len(np.unique(edges, axis=0)) == len(edges)
    np.testing.assert_array_equal(edges, edges[np.lexsort((edges[:, 1], edges[:, 0]))])
    triangle_edges = {
        tuple(sorted((int(t[i]), int(t[(i + 1) % 3]))))
        for t in random_mesh.simplices
        for i in (0, 1, 2)
    }
    assert triangle_edges == {tuple(e) for e in edges.tolist()}
    indptr, indices = random_mesh.neighbour_indptr, random_mesh.neighbour_indices
    pairs = set()
    for j in range(random_mesh.n_points):
        row = indices[indptr[j] : indptr[j + 1]]
        assert (np.diff(row) > 0).all()
        pairs |= {(j, int(neighbour)) for neighbour in row}
    assert pairs == {(a, b) for a, b in edges.tolist()} | {(b, a) for a, b in edges.tolist()}


def test_triangles_are_counter_clockwise_with_consistent_neighbours(random_mesh):
    simplices, neighbors = random_mesh.simplices, random_mesh.neighbors
    assert simplices.dtype == np.int32
    assert (triangle_doubled_areas(random_mesh.points, simplices) > 0).all()
    for t, k in zip(*np.nonzero(neighbors >= 0), strict=True):
        edge = {simplices[t, (k + 1) % 3], simplices[t, (k + 2) % 3]}
        assert edge <= set(simplices[neighbors[t, k]])
        assert t in neighbors[neighbors[t, k]]
    boundary = neighbors < 0
    assert boundary.sum() == random_mesh.edge_pixels.sum()  # one hull edge per hull vertex


def test_circumcircles_pass_through_the_vertices(random_mesh):
    vertices = random_mesh.points[random_mesh.simplices]
    d2 = ((vertices - random_mesh.circumcentres[:, None, :]) ** 2).sum(axis=2)
    np.testing.assert_allclose(d2, random_mesh.circumradii_sq[:, None] * np.ones(3), rtol=1e-9)


@pytest.mark.parametrize(
    ("x", "y", "reason"),
    [
        ([0.0, 1.0], [0.0, 1.0], "at least 3"),
        ([0.0, 1.0, 0.5, 0.0], [0.0, 0.0, 1.0, 0.0], "coincide"),
        ([0.0, 1.0, 2.0, 3.0], [0.0, 1.0, 2.0, 3.0], "collinear"),
        ([0.0, 1.0, 0.5, np.nan], [0.0, 0.0, 1.0, 0.2], "non-finite"),
        ([0.0, 1.0, 1.0, 0.0], [0.0, 0.0, 1.0, 1.0], "convex hull"),
    ],
)
def test_degenerate_input_raises_mesh_error(x, y, reason):
    with pytest.raises(MeshError, match=reason):
        VoronoiMesh.from_points(np.array(x), np.array(y))


def test_mesh_error_is_a_value_error_and_shapes_are_checked():
    assert issubclass(MeshError, ValueError)
    with pytest.raises(ValueError, match="equal length"):
        VoronoiMesh.from_points(np.zeros(4), np.zeros(5))


def test_continuous_rule_takes_the_areas_of_the_ringed_mesh(random_mesh):
    x, y = random_mesh.points.T
    continuous = VoronoiMesh.from_points(x, y, edge_rule="continuous")
    ringed = continuous.ringed
    np.testing.assert_array_equal(ringed.points[: len(x)], random_mesh.points)
    assert not ringed.edge_pixels[: len(x)].any()  # every real cell is bounded
    cells = voronoi_cell_areas(ringed.points, ringed.simplices, ringed.circumcentres)[: len(x)]
    cap = np.percentile(cells, AREA_PERCENTILE)
    np.testing.assert_allclose(continuous.areas, np.minimum(cells, cap))
    # cells far from the hull are the same under both rules (below both caps)
    inner = (np.hypot(x, y) < 0.6) & (continuous.areas < random_mesh.areas.max())
    assert inner.sum() > 50
    np.testing.assert_allclose(continuous.areas[inner], random_mesh.areas[inner], rtol=1e-12)


def test_the_continuous_area_cap_does_not_jump_when_a_point_joins_the_hull():
    """A point walks outwards through a hull edge. The anchor's cap (the largest area)
    drops by one percentile rank at the crossing whatever the step; the continuous rule's
    cap changes by less when the step is halved (it is continuous)."""
    x, y = random_disc(5, 120)
    points = np.column_stack([x, y])
    hull = ConvexHull(points)
    a, b = points[hull.simplices[0]]
    target = 0.5 * (a + b) + 0.02 * hull.equations[0, :2]
    interior = np.flatnonzero(~VoronoiMesh.from_points(x, y).edge_pixels)
    k = interior[np.argmin(np.linalg.norm(points[interior] - 0.5 * (a + b), axis=1))]
    largest = {}
    for rule in EDGE_RULES:
        for n_steps in (200, 399):
            caps = []
            for f in np.linspace(0.0, 1.0, n_steps):
                moved = points.copy()
                moved[k] = (1 - f) * points[k] + f * target
                caps.append(VoronoiMesh.from_points(*moved.T, edge_rule=rule).areas.max())
            largest[rule, n_steps] = np.abs(np.diff(caps)).max() / np.median(caps)
    assert largest["anchor", 399] > 0.01
    assert largest["anchor", 399] > 0.9 * largest["anchor", 200]
    assert largest["continuous", 399] < 0.6 * largest["continuous", 200]

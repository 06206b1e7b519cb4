"""Voronoi mesh of the traced source-plane mesh centres (SPEC §4.3).

Conventions:

* Positions (x, y) in arcsec in the source plane; ``points[j] = (x_j, y_j)``.
* Triangles are the Delaunay triangles of the points (scipy / Qhull), stored
  **counter-clockwise**; ``neighbors[t, k]`` is the triangle across the edge opposite
  vertex ``simplices[t, k]`` (−1 on the convex hull), as in scipy.
* A Voronoi cell is unbounded iff its point lies on the boundary of the triangulation
  (convex-hull vertices and points lying on hull edges); these are the ``edge_pixels``.
* Cell areas in arcsec²: bounded cells exactly, unbounded cells and every area above it
  set to the 90th percentile of the bounded areas (anchor ``voronoi_pixel_areas``).
* ``edge_rule`` chooses how the mesh treats its convex hull: ``"anchor"`` (SPEC §4.3–4.4)
  or ``"continuous"``. The continuous rule embeds the points in a distant ring of
  auxiliary points (:attr:`VoronoiMesh.ringed`), inside which every real cell is bounded:
  areas are those cells' (then capped at their 90th percentile) and interpolation weights
  are Sibson weights over the ringed mesh, so both vary continuously as points join or
  leave the hull.

Degenerate input (fewer than 3 points, non-finite, duplicate or Qhull-merged points, all
points collinear, no interior point) raises :class:`MeshError`, which a sampler catches to
reject the sample (SPEC §8.4).
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial import Delaunay, QhullError

from mgelens.source.schemes import EDGE_RULES

QHULL_OPTIONS = "Qbb Qc Qz Q12"
"""Qhull options of the triangulation (scipy's 2-D default, made explicit).

``Qc`` keeps points that Qhull merges (exact or near duplicates) in ``coplanar`` instead of
dropping them silently, so they can be reported; ``Qz`` handles co-circular input such as
regular lattices; flat (collinear) input raises ``QhullError``.
"""

AREA_PERCENTILE = 90.0
"""Percentile of the cell areas used for unbounded cells and as the area cap."""

RING_POINTS = 32
"""Auxiliary points of the ring that embeds a mesh under the continuous edge rule."""

RING_RADIUS = 4.0
"""Radius of that ring, in units of the largest distance of a mesh point from the mesh
centroid: far enough that only queries near the hull feel it."""


class MeshError(ValueError):
    """The mesh centres cannot form a valid Voronoi mesh; the sample should be rejected."""


@dataclass(frozen=True, eq=False)
class VoronoiMesh:
    """Delaunay triangulation and Voronoi cells of the source-plane mesh centres.

    Build with :meth:`from_points`. All arrays are read-only by convention.

    Attributes
    ----------
    points : ndarray (N_S, 2), float64
        Mesh centres (x, y), arcsec.
    delaunay : scipy.spatial.Delaunay
        The Qhull triangulation (its ``simplices`` may be oriented either way).
    simplices : ndarray (n_tri, 3), int32
        Vertex indices of every triangle, counter-clockwise.
    neighbors : ndarray (n_tri, 3), int32
        ``neighbors[t, k]`` = triangle opposite vertex k of triangle t, −1 if none.
    circumcentres : ndarray (n_tri, 2), float64
        Circumcentre of every triangle, arcsec.
    circumradii_sq : ndarray (n_tri,), float64
        Squared circumradius of every triangle, arcsec².
    edges : ndarray (n_edges, 2), int64
        Unique Delaunay edges (j, l) with j < l, sorted; the neighbour pairs of §5.1–5.2.
    neighbour_indptr, neighbour_indices : ndarray, int64
        CSR adjacency: the Delaunay neighbours of point j are
        ``neighbour_indices[neighbour_indptr[j]:neighbour_indptr[j + 1]]`` (ascending).
    edge_pixels : ndarray (N_S,), bool
        True for points on the triangulation boundary (unbounded Voronoi cells).
    areas : ndarray (N_S,), float64
        Voronoi cell areas, arcsec², with the 90th-percentile rule of §4.3; under the
        continuous rule, the cells of :attr:`ringed`, all bounded, capped at their 90th
        percentile.
    edge_rule : {"anchor", "continuous"}
        Treatment of the convex hull (:data:`EDGE_RULES`).
    ringed : VoronoiMesh or None
        Continuous rule only: the mesh of these points followed by :data:`RING_POINTS`
        points on a circle about their centroid, :data:`RING_RADIUS` times their largest
        distance from it. Sibson weights over it with the ring's share dropped are
        continuous across the hull of the real points
        (:func:`mgelens.source.interpolate.natural_neighbour_weights`).
    """

    points: np.ndarray
    delaunay: Delaunay
    simplices: np.ndarray
    neighbors: np.ndarray
    circumcentres: np.ndarray
    circumradii_sq: np.ndarray
    edges: np.ndarray
    neighbour_indptr: np.ndarray
    neighbour_indices: np.ndarray
    edge_pixels: np.ndarray
    areas: np.ndarray
    edge_rule: str = "anchor"
    ringed: "VoronoiMesh | None" = None

    @property
    def n_points(self) -> int:
        """Number of mesh points N_S."""
        return self.points.shape[0]

    @property
    def extent(self) -> float:
        """Largest side of the bounding box of the points, arcsec."""
        return float(np.ptp(self.points, axis=0).max())

    @classmethod
    def from_points(cls, x: np.ndarray, y: np.ndarray, edge_rule: str = "anchor") -> "VoronoiMesh":
        """Triangulate the mesh centres ``(x, y)`` (arcsec) and derive the Voronoi cells.

        Raises
        ------
        MeshError
            If the points cannot form a mesh (see the module docstring).
        """
        if edge_rule not in EDGE_RULES:
            raise ValueError(f"edge_rule must be one of {EDGE_RULES}, got {edge_rule!r}")
        points = _validated_points(x, y)
        delaunay = _triangulate(points)
        simplices, neighbors = _counter_clockwise(points, delaunay.simplices, delaunay.neighbors)
        circumcentres, circumradii_sq = circumcircles(points, simplices)
        edges = unique_edges(simplices, neighbors)
        indptr, indices = adjacency_csr(edges, len(points))
        edge_pixels = boundary_vertices(simplices, neighbors, len(points))
        if edge_pixels.all():
            raise MeshError("every mesh point lies on the convex hull: no bounded Voronoi cell")
        if edge_rule == "anchor":
            ringed = None
            areas = capped_areas(voronoi_cell_areas(points, simplices, circumcentres), edge_pixels)
        else:
            ringed = cls.from_points(*_with_ring(points).T)
            cells = voronoi_cell_areas(ringed.points, ringed.simplices, ringed.circumcentres)
            areas = capped_areas(cells[: len(points)], np.zeros(len(points), dtype=bool))
        return cls(
            points=points,
            delaunay=delaunay,
            simplices=simplices,
            neighbors=neighbors,
            circumcentres=circumcentres,
            circumradii_sq=circumradii_sq,
            edges=edges,
            neighbour_indptr=indptr,
            neighbour_indices=indices,
            edge_pixels=edge_pixels,
            areas=areas,
            edge_rule=edge_rule,
            ringed=ringed,
        )


def _with_ring(points: np.ndarray) -> np.ndarray:
    """``points`` followed by the ring of :attr:`VoronoiMesh.ringed`."""
    centre = points.mean(axis=0)
    radius = RING_RADIUS * np.hypot(*(points - centre).T).max()
    angle = 2.0 * np.pi * (np.arange(RING_POINTS) + 0.5) / RING_POINTS
    return np.vstack([points, centre + radius * np.column_stack([np.cos(angle), np.sin(angle)])])


def _validated_points(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Stack ``x, y`` into an (N, 2) float64 array after the cheap validity checks."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.ndim != 1 or x.shape != y.shape:
        raise ValueError(f"x and y must be 1-D of equal length, got {x.shape} and {y.shape}")
    if x.size < 3:
        raise MeshError(f"a Voronoi mesh needs at least 3 points, got {x.size}")
    points = np.column_stack([x, y])
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        raise MeshError(f"non-finite mesh point(s) at index {np.flatnonzero(bad)[:10].tolist()}")
    return points


def _triangulate(points: np.ndarray) -> Delaunay:
    """Qhull Delaunay triangulation; raise :class:`MeshError` on flat or merged input."""
    try:
        delaunay = Delaunay(points, qhull_options=QHULL_OPTIONS)
    except QhullError as error:
        first_line = str(error).strip().splitlines()[0]
        raise MeshError(f"Qhull cannot triangulate the mesh (collinear?): {first_line}") from error
    if len(delaunay.coplanar):
        merged, _, kept = delaunay.coplanar[0]
        raise MeshError(
            f"{len(delaunay.coplanar)} mesh point(s) coincide with others, e.g. point {merged} "
            f"with point {kept} at {points[merged].tolist()}"
        )
    return delaunay


def _counter_clockwise(
    points: np.ndarray, simplices: np.ndarray, neighbors: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Re-order each triangle counter-clockwise (swapping vertex 1 and 2 with its neighbours)."""
    doubled_area = triangle_doubled_areas(points, simplices)
    if not (doubled_area != 0.0).all():
        raise MeshError("the triangulation contains a zero-area triangle")
    simplices = simplices.astype(np.int32)
    neighbors = neighbors.astype(np.int32)
    clockwise = doubled_area < 0.0
    simplices[clockwise] = simplices[clockwise][:, [0, 2, 1]]
    neighbors[clockwise] = neighbors[clockwise][:, [0, 2, 1]]
    return simplices, neighbors


def triangle_doubled_areas(points: np.ndarray, simplices: np.ndarray) -> np.ndarray:
    """Twice the signed area of every triangle (> 0 counter-clockwise), arcsec²."""
    a, b, c = (points[simplices[:, k]] for k in range(3))
    return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])


def circumcircles(points: np.ndarray, simplices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Circumcentres (n_tri, 2) and squared circumradii (n_tri,) of the triangles, arcsec."""
    a = points[simplices[:, 0]]
    b = points[simplices[:, 1]] - a
    c = points[simplices[:, 2]] - a
    b2 = (b**2).sum(axis=1)
    c2 = (c**2).sum(axis=1)
    d = 2.0 * (b[:, 0] * c[:, 1] - b[:, 1] * c[:, 0])
    u = np.column_stack([(c[:, 1] * b2 - b[:, 1] * c2) / d, (b[:, 0] * c2 - c[:, 0] * b2) / d])
    return a + u, (u**2).sum(axis=1)


def unique_edges(simplices: np.ndarray, neighbors: np.ndarray) -> np.ndarray:
    """Unique edges of a consistently oriented triangulation, (n_edges, 2) int64 pairs (j, l).

    j < l, sorted by (j, l). Edge k of triangle t joins its vertices k + 1 and k + 2; an
    interior edge appears twice in opposite directions, so keep the ascending copy, and
    every boundary edge (no neighbour) once.
    """
    starts = simplices[:, [1, 2, 0]].astype(np.int64)
    ends = simplices[:, [2, 0, 1]].astype(np.int64)
    keep = (starts < ends) | (neighbors < 0)
    low = np.minimum(starts, ends)[keep]
    high = np.maximum(starts, ends)[keep]
    order = np.lexsort((high, low))
    return np.column_stack([low[order], high[order]])


def adjacency_csr(edges: np.ndarray, n_points: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR ``(indptr, indices)`` of the undirected graph ``edges``, neighbours ascending."""
    rows = np.concatenate([edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 1], edges[:, 0]])
    order = np.lexsort((cols, rows))
    indptr = np.zeros(n_points + 1, dtype=np.int64)
    np.cumsum(np.bincount(rows, minlength=n_points), out=indptr[1:])
    return indptr, cols[order]


def boundary_vertices(simplices: np.ndarray, neighbors: np.ndarray, n_points: int) -> np.ndarray:
    """Bool mask of points on a triangle edge without neighbour (the triangulation boundary)."""
    on_boundary = np.zeros(n_points, dtype=bool)
    triangle, opposite = np.nonzero(neighbors < 0)
    for shift in (1, 2):
        on_boundary[simplices[triangle, (opposite + shift) % 3]] = True
    return on_boundary


def voronoi_cell_areas(
    points: np.ndarray, simplices: np.ndarray, circumcentres: np.ndarray
) -> np.ndarray:
    """Shoelace areas of the Voronoi cells, arcsec² (meaningless for boundary points).

    The cell of p is the polygon of the circumcentres c_t of its triangles in
    counter-clockwise order; inserting the midpoints m of its Delaunay edges (collinear
    with consecutive circumcentres) leaves the signed area unchanged and splits it into one
    term per (triangle, vertex): for a counter-clockwise triangle (p, q₁, q₂),
    ½[(m₁ − p) × (c_t − p) + (c_t − p) × (m₂ − p)], m_i = (p + q_i)/2.
    """
    areas = np.zeros(len(points))
    for k in range(3):
        p = points[simplices[:, k]]
        q1 = points[simplices[:, (k + 1) % 3]] - p
        q2 = points[simplices[:, (k + 2) % 3]] - p
        c = circumcentres - p
        term = 0.25 * (
            (q1[:, 0] * c[:, 1] - q1[:, 1] * c[:, 0]) + (c[:, 0] * q2[:, 1] - c[:, 1] * q2[:, 0])
        )
        areas += np.bincount(simplices[:, k], weights=term, minlength=len(points))
    return areas


def capped_areas(areas: np.ndarray, unbounded: np.ndarray) -> np.ndarray:
    """Replace unbounded-cell areas by, and clip all areas to, the 90th percentile.

    As the anchor (``voronoi_pixel_areas``), the percentile is taken over all N_S cells
    with the unbounded ones entered as −1, so they pull it down (SPEC §4.3 says "of the
    finite areas"; the anchor's rule gives a cap 0.3 % lower on configuration R's mesh).
    """
    cap = np.percentile(np.where(unbounded, -1.0, areas), AREA_PERCENTILE)
    return np.minimum(np.where(unbounded, cap, areas), cap)

"""Interpolation weights of source-plane points over a Voronoi mesh (SPEC §4.4, §5.3).

Every weight routine returns a CSR triple ``(indptr, indices, weights)``
(int64, int64, float64): row i, ``slice(indptr[i], indptr[i + 1])``, lists the mesh points
(ascending) that carry a weight for query i; each row's weights are > 0 and sum to 1.
``scipy.sparse.csr_array((weights, indices, indptr), shape=(n_queries, N_S))`` is the
interpolation matrix. Positions are arcsec in the source plane.

Natural-neighbour (Sibson) weights follow Watson's method (SPEC §4.4): locate the query x,
flood-fill the conflict cavity (the triangles whose circumcircle strictly contains x) and
add, for every cavity triangle t = (v₀, v₁, v₂) with circumcentre c_t,
(g_{j+1} − c_t) × (g_{j+2} − c_t) to the weight of v_j, where g_j is the circumcentre of
(v_{j+1}, v_{j+2}, x); then normalise. Coordinates are taken relative to x. Special cases,
in this order:

1. x outside the convex hull → weight 1 on the nearest mesh point;
2. x within 1e−12·extent of a mesh point → weight 1 on that point;
3. degenerate geometry: x (nearly, |sin| < 1e−6) collinear with two vertices of a cavity
   triangle, which makes a g_j blow up (non-finite or catastrophic cancellation) → the
   average of the weights at x ± h·u, h = 1e−5 × the longest edge of x's triangle,
   u = (cos 1, sin 1), or u turned by 90° if that pair is degenerate too (nn-c shifts by
   1e−5 of the mesh extent; the symmetric pair keeps linear precision);
4. a normalised weight < −1e−12, or no weight at all → weight 1 on the nearest mesh point;
   weights in [−1e−12, 0] are round-off of a vanishing weight and are dropped (the row is
   then renormalised), so that rows stay continuous in x.

Rule 1 makes rows jump when the nearest point changes and when a point joins or leaves the
hull. A mesh built with ``edge_rule="continuous"`` replaces it: the weights are Sibson
weights over the mesh embedded in a distant ring of auxiliary points
(:attr:`~mgelens.source.mesh.VoronoiMesh.ringed`), with the ring's share dropped and each
row renormalised. They equal the plain Sibson weights wherever x's cavity does not reach
the ring (all but a thin band inside the hull), are continuous in x and in the mesh points
everywhere inside the ring, and extend smoothly beyond the hull; only queries outside the
ring itself fall back to the nearest mesh point.

The rows are computed by the numba kernels of :mod:`mgelens.source.delaunay_kernels` (point
location by a visibility walk, the nearest mesh point by a greedy descent on the Delaunay
graph), which release the GIL and run on ``numba.get_num_threads()`` threads over ranges of
queries; a query costs ≈ 0.5 µs of CPU on a 1500-point mesh (6 weights on average).
"""

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np

from mgelens.source.delaunay_kernels import (
    TOO_MANY,
    chunk_rows,
    drop_ring,
    nearest_rows,
    start_table,
)
from mgelens.source.mesh import MeshError, VoronoiMesh

COINCIDENCE_TOLERANCE = 1e-12
"""Distance, in units of the mesh extent, below which a query sits on a mesh point."""

BUCKETS_PER_TRIANGLE = 2.0
"""Cells of the point-location bucket grid per Delaunay triangle."""

MIN_TASK_SIZE = 4096
"""Fewest queries per thread task; there are at most 4 tasks per numba thread."""

SLAB_SLOTS_PER_QUERY = 8
"""First-pass storage per query (a row has ~6 entries on average); a task whose rows
overflow its slab recomputes the remaining rows in the second pass."""

_PERTURBATION_ANGLE = 1.0
"""Direction of the perturbation, radians from +x (irrational slope: off lattice lines)."""


def natural_neighbour_weights(
    mesh: VoronoiMesh, qx: np.ndarray, qy: np.ndarray, max_neighbours: int = 300
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sibson natural-neighbour weights of the query points ``(qx, qy)`` (arcsec).

    Parameters
    ----------
    mesh : VoronoiMesh
        Source-plane mesh.
    qx, qy : array_like (n_queries,)
        Query positions, arcsec.
    max_neighbours : int
        Largest allowed number of natural neighbours of one query (anchor: 300).

    Returns
    -------
    indptr, indices, weights : ndarray
        CSR triple (see the module docstring).

    Raises
    ------
    MeshError
        If a query is non-finite or has more than ``max_neighbours`` natural neighbours.
    """
    if max_neighbours < 3:
        raise ValueError(f"max_neighbours must be at least 3, got {max_neighbours}")
    qx, qy = _validated_queries(qx, qy)
    if mesh.edge_rule == "continuous":
        return _without_ring(mesh, qx, qy, *natural_neighbour_weights(mesh.ringed, qx, qy))
    geometry = _geometry(mesh)
    params = _query_params(mesh)
    bounds = _task_bounds(qx.size)
    counts = np.empty(qx.size, dtype=np.int64)
    slab_indices = np.empty(qx.size * SLAB_SLOTS_PER_QUERY, dtype=np.int64)
    slab_weights = np.empty(qx.size * SLAB_SLOTS_PER_QUERY, dtype=np.float64)

    def first_pass(first: int, end: int) -> int:
        """Row lengths of queries first..end − 1; returns how many rows fit the slab."""
        return chunk_rows(
            qx, qy, first, end, geometry, params, max_neighbours, counts,
            slab_indices, slab_weights, first * SLAB_SLOTS_PER_QUERY, end * SLAB_SLOTS_PER_QUERY,
        )  # fmt: skip

    n_stored = _run_tasks(first_pass, bounds)
    too_many = np.flatnonzero(counts == TOO_MANY)
    if too_many.size:
        q = too_many[0]
        raise MeshError(
            f"{too_many.size} query point(s) have more than {max_neighbours} natural "
            f"neighbours, e.g. query {q} at ({qx[q]}, {qy[q]})"
        )
    indptr = np.zeros(qx.size + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    indices = np.empty(indptr[-1], dtype=np.int64)
    weights = np.empty(indptr[-1], dtype=np.float64)

    def fill_pass(first: int, end: int, stored: int) -> None:
        """Copy the stored rows of a task to the CSR arrays and recompute the others."""
        start, n_done = indptr[first], indptr[first + stored] - indptr[first]
        slab = first * SLAB_SLOTS_PER_QUERY
        indices[start : start + n_done] = slab_indices[slab : slab + n_done]
        weights[start : start + n_done] = slab_weights[slab : slab + n_done]
        if first + stored < end:
            chunk_rows(
                qx, qy, first + stored, end, geometry, params, max_neighbours, counts,
                indices, weights, start + n_done, indptr[end],
            )  # fmt: skip

    _run_tasks(fill_pass, bounds, n_stored)
    return indptr, indices, weights


def nearest_cell_weights(
    mesh: VoronoiMesh, qx: np.ndarray, qy: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Voronoi-cell membership: weight 1 on the nearest mesh point of each query.

    Same CSR format as :func:`natural_neighbour_weights`; a query equidistant from several
    mesh points goes to any one of them.
    """
    qx, qy = _validated_queries(qx, qy)
    geometry, params = _geometry(mesh), _query_params(mesh)
    indices = np.empty(qx.size, dtype=np.int64)
    _run_tasks(
        lambda first, end: nearest_rows(qx, qy, first, end, geometry, params, indices),
        _task_bounds(qx.size),
    )
    indptr = np.arange(qx.size + 1, dtype=np.int64)
    return indptr, indices, np.ones(qx.size, dtype=np.float64)


def _without_ring(
    mesh: VoronoiMesh,
    qx: np.ndarray,
    qy: np.ndarray,
    indptr: np.ndarray,
    indices: np.ndarray,
    weights: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows over ``mesh.ringed`` restricted to the real points and renormalised.

    A row left empty (a query outside the ring, which fell back to a ring point) takes
    weight 1 on the nearest real mesh point.
    """
    new_indptr, indices, weights = drop_ring(indptr, indices, weights, mesh.n_points)
    lost = np.flatnonzero(np.diff(new_indptr) == 0)
    if lost.size == 0:
        return new_indptr, indices, weights
    nearest = nearest_cell_weights(mesh, qx[lost], qy[lost])[1]
    counts = np.diff(new_indptr)
    counts[lost] = 1
    at = new_indptr[lost + 1]  # where each lost row's entry goes among the kept ones
    np.cumsum(counts, out=new_indptr[1:])
    return new_indptr, np.insert(indices, at, nearest), np.insert(weights, at, 1.0)


def cross_points(mesh: VoronoiMesh, offset: str = "anchor") -> np.ndarray:
    """Positions (4·N_S, 2), arcsec, of the split-regularization cross points (SPEC §5.3).

    Rows ``4j .. 4j + 3`` are p_j + (δ_j, 0), p_j − (δ_j, 0), p_j + (0, δ_j), p_j − (0, δ_j),
    with δ_j = ½√A_j for ``offset="anchor"`` (the code behind the paper's results, default)
    or δ_j = √(A_j/2) for ``offset="paper"`` (the paper's text); A_j = ``mesh.areas``.
    """
    if offset == "anchor":
        delta = 0.5 * np.sqrt(mesh.areas)
    elif offset == "paper":
        delta = np.sqrt(0.5 * mesh.areas)
    else:
        raise ValueError(f"offset must be 'anchor' or 'paper', got {offset!r}")
    directions = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    points = mesh.points[:, None, :] + delta[:, None, None] * directions[None, :, :]
    return points.reshape(-1, 2)


def _validated_queries(qx: np.ndarray, qy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Contiguous float64 1-D query arrays; :class:`MeshError` if any is non-finite."""
    qx = np.ascontiguousarray(qx, dtype=np.float64)
    qy = np.ascontiguousarray(qy, dtype=np.float64)
    if qx.ndim != 1 or qx.shape != qy.shape:
        raise ValueError(f"qx and qy must be 1-D of equal length, got {qx.shape} and {qy.shape}")
    bad = ~(np.isfinite(qx) & np.isfinite(qy))
    if bad.any():
        raise MeshError(
            f"non-finite query position(s) at index {np.flatnonzero(bad)[:10].tolist()}"
        )
    return qx, qy


def _task_bounds(n_queries: int) -> np.ndarray:
    """Boundaries of the contiguous query ranges handed to the threads."""
    n_threads = numba.get_num_threads()
    n_tasks = max(1, min(4 * n_threads, n_queries // MIN_TASK_SIZE))
    return np.linspace(0, n_queries, n_tasks + 1).astype(np.int64)


def _run_tasks(task: Callable, bounds: np.ndarray, *extra: np.ndarray) -> list:
    """``task(first, end, *extra[i])`` for every range of ``bounds``, on numba's thread count.

    The kernels release the GIL, so the tasks run in parallel; ``numba.set_num_threads``
    limits the number of threads as for the other kernels of mgelens.
    """
    args = [
        (int(bounds[i]), int(bounds[i + 1]), *(int(e[i]) for e in extra))
        for i in range(len(bounds) - 1)
    ]
    n_workers = min(numba.get_num_threads(), len(args))
    if n_workers == 1:
        return [task(*a) for a in args]
    with ThreadPoolExecutor(max_workers=n_workers) as pool:
        return list(pool.map(lambda a: task(*a), args))


def _geometry(mesh: VoronoiMesh) -> tuple:
    """Mesh arrays in the layout of the kernels (contiguous, coordinates split)."""
    return (
        np.ascontiguousarray(mesh.points[:, 0]),
        np.ascontiguousarray(mesh.points[:, 1]),
        mesh.simplices,
        mesh.neighbors,
        np.ascontiguousarray(mesh.circumcentres[:, 0]),
        np.ascontiguousarray(mesh.circumcentres[:, 1]),
        mesh.circumradii_sq,
        mesh.neighbour_indptr,
        mesh.neighbour_indices,
    )


def _query_params(mesh: VoronoiMesh) -> tuple:
    """Bucket grid of walk start triangles, and the tolerances scaled to the mesh extent.

    Returns ``(table, x0, y0, inv_dx, inv_dy, n_side, tol², dir_x, dir_y)``, (dir_x, dir_y)
    being the unit direction of the perturbation.
    """
    px, py = np.ascontiguousarray(mesh.points.T)
    x0, y0 = px.min(), py.min()
    n_side = max(1, int(np.sqrt(BUCKETS_PER_TRIANGLE * len(mesh.simplices))))
    inv_dx, inv_dy = n_side / np.ptp(px), n_side / np.ptp(py)
    table = start_table(px, py, mesh.simplices, x0, y0, inv_dx, inv_dy, n_side)
    return (
        table, float(x0), float(y0), float(inv_dx), float(inv_dy), n_side,
        (COINCIDENCE_TOLERANCE * mesh.extent) ** 2,
        np.cos(_PERTURBATION_ANGLE), np.sin(_PERTURBATION_ANGLE),
    )  # fmt: skip

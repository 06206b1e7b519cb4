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

Point location is a visibility walk started from a bucket grid of triangle centroids, with
orientation tests that agree exactly on shared edges; the nearest mesh point comes from a
greedy descent on the Delaunay graph (exact on a Delaunay triangulation). The kernels are
numba functions without the GIL, run on ``numba.get_num_threads()`` threads over ranges of
queries; a query costs ≈ 0.5 µs of CPU on a 1500-point mesh (6 weights on average).
"""

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np

from mgelens._jit import njit
from mgelens.source.mesh import MeshError, VoronoiMesh

INTERPOLATIONS = ("natural_neighbour", "nearest")
"""The source-plane interpolation schemes: natural-neighbour (Sibson) weights, or the
nearest mesh cell with weight 1 (SPEC §4.4)."""

COINCIDENCE_TOLERANCE = 1e-12
"""Distance, in units of the mesh extent, below which a query sits on a mesh point."""

PERTURBATION = 1e-5
"""Shift of the two perturbed copies of a degenerate query, in units of the longest edge of
its triangle (nn-c: of the mesh extent, which is ~40× coarser for 1500 points and made the
averaged weights wrong by ~1e−6)."""

NEAR_COLLINEAR = 1e-6
"""|sin| of the angle at x between two vertices below which Watson's circumcentre of (v, w, x)
is treated as degenerate: its ≈ 1e−16/|sin| cancellation error would exceed 1e−10."""

NEGATIVE_TOLERANCE = 1e-12
"""Normalised weights in [−tol, 0] count as round-off; below −tol the row falls back."""

BUCKETS_PER_TRIANGLE = 2.0
"""Cells of the point-location bucket grid per Delaunay triangle."""

MIN_TASK_SIZE = 4096
"""Fewest queries per thread task; there are at most 4 tasks per numba thread."""

SLAB_SLOTS_PER_QUERY = 8
"""First-pass storage per query (a row has ~6 entries on average); a task whose rows
overflow its slab recomputes the remaining rows in the second pass."""

_PERTURBATION_ANGLE = 1.0
"""Direction of the perturbation, radians from +x (irrational slope: off lattice lines)."""

_TOO_MANY = -1
_DEGENERATE = 0

_WALK_FAILED = -2

_kernel = njit(error_model="numpy", nogil=True)
"""Decorator of the kernels: IEEE division (x/0 → inf/nan, no exception), which the
degeneracy detection relies on, and no GIL, so that threads run them in parallel."""


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
        return _chunk_rows(
            qx, qy, first, end, geometry, params, max_neighbours, counts,
            slab_indices, slab_weights, first * SLAB_SLOTS_PER_QUERY, end * SLAB_SLOTS_PER_QUERY,
        )  # fmt: skip

    n_stored = _run_tasks(first_pass, bounds)
    too_many = np.flatnonzero(counts == _TOO_MANY)
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
            _chunk_rows(
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
        lambda first, end: _nearest_rows(qx, qy, first, end, geometry, params, indices),
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
    new_indptr, indices, weights = _drop_ring(indptr, indices, weights, mesh.n_points)
    lost = np.flatnonzero(np.diff(new_indptr) == 0)
    if lost.size == 0:
        return new_indptr, indices, weights
    nearest = nearest_cell_weights(mesh, qx[lost], qy[lost])[1]
    counts = np.diff(new_indptr)
    counts[lost] = 1
    at = new_indptr[lost + 1]  # where each lost row's entry goes among the kept ones
    np.cumsum(counts, out=new_indptr[1:])
    return new_indptr, np.insert(indices, at, nearest), np.insert(weights, at, 1.0)


@_kernel
def _drop_ring(indptr, indices, weights, n_real):
    """Rows without the entries ≥ ``n_real``, renormalised (an emptied row stays empty)."""
    n_queries = indptr.size - 1
    new_indptr = np.zeros(n_queries + 1, dtype=np.int64)
    new_indices = np.empty(indices.size, dtype=np.int64)
    new_weights = np.empty(weights.size, dtype=np.float64)
    n = 0
    for q in range(n_queries):
        start = n
        total = 0.0
        for k in range(indptr[q], indptr[q + 1]):
            if indices[k] < n_real:
                new_indices[n] = indices[k]
                new_weights[n] = weights[k]
                total += weights[k]
                n += 1
        for k in range(start, n):
            new_weights[k] /= total
        new_indptr[q + 1] = n
    return new_indptr, new_indices[:n], new_weights[:n]


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
    table = _start_table(px, py, mesh.simplices, x0, y0, inv_dx, inv_dy, n_side)
    return (
        table, float(x0), float(y0), float(inv_dx), float(inv_dy), n_side,
        (COINCIDENCE_TOLERANCE * mesh.extent) ** 2,
        np.cos(_PERTURBATION_ANGLE), np.sin(_PERTURBATION_ANGLE),
    )  # fmt: skip


@_kernel
def _start_table(px, py, simplices, x0, y0, inv_dx, inv_dy, n_side):
    """Per bucket-grid cell, a triangle whose centroid lies in it or in a nearby cell."""
    table = np.full(n_side * n_side, -1, dtype=np.int32)
    for t in range(simplices.shape[0]):
        a, b, c = simplices[t, 0], simplices[t, 1], simplices[t, 2]
        gx = (px[a] + px[b] + px[c]) / 3.0
        gy = (py[a] + py[b] + py[c]) / 3.0
        table[_cell(gx, gy, x0, y0, inv_dx, inv_dy, n_side)] = t
    last = -1
    for i in range(table.size):  # empty cells: previous filled cell in raster order
        if table[i] >= 0:
            last = table[i]
        else:
            table[i] = last
    following = table[table.size - 1]
    for i in range(table.size - 1, -1, -1):  # leading empty cells: next filled cell
        if table[i] >= 0:
            following = table[i]
        else:
            table[i] = following
    return table


@_kernel
def _cell(x, y, x0, y0, inv_dx, inv_dy, n_side):
    """Flat index of the bucket-grid cell of (x, y), clamped to the grid."""
    ix = int(min(max((x - x0) * inv_dx, 0.0), n_side - 1.0))
    iy = int(min(max((y - y0) * inv_dy, 0.0), n_side - 1.0))
    return iy * n_side + ix


@_kernel
def _orientation(a, b, ax, ay, bx, by, x, y):
    """Twice the signed area of (p_a, p_b, x): > 0 if x lies left of the line p_a → p_b.

    Evaluated from the lower-indexed vertex, so that the two triangles sharing an edge get
    exactly opposite values: a point can never be outside both (walks cannot ping-pong).
    """
    if a < b:
        return (bx - ax) * (y - ay) - (by - ay) * (x - ax)
    return -((ax - bx) * (y - by) - (ay - by) * (x - bx))


@_kernel
def _circumcentre(ax, ay, bx, by):
    """Circumcentre of (0, a, b); NaN if a and b are (nearly) collinear with the origin."""
    a2 = ax * ax + ay * ay
    b2 = bx * bx + by * by
    d = ax * by - ay * bx
    if d * d <= NEAR_COLLINEAR**2 * a2 * b2:
        return np.nan, np.nan
    half_inv_d = 0.5 / d
    return (by * a2 - ay * b2) * half_inv_d, (ax * b2 - bx * a2) * half_inv_d


@_kernel
def _walk(x, y, start, px, py, simplices, neighbors):
    """Visibility walk from triangle ``start`` towards (x, y).

    Returns ``(t, last)``: t = the triangle containing (x, y), −1 if it lies outside the
    convex hull, −2 if the walk does not terminate (round-off cycle); ``last`` = the last
    triangle visited.
    """
    t = start
    for _ in range(simplices.shape[0] + 1):
        k = 0
        while k < 3:
            a = simplices[t, 1 if k == 0 else (2 if k == 1 else 0)]
            b = simplices[t, 2 if k == 0 else (0 if k == 1 else 1)]
            if _orientation(a, b, px[a], py[a], px[b], py[b], x, y) < 0.0:
                break
            k += 1
        if k == 3:
            return t, t
        u = neighbors[t, k]
        if u < 0:
            return -1, t
        t = u
    return _WALK_FAILED, t


@_kernel
def _scan(x, y, px, py, simplices):
    """First triangle containing (x, y) by testing them all, −1 if none (walk fallback)."""
    for t in range(simplices.shape[0]):
        inside = True
        for k in range(3):
            a = simplices[t, 1 if k == 0 else (2 if k == 1 else 0)]
            b = simplices[t, 2 if k == 0 else (0 if k == 1 else 1)]
            inside = inside and _orientation(a, b, px[a], py[a], px[b], py[b], x, y) >= 0.0
        if inside:
            return t
    return -1


@_kernel
def _nearest_vertex(x, y, v, px, py, adj_indptr, adj_indices):
    """Nearest mesh point to (x, y) by greedy descent on the Delaunay graph from ``v``."""
    best = (px[v] - x) ** 2 + (py[v] - y) ** 2
    while True:
        current = v
        for i in range(adj_indptr[current], adj_indptr[current + 1]):
            u = adj_indices[i]
            d = (px[u] - x) ** 2 + (py[u] - y) ** 2
            if d < best:
                best = d
                v = u
        if v == current:
            return v


@_kernel
def _coincident_vertex(x, y, t, tol2, px, py, simplices):
    """Vertex of triangle t within √tol2 of (x, y), or −1."""
    for k in range(3):
        v = simplices[t, k]
        if (px[v] - x) ** 2 + (py[v] - y) ** 2 <= tol2:
            return v
    return -1


@_kernel
def _cavity(x, y, t0, neighbors, cx, cy, r2, cavity, in_cavity):
    """Flood-fill from ``t0`` the triangles whose circumcircle strictly contains (x, y).

    Writes them to ``cavity`` and returns their number (−1 if ``cavity`` overflows).
    ``in_cavity`` (all False) is scratch and is restored.
    """
    cavity[0] = t0
    in_cavity[t0] = True
    n = 1
    i = 0
    overflow = False
    while i < n and not overflow:
        t = cavity[i]
        i += 1
        for k in range(3):
            u = neighbors[t, k]
            if u < 0 or in_cavity[u]:
                continue
            dx = x - cx[u]
            dy = y - cy[u]
            if dx * dx + dy * dy < r2[u]:
                if n == cavity.size:
                    overflow = True
                    break
                cavity[n] = u
                in_cavity[u] = True
                n += 1
    for m in range(n):
        in_cavity[cavity[m]] = False
    return _TOO_MANY if overflow else n


@_kernel
def _watson_weights(x, y, cavity, n_cavity, px, py, simplices, cx, cy, slot, nb, wt):
    """Normalised Sibson weights of (x, y) from its cavity (Watson's formula, SPEC §4.4).

    Writes the natural neighbours to ``nb`` and their weights to ``wt`` and returns their
    number; 0 if degenerate (non-finite or non-positive total), −1 if there are more than
    ``nb.size``. ``slot`` (all −1; slot[v] = position of v in the row) is scratch and is
    restored. Coordinates are taken relative to x for accuracy.
    """
    n = 0
    m = 0
    while m < n_cavity and n >= 0:  # no `break`: it defeats numba's refcount pruning
        t = cavity[m]
        m += 1
        a, b, c = simplices[t, 0], simplices[t, 1], simplices[t, 2]
        ox, oy = cx[t] - x, cy[t] - y
        g_ab_x, g_ab_y = _circumcentre(px[a] - x, py[a] - y, px[b] - x, py[b] - y)
        g_bc_x, g_bc_y = _circumcentre(px[b] - x, py[b] - y, px[c] - x, py[c] - y)
        g_ca_x, g_ca_y = _circumcentre(px[c] - x, py[c] - y, px[a] - x, py[a] - y)
        g_ab_x, g_ab_y = g_ab_x - ox, g_ab_y - oy
        g_bc_x, g_bc_y = g_bc_x - ox, g_bc_y - oy
        g_ca_x, g_ca_y = g_ca_x - ox, g_ca_y - oy
        for j in range(3):
            if j == 0:
                v, w = a, g_ca_x * g_ab_y - g_ca_y * g_ab_x
            elif j == 1:
                v, w = b, g_ab_x * g_bc_y - g_ab_y * g_bc_x
            else:
                v, w = c, g_bc_x * g_ca_y - g_bc_y * g_ca_x
            if slot[v] >= 0:
                wt[slot[v]] += w
            elif 0 <= n < nb.size:
                slot[v] = n
                nb[n] = v
                wt[n] = w
                n += 1
            else:
                n = _TOO_MANY
    for i in range(n if n >= 0 else nb.size):
        slot[nb[i]] = -1
    if n < 0:
        return _TOO_MANY
    total = 0.0
    for i in range(n):
        total += wt[i]
    if not (np.isfinite(total) and total > 0.0):
        return _DEGENERATE
    for i in range(n):
        wt[i] /= total
    return n


@_kernel
def _merge_half(nb, wt, n, nb_add, wt_add, m):
    """Add half of the row ``nb_add[:m]`` to the row ``nb[:n]``; new length or −1 if full."""
    for i in range(m):
        found = False
        for k in range(n):
            if nb[k] == nb_add[i]:
                wt[k] += 0.5 * wt_add[i]
                found = True
                break
        if not found:
            if n == nb.size:
                return _TOO_MANY
            nb[n] = nb_add[i]
            wt[n] = 0.5 * wt_add[i]
            n += 1
    return n


@_kernel
def _perturbed(
    x, y, t0, dir_x, dir_y, px, py, simplices, neighbors, cx, cy, r2,
    cavity, in_cavity, slot, nb, wt, nb_tmp, wt_tmp,
):  # fmt: skip
    """Weights of a degenerate query as the average of those at (x, y) ± h·u.

    h = PERTURBATION × the longest edge of the containing triangle ``t0``; u = ``dir``, or
    ``dir`` turned by 90° if the pair along ``dir`` is still degenerate (x on an edge parallel
    to ``dir``). Writes to ``nb``/``wt``; return codes as :func:`_watson_weights`.
    """
    step = 0.0
    for k in range(3):
        a, b = simplices[t0, k], simplices[t0, 2 if k == 0 else k - 1]
        step = max(step, PERTURBATION * np.hypot(px[a] - px[b], py[a] - py[b]))
    n = _symmetric_average(
        x, y, t0, step * dir_x, step * dir_y, px, py, simplices, neighbors, cx, cy, r2,
        cavity, in_cavity, slot, nb, wt, nb_tmp, wt_tmp,
    )  # fmt: skip
    if n == _DEGENERATE:
        n = _symmetric_average(
            x, y, t0, -step * dir_y, step * dir_x, px, py, simplices, neighbors, cx, cy, r2,
            cavity, in_cavity, slot, nb, wt, nb_tmp, wt_tmp,
        )  # fmt: skip
    return n


@_kernel
def _symmetric_average(
    x, y, t0, shift_x, shift_y, px, py, simplices, neighbors, cx, cy, r2,
    cavity, in_cavity, slot, nb, wt, nb_tmp, wt_tmp,
):  # fmt: skip
    """Average of the Sibson weights at (x, y) ± shift, written to ``nb``/``wt``.

    Same return codes as :func:`_watson_weights`; 0 also if a shifted point leaves the hull.
    """
    n = 0
    for sign in (1.0, -1.0):
        xs = x + sign * shift_x
        ys = y + sign * shift_y
        t, _ = _walk(xs, ys, t0, px, py, simplices, neighbors)
        if t == _WALK_FAILED:
            t = _scan(xs, ys, px, py, simplices)
        if t < 0:
            return _DEGENERATE
        m = _cavity(xs, ys, t, neighbors, cx, cy, r2, cavity, in_cavity)
        if m > 0:
            m = _watson_weights(xs, ys, cavity, m, px, py, simplices, cx, cy, slot, nb_tmp, wt_tmp)
        if m <= 0:
            return m
        n = _merge_half(nb, wt, n, nb_tmp, wt_tmp, m)
        if n < 0:
            return _TOO_MANY
    return n


@_kernel
def _clean_row(nb, wt, n):
    """Drop round-off weights ≤ 0, renormalise, sort by vertex; 0 if one is truly negative."""
    kept = 0
    total = 0.0
    for i in range(n):
        if wt[i] < -NEGATIVE_TOLERANCE:
            return 0
        if wt[i] > 0.0:
            nb[kept] = nb[i]
            wt[kept] = wt[i]
            total += wt[i]
            kept += 1
    if kept < n:  # rows from _watson_weights are already normalised
        for i in range(kept):
            wt[i] /= total
    for i in range(1, kept):  # insertion sort: rows are short
        v, w = nb[i], wt[i]
        j = i - 1
        while j >= 0 and nb[j] > v:
            nb[j + 1] = nb[j]
            wt[j + 1] = wt[j]
            j -= 1
        nb[j + 1] = v
        wt[j + 1] = w
    return kept


@_kernel
def _chunk_rows(
    qx, qy, first, end, geometry, params, max_neighbours, counts, out_indices, out_weights,
    start, stop,
):  # fmt: skip
    """Weights of the queries ``first .. end − 1``, one after the other.

    Sets ``counts[q]`` (row length; −1: too many neighbours) and writes the leading rows
    consecutively to ``out_*[start:stop]`` while they fit; returns the number written.
    Only leaf kernels (no array-passing calls inside) are called per query, which keeps
    numba's reference counting out of the loop.
    """
    px, py, simplices, neighbors, cx, cy, r2, adj_indptr, adj_indices = geometry
    table, x0, y0, inv_dx, inv_dy, n_side, tol2, dir_x, dir_y = params
    cavity = np.empty(2 * max_neighbours, dtype=np.int64)
    in_cavity = np.zeros(simplices.shape[0], dtype=np.bool_)
    slot = np.full(px.size, -1, dtype=np.int64)
    nb = np.empty(max_neighbours, dtype=np.int64)
    wt = np.empty(max_neighbours, dtype=np.float64)
    nb_tmp = np.empty(max_neighbours, dtype=np.int64)
    wt_tmp = np.empty(max_neighbours, dtype=np.float64)
    used = start
    stored = 0
    for q in range(first, end):
        x, y = qx[q], qy[q]
        cell = _cell(x, y, x0, y0, inv_dx, inv_dy, n_side)
        t, last = _walk(x, y, table[cell], px, py, simplices, neighbors)
        if t == _WALK_FAILED:
            t = _scan(x, y, px, py, simplices)
        n = 0  # 0: weight 1 on the nearest mesh point
        if t >= 0:
            v = _coincident_vertex(x, y, t, tol2, px, py, simplices)
            if v >= 0:
                nb[0] = v
                wt[0] = 1.0
                n = 1
            else:
                n = _cavity(x, y, t, neighbors, cx, cy, r2, cavity, in_cavity)
                if n > 0:
                    n = _watson_weights(x, y, cavity, n, px, py, simplices, cx, cy, slot, nb, wt)
                if n == _DEGENERATE:
                    n = _perturbed(
                        x, y, t, dir_x, dir_y, px, py, simplices, neighbors, cx, cy, r2,
                        cavity, in_cavity, slot, nb, wt, nb_tmp, wt_tmp,
                    )  # fmt: skip
                if n > 0:
                    n = _clean_row(nb, wt, n)
            last = t
        if n == 0:
            nb[0] = _nearest_vertex(x, y, simplices[last, 0], px, py, adj_indptr, adj_indices)
            wt[0] = 1.0
            n = 1
        counts[q] = n
        if stored == q - first and 0 < n <= stop - used:
            for i in range(n):
                out_indices[used + i] = nb[i]
                out_weights[used + i] = wt[i]
            used += n
            stored += 1
    return stored


@_kernel
def _nearest_rows(qx, qy, first, end, geometry, params, out):
    """Index of the nearest mesh point of the queries ``first .. end − 1`` into ``out``."""
    px, py, simplices, _, _, _, _, adj_indptr, adj_indices = geometry
    table, x0, y0, inv_dx, inv_dy, n_side, _, _, _ = params
    for q in range(first, end):
        start = simplices[table[_cell(qx[q], qy[q], x0, y0, inv_dx, inv_dy, n_side)], 0]
        out[q] = _nearest_vertex(qx[q], qy[q], start, px, py, adj_indptr, adj_indices)

"""numba kernels of the natural-neighbour and nearest-cell weights (SPEC §4.4).

:mod:`mgelens.source.interpolate` validates the queries, lays the mesh out for these kernels
and hands them ranges of queries on several threads; the kernels compute the rows of a range.
They take

* ``geometry = (px, py, simplices, neighbors, cx, cy, r2, adj_indptr, adj_indices)``: the
  mesh points, the (counter-clockwise) Delaunay triangles and their neighbours, the
  triangles' circumcentres and squared circumradii, and the Delaunay graph in CSR form;
* ``params = (table, x0, y0, inv_dx, inv_dy, n_side, tol², dir_x, dir_y)``: the bucket grid
  of walk start triangles (:func:`start_table`), the squared distance below which a query
  sits on a mesh point, and the unit direction of the perturbation of degenerate queries.

:func:`chunk_rows` writes the Sibson rows of a range of queries, with the special cases of
:mod:`mgelens.source.interpolate` in their order; :func:`nearest_rows` the nearest mesh point
of each query; :func:`drop_ring` restricts rows over a ringed mesh to its real points. A row
of more natural neighbours than the buffers hold has length :data:`TOO_MANY`.

Point location is a visibility walk started from the bucket grid of triangle centroids, with
orientation tests that agree exactly on shared edges; the nearest mesh point comes from a
greedy descent on the Delaunay graph (exact on a Delaunay triangulation). The kernels call
each other, so they stay in one module: numba's cache is invalidated only when the defining
file changes (:mod:`mgelens._jit`).
"""

import numpy as np

from mgelens._jit import njit

PERTURBATION = 1e-5
"""Shift of the two perturbed copies of a degenerate query, in units of the longest edge of
its triangle (nn-c: of the mesh extent, which is ~40× coarser for 1500 points and made the
averaged weights wrong by ~1e−6)."""

NEAR_COLLINEAR = 1e-6
"""|sin| of the angle at x between two vertices below which Watson's circumcentre of (v, w, x)
is treated as degenerate: its ≈ 1e−16/|sin| cancellation error would exceed 1e−10."""

NEGATIVE_TOLERANCE = 1e-12
"""Normalised weights in [−tol, 0] count as round-off; below −tol the row falls back."""

TOO_MANY = -1
"""Row length of a query with more natural neighbours than the row buffers hold."""

_DEGENERATE = 0

_WALK_FAILED = -2

_kernel = njit(error_model="numpy", nogil=True)
"""Decorator of the kernels: IEEE division (x/0 → inf/nan, no exception), which the
degeneracy detection relies on, and no GIL, so that threads run them in parallel."""


@_kernel
def drop_ring(indptr, indices, weights, n_real):
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


@_kernel
def start_table(px, py, simplices, x0, y0, inv_dx, inv_dy, n_side):
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
    return TOO_MANY if overflow else n


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
                n = TOO_MANY
    for i in range(n if n >= 0 else nb.size):
        slot[nb[i]] = -1
    if n < 0:
        return TOO_MANY
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
                return TOO_MANY
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
            return TOO_MANY
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
def chunk_rows(
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
def nearest_rows(qx, qy, first, end, geometry, params, out):
    """Index of the nearest mesh point of the queries ``first .. end − 1`` into ``out``."""
    px, py, simplices, _, _, _, _, adj_indptr, adj_indices = geometry
    table, x0, y0, inv_dx, inv_dy, n_side, _, _, _ = params
    for q in range(first, end):
        start = simplices[table[_cell(qx[q], qy[q], x0, y0, inv_dx, inv_dy, n_side)], 0]
        out[q] = _nearest_vertex(qx[q], qy[q], start, px, py, adj_indptr, adj_indices)

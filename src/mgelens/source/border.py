"""Border relocation of traced positions (SPEC §4.2, on by default as in the paper era).

The border is the set of traced source-plane positions of the outermost sub-pixel of
every border pixel of the mask (:func:`border_pixels`, the mask's exterior edge). Traced
points that land beyond the border (the demagnified centre of the lens and far outliers)
are pulled back onto it, so the source mesh never stretches over empty source plane.

Two rules say where "beyond" begins (:data:`BORDER_RULES`): the anchor's radius of the
nearest border point, which jumps when that nearest point changes, and the radius of the
closed border polygon along the ray from its centre, which varies continuously with the
traced positions.
"""

import math

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from mgelens._jit import njit

BORDER_RULES = ("nearest_point", "polygon")
"""Border radius of a point: its nearest border point's (anchor) or the border polygon's."""

_ON_SEGMENT = 1e-9
"""Slack of the segment parameter, so that a ray through a polygon vertex hits it."""


def border_pixels(mask: np.ndarray) -> np.ndarray:
    """Slim indices of the pixels on the exterior edge of the mask (the anchor's border).

    A border pixel is an unmasked pixel with a masked (or off-array) 8-neighbour from which
    at least one of the four axis directions (±x, ±y) reaches the array edge through masked
    pixels only. The second condition drops the inner edge of an annular mask and the
    pixels of a circular mask's staircase that touch the masked region only diagonally
    (anchor ``mask_2d_util.border_slim_indexes_from``).
    """
    used = ~mask
    padded = np.pad(used, 1, constant_values=False)
    interior = ndimage.binary_erosion(padded, structure=np.ones((3, 3), dtype=bool))[1:-1, 1:-1]
    edge = used & ~interior
    exterior = np.zeros_like(used)
    for axis in (0, 1):
        before = np.cumsum(used, axis=axis) - used  # unmasked pixels before, along the axis
        after = np.flip(np.cumsum(np.flip(used, axis), axis=axis), axis) - used
        exterior |= (before == 0) | (after == 0)
    slim_index = np.cumsum(used.ravel()) - 1
    return slim_index[np.flatnonzero((edge & exterior).ravel())]


def border_sub_pixels(
    mask: np.ndarray,
    sub_x: np.ndarray,
    sub_y: np.ndarray,
    sub_size: int,
    centre: tuple[float, float],
) -> np.ndarray:
    """Indices into a uniform sub-grid of the outermost sub-pixel of every border pixel.

    ``sub_x, sub_y`` are the image-plane sub-pixel positions of the unmasked pixels
    (slim order, s² per pixel, :func:`mgelens.grid.sub_grid`); "outermost" means
    furthest from ``centre`` (the mask centre). They are returned in order of polar angle
    about ``centre``, i.e. along the mask edge for the star-shaped masks of
    :mod:`mgelens.mask`, which makes consecutive points the sides of the border polygon.
    """
    n_sub = sub_size * sub_size
    pixels = border_pixels(mask)
    candidates = pixels[:, None] * n_sub + np.arange(n_sub)[None, :]
    r2 = (sub_x[candidates] - centre[0]) ** 2 + (sub_y[candidates] - centre[1]) ** 2
    outermost = candidates[np.arange(pixels.size), np.argmax(r2, axis=1)]
    angle = np.arctan2(sub_y[outermost] - centre[1], sub_x[outermost] - centre[0])
    return outermost[np.argsort(angle, kind="stable")]


def relocate_to_border(
    x: np.ndarray,
    y: np.ndarray,
    border_x: np.ndarray,
    border_y: np.ndarray,
    rule: str = "nearest_point",
) -> tuple[np.ndarray, np.ndarray]:
    """Pull traced points that lie outside the border back onto it (SPEC §4.2).

    With o the mean of the border points, a point p gets a border radius R(p); if
    |p − o| > R(p) it moves radially to o + (R(p)/|p − o|)(p − o). Returns new arrays;
    the inputs are not modified.

    ``rule="nearest_point"`` (anchor): R(p) = |b − o| of the border point b nearest to p,
    for points farther from o than the nearest border point (others stay).
    ``rule="polygon"``: R(p) = distance from o of the farthest crossing of the ray o → p
    with the closed polygon through the border points in the order given (consecutive
    points along the mask edge, as :func:`border_sub_pixels` returns them); for a
    star-shaped border there is one crossing and R is continuous in p and in the border.
    """
    if rule not in BORDER_RULES:
        raise ValueError(f"border rule must be one of {BORDER_RULES}, got {rule!r}")
    ox, oy = border_x.mean(), border_y.mean()
    border_r = np.hypot(border_x - ox, border_y - oy)
    r = np.hypot(x - ox, y - oy)
    if rule == "nearest_point":
        candidates = np.flatnonzero(r > border_r.min())
        tree = cKDTree(np.column_stack([border_x, border_y]))
        _, nearest = tree.query(np.column_stack([x[candidates], y[candidates]]))
        radius = border_r[nearest]
    else:
        candidates = np.flatnonzero(r > _polygon_inner_radius(border_x - ox, border_y - oy))
        radius = _polygon_radius(
            x[candidates] - ox, y[candidates] - oy, border_x - ox, border_y - oy
        )
    factor = radius / r[candidates]
    move = factor < 1.0
    idx = candidates[move]
    new_x, new_y = np.array(x, dtype=float), np.array(y, dtype=float)
    new_x[idx] = ox + factor[move] * (x[idx] - ox)
    new_y[idx] = oy + factor[move] * (y[idx] - oy)
    return new_x, new_y


def _polygon_inner_radius(vx: np.ndarray, vy: np.ndarray) -> float:
    """Smallest distance from the origin to a side of the closed polygon (vx, vy): no
    point closer than this lies beyond the polygon."""
    ex, ey = np.roll(vx, -1) - vx, np.roll(vy, -1) - vy
    length2 = ex * ex + ey * ey
    t = np.clip(-(vx * ex + vy * ey) / np.where(length2 > 0.0, length2, 1.0), 0.0, 1.0)
    return float(np.hypot(vx + t * ex, vy + t * ey).min())


def _polygon_radius(dx: np.ndarray, dy: np.ndarray, vx: np.ndarray, vy: np.ndarray) -> np.ndarray:
    """Distance from the origin of the farthest crossing of the ray towards each (dx, dy)
    with the closed polygon (vx, vy) (coordinates relative to the ray origin); +∞ where
    the ray misses it (the point is then left where it is).

    A polygon whose vertices turn monotonically once around the origin (star-shaped, the
    usual traced border) is crossed once, in the side found by a binary search in polar
    angle; any other polygon is intersected side by side.
    """
    angle = np.arctan2(vy, vx)
    turn = (np.diff(angle, append=angle[0]) + np.pi) % (2.0 * np.pi) - np.pi
    if np.all(turn < 0.0):  # clockwise: the same polygon counter-clockwise
        vx, vy, angle, turn = vx[::-1], vy[::-1], angle[::-1], -np.roll(turn[::-1], -1)
    if np.all(turn > 0.0) and np.isclose(turn.sum(), 2.0 * np.pi):
        first = np.argmin(angle)
        vx, vy, angle = np.roll(vx, -first), np.roll(vy, -first), np.roll(angle, -first)
        side = np.searchsorted(angle, np.arctan2(dy, dx), side="right") - 1  # −1: the last side
        farthest = _ray_side_distance(dx, dy, vx, vy, side % vx.size)
    else:
        farthest = _farthest_crossings(
            np.asarray(dx, dtype=float),
            np.asarray(dy, dtype=float),
            np.asarray(vx, dtype=float),
            np.asarray(vy, dtype=float),
        )
    return np.where(np.isfinite(farthest), farthest, np.inf)


def _ray_side_distance(dx, dy, vx, vy, side):
    """Distance from the origin at which the ray towards (dx, dy) crosses polygon side
    ``side`` (from vertex ``side`` to the next, cyclically); −∞ where it does not.
    Arrays broadcast against each other."""
    ax, ay = vx[side], vy[side]
    following = (side + 1) % vx.size
    ex, ey = vx[following] - ax, vy[following] - ay
    norm = np.hypot(dx, dy)
    ux, uy = dx / norm, dy / norm
    # o + s·u = a + t·e  ⇒  s = (a × e)/(u × e), t = (a × u)/(u × e)
    denominator = ux * ey - uy * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (ax * ey - ay * ex) / denominator
        t = (ax * uy - ay * ux) / denominator
    hit = (t >= -_ON_SEGMENT) & (t <= 1.0 + _ON_SEGMENT) & (s > 0.0) & np.isfinite(s)
    return np.where(hit, s, -np.inf)


@njit(error_model="numpy")
def _farthest_crossings(dx, dy, vx, vy):
    """The largest of :func:`_ray_side_distance` over every side of the polygon (vx, vy),
    per ray towards (dx, dy): the same arithmetic, one ray and side at a time instead of
    (rays × sides) work arrays (for a traced border that is not star-shaped)."""
    n_sides = vx.size
    farthest = np.full(dx.size, -np.inf)
    for i in range(dx.size):
        norm = math.hypot(dx[i], dy[i])
        ux, uy = dx[i] / norm, dy[i] / norm
        best = -np.inf
        for side in range(n_sides):
            following = side + 1 if side + 1 < n_sides else 0
            ax, ay = vx[side], vy[side]
            ex, ey = vx[following] - ax, vy[following] - ay
            denominator = ux * ey - uy * ex
            if denominator == 0.0:  # parallel: no crossing (numpy's ±inf or nan there)
                continue
            s = (ax * ey - ay * ex) / denominator
            t = (ax * uy - ay * ux) / denominator
            if t >= -_ON_SEGMENT and t <= 1.0 + _ON_SEGMENT and s > 0.0 and np.isfinite(s):
                best = max(best, s)
        farthest[i] = best
    return farthest

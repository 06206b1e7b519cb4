"""Border relocation of traced positions (SPEC §4.2, on by default as in the paper era).

The border is the set of traced source-plane positions of the outermost sub-pixel of
every border pixel of the mask (:func:`border_pixels`, the mask's exterior edge). Traced
points that land beyond the border (the demagnified centre of the lens and far outliers)
are pulled back onto it, so the source mesh never stretches over empty source plane.
"""

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree


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
    furthest from ``centre`` (the mask centre).
    """
    n_sub = sub_size * sub_size
    pixels = border_pixels(mask)
    candidates = pixels[:, None] * n_sub + np.arange(n_sub)[None, :]
    r2 = (sub_x[candidates] - centre[0]) ** 2 + (sub_y[candidates] - centre[1]) ** 2
    return candidates[np.arange(pixels.size), np.argmax(r2, axis=1)]


def relocate_to_border(
    x: np.ndarray, y: np.ndarray, border_x: np.ndarray, border_y: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Pull traced points that lie outside the border back onto it (SPEC §4.2).

    With o the mean of the border points and r_min their smallest distance from o, a
    point p with |p − o| > r_min is compared with its nearest border point b; if
    |p − o| > |b − o| it moves radially to o + (|b − o|/|p − o|)(p − o). Returns new
    arrays; the inputs are not modified.
    """
    ox, oy = border_x.mean(), border_y.mean()
    border_r = np.hypot(border_x - ox, border_y - oy)
    r = np.hypot(x - ox, y - oy)
    candidates = np.flatnonzero(r > border_r.min())
    new_x, new_y = np.array(x, dtype=float), np.array(y, dtype=float)
    if candidates.size == 0:
        return new_x, new_y
    tree = cKDTree(np.column_stack([border_x, border_y]))
    _, nearest = tree.query(np.column_stack([x[candidates], y[candidates]]))
    factor = border_r[nearest] / r[candidates]
    move = factor < 1.0
    idx = candidates[move]
    new_x[idx] = ox + factor[move] * (x[idx] - ox)
    new_y[idx] = oy + factor[move] * (y[idx] - oy)
    return new_x, new_y

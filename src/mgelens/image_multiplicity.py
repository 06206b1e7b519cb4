"""How many images a mass model makes of source-plane points, and how much of a fitted
lensed source is multiply imaged.

A lens whose source lies outside every caustic is imaged once: the arc's curvature and
length then constrain θ_E far more weakly than a counter-image does, and a pixelized
source can trade θ_E against its own shape (docs/slacs.md, slacs0157−0056: a single long
arc, θ_E 17 % above Bolton's). This module counts images by **triangle mapping**: the
image plane is covered by a uniform grid of triangles, each vertex ray-traced with the
lens equation β = θ − α(θ) (SPEC §3.1); a source point β has one image in every image
triangle whose mapped triangle contains it. The count is exact up to the grid's
resolution: a point within about one mapped triangle of a caustic may be counted with one
image too many or too few (the fold straddles a triangle).

Triangles with a vertex within ``core_radius`` of a mass centre are left out: there the
deflection of a singular profile jumps, its mapped triangles span the source plane, and
the only images (the central image of a power law with γ < 2) are demagnified beyond any
detection and buried in the lens light. Counts are therefore of images outside the core.

Units: arcsec; coordinates as SPEC §1.1 (+x right, +y up).
"""

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from mgelens._jit import njit
from mgelens.mass import MassProfile, ray_trace

GRID_SPACING = 0.01
"""Image-plane triangle grid spacing (arcsec): a fifth of an HST pixel."""
CORE_RADIUS = 0.05
"""Triangles with a vertex this close (arcsec) to a mass centre are left out (module)."""
GRID_OFFSET = (np.sqrt(2.0) - 1.0) / 2.0, (np.sqrt(3.0) - 1.0) / 2.0
"""The triangle grid's nodes sit this far (in grid spacings, x and y) from multiples of
the spacing around the centre: irrational offsets keep pixel centres and other regular
points off the triangles' shared edges, where a point would be counted twice."""
MIN_MULTIPLY_IMAGED_FRACTION = 0.5
"""A fit with less than this share of its lensed source's signal multiply imaged is
flagged as singly imaged (:func:`multiplicity_check`): most of what constrains its mass
then comes in one image."""


@njit
def _count_in_triangles(bx, by, excluded, px, py, order, starts, origin, size, shape):
    """Images per point: for every grid triangle not ``excluded`` (per cell), the points
    inside its mapped triangle (barycentric test, either orientation) among those of the
    source-plane buckets its bounding box overlaps. ``order``/``starts``: the points sorted
    by bucket and each bucket's first index (CSR); buckets of side ``size`` from ``origin``,
    ``shape`` = (rows, columns)."""
    counts = np.zeros(px.size, dtype=np.int64)
    rows, columns = bx.shape
    for i in range(rows - 1):
        for j in range(columns - 1):
            if excluded[i, j]:
                continue
            for half in range(2):
                if half == 0:
                    ax, ay = bx[i, j], by[i, j]
                    cx, cy = bx[i, j + 1], by[i, j + 1]
                    dx, dy = bx[i + 1, j], by[i + 1, j]
                else:
                    ax, ay = bx[i + 1, j + 1], by[i + 1, j + 1]
                    cx, cy = bx[i + 1, j], by[i + 1, j]
                    dx, dy = bx[i, j + 1], by[i, j + 1]
                area = (cx - ax) * (dy - ay) - (dx - ax) * (cy - ay)
                if area == 0.0:
                    continue
                low_column = int(np.floor((min(ax, cx, dx) - origin[0]) / size))
                high_column = int(np.floor((max(ax, cx, dx) - origin[0]) / size))
                low_row = int(np.floor((min(ay, cy, dy) - origin[1]) / size))
                high_row = int(np.floor((max(ay, cy, dy) - origin[1]) / size))
                low_column, low_row = max(low_column, 0), max(low_row, 0)
                high_column = min(high_column, shape[1] - 1)
                high_row = min(high_row, shape[0] - 1)
                for row in range(low_row, high_row + 1):
                    for column in range(low_column, high_column + 1):
                        bucket = row * shape[1] + column
                        for k in range(starts[bucket], starts[bucket + 1]):
                            point = order[k]
                            x, y = px[point], py[point]
                            s = ((cx - x) * (dy - y) - (dx - x) * (cy - y)) / area
                            t = ((dx - x) * (ay - y) - (ax - x) * (dy - y)) / area
                            u = 1.0 - s - t
                            if s >= 0.0 and t >= 0.0 and u >= 0.0:
                                counts[point] += 1
    return counts


def image_counts(
    profiles: Sequence[MassProfile],
    source_x: np.ndarray,
    source_y: np.ndarray,
    half_width: float,
    centre: tuple[float, float] = (0.0, 0.0),
    grid_spacing: float = GRID_SPACING,
    core_radius: float = CORE_RADIUS,
) -> np.ndarray:
    """Number of images outside the core of each source-plane point (module docstring).

    Parameters
    ----------
    profiles : sequence of MassProfile
    source_x, source_y : array_like
        Source-plane points (arcsec), any shape.
    half_width : float
        Images are sought in the square of this half width (arcsec) around ``centre``.
    grid_spacing, core_radius : float
        Triangle grid spacing and the core left out around each profile's centre (arcsec;
        profiles without a centre, such as external shear, leave none out).

    Returns
    -------
    ndarray of int, shape of ``source_x``
    """
    source_x, source_y = np.broadcast_arrays(
        np.asarray(source_x, dtype=float), np.asarray(source_y, dtype=float)
    )
    n_half = int(np.ceil(half_width / grid_spacing))
    axis = np.arange(-n_half, n_half + 1) * grid_spacing
    x_offset, y_offset = GRID_OFFSET
    x, y = np.meshgrid(
        axis + centre[0] + x_offset * grid_spacing, axis + centre[1] + y_offset * grid_spacing
    )
    bx, by = ray_trace(profiles, x, y)
    near = np.zeros(x.shape, dtype=bool)
    for profile in profiles:
        if hasattr(profile, "centre"):
            near |= np.hypot(x - profile.centre[0], y - profile.centre[1]) < core_radius
    excluded = near[:-1, :-1] | near[1:, :-1] | near[:-1, 1:] | near[1:, 1:]
    px, py = source_x.ravel(), source_y.ravel()
    if not px.size:
        return np.zeros(source_x.shape, dtype=np.int64)
    size = 4.0 * grid_spacing
    origin = np.array([px.min(), py.min()])
    columns = int((px.max() - origin[0]) // size) + 1
    rows = int((py.max() - origin[1]) // size) + 1
    bucket = ((py - origin[1]) // size).astype(np.int64) * columns + (
        (px - origin[0]) // size
    ).astype(np.int64)
    order = np.argsort(bucket, kind="stable")
    starts = np.searchsorted(bucket[order], np.arange(rows * columns + 1))
    counts = _count_in_triangles(
        bx, by, excluded, px, py, order, starts, origin, size, np.array([rows, columns])
    )
    return counts.reshape(source_x.shape)


@dataclass(frozen=True)
class MultiplicityCheck:
    """How much of a fitted lensed source is multiply imaged (:func:`multiplicity_check`).

    ``multiply_imaged_fraction`` is the share of the lensed source's signal, Σ (LENSED/σ)²
    over the fit pixels where LENSED > σ, in pixels whose source-plane position has two or
    more images outside the core (``None`` with no such pixel); ``n_pixels`` counts those
    pixels; ``flag`` is True when the share is below :data:`MIN_MULTIPLY_IMAGED_FRACTION`,
    with the ``reason``.
    """

    multiply_imaged_fraction: float | None
    n_pixels: int
    flag: bool
    reason: str

    def to_dict(self) -> dict:
        return asdict(self)


def multiplicity_check(
    profiles: Sequence[MassProfile],
    lensed: np.ndarray,
    noise_map: np.ndarray,
    used: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    half_width: float,
    centre: tuple[float, float] = (0.0, 0.0),
) -> MultiplicityCheck:
    """The multiply imaged share of the lensed source's signal (:class:`MultiplicityCheck`).

    ``lensed`` is the blurred lensed-source model, ``noise_map`` σ, ``used`` the fit's
    pixels and ``x``, ``y`` the pixel centres (arcsec), all of one shape; images are sought
    within ``half_width`` (arcsec) of ``centre`` (the fit circle's bounding square). Each
    pixel with LENSED > σ is traced to the source plane and its images counted
    (:func:`image_counts`); its weight is (LENSED/σ)², its share of the lensed source's
    χ² against a model without it, so that the share measures the signal the likelihood
    fits rather than the flux, which faint wide arcs dominate.
    """
    bright = used & (lensed > noise_map)
    if not bright.any():
        return MultiplicityCheck(None, 0, False, "no lensed-source pixel above the noise")
    bx, by = ray_trace(profiles, x[bright], y[bright])
    counts = image_counts(profiles, bx, by, half_width, centre)
    weight = (lensed[bright] / noise_map[bright]) ** 2
    fraction = float(weight[counts >= 2].sum() / weight.sum())
    if fraction < MIN_MULTIPLY_IMAGED_FRACTION:
        reason = (
            f"singly imaged: {fraction:.0%} of the lensed source's signal (Σ (LENSED/σ)² "
            f"above the noise) has a counter-image, less than {MIN_MULTIPLY_IMAGED_FRACTION:.0%}"
            ": θ_E rests mostly on the shape of single arcs"
        )
        return MultiplicityCheck(fraction, int(bright.sum()), True, reason)
    return MultiplicityCheck(fraction, int(bright.sum()), False, "")

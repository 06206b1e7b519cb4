"""Pixel grids: coordinates, masked (slim) vectors, sub-grids and the blurring region.

Conventions (SPEC §1.1):

* Native 2D arrays have shape ``(n_y, n_x)``, are indexed ``image[row, col]``, and the
  **row index increases with +y** (FITS / astropy orientation; plot with
  ``origin="lower"``). Pixel ``(r, c)`` has centre
  ``x = (c - (n_x - 1)/2) Δ + x0``, ``y = (r - (n_y - 1)/2) Δ + y0`` (arcsec).
* Masks are boolean with **True = excluded**.
* "Slim" vectors hold the unmasked pixels in row-major order of the native array.
* A sub-grid of size s×s in a pixel of centre (x_p, y_p) has sub-pixel (a, b) at
  ``x = x_p − Δ/2 + (b + ½)Δ/s``, ``y = y_p − Δ/2 + (a + ½)Δ/s``, ordered row-major
  (a = row, increasing with y). Binning averages the s² sub-pixels (SPEC §1.3).
"""

from dataclasses import dataclass

import numpy as np
from scipy import ndimage


def pixel_centres(
    shape: tuple[int, int], pixel_scale: float, origin: tuple[float, float] = (0.0, 0.0)
) -> tuple[np.ndarray, np.ndarray]:
    """Return the (x, y) arcsec coordinates of every pixel centre, each of ``shape``."""
    n_y, n_x = shape
    x1 = (np.arange(n_x) - (n_x - 1) / 2.0) * pixel_scale + origin[0]
    y1 = (np.arange(n_y) - (n_y - 1) / 2.0) * pixel_scale + origin[1]
    x, y = np.meshgrid(x1, y1)
    return x, y


def to_slim(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Unmasked pixels of a native ``image`` (or a stack ``(..., n_y, n_x)``) in slim order."""
    return image[..., ~mask]


def to_native(values: np.ndarray, mask: np.ndarray, fill: float = 0.0) -> np.ndarray:
    """Place slim ``values`` (n_unmasked,) back on the native grid, ``fill`` elsewhere."""
    values = np.asarray(values)
    out = np.full(mask.shape, fill, dtype=np.result_type(values.dtype, np.float64))
    out[~mask] = values
    return out


def sub_pixel_offsets(sub_size: int, pixel_scale: float) -> tuple[np.ndarray, np.ndarray]:
    """(dx, dy) offsets of the s² sub-pixels from their pixel centre, row-major."""
    step = pixel_scale / sub_size
    offsets_1d = -pixel_scale / 2.0 + (np.arange(sub_size) + 0.5) * step
    dx, dy = np.meshgrid(offsets_1d, offsets_1d)
    return dx.ravel(), dy.ravel()


@dataclass(frozen=True)
class SubGrid:
    """Sub-pixel coordinates of a set of pixels, each pixel with its own sub-size.

    Attributes
    ----------
    x, y : ndarray (n_sub,)
        Sub-pixel centres in arcsec, pixel by pixel, each pixel's sub-pixels row-major.
    sub_sizes : ndarray (n_pixels,) of int
        The s of every pixel (s² sub-pixels each).
    starts : ndarray (n_pixels,) of int
        Index in ``x``/``y`` of each pixel's first sub-pixel.
    """

    x: np.ndarray
    y: np.ndarray
    sub_sizes: np.ndarray
    starts: np.ndarray

    @property
    def n_pixels(self) -> int:
        return self.sub_sizes.size

    @property
    def uniform_sub_size(self) -> int | None:
        """The common sub-size if every pixel has the same one, else None."""
        sizes = np.unique(self.sub_sizes)
        return int(sizes[0]) if sizes.size == 1 else None

    @property
    def weights(self) -> np.ndarray:
        """Binning weight 1/s² of every sub-pixel (n_sub,)."""
        return np.repeat(1.0 / self.sub_sizes.astype(float) ** 2, self.sub_sizes**2)

    def bin(self, values: np.ndarray) -> np.ndarray:
        """Mean over each pixel's sub-pixels; ``values`` is (n_sub,) or (n_sub, n_col)."""
        values = np.asarray(values)
        s = self.uniform_sub_size
        if s is not None:
            return values.reshape(self.n_pixels, s * s, *values.shape[1:]).mean(axis=1)
        w = self.weights if values.ndim == 1 else self.weights[:, None]
        return np.add.reduceat(values * w, self.starts, axis=0)


def sub_grid(
    x: np.ndarray, y: np.ndarray, pixel_scale: float, sub_sizes: int | np.ndarray
) -> SubGrid:
    """Sub-grid of the pixels centred at (x, y) (1D arrays, arcsec).

    ``sub_sizes`` is one int for a uniform sub-grid or one int per pixel (adaptive
    over-sampling, SPEC §1.3).
    """
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    sizes = np.broadcast_to(np.asarray(sub_sizes, dtype=np.int64), x.shape).copy()
    if np.any(sizes < 1):
        raise ValueError("sub-grid sizes must be >= 1")
    counts = sizes**2
    starts = np.concatenate(([0], np.cumsum(counts)[:-1])).astype(np.int64)
    xs = np.empty(counts.sum())
    ys = np.empty(counts.sum())
    for s in np.unique(sizes):
        pix = np.flatnonzero(sizes == s)
        dx, dy = sub_pixel_offsets(int(s), pixel_scale)
        idx = (starts[pix][:, None] + np.arange(s * s)[None, :]).ravel()
        xs[idx] = (x[pix][:, None] + dx[None, :]).ravel()
        ys[idx] = (y[pix][:, None] + dy[None, :]).ravel()
    return SubGrid(x=xs, y=ys, sub_sizes=sizes, starts=starts)


def adaptive_sub_sizes(
    x: np.ndarray,
    y: np.ndarray,
    centre: tuple[float, float],
    radius: float,
    sub_size: int = 4,
    sub_size_centre: int = 16,
) -> np.ndarray:
    """Per-pixel sub-size: ``sub_size_centre`` within ``radius`` arcsec of ``centre``.

    SPEC §1.3 DECISION: 4×4 everywhere, 16×16 for pixels whose centre lies within
    0.3″ of the lens-light prior centre.
    """
    r = np.hypot(np.asarray(x) - centre[0], np.asarray(y) - centre[1])
    return np.where(r <= radius, sub_size_centre, sub_size).astype(np.int64)


def blurring_mask(mask: np.ndarray, kernel_shape: tuple[int, int]) -> np.ndarray:
    """Blurring region as a mask (True = excluded, SPEC §1.4).

    The region is the set of masked-out pixels within the PSF footprint of an unmasked
    pixel: Chebyshev distance ≤ (k − 1)/2 per axis. Returned as a mask in which only
    those pixels are False.
    """
    ky, kx = kernel_shape
    structure = np.ones((ky, kx), dtype=bool)
    reach = ndimage.binary_dilation(~mask, structure=structure)
    region = reach & mask
    return ~region


def flat_points(x, y) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
    """Contiguous float64 1D copies of broadcast ``x``, ``y`` and their common shape (for
    kernels that take flat point arrays; reshape their output to the shape)."""
    x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    return np.ascontiguousarray(x).ravel(), np.ascontiguousarray(y).ravel(), x.shape

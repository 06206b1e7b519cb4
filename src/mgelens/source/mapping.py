"""Mapping matrix of the pixelized source and its PSF-blurred version (SPEC §4.5).

f_ij = (1/s²) Σ_{sub-pixels of image pixel i} ω_j(β_s): the mean, over the s×s
sub-pixels of image pixel i, of the interpolation weight of mesh point j at the
traced (and border-relocated) sub-pixel position β_s. Its PSF-blurred version
M^src = B f (columns convolved inside the mask only, SPEC §1.4) is never formed by the
fit: see :mod:`mgelens.inversion.system`.
"""

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from mgelens._jit import njit


@dataclass(frozen=True)
class SourceWeights:
    """Interpolation weights of traced sub-pixels onto mesh points (CSR rows per sub-pixel).

    Attributes
    ----------
    indptr, indices, values : ndarray
        Sub-pixel s has weights ``values[indptr[s]:indptr[s+1]]`` (≥ 0, summing to 1)
        on the mesh points ``indices[indptr[s]:indptr[s+1]]``.
    sub_size : int
        Sub-pixels per image pixel are s² and consecutive (uniform sub-grid).
    n_source : int
        Number of mesh points N_S.
    """

    indptr: np.ndarray
    indices: np.ndarray
    values: np.ndarray
    sub_size: int
    n_source: int

    @property
    def n_pixels(self) -> int:
        """Number of image pixels N_I."""
        return (self.indptr.size - 1) // self.sub_size**2

    @property
    def pixel_of_entry(self) -> np.ndarray:
        """Slim image pixel of every stored weight."""
        rows = np.repeat(np.arange(self.indptr.size - 1), np.diff(self.indptr))
        return rows // self.sub_size**2


def mapping_matrix(weights: SourceWeights) -> sparse.csr_matrix:
    """Sparse f (N_I × N_S), column indices sorted: sub-pixel weights averaged per pixel."""
    indptr, indices, values = _merge_sub_pixels(
        weights.indptr, weights.indices, weights.values, weights.sub_size**2, weights.n_source
    )
    return sparse.csr_matrix((values, indices, indptr), shape=(weights.n_pixels, weights.n_source))


@njit(inline="always")
def _insertion_sort(values, start, end):
    """Sort ``values[start:end]`` in place (a pixel's few mesh points: no allocation)."""
    for i in range(start + 1, end):
        key = values[i]
        k = i - 1
        while k >= start and values[k] > key:
            values[k + 1] = values[k]
            k -= 1
        values[k + 1] = key


@njit
def _merge_sub_pixels(indptr, indices, values, n_sub, n_source):
    n_pixels = (indptr.size - 1) // n_sub
    out_indptr = np.zeros(n_pixels + 1, dtype=np.int64)
    out_indices = np.empty(indices.size, dtype=np.int64)
    out_values = np.empty(indices.size)
    accumulated = np.zeros(n_source)
    seen = np.full(n_source, -1, dtype=np.int64)
    count = 0
    for pixel in range(n_pixels):
        start = count
        for p in range(indptr[pixel * n_sub], indptr[(pixel + 1) * n_sub]):
            j = indices[p]
            if seen[j] != pixel:
                seen[j] = pixel
                accumulated[j] = 0.0
                out_indices[count] = j
                count += 1
            accumulated[j] += values[p]
        _insertion_sort(out_indices, start, count)
        for q in range(start, count):
            out_values[q] = accumulated[out_indices[q]] / n_sub
        out_indptr[pixel + 1] = count
    return out_indptr, out_indices[:count], out_values[:count]

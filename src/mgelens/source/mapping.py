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
    """Sparse f (N_I × N_S): sub-pixel weights averaged over each image pixel."""
    f = sparse.csr_matrix(
        (weights.values / weights.sub_size**2, (weights.pixel_of_entry, weights.indices)),
        shape=(weights.n_pixels, weights.n_source),
    )
    f.sum_duplicates()
    return f


"""Regularization matrices of the pixelized source (SPEC §5).

Every scheme returns a symmetric sparse matrix H (N_S × N_S) that already contains its
coefficients, so the penalty is G_L = sᵀHs (no ½), plus a jitter ε = 1e−8 on the
diagonal that keeps H positive definite.

* :func:`constant_matrix`: H = c² L + εI, L the graph Laplacian of the Delaunay edges.
* :func:`adaptive_matrix`: for every directed neighbour pair (j → l) add
  ρ_l (e_j − e_l)(e_j − e_l)ᵀ with ρ_l = w_l², w = (λ_in S + λ_out(1 − S))².
* :func:`split_matrix` ("cross" regularization of the paper): H = εI + Σ_j ρ_j Σ_m b_jm b_jmᵀ
  with b_jm = e_j − Σ_l ω_l(q_jm) e_l the difference between pixel j and the
  natural-neighbour interpolation at its four cross points q_jm; ρ_j = c² (constant) or
  w_j² (adaptive).
"""

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from mgelens.source.image_mesh import floored_adapt_image
from mgelens.source.interpolate import cross_points, natural_neighbour_weights
from mgelens.source.mapping import SourceWeights
from mgelens.source.mesh import VoronoiMesh
from mgelens.source.schemes import SIGNAL_AVERAGES

JITTER = 1e-8


def adaptive_pixel_signals(
    weights: SourceWeights, adapt_image: np.ndarray, signal_scale: float, average: str = "anchor"
) -> np.ndarray:
    """Source-pixel signals S_j ∈ [0, 1] from the adapt image (SPEC §5.2).

    The adapt image Ξ is first floored at 1 % of its maximum (SPEC §4.1). For every
    sub-pixel s of image pixel i and every natural neighbour j of its traced position
    (weight ω_j(s) > 0), S_j += Ξ_i ω_j(s); the sum is then divided by

    * ``average="anchor"``: n_j, the number of such sub-pixels (SPEC §5.2, the anchor's
      ``adaptive_pixel_signals_from``);
    * ``average="weighted"``: Σ_s ω_j(s), making S_j the ω-weighted mean of Ξ.

    Both agree when every sub-pixel has a single weight 1 (nearest-cell mapping). With
    natural-neighbour weights the anchor's count jumps by one whenever a sub-pixel enters
    or leaves pixel j's natural-neighbour region, where its weight is ~0: S_j, and with it
    ln det H, then step as the mass model moves the traced sub-pixels
    (docs/design_notes.md, "Adaptive signals"). The weighted mean is continuous in the
    weights.

    S is then normalised by its maximum and raised to the power ``signal_scale`` κ_s.
    Pixels no sub-pixel reaches get S = 0.

    The anchor (2024.5.16) also adds 1 to n_{N_S−1} for every sub-pixel whose padded
    neighbour list holds unused (−1) slots, which drives that pixel's signal towards 0. That
    indexing slip is not reproduced (on configuration R it moves ln det H by 1.3).
    """
    if average not in SIGNAL_AVERAGES:
        raise ValueError(f"average must be one of {SIGNAL_AVERAGES}, got {average!r}")
    adapt_image = floored_adapt_image(adapt_image)
    pixel = weights.pixel_of_entry
    n = weights.n_source
    total = np.bincount(weights.indices, weights=adapt_image[pixel] * weights.values, minlength=n)
    if average == "anchor":
        norm = np.bincount(weights.indices, minlength=n).astype(float)
    else:
        norm = np.bincount(weights.indices, weights=weights.values, minlength=n)
    signals = np.divide(total, norm, out=np.zeros(n), where=norm > 0)
    peak = signals.max()
    if peak > 0:
        signals = signals / peak
    return signals**signal_scale


def adaptive_weights(signals: np.ndarray, inner_coefficient: float, outer_coefficient: float):
    """w_j = (λ_in S_j + λ_out (1 − S_j))² (SPEC §5.2)."""
    return (inner_coefficient * signals + outer_coefficient * (1.0 - signals)) ** 2


def _edge_matrix(edges: np.ndarray, edge_coefficients: np.ndarray, n: int) -> sparse.csc_matrix:
    """Σ_edges a_e (e_j − e_l)(e_j − e_l)ᵀ + εI as a sparse matrix."""
    first, second = edges[:, 0], edges[:, 1]
    diagonal = np.bincount(first, edge_coefficients, n) + np.bincount(second, edge_coefficients, n)
    rows = np.concatenate([first, second, np.arange(n)])
    cols = np.concatenate([second, first, np.arange(n)])
    values = np.concatenate([-edge_coefficients, -edge_coefficients, diagonal + JITTER])
    return sparse.csc_matrix((values, (rows, cols)), shape=(n, n))


def constant_matrix(mesh: VoronoiMesh, coefficient: float) -> sparse.csc_matrix:
    """Constant gradient regularization over Delaunay neighbours: c² L + εI (SPEC §5.1)."""
    edge_coefficients = np.full(len(mesh.edges), coefficient**2)
    return _edge_matrix(mesh.edges, edge_coefficients, mesh.n_points)


def adaptive_matrix(mesh: VoronoiMesh, weights: np.ndarray) -> sparse.csc_matrix:
    """Adaptive neighbour regularization with ρ_l = w_l² per directed pair (SPEC §5.2).

    Each undirected Delaunay edge (j, l) appears as j → l and l → j, so its coefficient
    is ρ_j + ρ_l.
    """
    rho = weights**2
    return _edge_matrix(mesh.edges, rho[mesh.edges[:, 0]] + rho[mesh.edges[:, 1]], mesh.n_points)


def cross_difference_matrix(mesh: VoronoiMesh, offset: str = "anchor") -> sparse.csr_matrix:
    """The 4 N_S × N_S matrix whose row (j, m) is b_jm = e_j − Σ_l ω_l(q_jm) e_l (SPEC §5.3).

    Cross points outside the convex hull take nearest-point weights, which can be pixel j
    itself: that row is then zero.
    """
    n = mesh.n_points
    cross = cross_points(mesh, offset)
    indptr, indices, values = natural_neighbour_weights(mesh, cross[:, 0], cross[:, 1])
    n_rows = cross.shape[0]
    interpolation = sparse.csr_matrix((values, indices, indptr), shape=(n_rows, n))
    owner = sparse.csr_matrix(
        (np.ones(n_rows), (np.arange(n_rows), np.repeat(np.arange(n), 4))), shape=(n_rows, n)
    )
    return (owner - interpolation).tocsr()


def split_matrix(
    mesh: VoronoiMesh, coefficients: np.ndarray | float, offset: str = "anchor"
) -> sparse.csc_matrix:
    """Cross ("split") regularization H = εI + Σ_j ρ_j Σ_m b_jm b_jmᵀ (SPEC §5.3).

    ``coefficients`` is ρ_j per source pixel (array) or one value for all of them:
    pass c² for ConstantSplit and w_j² (:func:`adaptive_weights` squared) for
    AdaptiveBrightnessSplit.
    """
    n = mesh.n_points
    rho = np.broadcast_to(np.asarray(coefficients, dtype=float), (n,))
    b = cross_difference_matrix(mesh, offset)
    weighted = sparse.diags(np.repeat(rho, 4)) @ b
    h = (b.T @ weighted).tocsc()
    return (h + JITTER * sparse.identity(n, format="csc")).tocsc()


def _signals(weights: SourceWeights, adapt_image: np.ndarray | None, scale: float, average: str):
    if adapt_image is None:
        raise ValueError("adaptive regularization needs an adapt image (lensed source model)")
    return adaptive_pixel_signals(weights, adapt_image, scale, average)


@dataclass(frozen=True)
class Constant:
    """Gradient regularization over Voronoi neighbours with coefficient c (SPEC §5.1)."""

    coefficient: float

    def matrix(self, mesh, weights, adapt_image=None) -> sparse.csc_matrix:
        return constant_matrix(mesh, self.coefficient)


@dataclass(frozen=True)
class AdaptiveBrightness:
    """Neighbour regularization weighted by the adapt image (SPEC §5.2); ``signals`` is the
    ``average`` of :func:`adaptive_pixel_signals`."""

    inner_coefficient: float
    outer_coefficient: float
    signal_scale: float
    signals: str = "anchor"

    def matrix(self, mesh, weights, adapt_image=None) -> sparse.csc_matrix:
        signals = _signals(weights, adapt_image, self.signal_scale, self.signals)
        w = adaptive_weights(signals, self.inner_coefficient, self.outer_coefficient)
        return adaptive_matrix(mesh, w)


@dataclass(frozen=True)
class ConstantSplit:
    """Cross regularization with ρ_j = c² (anchor ``ConstantSplit``, SPEC §5.3)."""

    coefficient: float
    offset: str = "anchor"

    def matrix(self, mesh, weights, adapt_image=None) -> sparse.csc_matrix:
        return split_matrix(mesh, self.coefficient**2, self.offset)


@dataclass(frozen=True)
class AdaptiveBrightnessSplit:
    """Cross regularization with ρ_j = w_j² (anchor ``AdaptiveBrightnessSplit``, SPEC §5.3);
    ``signals`` is the ``average`` of :func:`adaptive_pixel_signals`."""

    inner_coefficient: float
    outer_coefficient: float
    signal_scale: float
    offset: str = "anchor"
    signals: str = "anchor"

    def matrix(self, mesh, weights, adapt_image=None) -> sparse.csc_matrix:
        signals = _signals(weights, adapt_image, self.signal_scale, self.signals)
        w = adaptive_weights(signals, self.inner_coefficient, self.outer_coefficient)
        return split_matrix(mesh, w**2, self.offset)

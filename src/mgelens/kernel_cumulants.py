"""Cumulants of a pixel PSF (with the pixel's own light integral), for the closed-form
blurred columns of Gaussians much wider than the PSF
(:func:`mgelens.light.blurred_gaussian_columns`, a route of the lens-light columns beside
SPEC §1.3–1.4's sub-grid and convolution).

The numerical route evaluates a Gaussian on an s×s sub-grid of each pixel, averages, and
convolves with the pixel PSF P. Both steps are a convolution with a measure: the discrete
kernel μ_P = Σ_j P_j δ(x − d_j), d_j the offset of kernel entry j in arcsec, and the
pixel's own light integral (the s×s sub-grid approximates the uniform box of side Δ).
For a Gaussian wide against μ = μ_P ⊗ box, the Edgeworth expansion of μ around the
Gaussian with μ's mean m and covariance C gives, to fourth order in its cumulants,

    G ⊗ μ ≈ M F (1 + T₃/6 + T₄/24),
    F = √(det Σ_G / det S) exp(−½ uᵀ v),  S = Σ_G + C,  u = x − c − m,  v = S⁻¹ u,
    T₃ = κ₃[v, v, v] − 3 κ₃[S⁻¹, v],
    T₄ = κ₄[v, v, v, v] − 6 κ₄[S⁻¹, v, v] + 3 κ₄[S⁻¹, S⁻¹],

with G = exp(−(q² x′² + y′²)/(2σ²)) (unit peak, covariance Σ_G: σ²/q² along the major
axis, σ² along the minor), M = Σ_j P_j, and κ₃, κ₄ the third and fourth cumulant
tensors of μ (μ_P's plus the box's: Δ²/12 on the diagonal of C, −Δ⁴/120 on κ₄'s two
pure entries). Its error falls as σ⁻⁶ and depends only on the PSF:
:func:`mgelens.analytic_blur.smallest_analytic_sigma` finds, once per PSF, the minor-axis
σ from which it stays below a tolerance of the column's peak against the exact discrete
convolution. The box is integrated exactly, where the sub-grid differs from it by about
Δ²(1 − 1/s²)/12 in variance (a relative ≈ 0.02 Δ²/σ² for s = 2): wide columns move by
about that much between the two routes, which is the sub-grid's own error.

Conventions: (x, y) arcsec with +x along columns and +y along rows (``grid.pixel_centres``);
a kernel entry [a, b] of a (2h+1)² PSF moves light by ((b − h) Δ, (a − h) Δ), as
:mod:`mgelens.convolve` convolves.
"""

from dataclasses import dataclass

import numpy as np

from mgelens.convolve import check_psf

_BOX_VARIANCE = 1.0 / 12.0
_BOX_FOURTH_CUMULANT = -1.0 / 120.0
"""Variance and fourth cumulant of the uniform distribution on [−½, ½] (times Δ², Δ⁴)."""


@dataclass(frozen=True)
class KernelCumulants:
    """Total weight, mean, covariance and third and fourth cumulant tensors of a
    convolution kernel (arcsec, arcsec², …), the measure the expansion blurs with.

    Attributes
    ----------
    total : float
        Σ_j P_j.
    mean : ndarray (2,)
    covariance : ndarray (2, 2)
    third : ndarray (2, 2, 2)
    fourth : ndarray (2, 2, 2, 2)
    """

    total: float
    mean: np.ndarray
    covariance: np.ndarray
    third: np.ndarray
    fourth: np.ndarray

    @classmethod
    def of_psf(cls, psf: np.ndarray, pixel_scale: float, pixel_box: bool) -> "KernelCumulants":
        """Cumulants of the discrete kernel ``psf`` (odd, positive sum) with pixel scale
        Δ = ``pixel_scale``, convolved with the uniform Δ×Δ box when ``pixel_box``."""
        psf = check_psf(psf)
        total = float(psf.sum())
        if not total > 0.0:
            raise ValueError(f"the PSF must have a positive sum, got {total}")
        half_y, half_x = psf.shape[0] // 2, psf.shape[1] // 2
        rows, cols = np.mgrid[: psf.shape[0], : psf.shape[1]]
        offsets = np.stack([(cols - half_x).ravel(), (rows - half_y).ravel()], axis=1)
        offsets = offsets * float(pixel_scale)
        weights = psf.ravel() / total
        mean = weights @ offsets
        u = offsets - mean
        covariance = np.einsum("n,ni,nj->ij", weights, u, u)
        third = np.einsum("n,ni,nj,nk->ijk", weights, u, u, u)
        fourth = np.einsum("n,ni,nj,nk,nl->ijkl", weights, u, u, u, u) - _gaussian_fourth(
            covariance
        )
        if pixel_box:
            covariance = covariance + np.eye(2) * _BOX_VARIANCE * pixel_scale**2
            fourth = fourth.copy()
            fourth[0, 0, 0, 0] += _BOX_FOURTH_CUMULANT * pixel_scale**4
            fourth[1, 1, 1, 1] += _BOX_FOURTH_CUMULANT * pixel_scale**4
        return cls(total, mean, covariance, third, fourth)


def _gaussian_fourth(covariance: np.ndarray) -> np.ndarray:
    """E[u_i u_j u_k u_l] of a zero-mean Gaussian with ``covariance`` (Isserlis)."""
    c = covariance
    return (
        np.einsum("ij,kl->ijkl", c, c)
        + np.einsum("ik,jl->ijkl", c, c)
        + np.einsum("il,jk->ijkl", c, c)
    )

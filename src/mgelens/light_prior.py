"""A smoothness prior on the MGE lens light's intensities, weighed by the evidence.

An MGE set's Gaussians (σ_1 < … < σ_N, log-spaced) describe one smooth profile, but
solved freely their intensities I_k alternate between a few large values and zeros and
fit the noise (docs/recovery.md, "The isophote tolerance against the noise"). The prior
is Gaussian in f_k = I_k σ_k² (each Gaussian's flux, up to the set's shared 2πq):

    ½ λ w̄ (‖D₂ f‖² + ρ ‖f‖²)  per penalised set,

with D₂ the (N − 2) × N second difference along the σ ladder, ρ = :data:`RIDGE` (a small
ridge that makes the prior proper) and w̄ the median inverse variance of the fitted
pixels, so that λ is a pure number, free of the data's flux and noise units. On the
intensities the prior is ½ λ xᵀRx with R = w̄ S (D₂ᵀD₂ + ρ 1) S, S = diag(σ_k²), block
diagonal over the penalised sets (the central point set is not penalised). The linear
solve adds λR to the lens-light block of F + H, and the log evidence gains, as the
source's regularization does (SPEC §7, the same convention of a block's own log det),

    −½ [λ xᵀRx + ln det(F + λR)_PP − ln det(λR)_PP],

P the penalised intensities, F the curvature matrix with its ``mge_diagonal``. λ is a
hyper-parameter (``lens_light.smoothness``) that the LIGHT phase samples and MASS keeps
(``slam.lens_light_prior``).
"""

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import linalg

from mgelens.inversion.evidence import log_det_cholesky

RIDGE = 0.01
"""ρ: the ridge on the fluxes relative to their second differences."""


def smoothness_matrix(sigmas: np.ndarray, weight: float) -> tuple[np.ndarray, float]:
    """R of one set (N × N), w̄ S (D₂ᵀD₂ + ρ 1) S with S = diag(σ²), σ in arcsec, and
    ln det R, taken from its factors (R's own condition reaches ~1e13 for σ from 0.01″
    to 3″, so a Cholesky of R would lose digits that the factors keep). The arrays are
    shared between calls with the same σ and w̄ (read-only)."""
    sigmas = np.asarray(sigmas, dtype=float)
    return _smoothness_matrix(sigmas.tobytes(), float(weight))


@functools.lru_cache(maxsize=64)
def _smoothness_matrix(sigma_bytes: bytes, weight: float) -> tuple[np.ndarray, float]:
    sigmas = np.frombuffer(sigma_bytes)
    n = sigmas.size
    second = np.diff(np.eye(n), n=2, axis=0)
    inner = second.T @ second + RIDGE * np.eye(n)
    scale = sigmas**2
    matrix = weight * scale[:, None] * inner * scale[None, :]
    matrix.flags.writeable = False
    log_det = n * np.log(weight) + 2.0 * np.sum(np.log(scale)) + log_det_cholesky(inner)
    return matrix, float(log_det)


@dataclass(frozen=True)
class MGESmoothnessPrior:
    """λ and the lens-light components the prior applies to.

    Attributes
    ----------
    coefficient : float
        λ > 0 (dimensionless, see the module docstring).
    penalised : tuple of bool
        One flag per lens-light component of the model (True for an extended MGE set;
        a point set or a Sérsic is not penalised).
    """

    coefficient: float
    penalised: tuple[bool, ...]

    def __post_init__(self):
        if not (np.isfinite(self.coefficient) and self.coefficient > 0):
            raise ValueError(f"smoothness coefficient must be positive, got {self.coefficient}")
        object.__setattr__(self, "penalised", tuple(bool(p) for p in self.penalised))

    def system(self, components: Sequence, weight: float) -> "PriorSystem":
        """λR over the penalised lens-light columns of ``components`` (in the order of
        their columns), with ``weight`` = w̄, and ln det(λR)."""
        if len(components) != len(self.penalised):
            raise ValueError(
                f"the prior flags {len(self.penalised)} components, the model has {len(components)}"
            )
        indices, matrices, log_det, start = [], [], 0.0, 0
        for component, penalised in zip(components, self.penalised, strict=True):
            if penalised:
                if not hasattr(component, "sigmas"):
                    raise ValueError("the smoothness prior applies to MGE sets only")
                indices.append(np.arange(start, start + component.n_columns))
                matrix, set_log_det = smoothness_matrix(component.sigmas, weight)
                matrices.append(matrix)
                log_det += set_log_det
            start += component.n_columns
        if not indices:
            raise ValueError("the smoothness prior has no MGE set to penalise")
        n = sum(i.size for i in indices)
        return PriorSystem(
            np.concatenate(indices),
            self.coefficient * linalg.block_diag(*matrices),
            n * np.log(self.coefficient) + log_det,
        )


@dataclass(frozen=True, eq=False)
class PriorSystem:
    """The prior on one model's lens-light columns: ``indices`` P, ``matrix`` λR_PP and
    ``log_det`` = ln det(λR_PP)."""

    indices: np.ndarray
    matrix: np.ndarray
    log_det: float

    def add_to(self, q: np.ndarray) -> float:
        """Add λR to the P block of ``q`` (in place) and return ln det of that block,
        which the solve does not change."""
        block = np.ix_(self.indices, self.indices)
        q[block] += self.matrix
        return log_det_cholesky(q[block])

    def terms(self, x: np.ndarray, log_det_curvature: float) -> "PriorTerms":
        """The prior's evidence terms at the solution ``x``."""
        xp = x[self.indices]
        return PriorTerms(float(xp @ (self.matrix @ xp)), log_det_curvature, self.log_det)


@dataclass(frozen=True)
class PriorTerms:
    """The prior's part of ln ε, −½ (``penalty`` + ``log_det_curvature`` −
    ``log_det_prior``): λ x_PᵀR x_P, ln det(F + λR)_PP and ln det(λR)_PP."""

    penalty: float
    log_det_curvature: float
    log_det_prior: float

    @property
    def log_evidence_change(self) -> float:
        return -0.5 * (self.penalty + self.log_det_curvature - self.log_det_prior)

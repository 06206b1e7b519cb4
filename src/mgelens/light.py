"""Light profiles: elliptical Gaussian, elliptical Sérsic and MGE sets (SPEC §2).

MGE sets and Sérsics are also *linear* light components: ``columns(grid)`` gives their
unit-intensity images (one column per Gaussian, one per Sérsic), whose coefficients the
inversion solves.

Conventions: (x, y) in arcsec, angles in degrees counter-clockwise from +x,
``ell_comps = (e1, e2)`` (see :mod:`mgelens.geometry`); intensities are surface
brightness in data units per pixel (e.g. e⁻ s⁻¹ pix⁻¹), so a profile's pixel sum is
its integral over arcsec² divided by Δ².

The fitted MGE basis uses the PyAutoGalaxy ("anchor") Gaussian of SPEC §2.2,
G = I₀ exp(−(q² x′² + y′²)/(2σ²)), whose ``sigma`` is the **minor-axis** dispersion;
mgefit / the paper quote the **major-axis** dispersion σ_p = σ/q
(:meth:`Gaussian.from_major_axis`).
"""

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from numba import prange
from scipy.special import gamma as gamma_function

from mgelens._jit import njit
from mgelens.convolve import Convolver
from mgelens.geometry import axis_ratio_and_angle_from, ell_comps_from, to_profile_frame
from mgelens.grid import SubGrid, adaptive_sub_sizes, pixel_centres, sub_grid
from mgelens.kernel_cumulants import KernelCumulants

EXPONENT_CUTOFF = 40.0
"""Gaussian terms exp(−e) with e ≥ 40 are dropped: exp(−40) ≈ 4e−18 of a Gaussian's own peak,
below double precision, while a narrow Gaussian's column then stays zero (and unblurred)
beyond 8.9 of its major-axis σ (:class:`mgelens.convolve.Convolver` crops its FFT there)."""

_EXP_STEPS = 64
_EXP_TABLE = np.exp2(-np.arange(int(EXPONENT_CUTOFF * _EXP_STEPS / np.log(2.0)) + 2) / _EXP_STEPS)
"""2^(−j/64) for every j the Gaussian kernel's exp(−e), 0 ≤ e ≤ EXPONENT_CUTOFF, can need."""


@dataclass(frozen=True)
class Gaussian:
    """Elliptical Gaussian, anchor form (SPEC §2.2).

    Attributes
    ----------
    centre : (x, y) arcsec
    ell_comps : (e1, e2)
    sigma : float
        Minor-axis dispersion in arcsec (major-axis dispersion is ``sigma / q``).
    intensity : float
        Central surface brightness I₀ (data units per pixel).
    """

    centre: tuple[float, float] = (0.0, 0.0)
    ell_comps: tuple[float, float] = (0.0, 0.0)
    sigma: float = 1.0
    intensity: float = 1.0

    def __post_init__(self):
        if not self.sigma > 0.0:
            raise ValueError(f"Gaussian sigma must be > 0 arcsec, got {self.sigma}")

    @classmethod
    def from_major_axis(
        cls,
        centre: tuple[float, float],
        axis_ratio: float,
        angle: float,
        sigma_major: float,
        intensity: float = 1.0,
    ) -> "Gaussian":
        """Gaussian from the mgefit / paper parameters (major-axis σ, q, φ in degrees)."""
        return cls(
            centre=centre,
            ell_comps=ell_comps_from(axis_ratio, angle),
            sigma=axis_ratio * sigma_major,
            intensity=intensity,
        )

    @property
    def axis_ratio(self) -> float:
        return axis_ratio_and_angle_from(self.ell_comps)[0]

    @property
    def angle(self) -> float:
        return axis_ratio_and_angle_from(self.ell_comps)[1]

    @property
    def sigma_major(self) -> float:
        """Major-axis dispersion σ/q (the mgefit / paper σ), arcsec."""
        return self.sigma / self.axis_ratio

    def image(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Surface brightness at (x, y) (arrays of any matching shape)."""
        q, angle = self.axis_ratio, self.angle
        xp, yp = to_profile_frame(x, y, self.centre, angle)
        return self.intensity * np.exp(-(q**2 * xp**2 + yp**2) / (2.0 * self.sigma**2))

    def total_flux(self, pixel_scale: float = 1.0) -> float:
        """Integral 2πσ²I₀/q, divided by Δ² to give a pixel sum for ``pixel_scale`` Δ."""
        return 2.0 * np.pi * self.sigma**2 * self.intensity / self.axis_ratio / pixel_scale**2


def _kernel_geometry(grid: SubGrid, centre, ell_comps) -> tuple:
    """Leading arguments of the column kernels: sub-grid arrays, centre, q, φ (radians)."""
    q, angle = axis_ratio_and_angle_from(ell_comps)
    return (
        grid.x,
        grid.y,
        grid.starts,
        grid.sub_sizes,
        float(centre[0]),
        float(centre[1]),
        float(q),
        float(np.deg2rad(angle)),
    )


def sersic_constant(sersic_index: float) -> float:
    """b_n of Ciotti & Bertin (1999), the asymptotic series used by the anchor (SPEC §2.3)."""
    n = sersic_index
    return (
        2.0 * n
        - 1.0 / 3.0
        + 4.0 / (405.0 * n)
        + 46.0 / (25515.0 * n**2)
        + 131.0 / (1148175.0 * n**3)
        - 2194697.0 / (30690717750.0 * n**4)
    )


@dataclass(frozen=True)
class Sersic:
    """Elliptical Sérsic, I = I_e exp{−b_n[(ξ/R_e)^{1/n} − 1]}, ξ = sqrt(q x′² + y′²/q).

    ``effective_radius`` R_e is the circularised half-light radius in arcsec and
    ``intensity`` I_e the surface brightness at R_e (SPEC §2.3).
    """

    centre: tuple[float, float] = (0.0, 0.0)
    ell_comps: tuple[float, float] = (0.0, 0.0)
    effective_radius: float = 1.0
    sersic_index: float = 4.0
    intensity: float = 1.0

    def __post_init__(self):
        if not self.effective_radius > 0.0:
            raise ValueError(f"effective_radius must be > 0, got {self.effective_radius}")
        if not 0.2 <= self.sersic_index <= 10.0:
            raise ValueError(f"sersic_index must be in [0.2, 10], got {self.sersic_index}")

    def to_dict(self) -> dict:
        """The record of ``result.json`` (:func:`light_from_dict` reads it): ``kind``
        "sersic", the geometry (:func:`geometry_record`), R_e (arcsec), n and I_e."""
        return {
            "kind": "sersic",
            **geometry_record(self.centre, self.ell_comps),
            "effective_radius": self.effective_radius,
            "sersic_index": self.sersic_index,
            "intensity": float(self.intensity),
        }

    n_columns = 1
    """Columns a linear Sérsic adds to the linear system (its I_e)."""

    @property
    def cache_key(self) -> tuple:
        """Everything its unit-intensity column depends on (``intensity`` does not)."""
        return ("sersic", *self.centre, *self.ell_comps, self.effective_radius, self.sersic_index)

    def image(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        q, angle = axis_ratio_and_angle_from(self.ell_comps)
        xp, yp = to_profile_frame(x, y, self.centre, angle)
        xi = np.sqrt(q * xp**2 + yp**2 / q)
        b_n = sersic_constant(self.sersic_index)
        exponent = (xi / self.effective_radius) ** (1.0 / self.sersic_index) - 1.0
        return self.intensity * np.exp(-b_n * exponent)

    def columns(self, grid: SubGrid) -> np.ndarray:
        """Unit-I_e image binned over ``grid``: (n_pixels, 1), before the PSF.

        ``intensity`` is ignored: as a linear profile its I_e is solved (SPEC §2.3).
        """
        column = _sersic_column(
            *_kernel_geometry(grid, self.centre, self.ell_comps),
            float(np.log(self.effective_radius)),
            1.0 / self.sersic_index,
            sersic_constant(self.sersic_index),
        )
        return column[:, None]

    def total_flux(self, pixel_scale: float = 1.0) -> float:
        """Analytic integral 2π n R_e² I_e e^{b_n} Γ(2n)/b_n^{2n}, divided by Δ²."""
        n = self.sersic_index
        b_n = sersic_constant(n)
        flux = (
            2.0
            * np.pi
            * n
            * self.effective_radius**2
            * self.intensity
            * np.exp(b_n)
            * gamma_function(2.0 * n)
            / b_n ** (2.0 * n)
        )
        return flux / pixel_scale**2


def log_spaced_sigmas(sigma_min: float, sigma_max: float, n_gaussians: int) -> np.ndarray:
    """σ_k = 10^{lg σ_min + k (lg σ_max − lg σ_min)/(N − 1)}, k = 0..N−1 (SPEC §2.4)."""
    if not 0.0 < sigma_min < sigma_max:
        raise ValueError(f"need 0 < sigma_min < sigma_max, got {sigma_min}, {sigma_max}")
    if n_gaussians < 2:
        raise ValueError(f"an MGE set needs at least 2 Gaussians, got {n_gaussians}")
    return np.logspace(np.log10(sigma_min), np.log10(sigma_max), n_gaussians)


@dataclass(frozen=True)
class MGESet:
    """N Gaussians sharing centre and ell_comps with fixed (minor-axis) σ (SPEC §2.4).

    Each Gaussian is a linear object: its column is built with I₀ = 1 and its solved
    coefficient is I₀. Four non-linear parameters: centre (x, y) and ell_comps (e1, e2).
    """

    centre: tuple[float, float]
    ell_comps: tuple[float, float]
    sigmas: np.ndarray = field(repr=False)

    def __post_init__(self):
        sigmas = np.asarray(self.sigmas, dtype=float)
        if sigmas.ndim != 1 or sigmas.size == 0 or np.any(sigmas <= 0):
            raise ValueError("MGESet sigmas must be a non-empty 1D array of positive values")
        if np.any(np.diff(sigmas) <= 0):
            raise ValueError("MGESet sigmas must be strictly increasing")
        object.__setattr__(self, "sigmas", sigmas)

    @classmethod
    def extended(
        cls,
        centre: tuple[float, float],
        ell_comps: tuple[float, float],
        pixel_scale: float,
        mask_radius: float,
        n_gaussians: int = 30,
        sigma_min: float | None = None,
    ) -> "MGESet":
        """Paper set: N_g = 30, σ from Δ/5 (or ``sigma_min``) to the mask radius."""
        low = pixel_scale / 5.0 if sigma_min is None else sigma_min
        return cls(centre, ell_comps, log_spaced_sigmas(low, mask_radius, n_gaussians))

    @classmethod
    def point(
        cls, centre: tuple[float, float], ell_comps: tuple[float, float], pixel_scale: float
    ) -> "MGESet":
        """Point set: 10 Gaussians, σ log-spaced from Δ/5 to 2Δ, own centre and ell_comps."""
        return cls(centre, ell_comps, log_spaced_sigmas(pixel_scale / 5.0, 2.0 * pixel_scale, 10))

    @property
    def n_gaussians(self) -> int:
        return self.sigmas.size

    @property
    def n_columns(self) -> int:
        """Columns the set adds to the linear system (one per Gaussian)."""
        return self.sigmas.size

    @property
    def cache_key(self) -> tuple:
        """Everything its unit-intensity columns depend on."""
        return ("mge", *self.centre, *self.ell_comps, self.sigmas.tobytes())

    def to_dict(self, intensities: np.ndarray) -> dict:
        """The record of the set with its solved ``intensities`` I₀ (data units per pixel;
        :func:`light_from_dict` reads it): ``kind`` "mge", the geometry
        (:func:`geometry_record`), σ (minor axis, arcsec) and I₀."""
        return {
            "kind": "mge",
            **geometry_record(self.centre, self.ell_comps),
            "sigmas": self.sigmas.tolist(),
            "intensities": np.asarray(intensities).tolist(),
        }

    def gaussians(self, intensities: np.ndarray | None = None) -> list[Gaussian]:
        """The set as individual :class:`Gaussian` objects (unit intensity by default)."""
        values = np.ones(self.n_gaussians) if intensities is None else intensities
        return [
            Gaussian(self.centre, self.ell_comps, float(s), float(i))
            for s, i in zip(self.sigmas, values, strict=True)
        ]

    def columns(self, grid: SubGrid) -> np.ndarray:
        """Unit-intensity images binned over ``grid``: (n_pixels, N_g), before the PSF."""
        return _gaussian_columns(
            *_kernel_geometry(grid, self.centre, self.ell_comps),
            1.0 / (2.0 * self.sigmas**2),
            _EXP_TABLE,
        )

    def image(self, x: np.ndarray, y: np.ndarray, intensities: np.ndarray) -> np.ndarray:
        """Σ_k I_k G_k(x, y) at the given points (no over-sampling, no PSF)."""
        return sum(g.image(x, y) for g in self.gaussians(intensities))


@njit(inline="always")
def _exp_negative(e, table):
    """exp(−e) for 0 ≤ e ≤ EXPONENT_CUTOFF to ~1e−15 relative, in a form the compiler
    vectorises (the libm call it replaces does not): e = (j + f) ln2/64 with integer j and
    0 ≤ f < 1, exp(−e) = 2^(−j/64) (``table``) × exp(−f ln2/64) (Taylor to the 6th power,
    truncation < 4e−18)."""
    t = e * (_EXP_STEPS / np.log(2.0))
    j = np.int64(t)
    r = (t - j) * (np.log(2.0) / _EXP_STEPS)
    return table[j] * (
        1.0
        - r * (1.0 - r * (0.5 - r * (1.0 / 6.0 - r * (1.0 / 24.0 - r * (1.0 / 120.0 - r / 720.0)))))
    )


@njit(inline="always")
def _first_within_cutoff(rr, inv_two_sigma2):
    """First k with rr · inv_two_sigma2[k] < EXPONENT_CUTOFF (``inv_two_sigma2`` strictly
    decreasing, as σ grows along a set); its size if there is none."""
    lo, hi = 0, inv_two_sigma2.size
    while lo < hi:
        mid = (lo + hi) // 2
        if rr * inv_two_sigma2[mid] < EXPONENT_CUTOFF:
            hi = mid
        else:
            lo = mid + 1
    return lo


@njit(parallel=True, fastmath=True)
def _gaussian_columns(x, y, starts, sub_sizes, xc, yc, q, phi, inv_two_sigma2, table):
    """Binned unit Gaussians; at each sub-pixel only the Gaussians whose exponent is below
    :data:`EXPONENT_CUTOFF` are evaluated (the narrower ones contribute exactly zero)."""
    n_pix = starts.size
    n_g = inv_two_sigma2.size
    out = np.empty((n_pix, n_g))
    cos_phi = np.cos(phi)
    sin_phi = np.sin(phi)
    q2 = q * q
    for p in prange(n_pix):
        acc = np.zeros(n_g)
        n_sub = sub_sizes[p] * sub_sizes[p]
        for s in range(starts[p], starts[p] + n_sub):
            dx = x[s] - xc
            dy = y[s] - yc
            xp = dx * cos_phi + dy * sin_phi
            yp = -dx * sin_phi + dy * cos_phi
            rr = q2 * xp * xp + yp * yp
            for k in range(_first_within_cutoff(rr, inv_two_sigma2), n_g):
                acc[k] += _exp_negative(rr * inv_two_sigma2[k], table)
        for k in range(n_g):
            out[p, k] = acc[k] / n_sub
    return out


@njit(parallel=True, fastmath=True)
def _sersic_column(x, y, starts, sub_sizes, xc, yc, q, phi, log_re, inv_n, b_n):
    n_pix = starts.size
    out = np.empty(n_pix)
    cos_phi = np.cos(phi)
    sin_phi = np.sin(phi)
    for p in prange(n_pix):
        acc = 0.0
        n_sub = sub_sizes[p] * sub_sizes[p]
        for s in range(starts[p], starts[p] + n_sub):
            dx = x[s] - xc
            dy = y[s] - yc
            xp = dx * cos_phi + dy * sin_phi
            yp = -dx * sin_phi + dy * cos_phi
            xi2 = q * xp * xp + yp * yp / q
            if xi2 > 0.0:
                acc += np.exp(-b_n * (np.exp((0.5 * np.log(xi2) - log_re) * inv_n) - 1.0))
            else:
                acc += np.exp(b_n)
        out[p] = acc / n_sub
    return out


def blurred_gaussian_columns(
    x: np.ndarray,
    y: np.ndarray,
    centre: tuple[float, float],
    ell_comps: tuple[float, float],
    sigmas: np.ndarray,
    cumulants: KernelCumulants,
    out: np.ndarray | None = None,
    at: np.ndarray | None = None,
) -> np.ndarray:
    """Unit-peak Gaussians of one geometry (``sigmas`` minor-axis, arcsec; the anchor form
    of :class:`Gaussian`) convolved with the measure of ``cumulants`` (a PSF, with the
    pixel box for pixel-integrated columns), at the points (``x``, ``y``) (arcsec):
    (n_points, n_sigmas), by the fourth-order cumulant expansion of
    :mod:`mgelens.kernel_cumulants`. Accurate for σ wide against the measure only
    (:func:`mgelens.analytic_blur.smallest_analytic_sigma` says from where). With
    ``out`` (n_points, m) and ``at`` (n_sigmas,), the columns go to ``out[:, at]`` and
    ``out`` is returned."""
    q, angle = axis_ratio_and_angle_from(ell_comps)
    phi = np.deg2rad(angle)
    rotation = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
    sigmas = np.asarray(sigmas, dtype=float)
    variances = np.zeros((sigmas.size, 2, 2))
    variances[:, 0, 0] = (sigmas / q) ** 2
    variances[:, 1, 1] = sigmas**2
    sigma_gaussian = rotation @ variances @ rotation.T
    total = sigma_gaussian + cumulants.covariance
    det_total = total[:, 0, 0] * total[:, 1, 1] - total[:, 0, 1] ** 2
    p = np.empty_like(total)
    p[:, 0, 0] = total[:, 1, 1] / det_total
    p[:, 1, 1] = total[:, 0, 0] / det_total
    p[:, 0, 1] = p[:, 1, 0] = -total[:, 0, 1] / det_total
    amplitude = cumulants.total * np.sqrt((sigmas**2 / q) ** 2 / det_total)
    k3, k4 = cumulants.third, cumulants.fourth
    linear3 = 3.0 * np.einsum("ijk,gij->gk", k3, p)
    quad = 6.0 * np.einsum("ijkl,gij->gkl", k4, p)
    constant4 = 3.0 * np.einsum("gkl,gkl->g", np.einsum("ijkl,gij->gkl", k4, p), p)
    if out is None:
        out, at = np.empty((np.size(x), sigmas.size)), np.arange(sigmas.size)
    _closed_form_columns(
        np.ascontiguousarray(x, dtype=float),
        np.ascontiguousarray(y, dtype=float),
        float(centre[0] + cumulants.mean[0]),
        float(centre[1] + cumulants.mean[1]),
        np.stack([p[:, 0, 0], p[:, 0, 1], p[:, 1, 1]], axis=1),
        np.array([k3[0, 0, 0], k3[0, 0, 1], k3[0, 1, 1], k3[1, 1, 1]]),
        np.array([k4[0, 0, 0, 0], k4[0, 0, 0, 1], k4[0, 0, 1, 1], k4[0, 1, 1, 1], k4[1, 1, 1, 1]]),
        linear3,
        np.stack([quad[:, 0, 0], quad[:, 0, 1], quad[:, 1, 1]], axis=1),
        constant4,
        amplitude,
        _EXP_TABLE,
        out,
        np.asarray(at, dtype=np.int64),
    )
    return out


@njit(parallel=True, fastmath=True)
def _closed_form_columns(
    x,
    y,
    xc,
    yc,
    precision,
    third,
    fourth,
    linear3,
    quadratic4,
    constant4,
    amplitude,
    table,
    out,
    at,
):
    """out[p, at[k]]: column k of :func:`blurred_gaussian_columns` at point p; terms whose
    exponent reaches :data:`EXPONENT_CUTOFF` are zero, as in :func:`_gaussian_columns`."""
    n = x.size
    row = np.empty(n)
    for k in range(precision.shape[0]):
        pxx, pxy, pyy = precision[k, 0], precision[k, 1], precision[k, 2]
        column = at[k]
        for p in prange(n):
            ux = x[p] - xc
            uy = y[p] - yc
            vx = pxx * ux + pxy * uy
            vy = pxy * ux + pyy * uy
            t3 = (
                third[0] * vx * vx * vx
                + 3.0 * third[1] * vx * vx * vy
                + 3.0 * third[2] * vx * vy * vy
                + third[3] * vy * vy * vy
                - linear3[k, 0] * vx
                - linear3[k, 1] * vy
            )
            t4 = (
                fourth[0] * vx * vx * vx * vx
                + 4.0 * fourth[1] * vx * vx * vx * vy
                + 6.0 * fourth[2] * vx * vx * vy * vy
                + 4.0 * fourth[3] * vx * vy * vy * vy
                + fourth[4] * vy * vy * vy * vy
                - quadratic4[k, 0] * vx * vx
                - 2.0 * quadratic4[k, 1] * vx * vy
                - quadratic4[k, 2] * vy * vy
                + constant4[k]
            )
            exponent = 0.5 * (ux * vx + uy * vy)
            inside = exponent < EXPONENT_CUTOFF
            gaussian = _exp_negative(min(exponent, EXPONENT_CUTOFF), table) * inside
            row[p] = amplitude[k] * gaussian * (1.0 + t3 / 6.0 + t4 / 24.0)
        for p in prange(n):
            out[p, column] = row[p]


def geometry_record(centre: tuple[float, float], ell_comps: tuple[float, float]) -> dict:
    """A light component's geometry as recorded: centre (arcsec), ell_comps, and the axis
    ratio and angle (degrees CCW from +x) they mean (SPEC §2.1)."""
    q, angle = axis_ratio_and_angle_from(ell_comps)
    return {"centre": list(centre), "ell_comps": list(ell_comps), "axis_ratio": q, "angle": angle}


def light_from_dict(entry: dict) -> list:
    """The profiles of one lens-light record (``to_dict`` of :class:`Sersic` or
    :class:`MGESet`): the Sérsic, or the set's Gaussians with their intensities."""
    centre, ell_comps = tuple(entry["centre"]), tuple(entry["ell_comps"])
    if entry["kind"] == "sersic":
        return [
            Sersic(
                centre,
                ell_comps,
                entry["effective_radius"],
                entry["sersic_index"],
                entry["intensity"],
            )
        ]
    mge = MGESet(centre, ell_comps, entry["sigmas"])
    return mge.gaussians(np.asarray(entry["intensities"], dtype=float))


@dataclass(frozen=True)
class LightGrid:
    """Over-sampled evaluation grid + PSF for lens-light images inside a mask.

    Light is evaluated on the mask ∪ blurring region with per-pixel sub-sizes
    (SPEC §1.3 DECISION: ``sub_size`` everywhere, ``sub_size_centre`` within
    ``centre_radius`` arcsec of ``centre``), binned, PSF-convolved and cut to the mask.
    Gaussians of minor-axis σ ≥ ``analytic_sigma`` (arcsec) skip those steps: their
    columns are the closed-form pixel-integrated, blurred Gaussians of
    :func:`blurred_gaussian_columns` at the mask's pixel centres (``outputs``), with the
    PSF's and the pixel box's ``cumulants``.
    """

    convolver: Convolver
    grid: SubGrid
    outputs: tuple[np.ndarray, np.ndarray] = field(repr=False)
    cumulants: KernelCumulants = field(repr=False)
    analytic_sigma: float = np.inf

    @classmethod
    def from_mask(
        cls,
        mask: np.ndarray,
        psf: np.ndarray,
        pixel_scale: float,
        centre: tuple[float, float] = (0.0, 0.0),
        sub_size: int = 4,
        sub_size_centre: int = 16,
        centre_radius: float = 0.3,
        origin: tuple[float, float] = (0.0, 0.0),
        analytic_sigma: float = np.inf,
    ) -> "LightGrid":
        """``analytic_sigma`` (arcsec): the smallest minor-axis σ whose columns take the
        closed form (:func:`mgelens.analytic_blur.smallest_analytic_sigma`; inf: none)."""
        convolver = Convolver(mask, psf)
        x, y = pixel_centres(mask.shape, pixel_scale, origin)
        region = ~convolver.extended_mask
        xe, ye = x[region], y[region]
        sizes = adaptive_sub_sizes(xe, ye, centre, centre_radius, sub_size, sub_size_centre)
        return cls(
            convolver=convolver,
            grid=sub_grid(xe, ye, pixel_scale, sizes),
            outputs=(x[~mask], y[~mask]),
            cumulants=KernelCumulants.of_psf(convolver.psf, pixel_scale, pixel_box=True),
            analytic_sigma=float(analytic_sigma),
        )

    @cached_property
    def n_image_pixels(self) -> int:
        return int(np.count_nonzero(~self.convolver.mask))

    def blurred_columns(self, components: list) -> np.ndarray:
        """PSF-convolved unit-intensity columns of linear light components (MGE sets,
        Sérsics), (N_I, Σ n_columns), component by component."""
        out = np.zeros((self.n_image_pixels, sum(c.n_columns for c in components)))
        on_grid, on_grid_at = [], []
        start = 0
        for component in components:
            at = np.arange(start, start + component.n_columns)
            start += component.n_columns
            wide = self._wide(component)
            if wide.any():
                blurred_gaussian_columns(
                    *self.outputs,
                    component.centre,
                    component.ell_comps,
                    component.sigmas[wide],
                    self.cumulants,
                    out=out,
                    at=at[wide],
                )
            if not wide.all():
                narrow = component
                if wide.any():
                    narrow = replace(component, sigmas=component.sigmas[~wide])
                on_grid.append(narrow.columns(self.grid))
                on_grid_at.append(at[~wide])
        if on_grid:
            self.convolver.blur_columns(
                np.concatenate(on_grid, axis=1),
                include_blurring=True,
                out=out,
                at=np.concatenate(on_grid_at),
            )
        return out

    def _wide(self, component) -> np.ndarray:
        """Per column of ``component``: whether it takes the closed-form route."""
        if isinstance(component, MGESet):
            return component.sigmas >= self.analytic_sigma
        return np.zeros(component.n_columns, dtype=bool)

    def blurred_image(self, profiles: list) -> np.ndarray:
        """PSF-convolved image (N_I,) of profiles with an ``image(x, y)`` method, each
        Gaussian by the route its column takes in :meth:`blurred_columns`."""
        wide = [isinstance(p, Gaussian) and p.sigma >= self.analytic_sigma for p in profiles]
        image = np.zeros(self.n_image_pixels)
        narrow = [p for p, w in zip(profiles, wide, strict=True) if not w]
        if narrow:
            values = sum(p.image(self.grid.x, self.grid.y) for p in narrow)
            image += self.convolver.blur_columns(self.grid.bin(values), include_blurring=True)
        for profile in (p for p, w in zip(profiles, wide, strict=True) if w):
            column = blurred_gaussian_columns(
                *self.outputs, profile.centre, profile.ell_comps, [profile.sigma], self.cumulants
            )
            image += profile.intensity * column[:, 0]
        return image

"""Mock strong-lens imaging: the paper's mocks M1–M3 and a SLACS-like population (SPEC §10).

Conventions (SPEC §1.1, §2.1): coordinates (x, y) in arcsec, native arrays of shape
(n_y, n_x) with the row index increasing with +y, angles in degrees counter-clockwise
from +x, axis ratio q = minor/major. Surface brightness is in e⁻ s⁻¹ per image pixel
(Δ = 0.05″ by default), also for the unlensed source image.

Image formation (SPEC §10.4, :func:`simulate`):

1. Lens light and lensed source are evaluated on an s×s sub-grid (s = 16) of every pixel
   and averaged (the sub-grid of a regular image is the image grid at spacing Δ/s).
2. Their sum m is convolved with a Gaussian PSF (σ = 0.05″, 21×21 kernel, unit sum).
3. The source amplitude is set by bisection so that max_i (PSF ⊗ source)_i / σ_i = 50.
4. data = Poisson((m + b) t)/t − b with exposure t = 2000 s and sky b = 0.15 e⁻ s⁻¹;
   noise map σ = sqrt((m + b) t)/t from the noise-free model m.

Lens light models:

* :class:`MGELight`: Gaussians with their own q and φ and the mgefit **major-axis** σ
  (built with :meth:`mgelens.light.Gaussian.from_major_axis`), used for M1–M3 from the
  tables of SPEC §10.1 (:data:`PAPER_MOCKS`).
* :class:`IsophoteLight`: light defined directly by its isophotes, so that the isophote
  shape versus radius — q(a), PA(a) and the Bender a₄/a — is known by construction (the
  population, :func:`population_lens`). See the class docstring for the exact meaning.

Sources: :class:`ProceduralSource` (exponential discs with a logarithmic spiral
modulation and Gaussian clumps, :func:`procedural_source`) or :class:`ImageSource` (any
2D image with its pixel scale, bilinear interpolation, zero outside).

Randomness: every draw comes from ``numpy.random.default_rng`` seeded explicitly. A paper
mock with seed k draws its source from ``default_rng([k, 1])`` and its noise from
``default_rng(k)`` (k = 1, 2, 3 for M1, M2, M3), or from ``default_rng(n)`` with a noise
seed n. Population lens i of a population with
seed S draws its lens from ``default_rng([S, i, 0])``, its source from
``default_rng([S, i, 1])`` and its noise from ``default_rng([S, i, 2])``, so a lens does
not depend on how many others are drawn.
"""

import dataclasses
import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from math import atan2, cos, exp, log, sqrt
from pathlib import Path
from typing import Protocol

import numpy as np
from astropy.io import fits
from numba import prange

import mgelens
from mgelens._jit import njit
from mgelens.atomic import write_fits, write_json
from mgelens.convolve import convolve_image
from mgelens.imaging import Imaging
from mgelens.light import Gaussian, sersic_constant
from mgelens.mass import EPL, SIE, ExternalShear, ray_trace

logger = logging.getLogger(__name__)

BRIGHTNESS_UNIT = "electron/s"
"""FITS ``BUNIT`` of every image written (per image pixel)."""

SOURCE_STREAM = 1
"""Second seed word of the source draws of a paper mock: ``default_rng([seed, 1])``."""

ISOPHOTE_TRUTH_RADII = np.geomspace(0.1, 3.0, 40)
"""Semi-major axes (arcsec) at which a mock records its true isophote shape."""

SOURCE_KINDS = ("spiral", "clumpy", "merger")

MOCK_FILES = {
    "data": "data.fits",
    "noise_map": "noise_map.fits",
    "psf": "psf.fits",
    "model": "model.fits",
    "lens_light": "lens_light.fits",
    "lens_light_blurred": "lens_light_blurred.fits",
    "lensed_source": "lensed_source.fits",
    "lensed_source_blurred": "lensed_source_blurred.fits",
    "source": "source.fits",
    "truth": "truth.json",
}
"""Files of a mock folder (keys are also the ``files`` entries of ``truth.json``)."""

FILE_DESCRIPTIONS = {
    "data": "noisy image, e-/s per pixel: Poisson((model + sky) t)/t - sky",
    "noise_map": "1-sigma noise sqrt((model + sky) t)/t, e-/s per pixel",
    "psf": "Gaussian PSF kernel, unit sum",
    "model": "noise-free image = lens_light_blurred + lensed_source_blurred",
    "lens_light": "lens light averaged over the sub-grid, before the PSF",
    "lens_light_blurred": "lens light convolved with the PSF",
    "lensed_source": "lensed source averaged over the sub-grid, before the PSF",
    "lensed_source_blurred": "lensed source convolved with the PSF",
    "source": "unlensed source, e-/s per image pixel, on the source-plane grid of the header "
    "(PIXSCALE arcsec/pixel, centre XCENTRE, YCENTRE arcsec)",
    "truth": "every parameter of the mock",
}


# --------------------------------------------------------------------------------------
# observation


@dataclass(frozen=True)
class Observation:
    """Grid, PSF, noise and S/N settings of a mock (defaults: SPEC §10.4).

    Attributes
    ----------
    image_size : int
        Image is ``image_size`` × ``image_size`` pixels; odd, so (0, 0) is a pixel centre.
    pixel_scale : float
        Δ in arcsec/pixel.
    sub_size : int
        s: each pixel is the mean of s × s sub-pixel evaluations (lens light and source).
    psf_sigma : float
        Gaussian PSF dispersion in arcsec.
    psf_size : int
        The PSF kernel is ``psf_size`` × ``psf_size`` pixels (odd).
    exposure_time : float
        t in seconds.
    sky : float
        Sky level b in e⁻ s⁻¹ per pixel (added, Poisson-sampled, subtracted).
    signal_to_noise : float
        Target max_i (PSF ⊗ source)_i / σ_i.
    source_plane_pixel_scale : float
        Pixel of the saved unlensed source image, arcsec.
    source_plane_size : int
        The unlensed source image is this many pixels square, centred on the source.
    """

    image_size: int = 151
    pixel_scale: float = 0.05
    sub_size: int = 16
    psf_sigma: float = 0.05
    psf_size: int = 21
    exposure_time: float = 2000.0
    sky: float = 0.15
    signal_to_noise: float = 50.0
    source_plane_pixel_scale: float = 0.01
    source_plane_size: int = 241

    def __post_init__(self):
        for name in ("image_size", "psf_size", "source_plane_size"):
            value = getattr(self, name)
            if not (isinstance(value, int | np.integer) and value >= 3 and value % 2 == 1):
                raise ValueError(f"{name} must be an odd integer >= 3, got {value!r}")
        if not (isinstance(self.sub_size, int | np.integer) and self.sub_size >= 1):
            raise ValueError(f"sub_size must be an integer >= 1, got {self.sub_size!r}")
        for name in (
            "pixel_scale",
            "psf_sigma",
            "exposure_time",
            "signal_to_noise",
            "source_plane_pixel_scale",
        ):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if not self.sky >= 0.0:
            raise ValueError(f"sky must be >= 0 e-/s per pixel, got {self.sky!r}")

    def psf(self) -> np.ndarray:
        """The PSF kernel (psf_size × psf_size, unit sum)."""
        return gaussian_psf(self.psf_size, self.psf_sigma / self.pixel_scale)


def gaussian_psf(size: int, sigma_pixels: float) -> np.ndarray:
    """Circular Gaussian kernel evaluated at pixel centres, normalised to unit sum.

    Parameters
    ----------
    size : int
        Odd kernel size in pixels; the peak is the central pixel.
    sigma_pixels : float
        Dispersion in pixels.
    """
    if size % 2 != 1 or sigma_pixels <= 0.0:
        raise ValueError(f"need an odd size and sigma > 0, got {size}, {sigma_pixels}")
    offsets = np.arange(size) - size // 2
    profile = np.exp(-0.5 * (offsets / sigma_pixels) ** 2)
    kernel = np.outer(profile, profile)
    return kernel / kernel.sum()


class Profile(Protocol):
    """Anything with a surface brightness ``image(x, y)`` at points (x, y), arcsec."""

    def image(self, x: np.ndarray, y: np.ndarray) -> np.ndarray: ...


def oversampled_image(
    profile: Profile,
    shape: tuple[int, int],
    pixel_scale: float,
    sub_size: int,
    origin: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """Pixel averages of ``profile`` over a uniform s × s sub-grid (SPEC §1.3).

    The sub-pixels of a regular grid form the regular grid of spacing Δ/s, so sub-pixel
    (a, b) of pixel (r, c) is fine-grid node (r s + a, c s + b). The image is evaluated a
    band of rows at a time (≈ 5·10⁵ points), which bounds the memory. Profiles with an
    ``image_on_grid(x_axis, y_axis)`` method (values on the outer grid of two 1D axes,
    shape (n_y, n_x)) are evaluated through it; others through ``image(x, y)``.

    Parameters
    ----------
    profile : Profile
    shape : (n_y, n_x)
    pixel_scale : float
        Δ in arcsec.
    sub_size : int
        s.
    origin : (x0, y0)
        Grid origin in arcsec (SPEC §1.1).
    """
    n_y, n_x = shape
    s = int(sub_size)
    step = pixel_scale / s
    fine_x = (np.arange(n_x * s) - (n_x * s - 1) / 2.0) * step + origin[0]
    rows_per_band = max(1, 2**19 // (n_x * s * s))
    on_grid = getattr(profile, "image_on_grid", None)
    out = np.empty(shape)
    for start in range(0, n_y, rows_per_band):
        stop = min(start + rows_per_band, n_y)
        fine_y = (np.arange(start * s, stop * s) - (n_y * s - 1) / 2.0) * step + origin[1]
        if on_grid is None:
            x, y = np.meshgrid(fine_x, fine_y)
            values = np.asarray(profile.image(x.ravel(), y.ravel()), dtype=float)
        else:
            values = on_grid(fine_x, fine_y)
        out[start:stop] = values.reshape(stop - start, s, n_x, s).mean(axis=(1, 3))
    return out


def noise_map_from(model: np.ndarray, exposure_time: float, sky: float) -> np.ndarray:
    """σ = sqrt((m + b) t)/t in e⁻ s⁻¹ per pixel for a noise-free model m (SPEC §10.4)."""
    return np.sqrt((np.asarray(model) + sky) * exposure_time) / exposure_time


def noisy_data(
    model: np.ndarray, exposure_time: float, sky: float, rng: np.random.Generator
) -> np.ndarray:
    """One noise realisation Poisson((m + b) t)/t − b of a non-negative model m."""
    counts = rng.poisson((np.asarray(model) + sky) * exposure_time)
    return counts / exposure_time - sky


def source_amplitude(
    lens_blurred: np.ndarray,
    source_blurred: np.ndarray,
    exposure_time: float,
    sky: float,
    signal_to_noise: float,
    relative_tolerance: float = 1e-12,
) -> float:
    """Factor A with max_i A s_i / σ_i(A) = target, σ from m = lens + A s (bisection).

    The maximum S/N grows monotonically with A (A s / sqrt(L + A s + b) does), so the
    root is unique. ``source_blurred`` must have a positive maximum.
    """
    peak = float(np.max(source_blurred))
    if not peak > 0.0:
        raise ValueError("the lensed source is zero everywhere: it misses the image")
    unit = source_blurred / peak

    def snr(amplitude: float) -> float:
        noise = noise_map_from(lens_blurred + amplitude * unit, exposure_time, sky)
        return float(np.max(amplitude * unit / noise))

    low, high = 0.0, 1.0
    while snr(high) < signal_to_noise:
        low, high = high, 2.0 * high
        if high > 1e30:
            raise ValueError(f"cannot reach S/N {signal_to_noise}: check exposure and sky")
    while high - low > relative_tolerance * high:
        middle = 0.5 * (low + high)
        if snr(middle) < signal_to_noise:
            low = middle
        else:
            high = middle
    return 0.5 * (low + high) / peak


# --------------------------------------------------------------------------------------
# numba kernels


EXPONENT_CUTOFF = 100.0
"""Gaussian terms with exponent above this (e^−100 ≈ 4e−44) are dropped."""

_POINTS_PER_TASK = 1024
"""Consecutive points handled by one parallel task of the point kernels."""


@njit(parallel=True, fastmath=True)
def _gaussian_sum_kernel(x, y, centre_x, centre_y, a_xx, a_xy, a_yy, peak):
    """Σ_k I_k exp(−E_k) at points, E_k = a_xx dx² + a_xy dx dy + a_yy dy²."""
    out = np.zeros(x.size)
    for i in prange(x.size):
        total = 0.0
        for k in range(peak.size):
            dx = x[i] - centre_x[k]
            dy = y[i] - centre_y[k]
            exponent = a_xx[k] * dx * dx + a_xy[k] * dx * dy + a_yy[k] * dy * dy
            if exponent < EXPONENT_CUTOFF:
                total += peak[k] * exp(-exponent)
        out[i] = total
    return out


@njit(parallel=True, fastmath=True)
def _gaussian_sum_grid_kernel(x_axis, y_axis, segment, centre_x, centre_y, a_xx, a_xy, a_yy, peak):
    """Σ_k I_k exp(−E_k) on the outer grid of ``x_axis`` (uniform) and ``y_axis``.

    Along a row, E_k is quadratic in the node index, so over a segment of ``segment``
    nodes (one pixel's sub-pixels) exp(−E) follows the recurrence G ← G R, R ← R C
    (R = exp(−ΔE), C = exp(−2 a_xx h²)): two exponentials per segment instead of one per
    node, restarted every segment so rounding stays ~1e−15. Segments whose smallest E
    exceeds ``EXPONENT_CUTOFF`` are skipped; segments spanning more than 600 in E (very
    narrow Gaussians) use one exponential per node.
    """
    n_x = x_axis.size
    h = x_axis[1] - x_axis[0] if n_x > 1 else 1.0
    out = np.zeros((y_axis.size, n_x))
    for row in prange(y_axis.size):
        for k in range(peak.size):
            dy = y_axis[row] - centre_y[k]
            curvature = a_xx[k] * h * h
            decay = exp(-2.0 * curvature)
            for first in range(0, n_x, segment):
                count = min(segment, n_x - first)
                dx = x_axis[first] - centre_x[k]
                e0 = a_xx[k] * dx * dx + a_xy[k] * dx * dy + a_yy[k] * dy * dy
                slope = 2.0 * a_xx[k] * dx * h + a_xy[k] * dy * h
                vertex = min(max(-slope / (2.0 * curvature), 0.0), count - 1.0)
                e_min = e0 + vertex * slope + vertex * vertex * curvature
                if e_min > EXPONENT_CUTOFF:
                    continue
                last = count - 1.0
                e_max = max(e0, e0 + last * slope + last * last * curvature)
                if e_max - e_min < 600.0:
                    value = peak[k] * exp(-e0)
                    ratio = exp(-(slope + curvature))
                    for j in range(count):
                        out[row, first + j] += value
                        value *= ratio
                        ratio *= decay
                else:
                    for j in range(count):
                        e = e0 + j * slope + j * j * curvature
                        if e < EXPONENT_CUTOFF:
                            out[row, first + j] += peak[k] * exp(-e)
    return out


@njit(inline="always")
def _log_isophote_radius(u, cos_theta, sin_theta, table, u_min, inv_du):
    """ln ρ of isophote a = e^u at the sky direction (cos θ, sin θ).

    ``table`` rows hold (q, cos φ, sin φ, c) at u = u_min + k/inv_du (linear
    interpolation); ρ = q/sqrt(q² cos²ψ + sin²ψ) + c cos 4ψ with ψ = θ − φ(a).
    """
    t = (u - u_min) * inv_du
    k = min(max(int(np.floor(t)), 0), table.shape[0] - 2)
    f = min(max(t - k, 0.0), 1.0)
    q = table[k, 0] + f * (table[k + 1, 0] - table[k, 0])
    cos_phi = table[k, 1] + f * (table[k + 1, 1] - table[k, 1])
    sin_phi = table[k, 2] + f * (table[k + 1, 2] - table[k, 2])
    c4 = table[k, 3] + f * (table[k + 1, 3] - table[k, 3])
    norm = sqrt(cos_phi * cos_phi + sin_phi * sin_phi)
    c = (cos_theta * cos_phi + sin_theta * sin_phi) / norm
    s = (sin_theta * cos_phi - cos_theta * sin_phi) / norm
    c2 = c * c
    return log(q / sqrt(q * q * c2 + s * s) + c4 * (8.0 * c2 * c2 - 8.0 * c2 + 1.0))


@njit(inline="always")
def _semi_major_axis(dx, dy, guess, table, u_min, inv_du):
    """ln of the label a of the isophote through (dx, dy): root u of g = u + ln ρ − ln r.

    g′ ∈ [½, 3/2] (checked by :class:`IsophoteLight`), so the fixed-point step
    u ← ln r − ln ρ(u) contracts; it starts from ``guess`` (the previous point's root, or
    ln r when NaN) and is followed by secant steps until |g| < 1e−13. Returns −inf at
    the centre.
    """
    r = sqrt(dx * dx + dy * dy)
    if r < 1e-300:
        return -np.inf
    cos_theta = dx / r
    sin_theta = dy / r
    log_r = log(r)
    u0 = log_r if np.isnan(guess) else guess
    g0 = u0 + _log_isophote_radius(u0, cos_theta, sin_theta, table, u_min, inv_du) - log_r
    if abs(g0) < 1e-13:
        return u0
    u1 = u0 - g0
    for _ in range(60):
        g1 = u1 + _log_isophote_radius(u1, cos_theta, sin_theta, table, u_min, inv_du) - log_r
        if abs(g1) < 1e-13 or g1 == g0:
            break
        u0, u1, g0 = u1, u1 - g1 * (u1 - u0) / (g1 - g0), g1
    return u1


@njit(parallel=True)
def _isophote_label_kernel(x, y, centre_x, centre_y, table, u_min, inv_du):
    """ln a of the isophote through each point (−inf at the centre)."""
    n = x.size
    out = np.empty(n)
    for task in prange((n + _POINTS_PER_TASK - 1) // _POINTS_PER_TASK):
        guess = np.nan
        for i in range(task * _POINTS_PER_TASK, min(n, (task + 1) * _POINTS_PER_TASK)):
            u = _semi_major_axis(x[i] - centre_x, y[i] - centre_y, guess, table, u_min, inv_du)
            out[i] = u
            guess = u if np.isfinite(u) else np.nan
    return out


@njit(parallel=True)
def _isophote_light_kernel(x, y, centre_x, centre_y, table, u_min, inv_du, sersic):
    """Sérsic of the isophote label: I_e exp(−b_n[(a/R_e)^{1/n} − 1]) at each point.

    ``sersic`` = (I_e, ln R_e, 1/n, b_n).
    """
    n = x.size
    out = np.empty(n)
    for task in prange((n + _POINTS_PER_TASK - 1) // _POINTS_PER_TASK):
        guess = np.nan
        for i in range(task * _POINTS_PER_TASK, min(n, (task + 1) * _POINTS_PER_TASK)):
            u = _semi_major_axis(x[i] - centre_x, y[i] - centre_y, guess, table, u_min, inv_du)
            out[i] = sersic[0] * exp(-sersic[3] * (exp((u - sersic[1]) * sersic[2]) - 1.0))
            guess = u if np.isfinite(u) else np.nan
    return out


@njit(parallel=True, fastmath=True)
def _procedural_source_kernel(x, y, discs, clumps):
    """Sum of spiral discs and circular Gaussian clumps at source-plane points.

    ``discs`` rows: (x_c, y_c, q, cos φ, sin φ, h, I₀, A, m/tan p, arm phase (rad), m);
    ``clumps`` rows: (x_c, y_c, 1/(2σ²), I). Disc terms beyond 30 scale lengths
    (e^−30 ≈ 1e−13 of the centre) are dropped.
    """
    out = np.zeros(x.size)
    for i in prange(x.size):
        total = 0.0
        for d in range(discs.shape[0]):
            dx = x[i] - discs[d, 0]
            dy = y[i] - discs[d, 1]
            xp = dx * discs[d, 3] + dy * discs[d, 4]
            yp = (-dx * discs[d, 4] + dy * discs[d, 3]) / discs[d, 2]
            rh = sqrt(xp * xp + yp * yp) / discs[d, 5]
            if rh > 30.0:
                continue
            disc = discs[d, 6] * exp(-rh)
            if discs[d, 7] != 0.0 and rh > 1e-9:
                phase = discs[d, 10] * atan2(yp, xp) - discs[d, 8] * log(rh) - discs[d, 9]
                disc *= 1.0 + discs[d, 7] * (1.0 - exp(-rh * rh)) * cos(phase)
            total += disc
        for c in range(clumps.shape[0]):
            dx = x[i] - clumps[c, 0]
            dy = y[i] - clumps[c, 1]
            exponent = (dx * dx + dy * dy) * clumps[c, 2]
            if exponent < EXPONENT_CUTOFF:
                total += clumps[c, 3] * exp(-exponent)
        out[i] = total
    return out


# --------------------------------------------------------------------------------------
# lens light


@dataclass(frozen=True)
class MGELight:
    """Lens light as a sum of elliptical Gaussians, each with its own q and φ.

    Attributes
    ----------
    gaussians : tuple of :class:`~mgelens.light.Gaussian`
        Anchor-form Gaussians (minor-axis ``sigma``); build mgefit tables (major-axis σ)
        with :meth:`from_table`.
    """

    gaussians: tuple[Gaussian, ...]

    @classmethod
    def from_table(
        cls,
        centre: tuple[float, float],
        axis_ratios: Sequence[float],
        angles: Sequence[float],
        log_intensities: Sequence[float],
        log_sigmas: Sequence[float],
    ) -> "MGELight":
        """From an mgefit table: q, φ (degrees), lg I (e⁻ s⁻¹ pix⁻¹), lg σ_major (arcsec).

        Each Gaussian is I exp[−(x′² + y′²/q²)/(2σ²)] (SPEC §10.1), i.e. the anchor form
        with minor-axis σ = q σ_table (:meth:`~mgelens.light.Gaussian.from_major_axis`).
        """
        rows = zip(axis_ratios, angles, log_intensities, log_sigmas, strict=True)
        return cls(
            tuple(
                Gaussian.from_major_axis(centre, q, phi, 10.0**lg_sigma, 10.0**lg_intensity)
                for q, phi, lg_intensity, lg_sigma in rows
            )
        )

    def _quadratic_forms(self) -> tuple[np.ndarray, ...]:
        """Per Gaussian: centre x, centre y, a_xx, a_xy, a_yy, I with the exponent
        E = a_xx dx² + a_xy dx dy + a_yy dy² = (q² x′² + y′²)/(2σ²)."""
        g = self.gaussians
        phi = np.deg2rad([gaussian.angle for gaussian in g])
        c, s = np.cos(phi), np.sin(phi)
        q2 = np.array([gaussian.axis_ratio for gaussian in g]) ** 2
        scale = 1.0 / (2.0 * np.array([gaussian.sigma for gaussian in g]) ** 2)
        return (
            np.array([gaussian.centre[0] for gaussian in g], dtype=float),
            np.array([gaussian.centre[1] for gaussian in g], dtype=float),
            (q2 * c * c + s * s) * scale,
            2.0 * c * s * (q2 - 1.0) * scale,
            (q2 * s * s + c * c) * scale,
            np.array([gaussian.intensity for gaussian in g], dtype=float),
        )

    def image(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Surface brightness (e⁻ s⁻¹ per pixel) at points (x, y), arcsec."""
        x_flat, y_flat, shape = _flat_points(x, y)
        return _gaussian_sum_kernel(x_flat, y_flat, *self._quadratic_forms()).reshape(shape)

    def image_on_grid(
        self, x_axis: np.ndarray, y_axis: np.ndarray, segment: int = 16
    ) -> np.ndarray:
        """Surface brightness on the grid of 1D axes (``x_axis`` uniform), (n_y, n_x).

        Same values as :meth:`image` (to ~1e−14 relative) but with two exponentials per
        ``segment`` nodes of a row (see ``_gaussian_sum_grid_kernel``).
        """
        return _gaussian_sum_grid_kernel(
            np.ascontiguousarray(x_axis, dtype=float),
            np.ascontiguousarray(y_axis, dtype=float),
            int(segment),
            *self._quadratic_forms(),
        )

    def total_flux(self, pixel_scale: float) -> float:
        """Σ 2π I σ_major² q / Δ² = Σ 2π I σ² / (q Δ²): the pixel sum over the whole plane."""
        return float(sum(g.total_flux(pixel_scale) for g in self.gaussians))

    def to_dict(self) -> dict:
        return {
            "model": "mge",
            "form": "I exp(-(x'^2 + y'^2/q^2)/(2 sigma_major^2)); sigma = q sigma_major is "
            "the anchor (minor-axis) sigma",
            "gaussians": [
                {
                    "centre": list(g.centre),
                    "axis_ratio": g.axis_ratio,
                    "angle": g.angle,
                    "ell_comps": list(g.ell_comps),
                    "intensity": g.intensity,
                    "sigma_major": g.sigma_major,
                    "sigma": g.sigma,
                }
                for g in self.gaussians
            ],
        }


@dataclass(frozen=True)
class Transition:
    """Smooth change of a quantity with semi-major axis a (arcsec).

    value(a) = inner + (outer − inner) · ½[1 + tanh(ln(a/radius)/width)]: ``inner`` for
    a ≪ radius, ``outer`` for a ≫ radius, half-way at a = radius; ``width`` in ln a.
    """

    inner: float
    outer: float
    radius: float = 1.0
    width: float = 0.5

    def __post_init__(self):
        if not (self.radius > 0.0 and self.width > 0.0):
            raise ValueError(f"radius and width must be > 0, got {self.radius}, {self.width}")

    def __call__(self, semi_major_axis) -> np.ndarray:
        u = np.log(np.asarray(semi_major_axis, dtype=float) / self.radius) / self.width
        return self.inner + (self.outer - self.inner) * 0.5 * (1.0 + np.tanh(u))


NESTING_RANGE = (0.5, 1.5)
"""Allowed range of ∂ ln(a ρ)/∂ ln a at fixed sky angle (1 for self-similar isophotes):
positive means the isophotes nest; the margins keep them well apart and make the label
equation a contraction for its fixed-point step."""

TABLE_LOG_RANGE = (np.log(1e-6), np.log(1e3))
TABLE_SIZE = 2**14 + 1
"""The kernels interpolate q, φ, a₄/a linearly in ln a on this grid (Δ ln a ≈ 1.3e−3):
relative error ≲ 1e−6 against the formulas for transition widths ≥ 0.3."""


def _isophote_shape(psi, axis_ratio, a4_over_a):
    """ρ(ψ) = q/sqrt(q² cos²ψ + sin²ψ) + (a₄/a) cos 4ψ: polar radius over a (NumPy)."""
    q = axis_ratio
    return q / np.sqrt((q * np.cos(psi)) ** 2 + np.sin(psi) ** 2) + a4_over_a * np.cos(4 * psi)


@dataclass(frozen=True)
class IsophoteLight:
    """Lens light defined by its isophotes, whose shape is known at every radius.

    Construction. The isophote labelled a (its semi-major axis) is the closed curve whose
    polar radius about ``centre``, at angle ψ from its major axis, is

        R(ψ; a) = a ρ(ψ),  ρ(ψ) = q/sqrt(q² cos²ψ + sin²ψ) + c cos 4ψ,

    with q = q(a), major axis at PA φ(a) (degrees CCW from +x, so ψ = θ − φ(a) for the sky
    polar angle θ) and c = (a₄/a)(a); q, φ and c are :class:`Transition` functions of a.
    The first term is the ellipse of semi-axes a and q a; the second is the radial
    deviation a₄ cos 4ψ with a₄ = c a. The surface brightness is a Sérsic function of the
    label, I = I_e exp{−b_n[(a/R_e)^{1/n} − 1]}, with R_e measured along the major axis.

    Meaning of the recorded truth (Bender & Möllenhoff 1987, SPEC §9.1): the ellipse
    (centre, a, q, φ) is the best ellipse in the sense that the isophote's radial deviation
    from it, as a function of the polar angle ψ in the ellipse frame, has no harmonic of
    order 0, 1 or 2; that deviation is exactly a₄ cos 4ψ, so a₄/a = c, **positive = disky**
    (isophote pointed along the axes), negative = boxy. Fitters that define the best
    ellipse otherwise (a plain algebraic conic fit; photutils, whose ``b4`` is an
    intensity harmonic divided by the gradient) differ from these numbers by amounts of
    order 0.1 |a₄/a| in q and 10–30 % in a₄/a.

    Attributes
    ----------
    centre : (x, y) arcsec
    intensity : float
        I_e, e⁻ s⁻¹ per pixel at a = R_e.
    effective_radius : float
        R_e, arcsec along the major axis.
    sersic_index : float
        n.
    axis_ratio, angle, a4 : Transition
        q(a); φ(a) in degrees; a₄/a (a).
    """

    centre: tuple[float, float]
    intensity: float
    effective_radius: float
    sersic_index: float
    axis_ratio: Transition
    angle: Transition
    a4: Transition

    def __post_init__(self):
        if not (self.intensity > 0.0 and self.effective_radius > 0.0):
            raise ValueError("intensity and effective_radius must be > 0")
        if not 0.3 <= self.sersic_index <= 10.0:
            raise ValueError(f"sersic_index must be in [0.3, 10], got {self.sersic_index}")
        low, high = self.nesting()
        if low < NESTING_RANGE[0] or high > NESTING_RANGE[1]:
            raise ValueError(
                f"isophotes change too fast with radius: d ln(a rho)/d ln a spans "
                f"[{low:.3f}, {high:.3f}], allowed {NESTING_RANGE}; widen the transitions or "
                "reduce the changes of q, angle or a4"
            )

    @cached_property
    def _table(self) -> tuple[np.ndarray, float, float]:
        """(q, cos φ, sin φ, a₄/a) at u = ln a on a uniform grid, its u_min and 1/Δu."""
        u = np.linspace(TABLE_LOG_RANGE[0], TABLE_LOG_RANGE[1], TABLE_SIZE)
        a = np.exp(u)
        phi = np.deg2rad(self.angle(a))
        table = np.column_stack([self.axis_ratio(a), np.cos(phi), np.sin(phi), self.a4(a)])
        return table, float(u[0]), float(1.0 / (u[1] - u[0]))

    def nesting(self) -> tuple[float, float]:
        """(min, max) over a ∈ [10⁻³, 10²]″ and all directions of ∂ ln(a ρ)/∂ ln a.

        This is g′ of the label equation; 1 for self-similar isophotes, > 0 where
        isophotes nest. Computed from the exact formulas (not the table).
        """
        u = np.linspace(np.log(1e-3), np.log(1e2), 600)[:, None]
        theta = np.linspace(0.0, 2.0 * np.pi, 360, endpoint=False)[None, :]
        du = 1e-4
        upper = self._log_radius(u + du, theta)
        lower = self._log_radius(u - du, theta)
        slope = 1.0 + (upper - lower) / (2.0 * du)
        return float(slope.min()), float(slope.max())

    def _log_radius(self, u: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """ln ρ of isophote a = e^u at sky polar angle θ (radians), exact formulas."""
        a = np.exp(u)
        psi = theta - np.deg2rad(self.angle(a))
        return np.log(_isophote_shape(psi, self.axis_ratio(a), self.a4(a)))

    def semi_major_axis(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Label a (arcsec) of the isophote through each point (0 at the centre)."""
        x_flat, y_flat, shape = _flat_points(x, y)
        table, u_min, inv_du = self._table
        u = _isophote_label_kernel(
            x_flat, y_flat, float(self.centre[0]), float(self.centre[1]), table, u_min, inv_du
        )
        return np.exp(u).reshape(shape)

    def profile(self, semi_major_axis) -> np.ndarray:
        """Surface brightness on the isophote of semi-major axis a (e⁻ s⁻¹ per pixel)."""
        a = np.asarray(semi_major_axis, dtype=float)
        n = self.sersic_index
        return self.intensity * np.exp(
            -sersic_constant(n) * ((a / self.effective_radius) ** (1.0 / n) - 1.0)
        )

    def image(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Surface brightness (e⁻ s⁻¹ per pixel) at points (x, y), arcsec."""
        x_flat, y_flat, shape = _flat_points(x, y)
        table, u_min, inv_du = self._table
        n = self.sersic_index
        sersic = np.array(
            [self.intensity, np.log(self.effective_radius), 1.0 / n, sersic_constant(n)]
        )
        values = _isophote_light_kernel(
            x_flat,
            y_flat,
            float(self.centre[0]),
            float(self.centre[1]),
            table,
            u_min,
            inv_du,
            sersic,
        )
        return values.reshape(shape)

    def isophote_curve(self, semi_major_axis: float, n_points: int = 360):
        """(x, y) arcsec of ``n_points`` points of the true isophote a, equally spaced in ψ."""
        a = float(semi_major_axis)
        q, phi, c4 = self.axis_ratio(a), np.deg2rad(self.angle(a)), self.a4(a)
        psi = np.linspace(0.0, 2.0 * np.pi, n_points, endpoint=False)
        radius = a * _isophote_shape(psi, q, c4)
        return (
            self.centre[0] + radius * np.cos(psi + phi),
            self.centre[1] + radius * np.sin(psi + phi),
        )

    def isophote_table(self, radii: np.ndarray = ISOPHOTE_TRUTH_RADII) -> dict:
        """True isophote shape at semi-major axes ``radii``: q, PA in [0, 180), a₄/a, I."""
        radii = np.asarray(radii, dtype=float)
        return {
            "sma": radii.tolist(),
            "axis_ratio": self.axis_ratio(radii).tolist(),
            "angle": np.mod(self.angle(radii), 180.0).tolist(),
            "a4_over_a": self.a4(radii).tolist(),
            "intensity": self.profile(radii).tolist(),
        }

    def to_dict(self) -> dict:
        return {
            "model": "isophote",
            "form": "isophote a: R(psi) = a [q/sqrt(q^2 cos^2 psi + sin^2 psi) + c cos 4 psi], "
            "psi = polar angle from the major axis at angle(a); q, angle, c = a4/a smooth in "
            "a; I = intensity exp(-b_n ((a/effective_radius)^(1/n) - 1))",
            "a4_convention": "Bender & Moellenhoff: radial deviation from the best ellipse is "
            "a4 cos 4 psi (psi polar angle in the ellipse frame); a4/a > 0 disky, < 0 boxy",
            "transition": "value(a) = inner + (outer - inner) (1 + tanh(ln(a/radius)/width))/2",
            "centre": list(self.centre),
            "intensity": self.intensity,
            "effective_radius": self.effective_radius,
            "sersic_index": self.sersic_index,
            "axis_ratio": dataclasses.asdict(self.axis_ratio),
            "angle": dataclasses.asdict(self.angle),
            "a4_over_a": dataclasses.asdict(self.a4),
            "isophotes": self.isophote_table(),
        }


# --------------------------------------------------------------------------------------
# sources


@dataclass(frozen=True)
class SpiralDisc:
    """Exponential disc with an m-arm logarithmic spiral modulation.

    In the disc plane (x′ along the projected major axis, y′/q deprojected), with polar
    coordinates (r, ϑ) and h = ``scale_length``:

        I = I₀ e^{−r/h} [1 + A (1 − e^{−(r/h)²}) cos(m ϑ − (m/tan p) ln(r/h) − ϕ)],

    whose arms follow r = h exp[tan p (ϑ − ϕ/m − 2πk/m)] (pitch angle p). A ≤ 1 keeps
    I ≥ 0; the arms fade inside r ≈ h.
    """

    centre: tuple[float, float]
    axis_ratio: float
    angle: float
    scale_length: float
    intensity: float = 1.0
    arm_amplitude: float = 0.0
    pitch_angle: float = 20.0
    arm_phase: float = 0.0
    n_arms: int = 2

    def __post_init__(self):
        if not (0.0 < self.axis_ratio <= 1.0 and self.scale_length > 0.0):
            raise ValueError("disc axis_ratio must be in (0, 1] and scale_length > 0")
        if not 0.0 <= self.arm_amplitude <= 1.0:
            raise ValueError(f"arm_amplitude must be in [0, 1], got {self.arm_amplitude}")
        if not 0.0 < self.pitch_angle < 90.0:
            raise ValueError(f"pitch_angle must be in (0, 90) degrees, got {self.pitch_angle}")

    def row(self) -> list[float]:
        phi = np.deg2rad(self.angle)
        return [
            self.centre[0],
            self.centre[1],
            self.axis_ratio,
            float(np.cos(phi)),
            float(np.sin(phi)),
            self.scale_length,
            self.intensity,
            self.arm_amplitude,
            self.n_arms / float(np.tan(np.deg2rad(self.pitch_angle))),
            float(np.deg2rad(self.arm_phase)),
            float(self.n_arms),
        ]

    def arm_point(self, radius: float, arm: int) -> tuple[float, float]:
        """(x, y) arcsec of the crest of arm ``arm`` at disc-plane radius ``radius``."""
        theta = (
            np.log(radius / self.scale_length) / np.tan(np.deg2rad(self.pitch_angle))
            + (np.deg2rad(self.arm_phase) + 2.0 * np.pi * arm) / self.n_arms
        )
        xp, yp = radius * np.cos(theta), self.axis_ratio * radius * np.sin(theta)
        phi = np.deg2rad(self.angle)
        return (
            float(self.centre[0] + xp * np.cos(phi) - yp * np.sin(phi)),
            float(self.centre[1] + xp * np.sin(phi) + yp * np.cos(phi)),
        )


@dataclass(frozen=True)
class Clump:
    """Circular Gaussian knot I exp(−d²/(2σ²)); σ in arcsec."""

    centre: tuple[float, float]
    sigma: float
    intensity: float


@dataclass(frozen=True)
class ProceduralSource:
    """Source made of spiral discs and clumps (SPEC §10.3); unit-free before scaling.

    Attributes
    ----------
    kind : str
        "spiral", "clumpy" or "merger" (how it was drawn, see :func:`procedural_source`).
    centre : (x, y) arcsec
        Placement point (disc centre, or the mid-point of a merger's two discs).
    discs, clumps : tuples of :class:`SpiralDisc` and :class:`Clump`
    """

    kind: str
    centre: tuple[float, float]
    discs: tuple[SpiralDisc, ...]
    clumps: tuple[Clump, ...] = ()

    def image(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Surface brightness at source-plane points (x, y), arcsec."""
        x_flat, y_flat, shape = _flat_points(x, y)
        discs = np.array([d.row() for d in self.discs], dtype=float).reshape(-1, 11)
        clumps = np.array(
            [
                [c.centre[0], c.centre[1], 1.0 / (2.0 * c.sigma**2), c.intensity]
                for c in self.clumps
            ],
            dtype=float,
        ).reshape(-1, 4)
        return _procedural_source_kernel(x_flat, y_flat, discs, clumps).reshape(shape)

    def to_dict(self) -> dict:
        return {"model": "procedural", **dataclasses.asdict(self)}


@dataclass(frozen=True, eq=False)
class ImageSource:
    """A 2D image as the source: bilinear interpolation, zero outside.

    Attributes
    ----------
    pixels : ndarray (n_y, n_x)
        Surface brightness (any unit: the amplitude is set by the S/N), row index
        increasing with +y like every mgelens array.
    pixel_scale : float
        Arcsec per source-image pixel.
    centre : (x, y) arcsec
        Source-plane position of the image centre (pixel centres follow SPEC §1.1 with
        this origin).
    path : str
        File the image came from (recorded in the truth), "" if none.
    """

    pixels: np.ndarray = field(repr=False)
    pixel_scale: float
    centre: tuple[float, float] = (0.0, 0.0)
    path: str = ""

    def __post_init__(self):
        pixels = np.asarray(self.pixels, dtype=float)
        if pixels.ndim != 2 or min(pixels.shape) < 2:
            raise ValueError(f"source image must be 2D and at least 2×2, got {pixels.shape}")
        if not np.all(np.isfinite(pixels)):
            raise ValueError(f"source image {self.path or ''} contains NaN or inf")
        if not self.pixel_scale > 0.0:
            raise ValueError(f"source pixel scale must be > 0 arcsec, got {self.pixel_scale}")
        object.__setattr__(self, "pixels", pixels)

    def image(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Bilinear interpolation between pixel centres; 0 beyond the outermost centres."""
        n_y, n_x = self.pixels.shape
        col = (np.asarray(x) - self.centre[0]) / self.pixel_scale + (n_x - 1) / 2.0
        row = (np.asarray(y) - self.centre[1]) / self.pixel_scale + (n_y - 1) / 2.0
        inside = (col >= 0.0) & (col <= n_x - 1) & (row >= 0.0) & (row <= n_y - 1)
        c0 = np.clip(np.floor(col), 0, n_x - 2).astype(np.intp)
        r0 = np.clip(np.floor(row), 0, n_y - 2).astype(np.intp)
        fc = np.clip(col - c0, 0.0, 1.0)
        fr = np.clip(row - r0, 0.0, 1.0)
        p = self.pixels
        value = (1.0 - fr) * ((1.0 - fc) * p[r0, c0] + fc * p[r0, c0 + 1]) + fr * (
            (1.0 - fc) * p[r0 + 1, c0] + fc * p[r0 + 1, c0 + 1]
        )
        return np.where(inside, value, 0.0)

    def to_dict(self) -> dict:
        return {
            "model": "image",
            "path": self.path,
            "shape": list(self.pixels.shape),
            "pixel_scale": self.pixel_scale,
            "centre": list(self.centre),
            "interpolation": "bilinear between pixel centres, zero outside",
        }


def load_source_image(path: str | os.PathLike) -> np.ndarray:
    """Read a 2D source image from a FITS file (first 2D image HDU) or a ``.npy`` file.

    Arrays are used as stored: row index = +y, as astropy reads FITS files.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: source image not found; give a .fits or .npy file")
    if path.suffix.lower() == ".npy":
        pixels = np.load(path, allow_pickle=False)
    elif path.suffix.lower() in {".fits", ".fit", ".fts"} or path.name.lower().endswith(".fits.gz"):
        with fits.open(path) as hdul:
            images = [h.data for h in hdul if h.data is not None and np.ndim(h.data) == 2]
            if not images:
                raise ValueError(f"{path}: no 2D image HDU found")
            pixels = np.array(images[0], dtype=float)
    else:
        raise ValueError(f"{path}: unknown source image format; use .fits or .npy")
    pixels = np.asarray(pixels, dtype=float)
    if pixels.ndim != 2:
        raise ValueError(f"{path}: source image must be 2D, got shape {pixels.shape}")
    return pixels


def procedural_source(kind: str, centre: tuple[float, float], rng: np.random.Generator):
    """Random SLACS-like source of total extent ≈ 1.0–1.5″ placed at ``centre``.

    * "spiral": one disc, h ~ U(0.12, 0.18)″, q ~ U(0.5, 0.9), two arms with amplitude
      U(0.5, 0.8) and pitch U(15°, 30°), 3–4 clumps (σ 0.02–0.04″, 0.3–0.7 I₀) on the arms.
    * "clumpy": a disc with h ~ U(0.15, 0.2)″, weaker arms (0.3–0.6) and 5–6 brighter
      knots (0.6–1.2 I₀) on the arms.
    * "merger": two discs (h ~ U(0.08, 0.12)″, second 0.5–1 times as bright, weak arms)
      0.35–0.55″ apart about ``centre``, and 3–6 tidal clumps along a curved tail
      leaving the second disc.
    """
    if kind not in SOURCE_KINDS:
        raise ValueError(f"unknown source kind {kind!r}; choose one of {', '.join(SOURCE_KINDS)}")
    centre = (float(centre[0]), float(centre[1]))
    if kind == "merger":
        separation = rng.uniform(0.35, 0.55)
        direction = rng.uniform(0.0, 2.0 * np.pi)
        half = 0.5 * separation * np.array([np.cos(direction), np.sin(direction)])
        first = _random_disc(tuple(centre + half), rng, (0.08, 0.12), (0.0, 0.3), 1.0)
        second = _random_disc(
            tuple(centre - half), rng, (0.08, 0.12), (0.0, 0.3), rng.uniform(0.5, 1.0)
        )
        bend = rng.choice([-1.0, 1.0]) * rng.uniform(1.5, 3.0)
        steps = np.sort(rng.uniform(0.15, 0.45, rng.integers(3, 7)))
        clumps = tuple(
            Clump(
                (
                    float(second.centre[0] + s * np.cos(direction + np.pi + bend * s)),
                    float(second.centre[1] + s * np.sin(direction + np.pi + bend * s)),
                ),
                float(rng.uniform(0.02, 0.035)),
                float(rng.uniform(0.3, 0.6) * second.intensity),
            )
            for s in steps
        )
        return ProceduralSource(kind, centre, (first, second), clumps)
    strong = kind == "spiral"
    scale_range = (0.12, 0.18) if strong else (0.15, 0.2)
    disc = _random_disc(centre, rng, scale_range, (0.5, 0.8) if strong else (0.3, 0.6), 1.0)
    n_clumps = rng.integers(3, 5) if strong else rng.integers(5, 7)
    brightness = (0.3, 0.7) if strong else (0.6, 1.2)
    clumps = tuple(
        Clump(
            disc.arm_point(rng.uniform(0.8, 2.5) * disc.scale_length, int(rng.integers(2))),
            float(rng.uniform(0.02, 0.04)),
            float(rng.uniform(*brightness)),
        )
        for _ in range(n_clumps)
    )
    return ProceduralSource(kind, centre, (disc,), clumps)


def _random_disc(centre, rng, scale_range, arm_range, intensity) -> SpiralDisc:
    return SpiralDisc(
        centre=(float(centre[0]), float(centre[1])),
        axis_ratio=float(rng.uniform(0.5, 0.9)),
        angle=float(rng.uniform(0.0, 180.0)),
        scale_length=float(rng.uniform(*scale_range)),
        intensity=float(intensity),
        arm_amplitude=float(rng.uniform(*arm_range)),
        pitch_angle=float(rng.uniform(15.0, 30.0)),
        arm_phase=float(rng.uniform(0.0, 360.0)),
    )


# --------------------------------------------------------------------------------------
# mocks


@dataclass(frozen=True)
class MockLens:
    """Everything that defines a mock lens system, before image formation.

    Attributes
    ----------
    name : str
        "M1", "P07", ...
    recipe : str
        How it was made (free text recorded in the truth).
    light : MGELight or IsophoteLight
    mass : tuple of mass profiles
        EPL and optionally ExternalShear (:mod:`mgelens.mass`).
    source : ProceduralSource or ImageSource
        Unit-free; :func:`simulate` scales it to the target S/N.
    caustic_centre : (x, y) arcsec
        Source-plane image of the mass centre, about which the source was placed.
    seed : int or tuple of int
        Entropy of the noise generator ``default_rng(seed)``.
    z_lens, z_source : float
    mask_radius : float
        Fit mask radius in arcsec (recorded for the fits).
    """

    name: str
    recipe: str
    light: MGELight | IsophoteLight
    mass: tuple
    source: ProceduralSource | ImageSource
    caustic_centre: tuple[float, float]
    seed: int | tuple[int, ...]
    z_lens: float
    z_source: float
    mask_radius: float

    def with_source(self, source: ProceduralSource | ImageSource) -> "MockLens":
        return dataclasses.replace(self, source=source)


@dataclass(frozen=True)
class PaperMock:
    """One of the paper's mocks: SPEC §10.1 lens-light MGE and §10.2 EPL mass (no shear).

    Angles are degrees CCW from +x; ``log_sigmas`` are lg of the mgefit major-axis σ in
    arcsec; ``log_intensities`` lg of the peak surface brightness in e⁻ s⁻¹ pix⁻¹.
    """

    name: str
    lens: str
    centre: tuple[float, float]
    axis_ratios: tuple[float, ...]
    angles: tuple[float, ...]
    log_intensities: tuple[float, ...]
    log_sigmas: tuple[float, ...]
    einstein_radius: float
    mass_axis_ratio: float
    mass_angle: float
    slope: float
    z_lens: float
    z_source: float
    mask_radius: float
    seed: int
    source_kind: str

    def light(self) -> MGELight:
        return MGELight.from_table(
            self.centre, self.axis_ratios, self.angles, self.log_intensities, self.log_sigmas
        )

    def mass(self) -> EPL:
        return EPL(
            centre=self.centre,
            einstein_radius=self.einstein_radius,
            axis_ratio=self.mass_axis_ratio,
            angle=self.mass_angle,
            slope=self.slope,
        )


# fmt: off
PAPER_MOCKS = {
    "M1": PaperMock(
        name="M1",
        lens="SDSSJ0252+0039",
        centre=(0.013, -0.070),
        axis_ratios=(0.83, 0.77, 0.83, 0.90, 0.65, 0.64, 0.77, 0.50,
                     1.00, 0.79, 0.48, 0.62, 0.41, 0.18, 0.78, 0.22),
        angles=(-19, -19, 71, -19, -70, 4, 56, -52, 0, -80, -2, -78, 28, 49, -73, -25),
        log_intensities=(0.86, 0.91, 0.29, 0.30, -0.24, -0.48, -0.13, -0.75,
                         -0.73, -0.76, -1.6, -1.4, -2.0, -2.2, -2.2, -2.4),
        log_sigmas=(-1.8, -1.6, -1.4, -1.1, -1.0, -0.85, -0.75, -0.56,
                    -0.25, -0.14, -0.13, 0.0018, 0.020, -0.19, 0.43, -0.11),
        einstein_radius=1.2,
        mass_axis_ratio=0.80,
        mass_angle=45.0,
        slope=2.1,
        z_lens=0.28,
        z_source=0.98,
        mask_radius=1.8,
        seed=1,
        source_kind="spiral",
    ),
    "M2": PaperMock(
        name="M2",
        lens="SDSSJ0330-0020",
        centre=(0.048, 0.017),
        axis_ratios=(0.82, 0.64, 1.0, 0.60, 0.62, 0.91, 0.58, 0.34,
                     1.00, 0.46, 0.59, 0.76, 0.21, 0.30, 0.44, 0.48),
        angles=(65, -64, 0, -78, -23, 65, -55, 84, 0, -66, -89, -40, -81, 7, 65, -47),
        log_intensities=(1.0, 0.69, 0.26, 0.14, -0.47, -0.19, -0.63, -1.1,
                         -1.1, -0.86, -1.1, -1.1, -2.3, -2.3, -1.8, -1.7),
        log_sigmas=(-1.7, -1.4, -1.1, -1.1, -0.91, -0.72, -0.72, -0.78,
                    -0.25, -0.50, -0.23, -0.11, -0.15, 0.018, 0.18, 0.22),
        einstein_radius=1.0,
        mass_axis_ratio=0.77,
        mass_angle=60.0,
        slope=1.9,
        z_lens=0.35,
        z_source=1.1,
        mask_radius=1.6,
        seed=2,
        source_kind="clumpy",
    ),
    "M3": PaperMock(
        name="M3",
        lens="SDSSJ1205+4910",
        centre=(-0.001, -0.034),
        axis_ratios=(0.92, 1.0, 0.85, 0.62, 0.84, 0.70, 0.73, 0.66, 0.58, 0.67, 0.36, 0.84),
        angles=(-63, -90, -24, 27, -62, -25, -18, -70, -25, 8, -31, -28),
        log_intensities=(0.78, 1.1, 0.71, -0.65, -0.24, 0.077, -0.015, -1.1,
                         -0.61, -0.90, -1.4, -1.2),
        log_sigmas=(-1.8, -1.3, -0.98, -0.86, -0.68, -0.75, -0.44, -0.22,
                    -0.17, 0.085, 0.082, -1.2),
        einstein_radius=1.1,
        mass_axis_ratio=0.75,
        mass_angle=30.0,
        slope=2.0,
        z_lens=0.22,
        z_source=0.48,
        mask_radius=1.8,
        seed=3,
        source_kind="merger",
    ),
}
"""The paper's mocks (SPEC §10.1–10.2); sources S1–S3 are procedural stand-ins (§10.3)."""
# fmt: on


def caustic_centre(mass: Sequence) -> tuple[float, float]:
    """Source-plane position of the first profile's centre (the caustics' centre).

    Taken as the mean ray-traced position of 16 points on a 10⁻³″ circle about the
    centre: exact for deflections that are odd about the centre (EPL, SIE) plus any
    linear field (shear), and it avoids the centre itself, where the EPL deflection is
    singular for γ > 2.
    """
    angles = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
    x = mass[0].centre[0] + 1e-3 * np.cos(angles)
    y = mass[0].centre[1] + 1e-3 * np.sin(angles)
    beta_x, beta_y = ray_trace(mass, x, y)
    return float(np.mean(beta_x)), float(np.mean(beta_y))


def _placed_source(kind: str, centre: tuple[float, float], rng: np.random.Generator):
    """Procedural source 0.05–0.15″ from ``centre`` in a random direction (SPEC §10.3)."""
    offset = rng.uniform(0.05, 0.15)
    direction = rng.uniform(0.0, 2.0 * np.pi)
    placed = (centre[0] + offset * np.cos(direction), centre[1] + offset * np.sin(direction))
    return procedural_source(kind, placed, rng)


def paper_mock(name: str, seed: int | None = None, noise_seed: int | None = None) -> MockLens:
    """The paper's mock ``name`` ("M1", "M2" or "M3"), optionally with other seeds.

    The seed (default 1, 2, 3) drives the noise (``default_rng(seed)``) and the procedural
    source (``default_rng([seed, 1])``). ``noise_seed`` replaces the seed of the noise
    alone: the same lens and source seen through another Poisson realisation, the test of
    whether a fit's miss is the noise image's (``MockLens.seed`` is the noise seed).
    """
    if name not in PAPER_MOCKS:
        raise ValueError(f"unknown mock {name!r}; choose one of {', '.join(PAPER_MOCKS)}")
    table = PAPER_MOCKS[name]
    seed = table.seed if seed is None else int(seed)
    noise = seed if noise_seed is None else int(noise_seed)
    if noise < 0:
        raise ValueError(f"noise_seed must be >= 0, got {noise}")
    mass = (table.mass(),)
    centre = caustic_centre(mass)
    source = _placed_source(table.source_kind, centre, np.random.default_rng([seed, SOURCE_STREAM]))
    seeds = "" if noise == seed else f"; source seed {seed}, noise seed {noise}"
    return MockLens(
        name=name,
        recipe=f"paper mock {name}: lens light = mgefit MGE of {table.lens} (SPEC 10.1), "
        f"EPL mass (SPEC 10.2), procedural {table.source_kind} source{seeds}",
        light=table.light(),
        mass=mass,
        source=source,
        caustic_centre=centre,
        seed=noise,
        z_lens=table.z_lens,
        z_source=table.z_source,
        mask_radius=table.mask_radius,
    )


DEFAULT_POPULATION_SEED = 2024
POPULATION_SIZE = 38
POPULATION_MASK_RADIUS = 3.0


def population_lens(index: int, population_seed: int = DEFAULT_POPULATION_SEED) -> MockLens:
    """Lens ``index`` of a SLACS-like mock population (named ``P{index:02d}``).

    Distributions (drawn from ``default_rng([population_seed, index, 0])``):

    * mass: EPL centre N(0, 0.02″) per axis; θ_E ~ U(0.8, 1.6)″; γ ~ N(2.08, 0.1)
      clipped to [1.8, 2.4]; q ~ N(0.75, 0.1) clipped to [0.5, 0.95]; φ = outer light PA
      + N(0, 10°); external shear |γ| ~ U(0, 0.1) at an angle U(0°, 180°).
    * light (:class:`IsophoteLight`, same centre as the mass): Sérsic n ~ U(3, 5),
      R_e ~ logU(0.8, 2.5)″, surface brightness at a = 1″ ~ logU(0.06, 0.25) e⁻ s⁻¹ pix⁻¹;
      q from U(0.6, 0.95) inside to that + U(−0.2, 0.15) outside (clipped to
      [0.5, 0.97]); PA from U(0°, 180°) twisting by N(0, 20°) clipped to ±45°; a₄/a from
      U(−0.02, 0.025) inside to U(−0.02, 0.025) outside; each transition at a radius
      logU(0.5, 2.0)″ with width U(0.5, 0.9) in ln a. Draws whose isophotes would not
      nest are redrawn.
    * source: kind uniform over spiral / clumpy / merger, placed 0.05–0.15″ from the
      caustic centre (``default_rng([population_seed, index, 1])``).
    * z_lens ~ U(0.1, 0.35), z_source = z_lens + U(0.2, 0.7); fit mask radius 3.0″.

    The noise uses ``default_rng([population_seed, index, 2])``.
    """
    if not (isinstance(index, int | np.integer) and index >= 0):
        raise ValueError(f"population index must be an integer >= 0, got {index!r}")
    rng = np.random.default_rng([population_seed, index, 0])
    centre = (float(rng.normal(0.0, 0.02)), float(rng.normal(0.0, 0.02)))
    light = _random_isophote_light(centre, rng)
    shear_magnitude = rng.uniform(0.0, 0.1)
    shear_angle = np.deg2rad(rng.uniform(0.0, 180.0))
    mass = (
        EPL(
            centre=centre,
            einstein_radius=float(rng.uniform(0.8, 1.6)),
            axis_ratio=float(np.clip(rng.normal(0.75, 0.1), 0.5, 0.95)),
            angle=float(np.mod(light.angle.outer + rng.normal(0.0, 10.0), 180.0)),
            slope=float(np.clip(rng.normal(2.08, 0.1), 1.8, 2.4)),
        ),
        ExternalShear(
            gamma_1=float(shear_magnitude * np.cos(2.0 * shear_angle)),
            gamma_2=float(shear_magnitude * np.sin(2.0 * shear_angle)),
        ),
    )
    z_lens = float(rng.uniform(0.1, 0.35))
    z_source = z_lens + float(rng.uniform(0.2, 0.7))
    source_rng = np.random.default_rng([population_seed, index, 1])
    kind = str(source_rng.choice(SOURCE_KINDS))
    centre_source = caustic_centre(mass)
    return MockLens(
        name=f"P{index:02d}",
        recipe=f"population lens {index} of seed {population_seed}: isophote lens light, "
        f"EPL + shear mass, procedural {kind} source",
        light=light,
        mass=mass,
        source=_placed_source(kind, centre_source, source_rng),
        caustic_centre=centre_source,
        seed=(int(population_seed), int(index), 2),
        z_lens=z_lens,
        z_source=z_source,
        mask_radius=POPULATION_MASK_RADIUS,
    )


def _random_isophote_light(centre, rng: np.random.Generator) -> IsophoteLight:
    n = float(rng.uniform(3.0, 5.0))
    effective_radius = float(np.exp(rng.uniform(np.log(0.8), np.log(2.5))))
    brightness_1 = float(np.exp(rng.uniform(np.log(0.06), np.log(0.25))))
    intensity = brightness_1 * float(
        np.exp(sersic_constant(n) * ((1.0 / effective_radius) ** (1.0 / n) - 1.0))
    )
    while True:
        q_inner = rng.uniform(0.6, 0.95)
        q_outer = np.clip(q_inner + rng.uniform(-0.2, 0.15), 0.5, 0.97)
        angle_inner = rng.uniform(0.0, 180.0)
        twist = np.clip(rng.normal(0.0, 20.0), -45.0, 45.0)
        transitions = [
            (float(np.exp(rng.uniform(np.log(0.5), np.log(2.0)))), float(rng.uniform(0.5, 0.9)))
            for _ in range(3)
        ]
        try:
            return IsophoteLight(
                centre=centre,
                intensity=intensity,
                effective_radius=effective_radius,
                sersic_index=n,
                axis_ratio=Transition(float(q_inner), float(q_outer), *transitions[0]),
                angle=Transition(float(angle_inner), float(angle_inner + twist), *transitions[1]),
                a4=Transition(
                    float(rng.uniform(-0.02, 0.025)),
                    float(rng.uniform(-0.02, 0.025)),
                    *transitions[2],
                ),
            )
        except ValueError:
            logger.debug("isophote draw does not nest; drawing again")


def with_image_source(lens: MockLens, pixels: np.ndarray, pixel_scale: float, path="") -> MockLens:
    """``lens`` with its procedural source replaced by an image at the same position."""
    centre = lens.source.centre
    return lens.with_source(ImageSource(pixels, pixel_scale, centre, str(path)))


# --------------------------------------------------------------------------------------
# image formation


@dataclass(frozen=True, eq=False)
class MockImaging:
    """A simulated data set with its noise-free components (native 2D arrays, e⁻ s⁻¹/pix).

    Attributes
    ----------
    imaging : Imaging
        Data, noise map and PSF.
    model : ndarray
        Noise-free data = ``lens_light_blurred + lensed_source_blurred``.
    lens_light, lensed_source : ndarray
        Pixel averages over the sub-grid, before the PSF.
    lens_light_blurred, lensed_source_blurred : ndarray
        The same after the PSF.
    source : ndarray
        Unlensed scaled source on the source-plane grid described in ``truth``.
    truth : dict
        Every parameter (written as ``truth.json``).
    """

    imaging: Imaging
    model: np.ndarray
    lens_light: np.ndarray
    lens_light_blurred: np.ndarray
    lensed_source: np.ndarray
    lensed_source_blurred: np.ndarray
    source: np.ndarray
    truth: dict


@dataclass(frozen=True)
class LensedSource:
    """A source seen through a lens: image(θ) = source(β(θ)), β = θ − α(θ)."""

    source: ProceduralSource | ImageSource
    mass: tuple

    def image(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return self.source.image(*ray_trace(self.mass, x, y))


def simulate(lens: MockLens, observation: Observation | None = None) -> MockImaging:
    """Form the image of ``lens`` (SPEC §10.4): over-sampled light, PSF, S/N scaling, noise.

    Light is evaluated on the image grid padded by half the PSF size on every side,
    convolved and cropped, so border pixels receive the PSF-scattered light from beyond
    the field as in a real cutout (no zero-padding edge darkening).
    """
    observation = Observation() if observation is None else observation
    scale, sub = observation.pixel_scale, observation.sub_size
    psf = observation.psf()
    pad = observation.psf_size // 2
    padded = (observation.image_size + 2 * pad,) * 2
    inner = (slice(pad, pad + observation.image_size),) * 2
    lens_light = oversampled_image(lens.light, padded, scale, sub)
    lensed_unit = oversampled_image(LensedSource(lens.source, lens.mass), padded, scale, sub)
    lens_blurred = convolve_image(lens_light, psf)[inner]
    source_blurred_unit = convolve_image(lensed_unit, psf)[inner]
    lens_light, lensed_unit = lens_light[inner], lensed_unit[inner]
    amplitude = source_amplitude(
        lens_blurred,
        source_blurred_unit,
        observation.exposure_time,
        observation.sky,
        observation.signal_to_noise,
    )
    lensed_source = amplitude * lensed_unit
    source_blurred = amplitude * source_blurred_unit
    model = lens_blurred + source_blurred
    noise_map = noise_map_from(model, observation.exposure_time, observation.sky)
    rng = np.random.default_rng(lens.seed)
    data = noisy_data(model, observation.exposure_time, observation.sky, rng)
    plane_scale = observation.source_plane_pixel_scale
    plane_shape = (observation.source_plane_size, observation.source_plane_size)
    source_plane = amplitude * oversampled_image(
        lens.source, plane_shape, plane_scale, 4, origin=lens.source.centre
    )
    truth = _truth(
        lens,
        observation,
        amplitude=amplitude,
        lens_light=lens_light,
        source_blurred=source_blurred,
        noise_map=noise_map,
        model=model,
        source_plane=source_plane,
    )
    imaging = Imaging(data, noise_map, psf, scale, name=lens.name, unit=BRIGHTNESS_UNIT)
    return MockImaging(
        imaging=imaging,
        model=model,
        lens_light=lens_light,
        lens_light_blurred=lens_blurred,
        lensed_source=lensed_source,
        lensed_source_blurred=source_blurred,
        source=source_plane,
        truth=truth,
    )


def _truth(
    lens, observation, *, amplitude, lens_light, source_blurred, noise_map, model, source_plane
) -> dict:
    """The ``truth.json`` content of a simulated mock."""
    scale = observation.pixel_scale
    light = lens.light.to_dict()
    if isinstance(lens.light, MGELight):
        light["total_flux_analytic"] = lens.light.total_flux(scale)
    light["total_flux_in_field"] = float(lens_light.sum())
    offset = np.subtract(lens.source.centre, lens.caustic_centre)
    bright = source_plane > 0.02 * source_plane.max()
    plane_axis = (np.arange(source_plane.shape[0]) - (source_plane.shape[0] - 1) / 2.0) * (
        observation.source_plane_pixel_scale
    )
    plane_x, plane_y = np.meshgrid(plane_axis, plane_axis)
    return {
        "name": lens.name,
        "recipe": lens.recipe,
        "conventions_version": mgelens.CONVENTIONS_VERSION,
        "mgelens_version": mgelens.__version__,
        "units": f"surface brightness in {BRIGHTNESS_UNIT} per image pixel; arcsec; degrees "
        "counter-clockwise from +x",
        "observation": dataclasses.asdict(observation),
        "seed": lens.seed,
        "z_lens": lens.z_lens,
        "z_source": lens.z_source,
        "mask_radius": lens.mask_radius,
        "lens_light": light,
        "mass": [mass_dict(profile) for profile in lens.mass],
        "source": {
            **lens.source.to_dict(),
            "amplitude": amplitude,
            "amplitude_meaning": "surface brightness = amplitude x the profile or image above",
            "caustic_centre": list(lens.caustic_centre),
            "offset_from_caustic_centre": float(np.hypot(*offset)),
            "extent": float(2.0 * np.max(np.hypot(plane_x, plane_y)[bright])),
            "extent_meaning": "diameter (arcsec) of the circle about the source centre that "
            "holds every source-plane pixel above 2% of the peak",
        },
        "signal_to_noise": {
            "source_max": float(np.max(source_blurred / noise_map)),
            "data_max": float(np.max(model / noise_map)),
            "definition": "max over pixels of the noise-free PSF-convolved component / noise",
        },
        "source_plane": {
            "pixel_scale": observation.source_plane_pixel_scale,
            "shape": list(source_plane.shape),
            "centre": list(lens.source.centre),
        },
        "files": {
            key: {"name": MOCK_FILES[key], "content": FILE_DESCRIPTIONS[key]} for key in MOCK_FILES
        },
    }


MASS_TYPES = {"EPL": EPL, "SIE": SIE, "ExternalShear": ExternalShear}


def mass_dict(profile) -> dict:
    """The ``truth.json`` entry of a mass profile: type, parameters and derived values."""
    entry = {"type": type(profile).__name__, "parameters": dataclasses.asdict(profile)}
    if isinstance(profile, EPL | SIE):
        entry["ell_comps"] = list(profile.ell_comps)
    if isinstance(profile, ExternalShear):
        entry["magnitude"] = profile.magnitude
        entry["angle"] = profile.angle
    return entry


def mass_from_truth(truth: dict) -> list:
    """Rebuild the mass profiles recorded in a ``truth.json`` content."""
    profiles = []
    for entry in truth["mass"]:
        if entry["type"] not in MASS_TYPES:
            raise ValueError(f"unknown mass profile type {entry['type']!r} in truth")
        parameters = dict(entry["parameters"])
        if "centre" in parameters:
            parameters["centre"] = tuple(parameters["centre"])
        profiles.append(MASS_TYPES[entry["type"]](**parameters))
    return profiles


def write_mock(mock: MockImaging, folder: str | os.PathLike) -> Path:
    """Write a mock's files (:data:`MOCK_FILES`) into ``folder``, each atomically.

    ``data.fits``, ``noise_map.fits`` and ``psf.fits`` use the layout of the real SLACS
    folders (:meth:`mgelens.imaging.Imaging.to_fits`); ``truth.json`` is written last.
    """
    folder = Path(folder)
    mock.imaging.to_fits(folder)
    scale = mock.imaging.pixel_scale
    for key in (
        "model",
        "lens_light",
        "lens_light_blurred",
        "lensed_source",
        "lensed_source_blurred",
    ):
        _write_image(folder / MOCK_FILES[key], getattr(mock, key), scale)
    plane = mock.truth["source_plane"]
    _write_image(folder / MOCK_FILES["source"], mock.source, plane["pixel_scale"], plane["centre"])
    write_json(folder / MOCK_FILES["truth"], mock.truth)
    return folder


def _write_image(path: Path, image: np.ndarray, pixel_scale: float, centre=(0.0, 0.0)) -> None:
    header = fits.Header()
    header["PIXSCALE"] = (float(pixel_scale), "[arcsec/pixel]")
    header["XCENTRE"] = (float(centre[0]), "[arcsec] x of the array centre")
    header["YCENTRE"] = (float(centre[1]), "[arcsec] y of the array centre")
    header["BUNIT"] = BRIGHTNESS_UNIT
    write_fits(path, fits.PrimaryHDU(data=np.asarray(image, dtype=np.float64), header=header))


def _flat_points(x, y) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
    x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    return np.ascontiguousarray(x).ravel(), np.ascontiguousarray(y).ravel(), x.shape


__all__ = [
    "DEFAULT_POPULATION_SEED",
    "ISOPHOTE_TRUTH_RADII",
    "MOCK_FILES",
    "PAPER_MOCKS",
    "POPULATION_SIZE",
    "SOURCE_KINDS",
    "Clump",
    "ImageSource",
    "IsophoteLight",
    "LensedSource",
    "MGELight",
    "MockImaging",
    "MockLens",
    "Observation",
    "PaperMock",
    "ProceduralSource",
    "SpiralDisc",
    "Transition",
    "caustic_centre",
    "gaussian_psf",
    "load_source_image",
    "mass_from_truth",
    "noise_map_from",
    "noisy_data",
    "oversampled_image",
    "paper_mock",
    "population_lens",
    "procedural_source",
    "simulate",
    "source_amplitude",
    "with_image_source",
    "write_mock",
]

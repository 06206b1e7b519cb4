"""Where the closed-form route of wide lens-light Gaussians holds (``FitSettings.
lp_analytic_tolerance``): its error against the exact discrete convolution, measured once per
PSF, and the smallest minor-axis σ from which it stays below a tolerance.

The route (:func:`mgelens.light.blurred_gaussian_columns`) expands the PSF and the pixel's
light integral to their fourth cumulants (:mod:`mgelens.kernel_cumulants`); its error falls
as σ⁻⁶ and depends on the PSF in pixel units only.
"""

import functools

import numpy as np
from scipy import signal
from scipy.special import erf

from mgelens.convolve import check_psf
from mgelens.kernel_cumulants import KernelCumulants
from mgelens.light import blurred_gaussian_columns

CALIBRATION_SIGMAS_PIXELS = np.geomspace(0.5, 24.0, 34)
"""Minor-axis σ (in pixels) at which :func:`smallest_analytic_sigma` compares the routes."""

CALIBRATION_OFFSET_PIXELS = (0.31, -0.17)
"""Sub-pixel centre of the calibration Gaussians, off the kernel's symmetry."""


def expansion_errors(psf: np.ndarray, sigmas_pixels: np.ndarray) -> np.ndarray:
    """Largest difference, relative to the column's peak, between the closed form and the
    exact column of a circular unit Gaussian: its mean over each pixel (erf, exact for a
    circular Gaussian) convolved with ``psf``; one per minor-axis σ in ``sigmas_pixels``
    (pixel units; the error depends on σ/Δ only).

    The Gaussian is centred at :data:`CALIBRATION_OFFSET_PIXELS`; outputs are compared
    within 5σ of it, where the frame holds every input they read.
    """
    psf = check_psf(psf)
    cumulants = KernelCumulants.of_psf(psf, 1.0, pixel_box=True)
    half = max(psf.shape) // 2
    errors = np.empty(len(sigmas_pixels))
    for k, sigma in enumerate(sigmas_pixels):
        reach = int(np.ceil(5.0 * sigma))
        n = reach + half
        axis = np.arange(-n, n + 1, dtype=float)
        x, y = np.meshgrid(axis, axis)
        image = _pixel_mean(x, CALIBRATION_OFFSET_PIXELS[0], sigma) * _pixel_mean(
            y, CALIBRATION_OFFSET_PIXELS[1], sigma
        )
        exact = signal.fftconvolve(image, psf, mode="same")
        inner = (np.abs(x) <= reach) & (np.abs(y) <= reach)
        expanded = blurred_gaussian_columns(
            x[inner], y[inner], CALIBRATION_OFFSET_PIXELS, (0.0, 0.0), [sigma], cumulants
        )[:, 0]
        errors[k] = np.abs(expanded - exact[inner]).max() / np.abs(exact[inner]).max()
    return errors


def _pixel_mean(t: np.ndarray, centre: float, sigma: float) -> np.ndarray:
    """Mean of exp(−(t′ − centre)²/(2σ²)) over unit pixels centred at ``t``."""
    scale = np.sqrt(2.0) * sigma
    upper, lower = (t - centre + 0.5) / scale, (t - centre - 0.5) / scale
    return np.sqrt(np.pi) * scale / 2.0 * (erf(upper) - erf(lower))


@functools.lru_cache(maxsize=8)
def _calibration_errors(psf_bytes: bytes, shape: tuple[int, int]) -> np.ndarray:
    """:func:`expansion_errors` at :data:`CALIBRATION_SIGMAS_PIXELS`, once per PSF."""
    psf = np.frombuffer(psf_bytes, dtype=float).reshape(shape)
    return expansion_errors(psf, CALIBRATION_SIGMAS_PIXELS)


def smallest_analytic_sigma(psf: np.ndarray, pixel_scale: float, tolerance: float) -> float:
    """The smallest minor-axis σ (arcsec) of :data:`CALIBRATION_SIGMAS_PIXELS` from which
    the expansion stays within ``tolerance`` of the column's peak at every larger
    calibration σ (:func:`expansion_errors`); ``inf`` if it never does or ``tolerance``
    is 0 (the analytic route off)."""
    if tolerance <= 0.0:
        return np.inf
    psf = check_psf(psf)
    errors = _calibration_errors(psf.tobytes(), psf.shape)
    failing = np.nonzero(errors > tolerance)[0]
    first = 0 if failing.size == 0 else failing[-1] + 1
    if first >= CALIBRATION_SIGMAS_PIXELS.size:
        return np.inf
    return float(CALIBRATION_SIGMAS_PIXELS[first] * pixel_scale)

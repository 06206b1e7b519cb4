"""The closed-form route of wide lens-light Gaussians (mgelens.analytic_blur) against
exact discrete convolutions and exact pixel integrals."""

import dataclasses

import numpy as np
import pytest
from scipy import signal
from scipy.special import erf

from mgelens.analytic_blur import (
    CALIBRATION_SIGMAS_PIXELS,
    expansion_errors,
    smallest_analytic_sigma,
)
from mgelens.convolve import Convolver
from mgelens.fit_settings import FitSettings
from mgelens.geometry import ell_comps_from
from mgelens.grid import pixel_centres
from mgelens.kernel_cumulants import KernelCumulants
from mgelens.light import Gaussian, LightGrid, MGESet, blurred_gaussian_columns

PIXEL = 0.05


def skewed_psf(size=15):
    """A unit-sum kernel with a core, an offset lobe and broad wings: skewed (κ₃ ≠ 0) and
    heavy-tailed (κ₄ > 0), as HST's are."""
    yy, xx = np.mgrid[:size, :size] - size // 2
    core = np.exp(-(xx**2 + (yy / 1.2) ** 2) / (2 * 1.1**2))
    lobe = 0.25 * np.exp(-((xx - 2.0) ** 2 + (yy + 1.0) ** 2) / (2 * 1.4**2))
    wings = 0.02 / (1.0 + (xx**2 + yy**2) / 4.0) ** 1.5
    psf = core + lobe + wings
    return psf / psf.sum()


def circular_mask(n=161, radius=3.0):
    x, y = pixel_centres((n, n), PIXEL)
    return np.hypot(x, y) > radius


def test_cumulants_of_a_shifted_delta_move_the_gaussian_by_the_kernels_offset():
    # A delta two columns right and one row up of the kernel centre moves light by
    # (+2Δ, +1Δ): the route must agree with Convolver's orientation, to rounding.
    psf = np.zeros((7, 7))
    psf[3 + 1, 3 + 2] = 1.0
    cumulants = KernelCumulants.of_psf(psf, PIXEL, pixel_box=False)
    assert cumulants.mean == pytest.approx([2 * PIXEL, PIXEL])
    assert np.abs(cumulants.covariance).max() < 1e-18
    mask = circular_mask(61, 1.2)
    x, y = pixel_centres(mask.shape, PIXEL)
    convolver = Convolver(mask, psf)
    inputs = ~convolver.extended_mask
    gaussian = Gaussian((0.02, -0.03), ell_comps_from(0.6, 35.0), 0.2)
    exact = convolver.blur_columns(gaussian.image(x[inputs], y[inputs]), include_blurring=True)
    closed = blurred_gaussian_columns(
        x[~mask], y[~mask], gaussian.centre, gaussian.ell_comps, [0.2], cumulants
    )[:, 0]
    np.testing.assert_allclose(closed, exact, rtol=0, atol=1e-14)


@pytest.mark.parametrize(("sigma_pixels", "tolerance"), [(2.0, 2e-5), (4.0, 3e-7), (8.0, 5e-9)])
def test_pixel_box_term_gives_the_exact_pixel_integral(sigma_pixels, tolerance):
    # A centred delta kernel with the pixel box: the closed form is the Gaussian's mean
    # over each pixel, which erf gives exactly for a circular Gaussian. The error of a
    # fourth-order expansion of the box falls as σ⁻⁶.
    psf = np.zeros((3, 3))
    psf[1, 1] = 1.0
    cumulants = KernelCumulants.of_psf(psf, PIXEL, pixel_box=True)
    assert cumulants.covariance == pytest.approx(np.eye(2) * PIXEL**2 / 12)
    sigma = sigma_pixels * PIXEL
    x, y = pixel_centres((81, 81), PIXEL)
    centre = (0.011, -0.007)

    def mean_over_pixel(t, c):
        s = np.sqrt(2.0) * sigma
        return (
            np.sqrt(np.pi) * s / 2 * (erf((t + PIXEL / 2 - c) / s) - erf((t - PIXEL / 2 - c) / s))
        )

    exact = mean_over_pixel(x, centre[0]) * mean_over_pixel(y, centre[1]) / PIXEL**2
    closed = blurred_gaussian_columns(x.ravel(), y.ravel(), centre, (0.0, 0.0), [sigma], cumulants)
    assert np.abs(closed[:, 0] - exact.ravel()).max() < tolerance


def test_expansion_matches_the_exact_convolution_of_a_skewed_kernel_and_needs_its_terms():
    psf = skewed_psf()
    cumulants = KernelCumulants.of_psf(psf, 1.0, pixel_box=False)
    assert np.abs(cumulants.third).max() > 0.05  # skewed
    assert cumulants.fourth[0, 0, 0, 0] > 0.5  # heavy-tailed
    sigmas = np.array([6.0, 10.0, 16.0])
    errors = expansion_errors(psf, sigmas)
    # σ⁻⁶ decay of the first neglected (sixth-order) terms
    assert errors[0] < 2e-3
    assert errors[1] < 1e-4
    assert errors[2] < 1e-5
    assert errors[1] / errors[2] > (16.0 / 10.0) ** 5
    # with only the mean and covariance (a Gaussian PSF of the same moments) the error
    # is that of the skewness: ten times larger at least
    x, y = np.meshgrid(np.arange(-60.0, 61.0), np.arange(-60.0, 61.0))
    image = np.exp(-(x**2 + y**2) / (2 * 10.0**2))
    exact = signal.fftconvolve(image, psf, mode="same")[40:81, 40:81].ravel()
    second = dataclasses.replace(
        cumulants, third=np.zeros((2, 2, 2)), fourth=np.zeros((2, 2, 2, 2))
    )
    xs, ys = x[40:81, 40:81].ravel(), y[40:81, 40:81].ravel()
    full = blurred_gaussian_columns(xs, ys, (0.0, 0.0), (0.0, 0.0), [10.0], cumulants)[:, 0]
    moments = blurred_gaussian_columns(xs, ys, (0.0, 0.0), (0.0, 0.0), [10.0], second)[:, 0]
    assert np.abs(moments - exact).max() > 10 * np.abs(full - exact).max()


def test_smallest_analytic_sigma_is_the_first_calibration_sigma_within_tolerance():
    psf = skewed_psf()
    errors = expansion_errors(psf, CALIBRATION_SIGMAS_PIXELS)
    for tolerance in (1e-3, 1e-4, 1e-5):
        sigma = smallest_analytic_sigma(psf, PIXEL, tolerance)
        k = int(np.argmin(np.abs(CALIBRATION_SIGMAS_PIXELS * PIXEL - sigma)))
        assert np.all(errors[k:] <= tolerance)
        assert errors[k - 1] > tolerance
    assert smallest_analytic_sigma(psf, PIXEL, 1e-4) < smallest_analytic_sigma(psf, PIXEL, 1e-5)
    assert smallest_analytic_sigma(psf, PIXEL, 0.0) == np.inf
    assert smallest_analytic_sigma(psf, PIXEL, 1e-12) == np.inf


def test_light_grid_columns_take_the_closed_form_where_it_beats_the_sub_grid():
    psf = skewed_psf()
    mask = circular_mask()
    grids = {
        "reference": LightGrid.from_mask(mask, psf, PIXEL, sub_size=12, sub_size_centre=12),
        "sub-grid": LightGrid.from_mask(mask, psf, PIXEL, sub_size=2, sub_size_centre=8),
        "closed form": LightGrid.from_mask(
            mask,
            psf,
            PIXEL,
            sub_size=2,
            sub_size_centre=8,
            analytic_sigma=smallest_analytic_sigma(psf, PIXEL, 1e-4),
        ),
    }
    threshold = grids["closed form"].analytic_sigma
    assert 0.1 < threshold < 1.0
    assert grids["sub-grid"].analytic_sigma == np.inf
    sets = [
        MGESet.extended((0.013, -0.021), ell_comps_from(0.7, 30.0), PIXEL, 3.0),
        MGESet.point((0.0, 0.01), ell_comps_from(0.9, 100.0), PIXEL),
        MGESet.extended((0.013, -0.021), ell_comps_from(0.5, 120.0), PIXEL, 3.0),
    ]
    columns = {name: grid.blurred_columns(sets) for name, grid in grids.items()}
    sigmas = np.concatenate([s.sigmas for s in sets])
    wide = sigmas >= threshold
    assert 8 <= wide.sum() < 40
    # narrow columns: the sub-grid route, unchanged (same windows, same FFTs)
    np.testing.assert_allclose(
        columns["closed form"][:, ~wide], columns["sub-grid"][:, ~wide], rtol=0, atol=1e-15
    )
    peak = np.abs(columns["reference"][:, wide]).max(axis=0)
    error_closed = np.abs(columns["closed form"][:, wide] - columns["reference"][:, wide]).max(0)
    error_grid = np.abs(columns["sub-grid"][:, wide] - columns["reference"][:, wide]).max(0)
    # the reference's own 12×12 sub-grid is good to ≈ Δ²/(12·144)/σ² relative
    reference_error = PIXEL**2 / (12 * 144) / sigmas[wide] ** 2
    assert np.all(error_closed / peak < 1e-4 + 2 * reference_error)
    assert np.all(error_closed < error_grid)
    # the fixed-light image takes the same routes
    intensities = np.linspace(1.0, 3.0, sets[0].n_gaussians)
    image = grids["closed form"].blurred_image(sets[0].gaussians(intensities))
    np.testing.assert_allclose(
        image, columns["closed form"][:, : sets[0].n_gaussians] @ intensities, atol=1e-13
    )


def test_analytic_tolerance_setting_is_checked():
    assert FitSettings(lp_analytic_tolerance=1e-4).lp_analytic_tolerance == 1e-4
    with pytest.raises(ValueError, match="lp_analytic_tolerance"):
        FitSettings(lp_analytic_tolerance=-1e-4)
    with pytest.raises(ValueError, match="lp_analytic_tolerance"):
        FitSettings(lp_analytic_tolerance=1.0)


def test_pixel_sum_of_a_closed_form_column_is_the_gaussians_flux():
    # Blurring and pixel integration conserve flux: the column sums to the Gaussian's
    # integral over Δ² times the kernel's sum.
    psf = skewed_psf() * 0.98
    cumulants = KernelCumulants.of_psf(psf, PIXEL, pixel_box=True)
    gaussian = Gaussian((0.02, 0.01), ell_comps_from(0.6, 70.0), 0.4)
    x, y = pixel_centres((241, 241), PIXEL)
    column = blurred_gaussian_columns(
        x.ravel(), y.ravel(), gaussian.centre, gaussian.ell_comps, [0.4], cumulants
    )
    assert column.sum() == pytest.approx(0.98 * gaussian.total_flux(PIXEL), rel=1e-9)

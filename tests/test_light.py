import json

import numpy as np
import pytest
from scipy import integrate, signal
from scipy.special import erf

from mgelens.geometry import ell_comps_from
from mgelens.grid import pixel_centres, sub_grid
from mgelens.light import (
    EXPONENT_CUTOFF,
    Gaussian,
    LightGrid,
    MGESet,
    Sersic,
    light_from_dict,
    log_spaced_sigmas,
    sersic_constant,
)


def gaussian_psf(size=11, sigma_pix=1.0):
    yy, xx = np.mgrid[:size, :size] - size // 2
    psf = np.exp(-(xx**2 + yy**2) / (2 * sigma_pix**2))
    return psf / psf.sum()


def test_gaussian_pixel_sum_equals_analytic_flux():
    g = Gaussian(centre=(0.03, -0.02), ell_comps=ell_comps_from(0.6, 35.0), sigma=0.2, intensity=3)
    x, y = pixel_centres((201, 201), 0.05)
    grid = sub_grid(x.ravel(), y.ravel(), 0.05, 4)
    pixel_sum = grid.bin(g.image(grid.x, grid.y)).sum()
    assert pixel_sum == pytest.approx(g.total_flux(0.05), rel=1e-9)
    assert g.total_flux() == pytest.approx(2 * np.pi * 0.2**2 * 3 / 0.6)


def test_gaussian_sigma_is_minor_axis_and_converter_uses_major_axis():
    g = Gaussian.from_major_axis((0.0, 0.0), axis_ratio=0.5, angle=30.0, sigma_major=0.4)
    assert g.sigma == pytest.approx(0.2)
    assert g.sigma_major == pytest.approx(0.4)
    phi = np.deg2rad(30.0)
    # one sigma along the major axis (direction φ) and along the minor axis
    major = g.image(0.4 * np.cos(phi), 0.4 * np.sin(phi))
    minor = g.image(-0.2 * np.sin(phi), 0.2 * np.cos(phi))
    assert major == pytest.approx(np.exp(-0.5), rel=1e-12)
    assert minor == pytest.approx(np.exp(-0.5), rel=1e-12)


def test_rotated_profile_equals_rotated_coordinates():
    rng = np.random.default_rng(4)
    x, y = rng.normal(size=(2, 50))
    for profile_cls, kwargs in [(Gaussian, {"sigma": 0.3}), (Sersic, {"sersic_index": 2.5})]:
        base = profile_cls(centre=(0.0, 0.0), ell_comps=ell_comps_from(0.7, 0.0), **kwargs)
        rotated = profile_cls(centre=(0.0, 0.0), ell_comps=ell_comps_from(0.7, 50.0), **kwargs)
        phi = np.deg2rad(50.0)
        xr = x * np.cos(phi) - y * np.sin(phi)
        yr = x * np.sin(phi) + y * np.cos(phi)
        assert np.allclose(rotated.image(xr, yr), base.image(x, y), rtol=1e-12)


@pytest.mark.parametrize("n", [0.8, 1.0, 2.5, 4.0, 6.0])
def test_sersic_total_flux_and_half_light_radius(n):
    s = Sersic(ell_comps=ell_comps_from(0.6, 20.0), effective_radius=0.7, sersic_index=n)

    def circular(xi):  # ellipses of circularised radius ξ enclose area π ξ²
        return 2 * np.pi * xi * np.exp(-sersic_constant(n) * ((xi / 0.7) ** (1 / n) - 1))

    total, _ = integrate.quad(circular, 0, np.inf, limit=400, epsabs=0, epsrel=1e-12)
    half, _ = integrate.quad(circular, 0, 0.7, limit=400, epsabs=0, epsrel=1e-12)
    assert s.total_flux() == pytest.approx(total, rel=1e-8)
    assert half / total == pytest.approx(0.5, abs=5e-5)  # b_n series accuracy


def test_sersic_elliptical_radius_convention():
    q = 0.5
    s = Sersic(ell_comps=ell_comps_from(q, 90.0), effective_radius=1.0, sersic_index=1.0)
    # ξ = sqrt(q x'^2 + y'^2/q) = R_e at x' = R_e/√q on the major axis (here along +y)
    assert s.image(0.0, 1.0 / np.sqrt(q)) == pytest.approx(1.0, rel=1e-12)
    assert s.image(np.sqrt(q), 0.0) == pytest.approx(1.0, rel=1e-12)


def test_mge_sigma_grid_matches_spec_numbers():
    sigmas = MGESet.extended((0, 0), (0, 0), pixel_scale=0.05, mask_radius=1.8).sigmas
    assert sigmas.size == 30
    assert np.round(sigmas[:3], 4).tolist() == [0.0100, 0.0120, 0.0143]
    assert np.round(sigmas[-3:], 3).tolist() == [1.258, 1.505, 1.800]
    assert sigmas[1] / sigmas[0] == pytest.approx(1.196, abs=5e-4)
    point = MGESet.point((0, 0), (0, 0), pixel_scale=0.05).sigmas
    expected = [0.0100, 0.0129, 0.0167, 0.0215, 0.0278, 0.0359, 0.0464, 0.0599, 0.0774, 0.1]
    assert np.round(point, 4).tolist() == expected


def test_mge_columns_equal_binned_gaussians():
    mge = MGESet.extended((0.02, -0.01), ell_comps_from(0.65, 120.0), 0.05, 1.0, n_gaussians=8)
    x, y = pixel_centres((21, 21), 0.05)
    grid = sub_grid(x.ravel(), y.ravel(), 0.05, np.where(np.hypot(x, y).ravel() < 0.2, 16, 4))
    columns = mge.columns(grid)
    dropped = np.exp(-EXPONENT_CUTOFF)  # the kernel drops terms below this (unit peak)
    for k, g in enumerate(mge.gaussians()):
        expected = grid.bin(g.image(grid.x, grid.y))
        assert np.allclose(columns[:, k], expected, rtol=1e-12, atol=dropped)
    intensities = np.linspace(1, 2, 8)
    assert np.allclose(
        columns @ intensities, grid.bin(mge.image(grid.x, grid.y, intensities)), rtol=1e-12
    )


@pytest.mark.parametrize("n", [0.8, 1.0, 4.0])
def test_sersic_column_is_the_binned_unit_intensity_image(n):
    """The linear Sérsic's column ignores ``intensity`` (it is solved) and handles a
    sub-pixel exactly at the centre (ξ = 0, I = I_e e^{b_n})."""
    x, y = pixel_centres((21, 21), 0.05)
    grid = sub_grid(x.ravel(), y.ravel(), 0.05, np.where(np.hypot(x, y).ravel() < 0.2, 15, 4))
    centre = (float(grid.x[0]), float(grid.y[0]))
    sersic = Sersic(centre, ell_comps_from(0.6, 25.0), 0.4, n, intensity=7.0)
    column = sersic.columns(grid)
    assert column.shape == (441, 1)
    unit = Sersic(centre, sersic.ell_comps, 0.4, n, intensity=1.0)
    assert np.allclose(column[:, 0], grid.bin(unit.image(grid.x, grid.y)), rtol=1e-12)
    assert sersic.n_columns == 1
    assert sersic.cache_key == unit.cache_key


@pytest.mark.parametrize(("sub_size", "tolerance"), [(4, 6e-3), (16, 4e-4)])
def test_over_sampling_converges_to_the_pixel_integral(sub_size, tolerance):
    sigma, delta = 0.05, 0.05
    x, y = pixel_centres((11, 11), delta)
    grid = sub_grid(x.ravel(), y.ravel(), delta, sub_size)
    column = MGESet((0.0, 0.0), (0.0, 0.0), np.array([sigma, 2 * sigma])).columns(grid)[:, 0]

    def pixel_integral_1d(c):
        s = np.sqrt(2) * sigma
        return np.sqrt(np.pi / 2) * sigma * (erf((c + delta / 2) / s) - erf((c - delta / 2) / s))

    exact = pixel_integral_1d(x.ravel()) * pixel_integral_1d(y.ravel()) / delta**2
    assert np.max(np.abs(column - exact)) / exact.max() < tolerance
    assert np.max(np.abs(column - exact)) / exact.max() > tolerance / 50  # still discretised


def test_light_grid_blurred_columns_equal_native_convolution():
    x, y = pixel_centres((41, 41), 0.05)
    mask = np.hypot(x, y) > 0.8
    psf = gaussian_psf(7)
    light_grid = LightGrid.from_mask(mask, psf, 0.05, centre=(0.0, 0.0))
    sets = [
        MGESet.extended((0.01, 0.0), ell_comps_from(0.7, 10.0), 0.05, 0.8, n_gaussians=6),
        MGESet.point((0.0, 0.02), (0.0, 0.0), 0.05),
    ]
    matrix = light_grid.blurred_columns(sets)
    assert matrix.shape == (np.count_nonzero(~mask), 16)
    region = ~light_grid.convolver.extended_mask
    centre_pixels = np.hypot(x[region], y[region]) <= 0.3
    assert np.all(light_grid.grid.sub_sizes[centre_pixels] == 16)
    assert np.all(light_grid.grid.sub_sizes[~centre_pixels] == 4)
    unblurred = np.concatenate([s.columns(light_grid.grid) for s in sets], axis=1)
    for k in (0, 5, 9):
        native = np.zeros(mask.shape)
        native[region] = unblurred[:, k]
        expected = signal.convolve2d(native, psf, mode="same")[~mask]
        assert np.allclose(matrix[:, k], expected, atol=1e-14)
    image = light_grid.blurred_image(sets[0].gaussians(np.arange(1.0, 7.0)))
    assert np.allclose(image, matrix[:, :6] @ np.arange(1.0, 7.0), rtol=1e-10)


def test_bad_light_parameters_raise():
    with pytest.raises(ValueError, match="increasing"):
        MGESet((0, 0), (0, 0), np.array([0.2, 0.1]))
    with pytest.raises(ValueError, match="positive"):
        MGESet((0, 0), (0, 0), np.array([-0.1, 0.2]))
    with pytest.raises(ValueError, match="sigma"):
        Gaussian(sigma=0.0)
    with pytest.raises(ValueError, match="sersic_index"):
        Sersic(sersic_index=20.0)
    with pytest.raises(ValueError, match="sigma_min"):
        log_spaced_sigmas(0.5, 0.1, 10)


def test_vectorised_exponential_matches_numpy_over_the_kernels_range():
    """The Gaussian kernel's own exp(−e) (table × Taylor, so the loop vectorises) equals
    numpy's from 0 to the cut-off, including the table's step edges, to a few ulp of the
    argument's own conditioning (a rounding of e changes exp(−e) by e·2⁻⁵² relative)."""
    from mgelens.light import _EXP_STEPS, _EXP_TABLE, EXPONENT_CUTOFF, _exp_negative

    steps = np.arange(int(EXPONENT_CUTOFF * _EXP_STEPS / np.log(2.0))) * np.log(2.0) / _EXP_STEPS
    e = np.concatenate([np.linspace(0.0, EXPONENT_CUTOFF, 200_001), steps, steps[1:] - 1e-13])
    e = e[::50]
    ours = np.array([_exp_negative(v, _EXP_TABLE) for v in e])
    assert np.all(np.abs(ours / np.exp(-e) - 1.0) <= 3e-16 * (1.0 + e))


def test_light_records_round_trip_and_state_the_geometry():
    """``to_dict`` next to each profile and :func:`light_from_dict` read back the same
    profiles; the record's axis ratio and angle are those the ell_comps mean."""
    e1, e2 = ell_comps_from(0.7, 123.0)
    sersic = Sersic((0.1, -0.2), (e1, e2), 0.8, 3.5, 2.5)
    record = json.loads(json.dumps(sersic.to_dict()))
    assert record["kind"] == "sersic"
    assert (record["axis_ratio"], record["angle"]) == pytest.approx((0.7, 123.0))
    assert light_from_dict(record) == [sersic]
    mge = MGESet((0.1, -0.2), (e1, e2), np.array([0.05, 0.2, 0.9]))
    intensities = np.array([3.0, 0.0, 0.25])
    record = json.loads(json.dumps(mge.to_dict(intensities)))
    assert record["kind"] == "mge"
    assert light_from_dict(record) == mge.gaussians(intensities)

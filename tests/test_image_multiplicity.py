"""Image counts by triangle mapping against the singular isothermal sphere's images and an
independent root finder, and the multiply imaged share of a lensed source."""

import numpy as np
import pytest
from scipy import optimize

from mgelens.grid import pixel_centres
from mgelens.image_multiplicity import (
    CORE_RADIUS,
    GRID_SPACING,
    MIN_MULTIPLY_IMAGED_FRACTION,
    image_counts,
    multiplicity_check,
)
from mgelens.mass import EPL, SIE, ExternalShear, ray_trace

SIS = (SIE((0.0, 0.0), 1.0, 1.0, 0.0),)


def test_the_isothermal_sphere_images_a_source_inside_its_einstein_radius_twice():
    """An SIS of θ_E 1″ images β < θ_E at θ_E ± β, one image beyond (SPEC §3.1)."""
    angle = np.deg2rad(np.array([0.0, 37.0, 141.0, 250.0, 300.0, 90.0]))
    radius = np.array([0.1, 0.3, 0.55, 0.8, 1.2, 2.0])
    counts = image_counts(SIS, radius * np.cos(angle), radius * np.sin(angle), 3.0)
    assert counts.tolist() == [2, 2, 2, 2, 1, 1]


def test_a_source_on_a_grid_line_is_counted_once():
    """Points in line with the triangle grid's nodes (pixel centres on an axis, the
    caustic point β = 0 left out) sit on no triangle edge: each image is counted once."""
    x = np.delete(np.arange(-8, 9), 8) * 0.05
    counts = image_counts(SIS, x, np.zeros_like(x), 3.0)
    assert counts.tolist() == [2] * len(x)


def test_an_elliptical_mass_makes_four_images_of_a_source_near_its_centre():
    sie = (SIE((0.05, -0.03), 1.2, 0.7, 30.0), ExternalShear(0.03, -0.02))
    counts = image_counts(sie, np.array([0.06]), np.array([-0.025]), 3.0)
    assert counts.tolist() == [4]
    assert image_counts(sie, np.array([1.6]), np.array([0.0]), 3.0).tolist() == [1]


def _root_images(profiles, source, half_width=3.0) -> list[np.ndarray]:
    """Distinct solutions of β(θ) = ``source`` in the square of ``half_width``, by
    scipy's root finder from the 200 nodes of a 41² grid that trace closest to it."""
    axis = np.linspace(-half_width, half_width, 41)
    starts = np.stack(np.meshgrid(axis, axis), -1).reshape(-1, 2)
    traced = np.stack(ray_trace(profiles, starts[:, 0], starts[:, 1]), -1)
    nearest = starts[np.argsort(np.hypot(*(traced - source).T))[:200]]

    def offset(theta):
        return np.ravel(ray_trace(profiles, theta[:1], theta[1:])) - source

    found = []
    for start in nearest:
        solution = optimize.root(offset, start, tol=1e-12)
        theta = solution.x
        if (
            solution.success
            and np.hypot(*offset(theta)) < 1e-8
            and np.abs(theta).max() < half_width
            and all(np.hypot(*(theta - other)) > 1e-5 for other in found)
        ):
            found.append(theta)
    return found


def test_image_counts_agree_with_a_root_finder_on_power_laws_with_shear():
    """Random elliptical power laws (γ 1.7–2.3) with shear, twelve source points each: the
    triangle count equals the number of the root finder's images outside the core (an
    image within two grid cells of the core's edge may or may not be counted)."""
    rng = np.random.default_rng(1)
    margin = CORE_RADIUS + 2 * np.sqrt(2) * GRID_SPACING
    for _ in range(3):
        centre = tuple(rng.uniform(-0.1, 0.1, 2))
        mass = (
            EPL(centre, rng.uniform(0.8, 1.6), rng.uniform(0.5, 0.95), rng.uniform(0, 180),
                rng.uniform(1.7, 2.3)),
            ExternalShear(*rng.uniform(-0.06, 0.06, 2)),
        )  # fmt: skip
        sources = rng.uniform(-1.2, 1.2, (12, 2))
        counts = image_counts(mass, sources[:, 0], sources[:, 1], 3.0)
        for source, count in zip(sources, counts, strict=True):
            distance = [np.hypot(*(t - centre)) for t in _root_images(mass, source)]
            outside = sum(d > CORE_RADIUS for d in distance)
            clear = sum(d > margin for d in distance)
            assert clear <= count <= outside, (source, count, distance)


def _gaussian_arc(profiles, source, width=0.08, peak=20.0):
    """A Gaussian source of σ ``width`` at ``source`` lensed by ``profiles`` on a 3″
    cutout of 0.05″ pixels (unit noise, no PSF): LENSED, σ, used pixels, x, y."""
    x, y = pixel_centres((121, 121), 0.05)
    bx, by = ray_trace(profiles, x, y)
    lensed = peak * np.exp(-((bx - source[0]) ** 2 + (by - source[1]) ** 2) / (2 * width**2))
    return lensed, np.ones_like(x), np.hypot(x, y) < 3.0, x, y


def test_a_source_inside_the_cut_is_multiply_imaged():
    check = multiplicity_check(SIS, *_gaussian_arc(SIS, (0.3, 0.2)), 3.0)
    assert check.multiply_imaged_fraction == pytest.approx(1.0)
    assert not check.flag
    assert check.n_pixels > 20


def test_a_source_beyond_the_cut_is_flagged_as_singly_imaged():
    check = multiplicity_check(SIS, *_gaussian_arc(SIS, (1.6, -0.4)), 3.0)
    assert check.multiply_imaged_fraction == 0.0
    assert check.flag
    assert "singly imaged" in check.reason


def test_a_source_across_the_cut_is_weighted_by_its_signal():
    """A source centred on the SIS's cut (|β| = θ_E): the inner half is imaged twice, the
    outer once. Its multiply imaged signal share, Σ (LENSED/σ)² over the pixels whose
    traced position lies inside the cut, is what the check returns."""
    lensed, noise, used, x, y = _gaussian_arc(SIS, (1.0, 0.0), width=0.15)
    check = multiplicity_check(SIS, lensed, noise, used, x, y, 3.0)
    bright = used & (lensed > noise)
    bx, by = ray_trace(SIS, x[bright], y[bright])
    weight = lensed[bright] ** 2
    # inside the cut, less the counter-images that fall into the core (at 1 − |β| from the
    # centre) or within two grid cells of its edge, which may or may not be counted
    distance = 1.0 - np.hypot(bx, by)
    low, high = (
        weight[distance > limit].sum() / weight.sum()
        for limit in (CORE_RADIUS + 2 * np.sqrt(2) * GRID_SPACING, CORE_RADIUS)
    )
    assert 0.2 < low <= high < 0.8
    assert low <= check.multiply_imaged_fraction <= high
    assert check.flag == (check.multiply_imaged_fraction < MIN_MULTIPLY_IMAGED_FRACTION)


def test_no_lensed_pixel_above_the_noise_is_not_measured():
    lensed, noise, used, x, y = _gaussian_arc(SIS, (0.3, 0.2), peak=0.5)
    check = multiplicity_check(SIS, lensed, noise, used, x, y, 3.0)
    assert check.multiply_imaged_fraction is None
    assert (check.n_pixels, check.flag) == (0, False)

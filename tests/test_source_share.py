"""The lensed-source share of the light along lens-light isophotes (mgelens.source_share)."""

import numpy as np
import pandas as pd
import pytest

from mgelens.geometry import to_profile_frame
from mgelens.grid import pixel_centres
from mgelens.isophotes import isophote_table
from mgelens.source_share import source_share

PIXEL = 0.05
SHAPE = (161, 161)
CENTRE = (0.1, -0.05)
AXIS_RATIO, ANGLE = 0.6, 30.0
SCALE = 0.7  # arcsec, of the exponential lens light


def elliptical_radius(x, y, centre=CENTRE, axis_ratio=AXIS_RATIO, angle=ANGLE):
    u, v = to_profile_frame(x, y, centre, angle)
    return np.hypot(u, v / axis_ratio)


@pytest.fixture(scope="module")
def lens_light():
    """An exponential lens light with exact elliptical isophotes, and its isophote table."""
    x, y = pixel_centres(SHAPE, PIXEL)
    lens = np.exp(-elliptical_radius(x, y) / SCALE)
    return x, y, lens, isophote_table(lens, PIXEL, centre=CENTRE)


def test_a_uniform_sheet_gives_its_ratio_to_the_light_on_the_isophote(lens_light):
    """With LENSED a constant k, the share around an isophote of semi-major axis a is
    k / I(a) = k e^{a/s} (to O(Δ²) of the annulus's curvature: under 1 %). An annulus
    turned by 90° (a wrong PA convention) sums the light elsewhere and misses by 8 % or
    more on half the isophotes."""
    _, _, lens, table = lens_light
    assert len(table) > 20
    sheet = np.full(SHAPE, 0.02)
    shares = source_share(table, lens, sheet, lens + sheet, PIXEL)
    expected = 0.02 * np.exp(table["sma"].to_numpy() / SCALE)
    np.testing.assert_allclose(shares, expected, rtol=0.01)
    turned = table.assign(pa=table["pa"] + 90.0)
    wrong = source_share(turned, lens, sheet, lens + sheet, PIXEL)
    assert np.median(np.abs(wrong / expected - 1.0)) > 0.08


def test_a_copy_of_the_lens_light_gives_its_scale_and_masked_annuli_are_undefined(lens_light):
    """LENSED = 0.3 × LENS gives 0.3 on every isophote whatever the mask leaves of it; an
    annulus less than half inside the fit (MODEL zero outside a 1.5″ circle) gets NaN."""
    x, y, lens, table = lens_light
    model = np.where(np.hypot(x, y) < 1.5, 1.3 * lens, 0.0)
    shares = source_share(table, lens, 0.3 * lens, model, PIXEL)
    sma = table["sma"].to_numpy()
    # inside: the whole annulus within 1.5″ of the origin; outside: not even its minor axis
    inside = sma + PIXEL + np.hypot(*CENTRE) < 1.5
    outside = AXIS_RATIO * sma - PIXEL - np.hypot(*CENTRE) > 1.5
    assert inside.sum() > 10
    assert outside.sum() > 3
    np.testing.assert_allclose(shares[inside], 0.3, rtol=1e-12)
    assert np.all(np.isnan(shares[outside]))
    defined = np.isfinite(shares)
    np.testing.assert_allclose(shares[defined], 0.3, rtol=1e-12)


def test_a_lensed_ring_peaks_on_its_isophote(lens_light):
    """A thin circular ring of radius 1.2″ about the centre: the share peaks where the
    isophote's annulus crosses it, between a = 1.2″ (major axis) and 1.2″/q (minor)."""
    x, y, lens, table = lens_light
    ring = 0.05 * np.exp(-0.5 * ((np.hypot(x - CENTRE[0], y - CENTRE[1]) - 1.2) / 0.05) ** 2)
    shares = source_share(table, lens, ring, lens + ring, PIXEL)
    peak = table["sma"].to_numpy()[np.nanargmax(shares)]
    assert 1.2 <= peak <= 1.2 / AXIS_RATIO
    assert shares[0] < 1e-3 * np.nanmax(shares)


def test_images_of_different_shapes_are_refused(lens_light):
    _, _, lens, table = lens_light
    with pytest.raises(ValueError, match="one shape"):
        source_share(table, lens, lens[:-1], lens, PIXEL)


def test_an_empty_table_gives_no_shares(lens_light):
    _, _, lens, table = lens_light
    assert source_share(pd.DataFrame(columns=table.columns), lens, lens, lens, PIXEL).size == 0

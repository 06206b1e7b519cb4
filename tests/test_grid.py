import numpy as np
import pytest

from mgelens.grid import (
    adaptive_sub_sizes,
    blurring_mask,
    pixel_centres,
    sub_grid,
    sub_pixel_offsets,
    to_native,
    to_slim,
)


def test_pixel_centres_follow_fits_orientation():
    x, y = pixel_centres((5, 7), 0.1, origin=(1.0, -2.0))
    assert x.shape == (5, 7)
    # (0, 0) + origin is the centre pixel of an odd grid; row index increases with +y
    assert x[2, 3] == pytest.approx(1.0)
    assert y[2, 3] == pytest.approx(-2.0)
    assert y[4, 0] - y[0, 0] == pytest.approx(0.4)
    assert x[0, 6] - x[0, 0] == pytest.approx(0.6)
    assert np.all(np.diff(y[:, 0]) > 0)
    assert np.all(np.diff(x[0]) > 0)


def test_even_grid_has_origin_on_a_pixel_corner():
    x, y = pixel_centres((4, 4), 1.0)
    assert np.allclose(x[0], [-1.5, -0.5, 0.5, 1.5])
    assert np.allclose(y[:, 0], [-1.5, -0.5, 0.5, 1.5])


def test_slim_native_round_trip_is_row_major():
    rng = np.random.default_rng(0)
    image = rng.random((6, 5))
    mask = rng.random((6, 5)) > 0.5
    slim = to_slim(image, mask)
    assert np.array_equal(slim, image.ravel()[~mask.ravel()])
    native = to_native(slim, mask, fill=-1.0)
    assert np.array_equal(native[~mask], image[~mask])
    assert np.all(native[mask] == -1.0)


def test_sub_pixel_offsets_row_major_and_centred():
    dx, dy = sub_pixel_offsets(2, 1.0)
    assert np.allclose(dx, [-0.25, 0.25, -0.25, 0.25])
    assert np.allclose(dy, [-0.25, -0.25, 0.25, 0.25])
    dx, dy = sub_pixel_offsets(4, 0.05)
    assert dx.mean() == pytest.approx(0.0, abs=1e-15)
    assert dx.min() == pytest.approx(-0.05 / 2 + 0.05 / 8)


def test_binning_a_linear_function_gives_the_pixel_centre_value():
    x, y = pixel_centres((9, 9), 0.05)
    sizes = adaptive_sub_sizes(x.ravel(), y.ravel(), (0.0, 0.0), 0.1, 4, 16)
    assert set(np.unique(sizes)) == {4, 16}
    grid = sub_grid(x.ravel(), y.ravel(), 0.05, sizes)
    assert grid.x.size == np.sum(sizes**2)
    values = 3.0 * grid.x - 2.0 * grid.y + 1.0
    binned = grid.bin(values)
    assert np.allclose(binned, 3.0 * x.ravel() - 2.0 * y.ravel() + 1.0, atol=1e-13)
    # two columns at once, and the uniform fast path agrees with reduceat
    stacked = grid.bin(np.stack([values, 2 * values], axis=1))
    assert np.allclose(stacked[:, 1], 2 * binned)
    uniform = sub_grid(x.ravel(), y.ravel(), 0.05, 4)
    assert uniform.uniform_sub_size == 4
    assert np.allclose(uniform.bin(uniform.x), x.ravel(), atol=1e-15)
    assert np.allclose(np.add.reduceat(uniform.x * uniform.weights, uniform.starts), x.ravel())


def test_sub_grid_rejects_zero_size():
    with pytest.raises(ValueError, match=">= 1"):
        sub_grid(np.zeros(2), np.zeros(2), 0.05, 0)


def test_blurring_region_is_chebyshev_reach_of_the_mask():
    rng = np.random.default_rng(3)
    x, y = pixel_centres((25, 25), 1.0)
    mask = np.hypot(x - 1, y + 2) > 6
    mask |= rng.random(mask.shape) > 0.97
    region = ~blurring_mask(mask, (5, 3))
    rows, cols = np.nonzero(~mask)
    expected = np.zeros_like(mask)
    for r in range(25):
        for c in range(25):
            near = np.any((np.abs(rows - r) <= 2) & (np.abs(cols - c) <= 1))
            expected[r, c] = mask[r, c] and near
    assert np.array_equal(region, expected)

"""Tests of mgelens.mask: geometric masks, FITS masks and contaminant noise scaling."""

import math
import re
from pathlib import Path

import numpy as np
import pytest
from astropy.io import fits

from mgelens.imaging import Imaging
from mgelens.mask import (
    MaskError,
    annular,
    circular,
    contaminant_regions_from_noise,
    contaminants,
    from_fits,
    read_contaminant_circles,
    validate_mask,
)


def _brute_force_used(
    shape: tuple[int, int], pixel_scale: float, centre: tuple[float, float], inside
) -> np.ndarray:
    """Used-pixel map from an explicit loop over pixel centres (SPEC §1.1 formula)."""
    n_y, n_x = shape
    used = np.zeros(shape, dtype=bool)
    for row in range(n_y):
        for col in range(n_x):
            x = (col - (n_x - 1) / 2) * pixel_scale
            y = (row - (n_y - 1) / 2) * pixel_scale
            used[row, col] = inside(math.hypot(x - centre[0], y - centre[1]))
    return used


def _imaging(shape: tuple[int, int] = (21, 25)) -> Imaging:
    rng = np.random.default_rng(1)
    return Imaging(
        data=rng.normal(size=shape),
        noise_map=rng.random(shape) + 0.5,
        psf=np.ones((3, 3)) / 9.0,
        pixel_scale=0.1,
        mask=circular(shape, 0.1, 0.8),
    )


# ------------------------------------------------------------------ circular / annular


@pytest.mark.parametrize(
    ("shape", "radius", "expected"),
    [
        ((151, 151), 1.8, 4053),  # SPEC §1.2
        ((151, 151), 1.6, 3209),  # SPEC §1.2
        ((201, 201), 1.8, 4053),  # same count on the SLACS stamp size
        ((201, 201), 3.0, 11289),  # SLACS R; 12 centres on the circle, 8 need the tolerance
    ],
)
def test_circular_pixel_counts(shape: tuple[int, int], radius: float, expected: int) -> None:
    mask = circular(shape, 0.05, radius)
    assert mask.dtype == bool
    assert mask.shape == shape
    assert int((~mask).sum()) == expected


def test_circular_counts_pixels_exactly_on_the_circle() -> None:
    # 3 × 0.1 = 0.30000000000000004 > 0.3: only the tolerance keeps those 4 pixels.
    # Lattice points with i² + j² ≤ 9 (Gauss circle problem): 29.
    assert int((~circular((11, 11), 0.1, 0.3)).sum()) == 29


@pytest.mark.parametrize("shape", [(40, 50), (41, 37)])
def test_circular_matches_brute_force(shape: tuple[int, int]) -> None:
    centre, radius, scale = (0.13, -0.07), 0.9, 0.05
    used = _brute_force_used(shape, scale, centre, lambda r: r <= radius + 1e-9)
    assert np.array_equal(~circular(shape, scale, radius, centre), used)


def test_annular_matches_brute_force_and_analytic_area() -> None:
    shape, scale, inner, outer, centre = (101, 101), 0.05, 0.5, 1.5, (0.02, -0.03)
    mask = annular(shape, scale, inner, outer, centre)
    used = _brute_force_used(shape, scale, centre, lambda r: inner - 1e-9 <= r <= outer + 1e-9)
    assert np.array_equal(~mask, used)
    analytic = math.pi * (outer**2 - inner**2) / scale**2  # 2513.3 pixels
    assert int((~mask).sum()) == pytest.approx(analytic, rel=0.02)


def test_annulus_with_zero_inner_radius_is_the_circle() -> None:
    assert np.array_equal(annular((51, 51), 0.05, 0.0, 1.0), circular((51, 51), 0.05, 1.0))


def test_masks_put_rows_along_y() -> None:
    # A circle centred at y = +0.5″ must be in the upper rows (row index grows with +y).
    mask = circular((41, 41), 0.05, 0.2, centre=(0.0, 0.5))
    rows, cols = np.nonzero(~mask)
    assert rows.mean() == pytest.approx(30.0)
    assert cols.mean() == pytest.approx(20.0)


def test_circular_empty_mask() -> None:
    with pytest.raises(MaskError, match=r"circular mask of radius 0.1″ .*mask is empty"):
        circular((51, 51), 0.05, 0.1, centre=(5.0, 5.0))


@pytest.mark.parametrize("radius", [0.0, -1.0, np.nan])
def test_circular_bad_radius(radius: float) -> None:
    with pytest.raises(MaskError, match=r"radius \(arcsec\) must be finite and > 0"):
        circular((51, 51), 0.05, radius)


@pytest.mark.parametrize("shape", [(51,), (51, 0), (51.5, 51), (2, 3, 4)])
def test_bad_shape(shape: tuple) -> None:
    with pytest.raises(MaskError, match="shape must be two positive integers"):
        circular(shape, 0.05, 1.0)


def test_bad_pixel_scale() -> None:
    with pytest.raises(MaskError, match=r"pixel_scale \(arcsec/pixel\) must be finite and > 0"):
        circular((51, 51), -0.05, 1.0)


@pytest.mark.parametrize(("inner", "outer"), [(1.0, 1.0), (1.5, 1.0), (-0.1, 1.0)])
def test_annular_bad_radii(inner: float, outer: float) -> None:
    with pytest.raises(MaskError, match="0 <= inner_radius < outer_radius"):
        annular((51, 51), 0.05, inner, outer)


def test_annular_empty_mask() -> None:
    # No pixel centre of a 0.05″ grid lies between 0.001″ and 0.002″ from the centre.
    with pytest.raises(MaskError, match=r"annular mask .*mask is empty"):
        annular((51, 51), 0.05, 0.001, 0.002)


# ------------------------------------------------------------------ validate_mask


def test_validate_mask_returns_a_copy() -> None:
    mask = circular((11, 11), 0.1, 0.3)
    checked = validate_mask(mask, (11, 11))
    assert np.array_equal(checked, mask)
    assert not np.shares_memory(checked, mask)


def test_validate_mask_errors() -> None:
    with pytest.raises(MaskError, match="mask is empty"):
        validate_mask(np.ones((5, 5), dtype=bool), (5, 5))
    with pytest.raises(
        MaskError, match=r"mask has shape \(5, 5\) but the image has shape \(5, 6\)"
    ):
        validate_mask(np.zeros((5, 5), dtype=bool), (5, 6))
    with pytest.raises(MaskError, match="mask must be a boolean array"):
        validate_mask(np.zeros((5, 5)), (5, 5))


# ------------------------------------------------------------------ FITS masks


def test_from_fits_nonzero_is_excluded(tmp_path: Path) -> None:
    values = np.zeros((6, 7), dtype=np.int16)
    values[0, :] = 1
    values[5, 3] = -2
    fits.PrimaryHDU(values).writeto(tmp_path / "mask.fits")
    mask = from_fits(tmp_path / "mask.fits", shape=(6, 7))
    assert np.array_equal(mask, values != 0)
    assert np.array_equal(from_fits(tmp_path / "mask.fits", invert=True), values == 0)


def test_from_fits_errors_name_the_file(tmp_path: Path) -> None:
    path = tmp_path / "mask.fits"
    named = re.escape(str(path))
    with pytest.raises(MaskError, match=named + ": FITS file not found"):
        from_fits(path)

    fits.PrimaryHDU(np.zeros((6, 7), dtype=np.uint8)).writeto(path)
    with pytest.raises(MaskError, match=named + r": mask has shape \(6, 7\) but the image"):
        from_fits(path, shape=(7, 6))
    with pytest.raises(MaskError, match=named + ": mask is empty"):
        from_fits(path, invert=True)

    path.write_bytes(b"\x00garbage" * 500)
    with pytest.raises(MaskError, match=named + ": not a readable FITS file"):
        from_fits(path)

    path.unlink()
    values = np.zeros((6, 7))
    values[2, 2] = np.nan
    fits.PrimaryHDU(values).writeto(path)
    with pytest.raises(MaskError, match=named + ": mask file holds 1 NaN/inf values"):
        from_fits(path)


# ------------------------------------------------------------------ contaminants


def test_contaminant_regions_from_noise() -> None:
    noise = np.full((4, 5), 0.02)
    noise[1, 2] = 1e8
    noise[3, 0] = 1e8
    noise[0, 0] = 999.0
    region = contaminant_regions_from_noise(noise)
    assert region.dtype == bool
    assert np.argwhere(region).tolist() == [[1, 2], [3, 0]]
    with pytest.raises(MaskError, match="noise_map must be 2D"):
        contaminant_regions_from_noise(noise.ravel())


def test_contaminants_scale_noise_inside_union_only() -> None:
    imaging = _imaging()
    box = np.zeros(imaging.shape, dtype=bool)
    box[0:3, 0:4] = True
    circle = (0.5, -0.3, 0.25)  # arcsec
    in_circle = _brute_force_used(
        imaging.shape, imaging.pixel_scale, circle[:2], lambda r: r <= circle[2] + 1e-9
    )
    union = box | in_circle
    assert int(in_circle.sum()) == 21  # lattice points with i² + j² ≤ 6.25
    noise_before = imaging.noise_map.copy()

    result = contaminants(imaging, [box, circle], factor=1e8)

    assert np.array_equal(result.noise_map[union], noise_before[union] * 1e8)
    assert np.array_equal(result.noise_map[~union], noise_before[~union])
    assert np.array_equal(result.mask, imaging.mask)
    assert np.array_equal(result.data, imaging.data)
    assert np.array_equal(imaging.noise_map, noise_before)  # input Imaging unchanged
    single = contaminants(imaging, box, factor=10.0)
    assert np.array_equal(single.noise_map[box], noise_before[box] * 10.0)


def test_contaminants_bad_regions() -> None:
    imaging = _imaging()
    with pytest.raises(MaskError, match=r"contaminant region must be a bool array of shape"):
        contaminants(imaging, [np.zeros((3, 3), dtype=bool)])
    with pytest.raises(MaskError, match=r"must be a bool array .* or a circle \(x, y, radius\)"):
        contaminants(imaging, [(1.0, 2.0)])
    with pytest.raises(MaskError, match="covers no pixel"):
        contaminants(imaging, [(50.0, 50.0, 1.0)])
    with pytest.raises(MaskError, match="factor must be finite and > 0"):
        contaminants(imaging, [(0.0, 0.0, 0.3)], factor=-1.0)


def test_contaminant_circles_are_read_with_comments_and_blank_lines(tmp_path: Path) -> None:
    path = tmp_path / "neighbours.txt"
    path.write_text("# x y radius\n\n1.15 2.70 0.35  # the edge object\n-2 0.5e0 1\n")
    assert read_contaminant_circles(path) == ((1.15, 2.7, 0.35), (-2.0, 0.5, 1.0))


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("1.0 2.0\n", r"line 1: '1.0 2.0' is not `x y radius`"),
        ("# a\n1 2 3 4\n", r"line 2: '1 2 3 4' is not `x y radius`"),
        ("1 two 0.3\n", r"line 1: '1 two 0.3' is not `x y radius`"),
        ("1 2 0\n", r"line 1: '1 2 0' needs finite numbers and a radius > 0"),
        ("nan 2 0.3\n", r"line 1: 'nan 2 0.3' needs finite numbers"),
        ("# only a comment\n", r"no contaminant circle; add `x y radius` lines"),
    ],
)
def test_bad_contaminant_files_name_the_file_and_line(tmp_path: Path, text, message) -> None:
    path = tmp_path / "neighbours.txt"
    path.write_text(text)
    with pytest.raises(MaskError, match=re.escape(str(path)) + ".*" + message):
        read_contaminant_circles(path)


def test_a_missing_contaminant_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(MaskError, match=re.escape("absent.txt: cannot read the contaminant")):
        read_contaminant_circles(tmp_path / "absent.txt")

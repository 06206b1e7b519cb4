"""Tests of mgelens.imaging: validation, FITS reading/writing and the real SLACS cutouts."""

import dataclasses
import json
import logging
import re
from pathlib import Path

import numpy as np
import pytest
from astropy.io import fits

from mgelens.imaging import Imaging
from mgelens.imaging_input import ImagingError, read_psf
from mgelens.mask import circular, contaminant_regions_from_noise

SHAPE = (12, 15)
PSF_SHAPE = (5, 7)


def _arrays(seed: int = 0) -> dict[str, np.ndarray]:
    """Valid data, noise map and unit-sum PSF (as positional Imaging arguments)."""
    rng = np.random.default_rng(seed)
    psf = rng.random(PSF_SHAPE) + 0.1
    return {
        "data": rng.normal(size=SHAPE),
        "noise_map": rng.random(SHAPE) + 0.5,
        "psf": psf / psf.sum(),
    }


def _imaging(**changes: object) -> Imaging:
    kwargs = {**_arrays(), "pixel_scale": 0.05, **changes}
    return Imaging(**kwargs)


def _write(path: Path, image: np.ndarray | None, header: fits.Header | None = None) -> Path:
    fits.PrimaryHDU(data=image, header=header).writeto(path)
    return path


def _write_folder(folder: Path, arrays: dict[str, np.ndarray]) -> Path:
    """Write keyword-less data/noise/psf files, like the SLACS cutouts."""
    folder.mkdir(parents=True, exist_ok=True)
    for key, array in arrays.items():
        _write(folder / f"{key}.fits", array)
    return folder


def _paths(folder: Path) -> tuple[Path, Path, Path]:
    return folder / "data.fits", folder / "noise_map.fits", folder / "psf.fits"


def _match_path(path: Path) -> str:
    return re.escape(str(path))


# ------------------------------------------------------------------ FITS round trip


def test_round_trip_keeps_everything_exactly(tmp_path: Path) -> None:
    folder = tmp_path / "lens_a"
    pixel_scale = 1.0 / 300.0  # 17 significant digits: longer than a default FITS float
    mask = circular(SHAPE, pixel_scale, 5 * pixel_scale, centre=(0.002, -0.001))
    original = _imaging(pixel_scale=pixel_scale, mask=mask, name="lens_a", unit="electrons/s")

    original.to_fits(folder)
    back = Imaging.from_folder(folder)

    for field in ("data", "noise_map", "psf", "mask"):
        assert np.array_equal(getattr(back, field), getattr(original, field)), field
    assert back.pixel_scale == pixel_scale
    assert (back.name, back.unit) == ("lens_a", "electrons/s")
    assert sorted(p.name for p in folder.iterdir()) == [
        "data.fits",
        "mask.fits",
        "noise_map.fits",
        "psf.fits",
    ]  # no temporary file left behind
    for name in ("data", "noise_map", "psf", "mask"):
        assert fits.getheader(folder / f"{name}.fits")["PIXSCALE"] == pixel_scale
    assert fits.getdata(folder / "mask.fits").dtype == np.uint8
    assert fits.getheader(folder / "data.fits")["BUNIT"] == "electrons/s"


def test_to_fits_without_mask_removes_a_stale_mask_file(tmp_path: Path) -> None:
    masked = _imaging(mask=circular(SHAPE, 0.05, 0.2))
    masked.to_fits(tmp_path)
    masked.with_mask(None).to_fits(tmp_path)
    assert not (tmp_path / "mask.fits").exists()
    assert Imaging.from_folder(tmp_path).mask is None


def test_image_in_hdu_1_with_empty_primary(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    arrays = _arrays()
    header = fits.Header({"PIXSCALE": 0.04, "BUNIT": "ELECTRONS/S"})
    paths = []
    for key, array in arrays.items():
        hdul = fits.HDUList([fits.PrimaryHDU(), fits.ImageHDU(array, header=header, name="SCI")])
        hdul.writeto(tmp_path / f"{key}.fits")
        paths.append(tmp_path / f"{key}.fits")

    with caplog.at_level(logging.INFO, logger="mgelens.imaging"):
        imaging = Imaging.from_fits(*paths)

    assert np.array_equal(imaging.data, arrays["data"])
    assert np.array_equal(imaging.psf, arrays["psf"])
    assert imaging.pixel_scale == 0.04
    assert imaging.unit == "ELECTRONS/S"
    assert "reading HDU 1" in caplog.text


def test_big_endian_float32_becomes_native_float64_and_input_is_untouched() -> None:
    arrays = {key: value.astype(">f4") for key, value in _arrays().items()}
    before = {key: value.copy() for key, value in arrays.items()}

    imaging = Imaging(**arrays, pixel_scale=0.05)

    for key, value in arrays.items():
        stored = getattr(imaging, key)
        assert stored.dtype == np.float64
        assert stored.dtype.isnative
        assert value.dtype == np.dtype(">f4")
        assert np.array_equal(value, before[key])
        assert not np.shares_memory(stored, value)
    assert np.array_equal(imaging.data, before["data"].astype(np.float64))


def test_imaging_is_immutable() -> None:
    imaging = _imaging()
    with pytest.raises(dataclasses.FrozenInstanceError):
        imaging.pixel_scale = 0.1  # type: ignore[misc]
    with pytest.raises(ValueError, match="read-only"):
        imaging.data[0, 0] = 1.0


def test_pixel_scale_from_celestial_wcs(tmp_path: Path) -> None:
    header = fits.Header(
        {
            "CTYPE1": "RA---TAN",
            "CTYPE2": "DEC--TAN",
            "CDELT1": -0.05 / 3600.0,
            "CDELT2": 0.05 / 3600.0,
            "CRVAL1": 150.0,
            "CRVAL2": 2.0,
            "CRPIX1": 8.0,
            "CRPIX2": 6.0,
        }
    )
    arrays = _arrays()
    _write(tmp_path / "data.fits", arrays["data"], header)
    _write(tmp_path / "noise_map.fits", arrays["noise_map"])
    _write(tmp_path / "psf.fits", arrays["psf"])

    imaging = Imaging.from_fits(*_paths(tmp_path))

    assert imaging.pixel_scale == pytest.approx(0.05, rel=1e-12)


def test_explicit_pixel_scale_wins_over_header_with_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    _imaging(pixel_scale=0.05).to_fits(tmp_path)
    with caplog.at_level(logging.WARNING, logger="mgelens.imaging"):
        imaging = Imaging.from_folder(tmp_path, pixel_scale=0.06)
    assert imaging.pixel_scale == 0.06
    assert [r.levelno for r in caplog.records] == [logging.WARNING]
    assert "differs from pixel_scale=0.06" in caplog.text


def test_pixel_scale_from_info_json(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    folder = _write_folder(tmp_path / "slacs9999+0000", _arrays())
    (folder / "info.json").write_text(json.dumps({"pixel_scale_arcsec": 0.05}))
    with caplog.at_level(logging.INFO, logger="mgelens.imaging"):
        imaging = Imaging.from_folder(folder)
    assert imaging.pixel_scale == 0.05
    assert imaging.name == "slacs9999+0000"
    assert "taken from info.json" in caplog.text


def test_unit_from_info_json_when_header_has_no_bunit(tmp_path: Path) -> None:
    folder = _write_folder(tmp_path / "slacs9999+0000", _arrays())
    units = "electrons/s (HST ACS/WFC F814W drizzled; units inferred upstream)"
    (folder / "info.json").write_text(json.dumps({"pixel_scale_arcsec": 0.05, "units": units}))
    assert Imaging.from_folder(folder).unit == "electrons/s"
    (folder / "info.json").write_text(json.dumps({"pixel_scale_arcsec": 0.05}))
    assert Imaging.from_folder(folder).unit == ""


def test_header_bunit_wins_over_info_json_units(tmp_path: Path) -> None:
    imaging = _imaging(pixel_scale=0.05)
    Imaging(imaging.data, imaging.noise_map, imaging.psf, 0.05, unit="counts").to_fits(tmp_path)
    (tmp_path / "info.json").write_text(json.dumps({"units": "electrons/s"}))
    assert Imaging.from_folder(tmp_path).unit == "counts"


def test_unreadable_info_json_is_ignored_when_the_pixel_scale_is_given(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    folder = _write_folder(tmp_path / "lens", _arrays())
    (folder / "info.json").write_text("{not json")
    with caplog.at_level(logging.WARNING, logger="mgelens.imaging"):
        imaging = Imaging.from_folder(folder, pixel_scale=0.05)
    assert (imaging.pixel_scale, imaging.unit) == (0.05, "")
    assert "cannot read JSON" in caplog.text
    with pytest.raises(ImagingError, match=r"info\.json: cannot read JSON"):
        Imaging.from_folder(folder)


def test_signal_to_noise_map() -> None:
    arrays = _arrays()
    arrays["noise_map"][0, 0] = 0.0
    mask = np.zeros(SHAPE, dtype=bool)
    mask[0, 0] = True
    imaging = Imaging(**arrays, pixel_scale=0.05, mask=mask)
    expected = arrays["data"] / np.where(mask, 1.0, arrays["noise_map"])
    expected[0, 0] = 0.0
    assert np.array_equal(imaging.signal_to_noise_map, expected)
    assert imaging.shape == SHAPE


# ------------------------------------------------------------------ bad files


def test_missing_file_is_named(tmp_path: Path) -> None:
    data, noise, psf = _paths(_write_folder(tmp_path, _arrays()))
    noise.unlink()
    with pytest.raises(ImagingError, match=_match_path(noise) + ": FITS file not found"):
        Imaging.from_fits(data, noise, psf, pixel_scale=0.05)


def test_missing_folder_is_named(tmp_path: Path) -> None:
    folder = tmp_path / "nowhere"
    with pytest.raises(ImagingError, match=_match_path(folder) + ": imaging folder not found"):
        Imaging.from_folder(folder, pixel_scale=0.05)


def test_corrupt_file_is_named(tmp_path: Path) -> None:
    data, noise, psf = _paths(_write_folder(tmp_path, _arrays()))
    psf.write_bytes(b"this is not a FITS file \x00\xff" * 200)
    with pytest.raises(ImagingError, match=_match_path(psf) + ": not a readable FITS file"):
        Imaging.from_fits(data, noise, psf, pixel_scale=0.05)


def test_truncated_file_is_named(tmp_path: Path) -> None:
    data, noise, psf = _paths(_write_folder(tmp_path, _arrays()))
    data.write_bytes(data.read_bytes()[:3000])
    with pytest.raises(ImagingError, match=_match_path(data) + ": not a readable FITS file"):
        Imaging.from_fits(data, noise, psf, pixel_scale=0.05)


def test_file_without_2d_image_is_named(tmp_path: Path) -> None:
    data, noise, psf = _paths(_write_folder(tmp_path, _arrays()))
    data.unlink()
    _write(data, np.ones((2, *SHAPE)))
    with pytest.raises(ImagingError, match=_match_path(data) + ": no 2D image in any HDU"):
        Imaging.from_fits(data, noise, psf, pixel_scale=0.05)


def test_hdu_out_of_range_is_named(tmp_path: Path) -> None:
    data, noise, psf = _paths(_write_folder(tmp_path, _arrays()))
    with pytest.raises(ImagingError, match=_match_path(data) + r": has 1 HDU\(s\), so hdu=3"):
        Imaging.from_fits(data, noise, psf, pixel_scale=0.05, hdu=3)


def test_missing_pixel_scale_names_file_and_fix(tmp_path: Path) -> None:
    data, noise, psf = _paths(_write_folder(tmp_path, _arrays()))
    with pytest.raises(ImagingError, match=_match_path(data) + ": no pixel scale.*pixel_scale="):
        Imaging.from_fits(data, noise, psf)


def test_invalid_content_names_the_file(tmp_path: Path) -> None:
    arrays = _arrays()
    arrays["noise_map"][3, 4] = -1.0
    data, noise, psf = _paths(_write_folder(tmp_path, arrays))
    with pytest.raises(ImagingError, match=_match_path(noise) + ": noise_map has 1 values <= 0"):
        Imaging.from_fits(data, noise, psf, pixel_scale=0.05)


def test_empty_mask_file_is_named(tmp_path: Path) -> None:
    folder = _write_folder(tmp_path, _arrays())
    _write(folder / "mask.fits", np.ones(SHAPE, dtype=np.uint8))
    with pytest.raises(ImagingError, match=_match_path(folder / "mask.fits") + ": mask is empty"):
        Imaging.from_folder(folder, pixel_scale=0.05)


# ------------------------------------------------------------------ bad arrays


@pytest.mark.parametrize("field", ["data", "noise_map", "psf"])
@pytest.mark.parametrize("shape", [(15,), (1, 5, 5)])
def test_non_2d_array(field: str, shape: tuple[int, ...]) -> None:
    with pytest.raises(ImagingError, match=f"{field} must be a 2D image"):
        _imaging(**{field: np.ones(shape)})


def test_non_numeric_array() -> None:
    with pytest.raises(ImagingError, match="data must be a real numeric array"):
        _imaging(data=np.full(SHAPE, "a"))


def test_mismatched_data_and_noise_shapes() -> None:
    with pytest.raises(ImagingError, match=r"noise_map has shape \(12, 14\) but data has shape"):
        _imaging(noise_map=np.ones((12, 14)))


def test_mismatched_mask_shape() -> None:
    with pytest.raises(ImagingError, match=r"mask has shape \(12, 14\) but the image has shape"):
        _imaging(mask=np.zeros((12, 14), dtype=bool))


def test_non_boolean_mask() -> None:
    with pytest.raises(ImagingError, match="mask must be a boolean array"):
        _imaging(mask=np.zeros(SHAPE, dtype=np.uint8))


def test_empty_mask() -> None:
    with pytest.raises(ImagingError, match="mask is empty"):
        _imaging(mask=np.ones(SHAPE, dtype=bool))


@pytest.mark.parametrize("field", ["data", "noise_map"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("masked", [False, True], ids=["no_mask", "with_mask"])
def test_non_finite_inside_mask(field: str, bad: float, masked: bool) -> None:
    arrays = _arrays()
    arrays[field][5, 6] = bad
    mask = circular(SHAPE, 0.05, 0.2) if masked else None  # (5, 6) is 0.056″ from centre
    with pytest.raises(
        ImagingError, match=rf"{field} has 1 NaN/inf values at unmasked pixels \(first at row 5"
    ):
        Imaging(**arrays, pixel_scale=0.05, mask=mask)


def test_bad_values_outside_mask_are_accepted() -> None:
    arrays = _arrays()
    mask = circular(SHAPE, 0.05, 0.2)
    arrays["data"][0, 0] = np.nan
    arrays["noise_map"][0, 1] = np.inf
    arrays["noise_map"][0, 2] = 0.0
    arrays["noise_map"][0, 3] = -1.0
    imaging = Imaging(**arrays, pixel_scale=0.05, mask=mask)
    assert np.isnan(imaging.data[0, 0])
    assert np.array_equal(imaging.noise_map, arrays["noise_map"])


@pytest.mark.parametrize("value", [0.0, -0.1])
def test_noise_not_positive_inside_mask(value: float) -> None:
    arrays = _arrays()
    arrays["noise_map"][6, 7] = value
    with pytest.raises(ImagingError, match=r"noise_map has 1 values <= 0 at unmasked pixels"):
        Imaging(**arrays, pixel_scale=0.05, mask=circular(SHAPE, 0.05, 0.2))


@pytest.mark.parametrize("shape", [(4, 5), (5, 4), (4, 4)])
def test_even_sized_psf(shape: tuple[int, int]) -> None:
    with pytest.raises(ImagingError, match="psf must have an odd size in both axes"):
        _imaging(psf=np.ones(shape))


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_psf(bad: float) -> None:
    psf = _arrays()["psf"]
    psf[2, 3] = bad
    with pytest.raises(ImagingError, match="psf has 1 NaN/inf values"):
        _imaging(psf=psf)


@pytest.mark.parametrize("scale", [0.0, -1.0])
def test_psf_sum_not_positive(scale: float) -> None:
    with pytest.raises(ImagingError, match=r"psf sums to (0|-1) <= 0"):
        _imaging(psf=scale * _arrays()["psf"])


def test_psf_not_summing_to_one_is_normalised_and_logged(
    caplog: pytest.LogCaptureFixture,
) -> None:
    psf = 3.0 * _arrays()["psf"]
    with caplog.at_level(logging.INFO, logger="mgelens.imaging"):
        imaging = _imaging(psf=psf, name="lens_b")
    assert imaging.psf.sum() == pytest.approx(1.0, abs=1e-14)
    assert np.allclose(imaging.psf, psf / 3.0, rtol=1e-14, atol=0.0)
    assert np.array_equal(psf, 3.0 * _arrays()["psf"])  # input untouched
    assert "PSF of lens_b sums to 3, not 1: normalised" in caplog.text


def test_psf_within_tolerance_is_kept_as_is(caplog: pytest.LogCaptureFixture) -> None:
    psf = (1.0 + 5e-7) * _arrays()["psf"]
    with caplog.at_level(logging.INFO, logger="mgelens.imaging"):
        imaging = _imaging(psf=psf)
    assert np.array_equal(imaging.psf, psf)
    assert caplog.records == []


@pytest.mark.parametrize("value", [0.0, -0.05, np.nan, np.inf, "fifty"])
def test_bad_pixel_scale(value: object) -> None:
    with pytest.raises(ImagingError, match="pixel_scale"):
        _imaging(pixel_scale=value)


# ------------------------------------------------------------------ noise scaling


def test_with_noise_scaled() -> None:
    imaging = _imaging()
    region = np.zeros(SHAPE, dtype=bool)
    region[2:4, 5:9] = True
    scaled = imaging.with_noise_scaled(region, 1e8)
    assert np.array_equal(scaled.noise_map[region], imaging.noise_map[region] * 1e8)
    assert np.array_equal(scaled.noise_map[~region], imaging.noise_map[~region])
    assert np.array_equal(scaled.data, imaging.data)


def test_with_noise_scaled_bad_input() -> None:
    imaging = _imaging()
    with pytest.raises(ImagingError, match="noise-scaling region must be a bool array"):
        imaging.with_noise_scaled(np.zeros((3, 3), dtype=bool), 10.0)
    with pytest.raises(ImagingError, match="noise scaling factor must be finite and > 0"):
        imaging.with_noise_scaled(np.zeros(SHAPE, dtype=bool), 0.0)


# ------------------------------------------------------------------ real SLACS cutouts


def test_every_slacs_lens_loads(slacs_dir: Path, caplog: pytest.LogCaptureFixture) -> None:
    folders = sorted(p for p in slacs_dir.iterdir() if (p / "data.fits").is_file())
    assert len(folders) == 61
    for folder in folders:
        caplog.clear()
        with caplog.at_level(logging.INFO, logger="mgelens.imaging"):
            imaging = Imaging.from_folder(folder)
        assert "normalised" not in caplog.text, folder.name  # raw PSF sum within 1e-6 of 1
        assert imaging.name == folder.name
        assert imaging.shape == (201, 201), folder.name
        assert imaging.pixel_scale == 0.05, folder.name
        assert imaging.data.dtype == np.float64
        assert imaging.data.dtype.isnative
        assert imaging.psf.shape == (15, 15), folder.name
        assert abs(imaging.psf.sum() - 1.0) <= 1e-6, folder.name
        assert np.unravel_index(np.argmax(imaging.psf), imaging.psf.shape) == (7, 7)
        assert np.all(imaging.noise_map > 0), folder.name
        assert imaging.unit == "electrons/s", folder.name


def test_slacs0252_contaminant_sentinels(slacs_dir: Path) -> None:
    imaging = Imaging.from_folder(slacs_dir / "slacs0252+0039")
    region = contaminant_regions_from_noise(imaging.noise_map)
    assert region.sum() == 2245  # the count quoted in its info.json notes
    assert np.all(imaging.noise_map[region] == 1e8)


def test_read_psf_validates_and_normalises_like_imaging(tmp_path):
    psf = np.outer([1.0, 2.0, 1.0], [1.0, 3.0, 1.0])
    fits.writeto(tmp_path / "psf.fits", psf)
    np.testing.assert_allclose(read_psf(tmp_path / "psf.fits"), psf / psf.sum(), rtol=1e-15)
    fits.writeto(tmp_path / "even.fits", np.ones((4, 4)))
    with pytest.raises(ImagingError, match=r"even\.fits: .*odd size"):
        read_psf(tmp_path / "even.fits")

"""Inputs a phase cannot fit are refused before sampling, with one line naming the file or
key and no result.json (docs/reliability.md). Tiny images: no case samples."""

import numpy as np
import pytest
from astropy.io import fits

from mgelens.cli import main
from mgelens.grid import pixel_centres
from mgelens.imaging import Imaging
from mgelens.imaging_input import ImagingError
from mgelens.pipeline import problem
from mgelens.pipeline.settings import LensSpec, settings_from_mapping
from mgelens.sheet import SheetError, read_sample_sheet

PIXEL = 0.1
SIZE = 41  # 4.1″ across: the largest circle about the centre has radius 2.05″
RADIUS = 1.5


def lens_arrays(seed: int = 0) -> dict[str, np.ndarray]:
    """A Gaussian galaxy (peak S/N 50) in unit noise, and a 5×5 Gaussian PSF."""
    x, y = pixel_centres((SIZE, SIZE), PIXEL)
    rng = np.random.default_rng(seed)
    data = 50.0 * np.exp(-0.5 * (x**2 + y**2) / 0.3**2) + rng.standard_normal(x.shape)
    k = np.arange(-2, 3)
    psf = np.exp(-0.5 * (k[:, None] ** 2 + k[None, :] ** 2))
    return {"data": data, "noise_map": np.ones_like(data), "psf": psf / psf.sum()}


def lens_folder(path, **changes):
    """A lens folder (data.fits, noise_map.fits, psf.fits) with ``changes`` to the arrays."""
    arrays = {**lens_arrays(), **changes}
    path.mkdir(parents=True, exist_ok=True)
    for name, array in arrays.items():
        fits.PrimaryHDU(array, fits.Header({"PIXSCALE": PIXEL})).writeto(path / f"{name}.fits")
    return path


def phase_sp(lens, results, *options):
    return main(["phase", "sp", "--lens-dir", str(lens), "--results", str(results), *options])


def assert_refused(code, caplog, results, *fragments):
    """Exit 1, one ERROR line holding every fragment, no result.json."""
    assert code == 1
    errors = [r.getMessage() for r in caplog.records if r.levelname == "ERROR"]
    assert len(errors) == 1
    assert "\n" not in errors[0]
    for fragment in fragments:
        assert fragment in errors[0]
    assert not list(results.glob("**/result.json"))


@pytest.fixture
def lens(tmp_path):
    return lens_folder(tmp_path)


@pytest.mark.parametrize(
    ("changes", "options", "message"),
    [
        ({"data": np.zeros((SIZE, SIZE))}, (), "data.fits: no signal inside the 1.5″ mask"),
        ({}, ("--mask-radius", "0.08"), "usable pixels, fewer than the 170 needed for 17"),
        ({}, ("--mask-radius", "100"), "data.fits: the 100″ mask centred at (0.0, 0.0)″ reaches"),
        ({"psf": np.pad([[-0.5]], 2) + lens_arrays()["psf"]}, (), "psf.fits: psf has negative"),
    ],
    ids=["zero_data", "tiny_mask", "mask_beyond_image", "negative_psf"],
)
def test_unfittable_inputs_are_refused_before_sampling(tmp_path, caplog, changes, options, message):
    lens = lens_folder(tmp_path / "lens", **changes)
    results = tmp_path / "results"
    code = phase_sp(lens, results, "--mask-radius", str(RADIUS), *options)
    assert_refused(code, caplog, results, str(lens), message)


def test_the_mask_circle_may_fill_the_image_but_not_pass_it(lens):
    settings = settings_from_mapping({})
    filling = LensSpec(mask_radius=SIZE * PIXEL / 2)
    dataset, _ = problem.load_dataset(lens, settings, filling, (0.0, 0.0))
    assert (~dataset.mask).sum() > 1000
    moved = LensSpec(mask_radius=1.0, mask_centre=(1.2, 0.0))
    with pytest.raises(ImagingError, match=r"at most 0\.85″"):
        problem.load_dataset(lens, settings, moved, (0.0, 0.0))


def test_nan_outside_the_fit_circle_is_accepted_and_inside_it_named(tmp_path):
    data = lens_arrays()["data"]
    data[0, 0] = np.nan  # the corner, 2.8″ from the centre
    outside = lens_folder(tmp_path / "outside", data=data)
    lens_spec = LensSpec(mask_radius=RADIUS)
    dataset, _ = problem.load_dataset(outside, settings_from_mapping({}), lens_spec, (0, 0))
    assert np.isfinite(dataset.data).all()
    data[20, 21] = np.inf
    inside = lens_folder(tmp_path / "inside", data=data)
    with pytest.raises(ImagingError) as error:
        problem.load_dataset(inside, settings_from_mapping({}), lens_spec, (0, 0))
    assert str(error.value).startswith(f"{inside / 'data.fits'}: data has 1 NaN/inf values at")
    assert "unmasked pixels (first at row 20, col 21), which the fit uses" in str(error.value)


def test_a_psf_with_a_shallow_negative_dip_is_accepted():
    arrays = lens_arrays()
    psf = arrays["psf"].copy()
    psf[0, 0] = -0.04 * psf.max()
    assert Imaging(arrays["data"], arrays["noise_map"], psf, PIXEL).psf.sum() == pytest.approx(1)


@pytest.mark.parametrize(
    ("slam", "message"),
    [
        (
            '{"fit": {"sub_size": "2"}}',
            "--slam: slam.fit.sub_size must be an integer >= 1, got '2'",
        ),
        (
            '{"mask_centre": [1]}',
            "--slam: slam.mask_centre is set per lens, not in slam: settings: give it with "
            "--mask-centre",
        ),
        ('{"samplers": {"sp": {"n_live": "many"}}}', "slam.samplers.sp.n_live must be"),
    ],
)
def test_phase_slam_values_are_checked_like_the_config(lens, tmp_path, caplog, slam, message):
    results = tmp_path / "results"
    code = phase_sp(lens, results, "--mask-radius", str(RADIUS), "--slam", slam)
    assert_refused(code, caplog, results, message)


def test_phase_results_under_a_file_are_named(lens, tmp_path, caplog):
    afile = tmp_path / "afile"
    afile.write_text("")
    code = phase_sp(lens, afile / "sub", "--mask-radius", str(RADIUS))
    message = f"phase sp: cannot write {afile / 'sub' / 'sp' / 'result.json'}: "
    assert_refused(code, caplog, tmp_path, message, "Not a directory")


def test_isophotes_output_under_a_file_is_named(lens, tmp_path, caplog):
    afile = tmp_path / "afile"
    afile.write_text("")
    out = afile / "x.csv"
    code = main(["isophotes", str(lens / "data.fits"), "--out", str(out)])
    assert_refused(code, caplog, tmp_path, f"cannot write {out}: {afile}: File exists")


@pytest.mark.parametrize("scale", ["-1", "0", "nan"])
def test_isophotes_refuse_a_non_positive_pixel_scale(lens, tmp_path, caplog, scale):
    out = tmp_path / "x.csv"
    code = main(["isophotes", str(lens / "data.fits"), "--pixel-scale", scale, "--out", str(out)])
    assert_refused(code, caplog, tmp_path, "--pixel-scale (arcsec/pixel) must be finite and > 0")
    assert not out.exists()


# -- sample sheets (mgelens.sheet; the workflow's snakemake -n cases: tests/test_workflow.py)
HEADER = "lens\tkind\tmock\tinput\tmask_radius\tmge_sets\tpoint_set\tz_lens\tz_source\n"
M1_ROW = "M1\tmock\tM1\t\t1.8\t4\tyes\t0.28\t0.98\n"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "is empty: it needs a tab-separated header line"),
        ("# only a comment\n\n", "is empty: it needs a tab-separated header line"),
        (HEADER, "lists no lens: add one tab-separated row per lens"),
        (HEADER + M1_ROW + "M2\tmock\tM2\t\t1.6\t4\tyes\t0.35\t1.1\t7\n", ", line 3: 10 cells but"),
        (HEADER + M1_ROW + M1_ROW, "lens ids must be unique, repeated: ['M1']"),
    ],
    ids=["zero_bytes", "comments_only", "header_only", "extra_cell", "repeated_id"],
)
def test_bad_sample_sheets_are_named(tmp_path, text, message):
    path = tmp_path / "sheet.tsv"
    path.write_text(text)
    with pytest.raises(SheetError) as error:
        read_sample_sheet(path)
    assert str(path) in str(error.value)
    assert message in str(error.value)


def test_sample_sheet_ids_are_read_as_written(tmp_path):
    path = tmp_path / "sheet.tsv"
    rows = [M1_ROW.replace("M1\tmock", f"{lens}\tmock", 1) for lens in ("nan", "NA", "007")]
    path.write_text(HEADER + "".join(rows) + "# a comment\n")
    sheet = read_sample_sheet(path)
    assert list(sheet.index) == ["nan", "NA", "007"]
    assert sheet["input"].isna().all()  # empty cells stay missing
    assert sheet["mask_radius"].tolist() == [1.8] * 3

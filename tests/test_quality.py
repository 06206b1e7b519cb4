"""Tests of mgelens.quality and ``mgelens quality`` (fit-quality flag, docs/slacs.md)."""

import json

import numpy as np
import pytest
from astropy.io import fits

from mgelens import quality
from mgelens.cli import main
from mgelens.convolve import convolve_image
from mgelens.grid import pixel_centres
from mgelens.imaging import Imaging
from mgelens.mask import circular
from mgelens.mass import EPL, SIE, ExternalShear
from mgelens.simulate import gaussian_psf

PIXEL = 0.05
SHAPE = (121, 121)
RADIUS = 2.8
NOISE = 0.01


@pytest.fixture(scope="module")
def scene():
    """A 3″-class mask with a 0.25″-wide lensed ring at 1.2″ (LENSED ≥ σ on it)."""
    x, y = pixel_centres(SHAPE, PIXEL)
    ring = 10 * NOISE * np.exp(-0.5 * ((np.hypot(x, y) - 1.2) / 0.12) ** 2)
    return {
        "x": x,
        "y": y,
        "lensed": ring,
        "noise": np.full(SHAPE, NOISE),
        "mask": circular(SHAPE, PIXEL, RADIUS),
    }


def statistic(scene, residuals, **changes):
    arrays = {k: scene[k] for k in ("lensed", "noise", "mask")} | changes
    return quality.quality_statistic(
        residuals, arrays["lensed"], arrays["noise"], arrays["mask"], PIXEL
    )


def blob(scene, centre, amplitude, width=0.2):
    return amplitude * np.exp(
        -0.5 * ((scene["x"] - centre[0]) ** 2 + (scene["y"] - centre[1]) ** 2) / width**2
    )


def test_white_noise_does_not_flag_over_many_seeds(scene):
    results = [
        statistic(scene, np.random.default_rng(seed).standard_normal(SHAPE)) for seed in range(400)
    ]
    assert all(r.measured for r in results)
    flagged = sum(r.flag for r in results)
    # calibration (docs/slacs.md): false-flag probability < 1e-3 per lens
    assert flagged <= 1
    significance = np.array([r.significance for r in results])
    coherence = np.array([r.coherence for r in results])
    assert abs(np.median(significance)) < 0.5
    assert np.median(coherence) == pytest.approx(1.0, abs=0.03)
    assert np.median([r.noise_scale for r in results]) == pytest.approx(1.0, abs=0.05)
    assert max(r.peak for r in results) < quality.PEAK_THRESHOLD


def test_psf_correlated_noise_does_not_flag(scene):
    kernel = gaussian_psf(9, 1.0)
    taus = []
    for seed in range(60):
        noise = np.random.default_rng(seed).standard_normal(SHAPE)
        correlated = convolve_image(noise, kernel) / np.sqrt(np.sum(kernel**2))
        result = statistic(scene, correlated)
        assert not result.flag
        taus.append(result.noise_scale)
    assert np.median(taus) > 2.0  # the blocks are wider than white noise's...


def test_planted_coherent_residual_flags_where_it_is(scene):
    rng = np.random.default_rng(1)
    centre = (-1.9, 0.9)  # upper left, away from the ring
    residuals = rng.standard_normal(SHAPE) + blob(scene, centre, 2.5)
    result = statistic(scene, residuals)
    assert result.flag
    assert result.peak > quality.PEAK_THRESHOLD
    assert result.n_outlier_blocks >= 1
    assert np.hypot(result.worst_x - centre[0], result.worst_y - centre[1]) < 0.25
    # row index = +y: the same blob flipped up-down is reported at −y
    flipped = statistic(scene, residuals[::-1])
    assert flipped.worst_y == pytest.approx(-result.worst_y, abs=0.2)
    assert flipped.worst_x == pytest.approx(result.worst_x, abs=0.2)


def test_extended_offset_flags_by_coherence(scene):
    """A lens light 0.25σ too faint everywhere: no block stands out, the sum does."""
    residuals = np.random.default_rng(2).standard_normal(SHAPE) + 0.25
    result = statistic(scene, residuals)
    assert result.peak < quality.PEAK_THRESHOLD
    assert result.significance > quality.COHERENCE_THRESHOLD
    assert result.flag


def test_pixels_under_the_source_are_excluded(scene):
    residuals = np.random.default_rng(3).standard_normal(SHAPE)
    ring = scene["lensed"] >= scene["noise"]
    assert not statistic(scene, residuals).flag
    arcs = residuals + 8.0 * ring  # large residuals on the arcs only
    result = statistic(scene, arcs)
    assert not result.flag
    no_source = statistic(scene, arcs, lensed=np.zeros(SHAPE))
    assert no_source.flag
    assert no_source.n_pixels == int((~scene["mask"]).sum()) - _partial(scene, np.zeros(SHAPE))
    assert result.n_pixels < no_source.n_pixels


def _partial(scene, lensed):
    """Used pixels lying in blocks that are not kept (their count is not in n_pixels)."""
    used = quality.used_pixels(np.zeros(SHAPE), lensed, scene["noise"], scene["mask"])
    blocks = quality.block_residuals(np.zeros(SHAPE), used, PIXEL, 5)
    return int(blocks.counts[~blocks.kept].sum())


def test_contaminant_pixels_are_excluded(scene):
    residuals = np.random.default_rng(4).standard_normal(SHAPE)
    companion = blob(scene, (1.8, -1.6), 1.0, 0.25) > 0.05
    residuals[companion] += 6.0
    assert statistic(scene, residuals).flag
    noise = scene["noise"].copy()
    noise[companion] = 1e8  # SLACS sentinel
    result = statistic(scene, residuals, noise=noise)
    assert not result.flag


def test_small_masks_are_not_measured(scene):
    small = circular(SHAPE, PIXEL, 1.0)
    result = statistic(scene, np.ones(SHAPE) * 5, mask=small)
    assert not result.measured
    assert not result.flag
    assert result.n_pairs < quality.MIN_PAIRS
    assert result.to_dict()["significance"] is None


def sky_scene(rng, sigma_pixels=None, peak=200.0, shape=(201, 201)):
    """Data of an elliptical Gaussian galaxy (``peak`` σ, σ_major 1″, q 0.7) plus noise that
    is white or Gaussian-correlated over ``sigma_pixels`` (unit pixel variance), in units of
    σ; returns the data and the noise."""
    x, y = pixel_centres(shape, PIXEL)
    galaxy = peak * np.exp(-0.5 * ((x / 1.0) ** 2 + (y / 0.7) ** 2))
    noise = rng.standard_normal(shape)
    if sigma_pixels is not None:
        kernel = gaussian_psf(2 * int(np.ceil(4 * sigma_pixels)) + 1, sigma_pixels)
        noise = convolve_image(noise, kernel, method="fft") / np.sqrt(np.sum(kernel**2))
    return galaxy + noise, noise


def sky_and_true_noise_scale(sigma_pixels, mask_radius, seeds=6):
    """Mean τ of the sky beyond ``mask_radius`` and of the same noise maps taken whole."""
    rng = np.random.default_rng(11)
    sky_taus, whole_taus = [], []
    for _ in range(seeds):
        data, noise = sky_scene(rng, sigma_pixels)
        ones = np.ones(data.shape)
        sky = quality.sky_pixels(data, ones, PIXEL, mask_radius)
        residuals = quality.sky_residual_map(data, ones, sky, PIXEL)
        blocks = quality.block_residuals(residuals, sky, PIXEL, 5)
        sky_taus.append(quality.noise_scale(quality.pair_differences(blocks.z)))
        whole = quality.block_residuals(noise, np.ones(data.shape, bool), PIXEL, 5)
        whole_taus.append(quality.noise_scale(quality.pair_differences(whole.z)))
    return np.mean(sky_taus), np.mean(whole_taus)


@pytest.mark.parametrize("sigma_pixels", [None, 1.0, 1.5])
def test_the_sky_measures_the_noise_scale_of_the_residuals(sigma_pixels):
    """Step 6: beyond a 2.5″ circle (galaxy ≤ 2σ per pixel) the sky's τ is the noise's
    within 3 %, for white and PSF-correlated noise; beyond 1.5″ (the galaxy 7–27σ per
    pixel at the sky's edge) its curvature leaks in and τ errs high, the safe side, by
    under 15 %."""
    sky, true = sky_and_true_noise_scale(sigma_pixels, 2.5)
    assert sky == pytest.approx(true, rel=0.03)
    sky, true = sky_and_true_noise_scale(sigma_pixels, 1.5)
    assert 0.97 * true < sky < 1.15 * true


def test_sky_pixels_leave_out_the_circle_contaminants_and_the_folder_mask():
    data = np.zeros(SHAPE)
    noise = np.full(SHAPE, NOISE)
    noise[0, 0] = 1e8  # a contaminant's sentinel
    data[0, 1] = np.nan
    excluded = np.zeros(SHAPE, dtype=bool)
    excluded[-1, -1] = True
    sky = quality.sky_pixels(data, noise, PIXEL, 2.0, (0.1, 0.0), excluded=excluded)
    x, y = pixel_centres(SHAPE, PIXEL)
    beyond = np.hypot(x - 0.1, y) > 2.0 + quality.SKY_GAP + 1e-9
    assert not sky[0, 0]
    assert not sky[0, 1]
    assert not sky[-1, -1]
    beyond[0, 0] = beyond[0, 1] = beyond[-1, -1] = False
    np.testing.assert_array_equal(sky, beyond)
    residuals = quality.sky_residual_map(data, noise, sky, PIXEL)
    assert np.all(np.isnan(residuals[~sky]))
    assert np.all(residuals[sky] == 0.0)


def filled_mask_statistic(rng, sigma_pixels, bump=0.0):
    """The statistic in a 1.0″ circle (52 judged blocks, 72 pairs: too few for the
    residuals' τ, as on the paper's failure lenses whose lensed source fills the mask,
    docs/slacs.md) of noise plus a central bump of ``bump`` σ per pixel and 0.25″ width."""
    shape = (201, 201)
    x, y = pixel_centres(shape, PIXEL)
    noise, mask = np.ones(shape), circular(shape, PIXEL, 1.0)
    data, pure = sky_scene(rng, sigma_pixels, peak=20.0)
    sky_residuals = quality.sky_residual_map(
        data, noise, quality.sky_pixels(data, noise, PIXEL, 1.0), PIXEL
    )
    residuals = pure + bump * np.exp(-8 * (x**2 + y**2))
    lensed = np.zeros(shape)
    without_sky = quality.quality_statistic(residuals, lensed, noise, mask, PIXEL)
    assert not without_sky.measured
    return quality.quality_statistic(
        residuals, lensed, noise, mask, PIXEL, sky_residuals=sky_residuals
    )


def test_a_mask_filled_by_the_source_takes_its_noise_scale_from_the_sky():
    rng = np.random.default_rng(3)
    correlated = [filled_mask_statistic(rng, 1.0) for _ in range(40)]
    planted = [filled_mask_statistic(rng, None, bump=2.5) for _ in range(20)]
    for r in correlated + planted:
        assert r.measured
        assert r.noise_scale_from == "sky"
        assert r.n_pairs < quality.MIN_PAIRS <= r.n_sky_pairs
        assert r.noise_scale == r.sky_noise_scale
    # PSF-correlated noise (σ = 1 pixel): its τ of 2.78 is found, and nothing is flagged
    assert np.median([r.noise_scale for r in correlated]) == pytest.approx(2.78, rel=0.05)
    assert not any(r.flag for r in correlated)
    # a 2.5σ-per-pixel bump at the centre, which the residuals' τ could not judge
    assert all(r.flag for r in planted)
    assert np.median([r.noise_scale for r in planted]) == pytest.approx(1.0, abs=0.05)


def test_mismatched_shapes_are_refused(scene):
    with pytest.raises(ValueError, match=r"one shape: NRESID \(120, 121\)"):
        statistic(scene, np.zeros((120, 121)))
    with pytest.raises(ValueError, match="positive"):
        quality.block_pixels(0.0)


def test_block_size_follows_the_pixel_scale():
    assert quality.block_pixels(0.05) == 5
    assert quality.block_pixels(0.1) == 2  # round(2.5) = 2
    assert quality.block_pixels(0.2) == 2


# -- command -----------------------------------------------------------------------------
@pytest.fixture
def phase(tmp_path, scene):
    """An imaging folder and a phase folder whose model.fits holds a planted residual."""
    rng = np.random.default_rng(5)
    lens_dir = tmp_path / "data"
    data = rng.normal(size=SHAPE) * NOISE
    Imaging(data, scene["noise"], gaussian_psf(5, 1.0), PIXEL).to_fits(lens_dir)
    folder = tmp_path / "L1" / "mass"
    folder.mkdir(parents=True)
    settings = {"lens_dir": str(lens_dir), "mask_radius": RADIUS, "slam": {"mask_centre": [0, 0]}}
    sie = {"centre": [0.0, 0.0], "einstein_radius": 1.2, "axis_ratio": 1.0, "angle": 0.0}
    mass = [{"type": "SIE", "parameters": sie}]
    light = {"components": [{"kind": "mge", "centre": [0.02, -0.01], "ell_comps": [0.0, 0.0]}]}
    record = {"settings": settings, "max_likelihood_fit": {"mass": mass, "lens_light": light}}
    (folder / "result.json").write_text(json.dumps(record))
    nresid = rng.standard_normal(SHAPE) + blob(scene, (1.5, 1.5), 2.5)
    nresid[scene["mask"]] = 0.0
    hdus = [fits.PrimaryHDU()]
    for name, image in (("LENSED", scene["lensed"]), ("NRESID", nresid)):
        hdus.append(fits.ImageHDU(image, name=name))
    fits.HDUList(hdus).writeto(folder / "model.fits")
    return folder


def test_quality_command_writes_the_record(phase, capsys):
    out = phase.parent / "quality.json"
    assert main(["quality", "--phase", str(phase), "--out", str(out)]) == 0
    record = json.loads(out.read_text())
    assert record["lens"] == "L1"
    assert record["phase"] == "mass"
    assert record["flag"] is True
    assert record["measured"] is True
    assert record["worst_x"] == pytest.approx(1.5, abs=0.25)
    assert record["worst_y"] == pytest.approx(1.5, abs=0.25)
    assert record["coherence_threshold"] == quality.COHERENCE_THRESHOLD
    assert record["peak_threshold"] == quality.PEAK_THRESHOLD
    assert record["block_pixels"] == 5
    assert record["n_blocks"] > 100
    assert record["noise_scale_from"] == "residuals"
    assert record["n_pairs"] >= quality.MIN_PAIRS
    assert record["n_sky_pairs"] < quality.MIN_PAIRS  # the 2.8″ circle leaves the corners
    # an SIS of θ_E = 1.2″: its critical curve is that circle, inside the 2.8″ fit circle
    lensing = record["lensing"]
    assert lensing["critical_curve_einstein_radius"] == pytest.approx(1.2, abs=0.01)
    assert lensing["flag"] is False
    # the ring at θ_E traces inside the SIS's cut: every pixel of it has a counter-image
    multiplicity = record["multiplicity"]
    assert multiplicity["multiply_imaged_fraction"] == pytest.approx(1.0)
    assert multiplicity["n_pixels"] > 100
    assert multiplicity["flag"] is False
    assert quality.flagged_checks(record) == "residuals"
    out = capsys.readouterr().out
    assert "FLAG" in out
    assert "100% of the lensed source's signal" in out


def test_flagged_checks_name_every_check_that_flags():
    record = {
        "measured": True,
        "flag": False,
        "lensing": {"flag": False},
        "multiplicity": {"flag": False},
    }
    assert quality.flagged_checks(record) == quality.NO_FLAG
    both = record | {"lensing": {"flag": True}, "multiplicity": {"flag": True}}
    assert quality.flagged_checks(both) == "lensing; singly imaged"
    # a residual statistic that was not measured flags nothing; records older than the
    # multiplicity check have none
    unmeasured = {"measured": False, "flag": True, "lensing": {"flag": False}}
    assert quality.flagged_checks(unmeasured) == quality.NO_FLAG
    with pytest.raises(KeyError):
        quality.flagged_checks({"measured": True, "flag": False})


def test_quality_command_takes_the_sky_noise_scale_for_a_small_circle(phase, capsys):
    result = phase / "result.json"
    record = json.loads(result.read_text())
    record["settings"]["mask_radius"] = 1.0
    result.write_text(json.dumps(record))
    out = phase.parent / "quality.json"
    assert main(["quality", "--phase", str(phase), "--out", str(out)]) == 0
    record = json.loads(out.read_text())
    assert record["measured"] is True
    assert record["noise_scale_from"] == "sky"
    assert record["n_pairs"] < quality.MIN_PAIRS <= record["n_sky_pairs"]
    # the folder's data are white noise of the noise map's σ: τ = 1
    assert record["noise_scale"] == pytest.approx(1.0, abs=0.1)
    assert record["flag"] is False  # the planted blob at (1.5, 1.5)″ lies outside 1.0″
    assert "from the sky" in capsys.readouterr().out


# -- lensing check -------------------------------------------------------------------------
def test_a_mass_that_lenses_inside_the_mask_passes_the_lensing_check():
    check = quality.lensing_check((SIE((0.0, 0.0), 1.0, 1.0, 0.0),), mask_radius=3.0)
    assert not check.flag
    assert check.critical_curve_einstein_radius == pytest.approx(1.0, abs=0.01)
    # an SIE with shear: the curve's circle-equivalent radius is still close to θ_E
    sie = (SIE((0.1, -0.05), 1.2, 0.8, 40.0), ExternalShear(0.03, -0.02))
    assert quality.lensing_check(sie, 3.0).critical_curve_einstein_radius == pytest.approx(
        1.2, rel=0.05
    )


def test_the_first_real_lens_degenerate_sp_mass_is_flagged():
    """slacs1020+1122's SP maximum (docs/slacs.md): a needle SIE and strong shear."""
    needle = (SIE((-0.5246, 0.0910), 5.3277, 0.02717, 155.70), ExternalShear(0.1156, -0.1577))
    check = quality.lensing_check(needle, mask_radius=3.0)
    assert check.flag
    assert check.critical_curve_einstein_radius is None
    assert "critical curve" in check.reason


def test_a_needle_thin_critical_curve_is_flagged():
    """slacs1020+1122's SPix1 mass (docs/slacs.md): q = 0.0005, a closed but needle curve."""
    needle = (SIE((-0.3184, 0.1576), 5.7640, 0.00050025, 158.94), ExternalShear(0.1401, -0.3324))
    check = quality.lensing_check(needle, mask_radius=3.0)
    assert check.flag
    assert "needle" in check.reason
    assert check.critical_curve_einstein_radius == pytest.approx(0.14, abs=0.02)
    # a flattened but galaxy-like mass passes
    flat = (SIE((0.0, 0.0), 1.2, 0.2, 30.0),)
    assert not quality.lensing_check(flat, mask_radius=3.0).flag


@pytest.mark.parametrize(
    ("radius", "centre", "mask_centre", "flagged"),
    [
        (2.9, (0.0, 0.0), (0.0, 0.0), False),
        (3.2, (0.0, 0.0), (0.0, 0.0), True),  # the curve lies beyond the 3″ circle
        (1.0, (0.5, 0.0), (0.0, 0.0), False),  # reaches 1.5″ from the centre
        (1.0, (0.0, 0.0), (1.5, 0.0), True),  # reaches 2.5″ from an offset 2″ circle
    ],
)
def test_the_critical_curve_must_lie_inside_the_fit_circle(radius, centre, mask_centre, flagged):
    mask_radius = 2.0 if mask_centre != (0.0, 0.0) else 3.0
    check = quality.lensing_check((SIE(centre, radius, 1.0, 0.0),), mask_radius, mask_centre)
    assert check.flag is flagged


def test_a_critical_curve_beside_the_lens_light_is_flagged():
    """slacs1250+0523's first MASS mass (docs/slacs.md): an EPL 1.9″ from the light with a
    0.15″ critical curve, which lenses nothing the galaxy holds."""
    beside = (EPL((-1.9305, 0.4204), 0.1701, 0.5986, 65.363, 2.9034),
              ExternalShear(-0.0434, -0.0684))  # fmt: skip
    assert not quality.lensing_check(beside, 3.0).flag  # the old checks pass it
    check = quality.lensing_check(beside, 3.0, light_centre=(-0.002, 0.005))
    assert check.flag
    assert "does not enclose the lens-light centre" in check.reason
    assert check.critical_curve_einstein_radius == pytest.approx(0.15, abs=0.02)
    # a mass 0.3″ from the light still encloses it: flagged for the offset alone
    near = quality.lensing_check((SIE((0.3, 0.0), 1.0, 0.8, 20.0),), 3.0, light_centre=(0, 0))
    assert near.flag
    assert "does not enclose" not in near.reason
    assert near.centre_offset == pytest.approx(0.3)


@pytest.mark.parametrize(("offset", "flagged"), [(0.0, False), (0.09, False), (0.11, True)])
def test_a_mass_centred_away_from_the_light_is_flagged(offset, flagged):
    """The threshold is the mass–light distance, in any direction."""
    light = (0.02, -0.03)
    direction = np.deg2rad(130.0)
    centre = (light[0] + offset * np.cos(direction), light[1] + offset * np.sin(direction))
    mass = (EPL(centre, 1.1, 0.8, 30.0, 2.0), ExternalShear(0.02, 0.01))
    check = quality.lensing_check(mass, 3.0, light_centre=light)
    assert check.flag is flagged
    assert check.centre_offset == pytest.approx(offset, abs=1e-12)
    assert check.critical_curve_einstein_radius == pytest.approx(1.1, rel=0.05)
    if flagged:
        assert f"is {offset:.2f}″ from the lens-light centre" in check.reason
    # without a light centre there is no offset to judge
    assert quality.lensing_check(mass, 3.0).centre_offset is None


def test_slacs1250_mass_offset_with_aligned_shear_is_flagged():
    """slacs1250+0523's MASS (docs/slacs.md): centre 0.26″ from the light, q 0.60 and an
    aligned shear of 0.12; its θ_E agrees with Bolton's, so only the offset shows it."""
    shear_angle = np.deg2rad(2 * 133.0)
    mass = (EPL((0.12, 0.24), 1.175, 0.60, 133.0, 2.02),
            ExternalShear(0.12 * np.cos(shear_angle), 0.12 * np.sin(shear_angle)))  # fmt: skip
    assert not quality.lensing_check(mass, 3.0).flag
    check = quality.lensing_check(mass, 3.0, light_centre=(0.0, 0.0))
    assert check.flag
    assert check.centre_offset == pytest.approx(0.268, abs=0.001)


def test_encloses_follows_the_even_odd_rule():
    t = np.linspace(0.0, 2.0 * np.pi, 101)
    x, y = np.cos(t), 0.5 * np.sin(t)
    assert quality.encloses(x, y, (0.0, 0.0))
    assert quality.encloses(x, y, (0.9, 0.0))
    assert not quality.encloses(x, y, (0.0, 0.6))
    assert not quality.encloses(x, y, (-1.1, 0.0))


def test_quality_command_names_a_missing_extension(phase, caplog):
    path = phase / "model.fits"
    with fits.open(path) as hdus:
        fits.HDUList([hdus[0], hdus["LENSED"].copy()]).writeto(path, overwrite=True)
    out = phase.parent / "quality.json"
    assert main(["quality", "--phase", str(phase), "--out", str(out)]) == 1
    assert "no NRESID extension" in caplog.text
    assert not out.exists()


def test_quality_command_refuses_other_shapes(phase, tmp_path, caplog):
    other = tmp_path / "other"
    Imaging(np.zeros((101, 101)), np.ones((101, 101)), gaussian_psf(5, 1.0), PIXEL).to_fits(other)
    out = phase.parent / "quality.json"
    arguments = ["quality", "--phase", str(phase), "--lens-dir", str(other), "--out", str(out)]
    assert main(arguments) == 1
    assert "one shape" in caplog.text

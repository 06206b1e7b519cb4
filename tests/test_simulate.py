"""Mock simulator (SPEC §10): numbers a wrong convention or wrong physics would fail."""

import json
import logging

import numpy as np
import pytest
from astropy.io import fits
from scipy import ndimage, optimize
from scipy.special import erf

import mgelens
from mgelens import cli, mock_lenses, mock_light, mock_sources
from mgelens import simulate as sim
from mgelens.convolve import convolve_image
from mgelens.grid import pixel_centres, sub_grid
from mgelens.imaging import Imaging

PIXEL_SCALE = 0.05
SPEC_TOTAL_FLUX = {"M1": 643.0, "M2": 460.0, "M3": 1140.0}
"""SPEC §10.1: Σ 2π I σ² q / Δ² in e⁻/s, quoted to 3 significant digits."""


@pytest.fixture(scope="module")
def m1():
    """M1 at the paper's settings (151×151, 16×16 sub-pixels, seed 1)."""
    return sim.simulate(mock_lenses.paper_mock("M1"))


@pytest.fixture(scope="module")
def population_mock():
    """Population lens 3 (seed 2024): q gradient, a 20° twist and boxy isophotes."""
    return sim.simulate(mock_lenses.population_lens(3))


def pixel_integrated_mge(table: mock_lenses.PaperMock, size: int, scale: float) -> np.ndarray:
    """Exact pixel averages of an mgefit MGE: erf along y, 24-node Gauss-Legendre along x.

    Independent of mgelens: each Gaussian is I exp[−(x′² + y′²/q²)/(2σ²)] with x′ along
    φ (CCW from +x), written as exp[−(A dx² + 2B dx dy + C dy²)/2]; for fixed dx the y
    integral over a pixel row is analytic.
    """
    nodes, weights = np.polynomial.legendre.leggauss(24)
    edges = (np.arange(size + 1) - size / 2.0) * scale
    mid = 0.5 * (edges[:-1] + edges[1:])
    out = np.zeros((size, size))
    rows = zip(
        table.axis_ratios, table.angles, table.log_intensities, table.log_sigmas, strict=True
    )
    for q, angle, log_intensity, log_sigma in rows:
        sigma2 = (10.0**log_sigma) ** 2
        c, s = np.cos(np.deg2rad(angle)), np.sin(np.deg2rad(angle))
        a = (c * c + s * s / q**2) / sigma2
        b = c * s * (1.0 - 1.0 / q**2) / sigma2
        cc = (s * s + c * c / q**2) / sigma2
        dx = mid[:, None] + 0.5 * scale * nodes[None, :] - table.centre[0]  # (column, node)
        y0 = edges[:-1, None, None] - table.centre[1]
        y1 = edges[1:, None, None] - table.centre[1]
        shift = (b * dx / cc)[None]
        k = np.sqrt(cc / 2.0)
        y_integral = np.sqrt(np.pi / (2.0 * cc)) * (erf(k * (y1 + shift)) - erf(k * (y0 + shift)))
        x_factor = np.exp(-0.5 * (a - b * b / cc) * dx**2)[None]
        integral = np.sum(y_integral * x_factor * weights, axis=2) * 0.5 * scale
        out += 10.0**log_intensity * integral / scale**2
    return out


def test_m1_lens_light_equals_pixel_integrated_gaussian_sum(m1):
    reference = pixel_integrated_mge(mock_lenses.PAPER_MOCKS["M1"], 151, PIXEL_SCALE)
    difference = m1.lens_light - reference
    # 16×16 midpoint rule: error (Δ/16)²/24 ∇²I, largest at the peak (σ_min = 0.013″).
    assert np.max(np.abs(difference)) < 1e-3 * reference.max()
    x, y = pixel_centres(reference.shape, PIXEL_SCALE)
    outside = np.hypot(x - 0.013, y + 0.070) > 0.2
    assert np.max(np.abs(difference[outside]) / reference[outside]) < 1e-4
    assert abs(difference.sum()) < 1e-6 * reference.sum()


@pytest.mark.parametrize("name", ["M1", "M2", "M3"])
def test_total_lens_flux_matches_spec(name):
    table = mock_lenses.PAPER_MOCKS[name]
    q = np.array(table.axis_ratios)
    intensity = 10.0 ** np.array(table.log_intensities)
    sigma = 10.0 ** np.array(table.log_sigmas)
    analytic = np.sum(2.0 * np.pi * intensity * sigma**2 * q) / PIXEL_SCALE**2
    assert analytic == pytest.approx(SPEC_TOTAL_FLUX[name], rel=5e-3)
    assert table.light().total_flux(PIXEL_SCALE) == pytest.approx(analytic, rel=1e-12)
    image = sim.oversampled_image(table.light(), (151, 151), PIXEL_SCALE, 16)
    in_field = pixel_integrated_mge(table, 151, PIXEL_SCALE).sum()
    assert image.sum() == pytest.approx(in_field, rel=1e-6)
    # SPEC §10.1: the 151×151 field holds ~97 % of M1 (widest σ ≈ 2.7″), nearly all of M2/M3.
    low, high = (0.96, 0.98) if name == "M1" else (0.99, 1.0)
    assert low < image.sum() / analytic < high


def test_source_signal_to_noise_is_fifty(m1, population_mock):
    for mock in (m1, population_mock):
        signal_to_noise = mock.lensed_source_blurred / mock.imaging.noise_map
        assert np.max(signal_to_noise) == pytest.approx(50.0, abs=1e-6)
        assert mock.truth["signal_to_noise"]["source_max"] == pytest.approx(50.0, abs=1e-6)
        # SPEC §10.4: a blurred source peak of ≈ 1.4–1.5 e⁻/s reaches S/N 50 at t = 2000 s.
        assert 1.3 < mock.lensed_source_blurred.max() < 1.6


def test_truth_images_add_up_to_the_noise_free_data(m1, tmp_path):
    np.testing.assert_allclose(m1.model, m1.lens_light_blurred + m1.lensed_source_blurred)
    blurred = convolve_image(m1.lens_light + m1.lensed_source, m1.imaging.psf)
    inner = (slice(10, -10),) * 2  # the mock convolves a padded grid; away from the edge
    np.testing.assert_allclose(blurred[inner], m1.model[inner], rtol=1e-12, atol=1e-14)
    expected_noise = np.sqrt((m1.model + 0.15) * 2000.0) / 2000.0
    np.testing.assert_allclose(m1.imaging.noise_map, expected_noise, rtol=1e-14)
    residual = (m1.imaging.data - m1.model) / m1.imaging.noise_map
    assert abs(residual.mean()) < 0.02
    assert residual.std() == pytest.approx(1.0, abs=0.02)

    sim.write_mock(m1, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(sim.MOCK_FILES.values())
    imaging = Imaging.from_folder(tmp_path)
    np.testing.assert_array_equal(imaging.data, m1.imaging.data)
    np.testing.assert_array_equal(imaging.noise_map, m1.imaging.noise_map)
    assert imaging.pixel_scale == PIXEL_SCALE
    for key in ("model", "lens_light_blurred", "lensed_source_blurred", "source"):
        np.testing.assert_array_equal(
            fits.getdata(tmp_path / sim.MOCK_FILES[key]), getattr(m1, key)
        )
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["conventions_version"] == mgelens.CONVENTIONS_VERSION
    assert truth["seed"] == 1
    assert truth["mass"][0]["parameters"]["slope"] == 2.1
    assert sim.mass_from_truth(truth) == [mock_lenses.PAPER_MOCKS["M1"].mass()]


def test_noise_map_matches_the_scatter_of_noise_realisations(m1):
    rng = np.random.default_rng(7)
    realisations = np.stack([sim.noisy_data(m1.model, 2000.0, 0.15, rng) for _ in range(200)])
    ratio = realisations.std(axis=0, ddof=1) / m1.imaging.noise_map
    # Sampling error of a 200-draw standard deviation: 1/sqrt(2·199) ≈ 5 % per pixel.
    assert abs(ratio.mean() - 1.0) < 0.003
    assert ratio.std() == pytest.approx(1.0 / np.sqrt(2 * 199), rel=0.1)
    assert np.max(np.abs(ratio - 1.0)) < 0.3
    pull = (realisations.mean(axis=0) - m1.model) / (m1.imaging.noise_map / np.sqrt(200))
    assert abs(pull.mean()) < 0.03
    assert pull.std() == pytest.approx(1.0, abs=0.03)


def _ellipse_radius(psi, a, q):
    return a * q / np.sqrt((q * np.cos(psi)) ** 2 + np.sin(psi) ** 2)


def _contour_residual(p, x, y):
    """Radial residual of contour points from an ellipse + cos/sin 3ψ, 4ψ harmonics."""
    x0, y0, a, q, angle, a3, b3, a4, b4 = p
    t = np.arctan2(y - y0, x - x0) - angle
    harmonics = a3 * np.cos(3 * t) + b3 * np.sin(3 * t) + a4 * np.cos(4 * t) + b4 * np.sin(4 * t)
    return np.hypot(x - x0, y - y0) - _ellipse_radius(t, a, q) - harmonics


def test_population_isophote_truth_matches_an_ellipse_fit(population_mock):
    """Independent check of the recorded q(a), PA(a), a₄/a(a) on the noise-free lens image.

    Bicubic-spline samples of the image (before the PSF) along the recorded isophotes
    must be constant; the contour at that level, found along 360 rays, is fitted with an
    ellipse + 3rd/4th harmonics of the polar angle (free centre), i.e. the ellipse whose
    radial residual has no harmonic below 3 (Bender & Möllenhoff).
    """
    light = population_mock.truth["lens_light"]
    isophotes = {key: np.array(value) for key, value in light["isophotes"].items()}
    in_range = (isophotes["sma"] >= 0.5) & (isophotes["sma"] <= 2.5)
    angle = np.rad2deg(np.unwrap(np.deg2rad(2.0 * isophotes["angle"][in_range]))) / 2.0
    assert np.ptp(angle) > 15.0  # the test needs a real twist, q gradient and a4
    assert np.ptp(isophotes["axis_ratio"][in_range]) > 0.05
    assert np.max(np.abs(isophotes["a4_over_a"][in_range])) > 0.015

    image = population_mock.lens_light
    n = image.shape[0]
    coefficients = ndimage.spline_filter(image, order=3)
    centre = np.array(light["centre"])

    def sample(x, y):
        rows, cols = y / PIXEL_SCALE + (n - 1) / 2.0, x / PIXEL_SCALE + (n - 1) / 2.0
        return ndimage.map_coordinates(coefficients, [rows, cols], order=3, prefilter=False)

    psi = np.linspace(0.0, 2.0 * np.pi, 360, endpoint=False)
    for k in np.flatnonzero(in_range)[::2]:
        a, q = isophotes["sma"][k], isophotes["axis_ratio"][k]
        phi, a4 = np.deg2rad(isophotes["angle"][k]), isophotes["a4_over_a"][k]
        radius = _ellipse_radius(psi, a, q) + a * a4 * np.cos(4.0 * psi)
        values = sample(
            centre[0] + radius * np.cos(psi + phi), centre[1] + radius * np.sin(psi + phi)
        )
        level = values.mean()
        # pixel averaging over Δ shifts intensities by ≈ Δ²∇²I/24 ≈ 1e−3 at a = 0.5″
        assert values.std() / level < 1.5e-3

        steps = a * np.linspace(0.6, 1.4, 321)[:, None]
        ray = sample(centre[0] + steps * np.cos(psi), centre[1] + steps * np.sin(psi))
        below = np.argmax(ray < level, axis=0)
        cols = np.arange(psi.size)
        i0, i1 = np.log(ray[below - 1, cols]), np.log(ray[below, cols])
        r0, r1 = steps[below - 1, 0], steps[below, 0]
        contour = r0 + (np.log(level) - i0) / (i1 - i0) * (r1 - r0)
        xc, yc = centre[0] + contour * np.cos(psi), centre[1] + contour * np.sin(psi)

        start = [*centre, 1.05 * a, min(q + 0.05, 0.99), phi + 0.05, 0.0, 0.0, 0.0, 0.0]
        fit = optimize.least_squares(_contour_residual, start, args=(xc, yc)).x
        # SPEC §9.2 targets: |Δq| < 0.01, |ΔPA| < 2° (q < 0.9), |Δ(a4/a)| < 0.003
        assert abs(fit[3] - q) < 0.003
        if q < 0.9:
            assert abs((np.rad2deg(fit[4] - phi) + 90.0) % 180.0 - 90.0) < 0.2
        assert abs(fit[7] / fit[2] - a4) < 1e-3
        assert abs(fit[2] / a - 1.0) < 2e-3


def test_isophote_light_label_solves_the_isophote_equation():
    light = mock_lenses.population_lens(3).light
    for a in (0.05, 0.3, 1.0, 2.7):
        x, y = light.isophote_curve(a, 90)
        np.testing.assert_allclose(light.semi_major_axis(x, y), a, rtol=1e-6)
        np.testing.assert_allclose(light.image(x, y), light.profile(a), rtol=1e-5)
    assert light.semi_major_axis(np.array(light.centre[0]), np.array(light.centre[1])) == 0.0


def test_crossing_isophotes_are_rejected():
    with pytest.raises(ValueError, match="isophotes change too fast"):
        mock_light.IsophoteLight(
            (0.0, 0.0), 1.0, 1.0, 4.0,
            axis_ratio=mock_light.Transition(0.5, 0.5),
            angle=mock_light.Transition(0.0, 90.0, 1.0, 0.1),
            a4=mock_light.Transition(0.0, 0.0),
        )  # fmt: skip


def test_oversampled_image_follows_the_sub_grid_convention():
    """Fine-grid evaluation equals mgelens.grid's sub-grid + bin (SPEC §1.3), any origin."""
    light = mock_lenses.PAPER_MOCKS["M2"].light()
    shape, origin = (9, 12), (0.11, -0.04)
    x, y = pixel_centres(shape, PIXEL_SCALE, origin)
    grid = sub_grid(x, y, PIXEL_SCALE, 5)
    expected = grid.bin(light.image(grid.x, grid.y)).reshape(shape)
    np.testing.assert_allclose(
        sim.oversampled_image(light, shape, PIXEL_SCALE, 5, origin), expected, rtol=1e-12
    )
    grid_values = light.image_on_grid(np.linspace(-1, 1, 97), np.linspace(-0.5, 0.7, 31))
    xx, yy = np.meshgrid(np.linspace(-1, 1, 97), np.linspace(-0.5, 0.7, 31))
    np.testing.assert_allclose(grid_values, light.image(xx, yy), rtol=1e-12, atol=1e-300)


def test_mge_light_uses_major_axis_sigma_and_ccw_angles():
    light = mock_light.MGELight.from_table((0.1, -0.2), [0.5], [30.0], [0.0], [np.log10(0.4)])
    major = np.array([np.cos(np.pi / 6), np.sin(np.pi / 6)])
    minor = np.array([-np.sin(np.pi / 6), np.cos(np.pi / 6)])
    # one σ along the major axis (0.4″) and along the minor axis (0.2″): e^{-1/2}
    for direction, distance in ((major, 0.4), (minor, 0.2)):
        x, y = np.array([0.1, -0.2]) + distance * direction
        assert light.image(np.array(x), np.array(y)) == pytest.approx(np.exp(-0.5), rel=1e-12)


def test_gaussian_psf_is_normalised_with_one_pixel_sigma():
    psf = sim.Observation().psf()
    assert psf.shape == (21, 21)
    assert psf.sum() == pytest.approx(1.0, rel=1e-14)
    assert np.unravel_index(psf.argmax(), psf.shape) == (10, 10)
    offsets = np.arange(21) - 10
    assert np.sum(psf.sum(axis=0) * offsets**2) == pytest.approx(1.0, rel=1e-6)


def test_image_source_is_bilinear_with_row_index_along_y():
    pixels = np.zeros((5, 7))
    pixels[3, 1] = 2.0
    source = mock_sources.ImageSource(pixels, 0.1, centre=(0.5, -0.3))
    x_peak, y_peak = 0.5 + (1 - 3) * 0.1, -0.3 + (3 - 2) * 0.1
    assert source.image(np.array(x_peak), np.array(y_peak)) == pytest.approx(2.0)
    assert source.image(np.array(x_peak + 0.05), np.array(y_peak)) == pytest.approx(1.0)
    assert source.image(np.array(x_peak + 0.025), np.array(y_peak - 0.05)) == pytest.approx(0.75)
    assert source.image(np.array(0.5 + 0.31), np.array(-0.3)) == 0.0


@pytest.mark.parametrize("name", ["M1", "M2", "M3"])
def test_paper_mock_sources_sit_near_the_caustic_centre(name):
    lens = mock_lenses.paper_mock(name)
    table = mock_lenses.PAPER_MOCKS[name]
    assert lens.caustic_centre == pytest.approx(table.centre, abs=1e-9)
    offset = np.hypot(*np.subtract(lens.source.centre, lens.caustic_centre))
    assert 0.05 <= offset <= 0.15
    assert lens.source.kind == table.source_kind
    small = sim.Observation(image_size=21, sub_size=1)
    extent = sim.simulate(lens, small).truth["source"]["extent"]
    assert 1.0 <= extent <= 1.6  # SPEC §10.3: total extent ≈ 1.0–1.5″
    assert mock_lenses.paper_mock(name).source == lens.source  # deterministic for a given seed
    assert mock_lenses.paper_mock(name, seed=11).source != lens.source


def test_noise_seed_changes_the_noise_alone():
    """Another noise seed: the same lens, source and noise-free images; data that differ
    from the mock's by pure Poisson noise (the model's residuals keep unit variance)."""
    small = sim.Observation(image_size=41, sub_size=2)
    own = sim.simulate(mock_lenses.paper_mock("M2"), small)
    other_lens = mock_lenses.paper_mock("M2", noise_seed=11)
    other = sim.simulate(other_lens, small)
    assert other_lens.source == mock_lenses.paper_mock("M2").source
    assert other_lens.seed == 11
    assert "source seed 2, noise seed 11" in other_lens.recipe
    np.testing.assert_array_equal(other.model, own.model)
    np.testing.assert_array_equal(other.imaging.noise_map, own.imaging.noise_map)
    assert not np.array_equal(other.imaging.data, own.imaging.data)
    for data in (own.imaging.data, other.imaging.data):
        residuals = (data - own.model) / own.imaging.noise_map
        assert abs(residuals.mean()) < 0.1
        assert 0.9 < residuals.std() < 1.1
    expected = sim.noisy_data(own.model, small.exposure_time, small.sky, np.random.default_rng(11))
    np.testing.assert_array_equal(other.imaging.data, expected)
    assert mock_lenses.paper_mock("M2", noise_seed=2) == mock_lenses.paper_mock("M2")
    with pytest.raises(ValueError, match="noise_seed must be >= 0, got -1"):
        mock_lenses.paper_mock("M2", noise_seed=-1)


def test_paper_mock_masses_follow_spec_table():
    rows = {"M1": (1.2, 0.80, 45, 2.1), "M2": (1.0, 0.77, 60, 1.9), "M3": (1.1, 0.75, 30, 2.0)}
    for name, (einstein_radius, q, angle, slope) in rows.items():
        mass = mock_lenses.paper_mock(name).mass
        assert len(mass) == 1  # no external shear in the truth (SPEC §10.2)
        assert mass[0].centre == mock_lenses.PAPER_MOCKS[name].centre
        assert (mass[0].einstein_radius, mass[0].axis_ratio) == (einstein_radius, q)
        assert (mass[0].angle, mass[0].slope) == (angle, slope)
    assert [len(mock_lenses.PAPER_MOCKS[n].axis_ratios) for n in ("M1", "M2", "M3")] == [16, 16, 12]


def test_population_is_slacs_like_and_reproducible():
    lenses = [mock_lenses.population_lens(i) for i in range(mock_lenses.POPULATION_SIZE)]
    assert [lens.name for lens in lenses[:3]] == ["P00", "P01", "P02"]
    epl = [lens.mass[0] for lens in lenses]
    shear = [lens.mass[1] for lens in lenses]
    assert all(0.8 <= m.einstein_radius <= 1.6 for m in epl)
    assert np.mean([m.slope for m in epl]) == pytest.approx(2.08, abs=0.05)
    assert all(s.magnitude <= 0.1 for s in shear)
    assert all(0.5 <= m.axis_ratio <= 0.95 for m in epl)
    twisted = [
        np.ptp(np.unwrap(np.deg2rad(2 * np.array(lens.light.isophote_table()["angle"])))) / 2
        for lens in lenses
    ]
    assert 5 < sum(np.rad2deg(t) > 10.0 for t in twisted) < 30
    assert {lens.source.kind for lens in lenses} == set(mock_sources.SOURCE_KINDS)
    assert mock_lenses.population_lens(5) == lenses[5]
    assert mock_lenses.population_lens(5, population_seed=1).light != lenses[5].light


def test_cli_simulates_an_image_source(tmp_path):
    y, x = np.mgrid[-40:41, -40:41] * 0.01
    image = np.exp(-(x**2 + (y / 0.6) ** 2) / (2 * 0.15**2)) * (1 + 0.5 * np.cos(8 * x))
    np.save(tmp_path / "galaxy.npy", image)
    out = tmp_path / "mock"
    code = cli.main(
        ["simulate", "--mock", "M1", "--source-image", str(tmp_path / "galaxy.npy"),
         "--source-pixel-scale", "0.01", "--image-size", "61", "--sub-size", "4",
         "--name", "M1img", "--out", str(out)]
    )  # fmt: skip
    assert code == 0
    truth = json.loads((out / "truth.json").read_text())
    assert truth["name"] == "M1img"
    assert truth["source"]["model"] == "image"
    assert truth["source"]["shape"] == [81, 81]
    assert truth["observation"]["image_size"] == 61
    assert truth["signal_to_noise"]["source_max"] == pytest.approx(50.0, abs=1e-6)
    assert fits.getdata(out / "data.fits").shape == (61, 61)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--mock", "M1", "--source-image", "nope.fits", "--source-pixel-scale", "0.01"],
         "nope.fits: source image not found"),
        (["--population-index", "2", "--seed", "4"], "--seed applies to paper mocks only"),
        (["--population-index", "2", "--noise-seed", "4"],
         "--noise-seed applies to paper mocks only"),
        (["--mock", "M2", "--image-size", "150"], "image_size must be an odd integer"),
        (["--mock", "M3", "--source-image", "x.fits"], "must be given together"),
    ],
)  # fmt: skip
def test_cli_reports_bad_input(tmp_path, caplog, argv, message):
    with caplog.at_level(logging.ERROR):
        assert cli.main(["simulate", *argv, "--out", str(tmp_path / "out")]) == 1
    assert message in caplog.text


def test_unknown_mock_names_the_choices():
    with pytest.raises(ValueError, match="unknown mock 'M9'; choose one of M1, M2, M3"):
        mock_lenses.paper_mock("M9")
    with pytest.raises(ValueError, match="unknown source kind"):
        mock_sources.procedural_source("elliptical", (0.0, 0.0), np.random.default_rng(0))

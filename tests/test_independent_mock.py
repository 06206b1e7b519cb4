"""Independent mocks (mgelens.independent_mock): images formed by lenstronomy, checked
against mgelens's own mass and grid conventions, and written in the mock folder layout."""

import json
import math

import numpy as np
import pytest
from astropy.io import fits

from mgelens import simulate
from mgelens.cli import main
from mgelens.grid import pixel_centres
from mgelens.imaging import Imaging
from mgelens.isophote_recovery import true_light_centre
from mgelens.mass import EPL, ExternalShear, ray_trace
from mgelens.recovery import true_mass_parameters

pytest.importorskip(
    "lenstronomy", reason='independent mocks need lenstronomy: pip install -e ".[independent]"'
)

from lenstronomy.LensModel.lens_model import LensModel
from lenstronomy.LightModel.light_model import LightModel

from mgelens.independent_mock import (
    independent_lens,
    lenstronomy_mass,
    simulate_independent,
)

SMALL = simulate.Observation(image_size=61, sub_size=1, psf_size=11)


@pytest.mark.parametrize(
    ("axis_ratio", "angle", "slope"), [(0.86, 30.0, 1.88), (0.6, 125.0, 2.35), (0.8, 45.0, 2.0)]
)
def test_lenstronomy_deflections_equal_mgelens_epl_and_shear(axis_ratio, angle, slope):
    """SPEC §3.1–3.3: with θ_E, ell_comps and shear converted by lenstronomy_mass, the two
    codes' deflections and convergence agree to 1e-9 (an independent check of the EPL)."""
    mass = (
        EPL(
            centre=(0.05, -0.03),
            einstein_radius=1.1,
            axis_ratio=axis_ratio,
            angle=angle,
            slope=slope,
        ),
        ExternalShear(gamma_1=-0.04, gamma_2=0.012),
    )
    names, kwargs = lenstronomy_mass(mass)
    x, y = np.random.default_rng(0).uniform(-2.5, 2.5, (2, 2000))
    alpha_x, alpha_y = LensModel(names).alpha(x, y, kwargs)
    own = [sum(parts) for parts in zip(*(p.deflections(x, y) for p in mass), strict=True)]
    assert np.abs(alpha_x - own[0]).max() < 1e-9
    assert np.abs(alpha_y - own[1]).max() < 1e-9
    kappa = LensModel(names[:1]).kappa(x, y, kwargs[:1])
    assert np.abs(kappa - mass[0].convergence(x, y)).max() < 1e-9


@pytest.fixture(scope="module")
def small_mock():
    lens = independent_lens(3)
    return lens, simulate_independent(lens, SMALL)


def test_lensed_source_is_the_source_at_mgelens_ray_traced_positions(small_mock):
    """Without sub-pixels, each pixel of lenstronomy's lensed source is the source's
    brightness at the pixel centre of SPEC §1.1 traced by mgelens's own mass model: the
    image orientation, the grid and the mass conventions all agree."""
    lens, mock = small_mock
    x, y = pixel_centres(mock.lensed_source.shape, SMALL.pixel_scale)
    beta_x, beta_y = ray_trace(lens.mass, x.ravel(), y.ravel())
    model = LightModel([name for name, _ in lens.source])
    kwargs = [k for _, k in lens.source]
    expected = model.surface_brightness(beta_x, beta_y, kwargs).reshape(x.shape)
    expected *= mock.truth["source"]["amplitude"] * SMALL.pixel_scale**2
    assert np.abs(mock.lensed_source - expected).max() < 1e-9 * expected.max()
    light = LightModel(["GAUSSIAN_ELLIPSE"] * len(lens.light))
    own_light = light.surface_brightness(x.ravel(), y.ravel(), list(lens.light)).reshape(x.shape)
    assert mock.lens_light == pytest.approx(own_light * SMALL.pixel_scale**2, rel=1e-9)
    peak = np.unravel_index(np.argmax(mock.lens_light), mock.lens_light.shape)
    assert x[peak] == pytest.approx(lens.light_centre[0], abs=SMALL.pixel_scale)
    assert y[peak] == pytest.approx(lens.light_centre[1], abs=SMALL.pixel_scale)


def test_source_scaled_to_the_target_signal_to_noise_and_psf_has_unit_sum(small_mock):
    _, mock = small_mock
    assert mock.truth["signal_to_noise"]["source_max"] == pytest.approx(50.0, rel=1e-6)
    assert mock.imaging.psf.sum() == pytest.approx(1.0)
    blurred = mock.lens_light_blurred + mock.lensed_source_blurred
    assert mock.model == pytest.approx(blurred)
    assert mock.lens_light_blurred.sum() == pytest.approx(mock.lens_light.sum(), rel=0.02)


def test_draws_are_reproducible_and_cover_the_stated_ranges():
    lenses = [independent_lens(i) for i in range(12)]
    assert independent_lens(5) == lenses[5]
    slopes = [lens.mass[0].slope for lens in lenses]
    assert all(1.75 <= s <= 2.45 for s in slopes)
    assert min(slopes) < 1.95
    assert max(slopes) > 2.25
    shear = [math.hypot(lens.mass[1].gamma_1, lens.mass[1].gamma_2) for lens in lenses]
    assert max(shear) <= 0.1
    assert all(0.55 <= lens.mass[0].axis_ratio <= 0.95 for lens in lenses)
    assert {lens.name for lens in lenses[:2]} == {"L00", "L01"}
    assert independent_lens(5, population_seed=7) != lenses[5]
    with pytest.raises(ValueError, match="integer >= 0"):
        independent_lens(-1)


def test_light_brightness_on_the_1_arcsec_circle_is_the_drawn_one():
    lens = independent_lens(4)
    model = LightModel(["GAUSSIAN_ELLIPSE"] * len(lens.light))
    angles = np.linspace(0.0, 2.0 * np.pi, 64, endpoint=False)
    cx, cy = lens.light_centre
    values = model.surface_brightness(cx + np.cos(angles), cy + np.sin(angles), list(lens.light))
    assert 24.0 <= values.mean() <= 100.0  # e-/s/arcsec² (0.06–0.25 per 0.05″ pixel)


def test_command_writes_the_mock_layout_with_truth_in_mgelens_conventions(tmp_path):
    folder = tmp_path / "L02" / "mock"
    code = main(
        [
            "simulate",
            "--independent-index",
            "2",
            "--image-size",
            "61",
            "--sub-size",
            "2",
            "--out",
            str(folder),
        ]
    )
    assert code == 0
    for name in simulate.MOCK_FILES.values():
        assert (folder / name).is_file(), name
    truth = json.loads((folder / "truth.json").read_text())
    lens = independent_lens(2)
    assert truth["simulated_with"].startswith("lenstronomy ")
    assert true_mass_parameters(truth)["mass.slope"] == pytest.approx(lens.mass[0].slope)
    assert simulate.mass_from_truth(truth) == list(lens.mass)
    assert true_light_centre(truth) == pytest.approx(lens.light_centre)
    imaging = Imaging.from_folder(folder)
    assert imaging.data.shape == (61, 61)
    assert fits.getheader(folder / "data.fits")["BUNIT"] == simulate.BRIGHTNESS_UNIT
    refused = main(
        ["simulate", "--independent-index", "2", "--seed", "4", "--out", str(tmp_path / "x")]
    )
    assert refused == 1

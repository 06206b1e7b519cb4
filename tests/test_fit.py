"""End-to-end tests of the semi-linear inversion (SPEC §4–7) on small synthetic lenses."""

import numpy as np
import pytest

from mgelens.fit import (
    REJECTED_LOG_LIKELIHOOD,
    FitDataset,
    LensModel,
    MGESource,
    PixelizedSource,
    SourceSystem,
    figure_of_merit,
    fit,
    pixelized_operator,
    source_light_columns,
)
from mgelens.fit_settings import FitSettings
from mgelens.geometry import ell_comps_from
from mgelens.grid import pixel_centres
from mgelens.imaging import Imaging
from mgelens.inversion.cholesky import InversionError
from mgelens.inversion.system import WeightedBlurredMapping
from mgelens.light import MGESet, Sersic
from mgelens.mass import SIE, ExternalShear
from mgelens.source.image_mesh import overlay_centres
from mgelens.source.regularization import Constant, ConstantSplit

PIXEL = 0.1
SHAPE = (41, 41)
MASK_RADIUS = 1.8
NOISE = 0.01


def gaussian_psf(size=5, sigma_pixels=0.8):
    yy, xx = np.mgrid[:size, :size] - size // 2
    psf = np.exp(-(xx**2 + yy**2) / (2 * sigma_pixels**2))
    return psf / psf.sum()


def make_dataset(data=None, settings=None, noise=NOISE):
    x, y = pixel_centres(SHAPE, PIXEL)
    mask = np.hypot(x, y) > MASK_RADIUS
    imaging = Imaging(
        data=np.zeros(SHAPE) if data is None else data,
        noise_map=np.full(SHAPE, noise),
        psf=gaussian_psf(),
        pixel_scale=PIXEL,
        mask=mask,
    )
    settings = settings or FitSettings(lp_sub_size_centre=8)
    return FitDataset.from_imaging(imaging, settings=settings)


def lens_sets():
    return (
        MGESet.extended((0.02, -0.03), ell_comps_from(0.75, 40.0), PIXEL, MASK_RADIUS, 12),
        MGESet.extended((0.02, -0.03), ell_comps_from(0.55, 70.0), PIXEL, MASK_RADIUS, 8),
    )


MASS = (SIE((0.02, -0.03), 1.1, 0.8, 40.0), ExternalShear(0.03, -0.02))


def true_intensities(n):
    return np.geomspace(20.0, 0.05, n)


def with_data(dataset, model_image):
    data = np.zeros(SHAPE)
    data[~dataset.mask] = model_image
    return make_dataset(data, dataset.settings)


def test_mge_only_noiseless_fit_recovers_intensities():
    blank = make_dataset()
    sets = lens_sets()
    columns = blank.lens_light_columns(sets)
    truth = true_intensities(columns.shape[1])
    dataset = with_data(blank, columns @ truth)
    for positive_only in (True, False):
        settings = FitSettings(lp_sub_size_centre=8, positive_only=positive_only, mge_diagonal=0)
        result = fit(make_dataset(dataset.imaging.data, settings), LensModel(lens_light=sets))
        assert np.allclose(result.lens_light_intensities, truth, rtol=1e-6)
        assert result.chi_squared < 1e-10
        assert result.log_evidence == result.log_likelihood


def source_truth(mesh_points):
    x, y = mesh_points[:, 0], mesh_points[:, 1]
    blob = 2.0 * np.exp(-((x - 0.05) ** 2 + (y + 0.02) ** 2) / (2 * 0.12**2))
    return blob + 0.8 * np.exp(-((x + 0.15) ** 2 + (y - 0.1) ** 2) / (2 * 0.06**2))


def pixelized_source(dataset, regularization, interpolation="natural_neighbour"):
    ox, oy = overlay_centres(dataset.mask, PIXEL, (16, 16))
    return PixelizedSource(ox, oy, regularization, interpolation)


def test_pixelized_noiseless_fit_recovers_lens_light_and_source():
    # μ = 0: the default μ = 1e-3 on the MGE diagonal biases individual intensities within
    # the near-degenerate MGE subspace (by up to ~20 % here) while leaving the image intact
    blank = make_dataset(settings=FitSettings(lp_sub_size_centre=8, mge_diagonal=0.0))
    sets = lens_sets()
    source = pixelized_source(blank, ConstantSplit(1e-6))
    operator = pixelized_operator(blank, MASS, source)  # the fit's own forward model
    mesh = operator.mesh
    fluxes = source_truth(mesh.points)
    fluxes[mesh.edge_pixels] = 0.0
    mapping = operator.blurred_mapping
    columns = blank.lens_light_columns(sets)
    truth = true_intensities(columns.shape[1])
    dataset = with_data(blank, columns @ truth + mapping @ fluxes)
    result = fit(dataset, LensModel(mass=MASS, lens_light=sets, source=source))
    assert np.allclose(result.lens_light_intensities, truth, rtol=1e-6)
    assert np.allclose(result.source.fluxes, fluxes, atol=1e-6 * fluxes.max())
    assert result.chi_squared < 1e-6
    assert np.all(result.solution.x >= 0.0)
    split = result.native(result.lens_light_image) + result.native(result.lensed_source_image)
    assert np.allclose(split[~dataset.mask], result.model_image)


@pytest.mark.parametrize("sparse_pass", [True, False])
def test_repeated_mass_and_source_reuse_the_source_system(sparse_pass, monkeypatch):
    """LIGHT-phase pattern: mass and source object fixed, lens light changing. From the
    second fit on, the source's part of the system is reused, with F_LS by either route
    (a sparse pass over W B f, or a transposed blur); every figure matches a fit on a
    fresh dataset (which builds the whole system by tiles)."""
    monkeypatch.setattr(WeightedBlurredMapping, "cheaper", lambda *args: sparse_pass)
    rng = np.random.default_rng(4)
    blank = make_dataset()
    data = np.zeros(SHAPE)
    data[~blank.mask] = rng.normal(0.05, NOISE, blank.data.size)
    dataset = make_dataset(data)
    source = pixelized_source(dataset, ConstantSplit(0.5))
    first, second = lens_sets()
    models = [
        LensModel(mass=MASS, lens_light=sets, source=source)
        for sets in ((first,), (second,), (first, second))
    ]
    for model in models + models[::-1]:
        reused = fit(dataset, model)
        fresh = fit(make_dataset(data), model)
        assert reused.log_evidence == pytest.approx(fresh.log_evidence, rel=1e-10)
        np.testing.assert_allclose(reused.solution.x, fresh.solution.x, rtol=1e-6, atol=1e-9)
        # warm-started (the sampler's calls): ln det(F_SS + H) comes from the system
        warm = fit(dataset, model, fresh.passive_set)
        assert warm.log_det_curvature_regularization == pytest.approx(
            fresh.log_det_curvature_regularization, rel=1e-12
        )
        assert warm.log_evidence == pytest.approx(fresh.log_evidence, rel=1e-10)
    system = dataset._source_cache["system"]
    assert (system.weighted_blurred is not None) == sparse_pass
    # another mass model (equal by value is enough) or source object starts afresh
    moved = (SIE((0.02, -0.03), 1.12, 0.8, 40.0), MASS[1])
    fit(dataset, LensModel(mass=moved, lens_light=(first,), source=source))
    assert dataset._source_cache.get("system") is None


def test_a_source_system_too_ill_conditioned_to_factorise_leaves_fits_to_the_general_route(
    monkeypatch,
):
    """Where F_SS + H cannot be factorised whole (an unconverged SPix2's regularization of
    4.6e5 did that to a LIGHT phase), the repeated source is not cached as a system, and
    each fit is the general route's, equal to a fit on a fresh dataset."""
    calls = []

    def unfactorisable(*args):
        calls.append(args)
        raise InversionError("matrix not positive definite (potrf info 60)")

    monkeypatch.setattr(SourceSystem, "build", unfactorisable)
    rng = np.random.default_rng(5)
    data = np.zeros(SHAPE)
    data[~make_dataset().mask] = rng.normal(0.05, NOISE, make_dataset().data.size)
    dataset = make_dataset(data)
    source = pixelized_source(dataset, ConstantSplit(0.5))
    model = LensModel(mass=MASS, lens_light=lens_sets()[:1], source=source)
    results = [fit(dataset, model) for _ in range(3)]
    assert len(calls) == 1  # tried once for this mass and source
    assert "system" in dataset._source_cache
    assert dataset._source_cache["system"] is None
    fresh = fit(make_dataset(data), model)
    for result in results:
        assert result.log_evidence == pytest.approx(fresh.log_evidence, rel=1e-12)


def test_the_source_system_keeps_the_factor_of_its_source_block():
    """The factor a warm start's Schur complement uses
    (:attr:`SourceSystem.curvature_regularization_factor`) is the Cholesky factor of
    F_SS + H, and its diagonal gives the system's ln det(F_SS + H)."""
    dataset = make_dataset()
    source = pixelized_source(dataset, ConstantSplit(0.5))
    model = LensModel(mass=MASS, lens_light=lens_sets()[:1], source=source)
    fit(dataset, model)
    fit(dataset, model)
    system = dataset._source_cache["system"]
    block = system.curvature_regularization
    factor = system.curvature_regularization_factor
    np.testing.assert_allclose(factor.T @ factor, block, rtol=0, atol=1e-12 * np.abs(block).max())
    assert np.allclose(np.tril(factor, -1), 0.0)
    assert system.log_det_curvature_regularization == pytest.approx(
        np.linalg.slogdet(block)[1], rel=1e-12
    )


def test_parametric_source_joins_the_linear_system():
    blank = make_dataset(settings=FitSettings(lp_sub_size_centre=8, mge_diagonal=0.0))
    sets = lens_sets()[:1]
    source_sets = (MGESet.extended((0.05, 0.0), ell_comps_from(0.8, 10.0), PIXEL, 1.0, 8),)
    lens_truth = true_intensities(12)
    source_truth_values = np.geomspace(5.0, 0.5, 8)
    image = blank.lens_light_columns(sets) @ lens_truth
    image += source_light_columns(blank, MASS, source_sets) @ source_truth_values
    model = LensModel(mass=MASS, lens_light=sets, source=MGESource(source_sets))
    result = fit(with_data(blank, image), model)
    assert (result.n_lens_light, result.n_source_light) == (12, 8)
    # Relative to the largest intensity: the normal equations of these 20 overlapping
    # Gaussians have a condition number of 3e9, so an intensity 400× below the largest
    # carries rounding errors of a few 1e-6 of its own value (seen as 3e-6 with another
    # CPU's BLAS kernels) while the normwise error stays below 1e-8.
    for solved, truth in (
        (result.lens_light_intensities, lens_truth),
        (result.source_light_intensities, source_truth_values),
    ):
        assert np.allclose(solved, truth, rtol=0.0, atol=1e-6 * truth.max())
    assert result.log_evidence == result.log_likelihood


def test_sersic_lens_light_is_solved_linearly_or_subtracted_when_fixed():
    """Two Sérsics + a source MGE: their I_e are recovered as linear unknowns (the
    profiles' own intensities are ignored); given as fixed light with the true I_e they
    are subtracted and only the source is solved."""
    blank = make_dataset(settings=FitSettings(lp_sub_size_centre=8, mge_diagonal=0.0))
    truth = (
        Sersic((0.02, -0.03), ell_comps_from(0.7, 40.0), 0.5, 3.5, intensity=2.0),
        Sersic((0.02, -0.03), ell_comps_from(0.5, 80.0), 1.2, 1.0, intensity=0.3),
    )
    source_sets = (MGESet.extended((0.05, 0.0), ell_comps_from(0.8, 10.0), PIXEL, 1.0, 8),)
    source_values = np.geomspace(5.0, 0.5, 8)
    lens_image = blank.light_grid.blurred_image(list(truth))
    image = lens_image + source_light_columns(blank, MASS, source_sets) @ source_values
    dataset = with_data(blank, image)
    unit = tuple(Sersic(s.centre, s.ell_comps, s.effective_radius, s.sersic_index) for s in truth)
    linear = fit(dataset, LensModel(MASS, lens_light=unit, source=MGESource(source_sets)))
    assert (linear.n_lens_light, linear.n_source_light) == (2, 8)
    assert np.allclose(linear.lens_light_intensities, [2.0, 0.3], rtol=1e-6)
    assert np.allclose(linear.source_light_intensities, source_values, rtol=1e-6)
    assert linear.chi_squared < 1e-8
    fixed = fit(dataset, LensModel(MASS, fixed_light=truth, source=MGESource(source_sets)))
    assert fixed.n_lens_light == 0
    assert np.allclose(fixed.source_light_intensities, source_values, rtol=1e-6)
    assert np.allclose(fixed.lens_light_image, lens_image, rtol=1e-12)
    wrong = fit(dataset, LensModel(MASS, lens_light=unit[:1], source=MGESource(source_sets)))
    assert wrong.chi_squared > 1e3


def test_quick_psf_trim_changes_model_images_far_below_the_noise():
    """The quick profile's psf_trim = 1e−4 cuts the mock's 21×21 Gaussian PSF (σ = 1 pixel)
    to 9×9, dropping 6e−6 of its flux; lens light and lensed source then change by less
    than 2e−5 of their peak (M1's peak S/N is a few hundred: far below the noise)."""
    x, y = pixel_centres(SHAPE, PIXEL)
    psf = gaussian_psf(21, 1.0)
    imaging = Imaging(np.zeros(SHAPE), np.full(SHAPE, NOISE), psf, PIXEL, mask=np.hypot(x, y) > 1.8)
    images = []
    for trim in (0.0, 1e-4):
        dataset = FitDataset.from_imaging(imaging, settings=FitSettings(psf_trim=trim))
        images.append(
            (
                dataset.light_grid.blurred_image(
                    [Sersic((0.02, -0.03), ell_comps_from(0.7, 40.0), 0.5, 4.0, intensity=5.0)]
                ),
                source_light_columns(dataset, MASS, lens_sets()[:1]) @ true_intensities(12),
            )
        )
    assert dataset.convolver.psf.shape == (9, 9)
    for wide, cut in zip(*images, strict=True):
        assert np.abs(cut - wide).max() < 2e-5 * np.abs(wide).max()
        assert np.abs(cut - wide).max() > 1e-8 * np.abs(wide).max()  # the cut is real


def test_evidence_peaks_near_the_true_regularization_strength():
    rng = np.random.default_rng(11)
    true_coefficient = 3.0
    settings = FitSettings(positive_only=False, use_border=True, lp_sub_size_centre=8)
    blank = make_dataset(settings=settings)
    source = pixelized_source(blank, Constant(true_coefficient))
    operator = pixelized_operator(blank, MASS, source)
    h = operator.regularization_matrix.toarray()
    eigenvalues, vectors = np.linalg.eigh(h)
    modes = eigenvalues > 1e-6  # drop the (jitter-only) constant mode
    draw = vectors[:, modes] @ (rng.normal(size=modes.sum()) / np.sqrt(eigenvalues[modes]))
    mapping = operator.blurred_mapping
    noise = 0.002
    data = np.zeros(SHAPE)
    data[~blank.mask] = mapping @ draw + rng.normal(scale=noise, size=mapping.shape[0])
    dataset = make_dataset(data, settings, noise=noise)
    coefficients = np.geomspace(0.3, 30.0, 21)
    evidences = [
        fit(dataset, LensModel(mass=MASS, source=pixelized_source(blank, Constant(c)))).log_evidence
        for c in coefficients
    ]
    best = coefficients[int(np.argmax(evidences))]
    assert true_coefficient / 1.5 <= best <= true_coefficient * 1.5
    assert evidences[0] < max(evidences) - 5
    assert evidences[-1] < max(evidences) - 5


def test_non_negative_and_unconstrained_solutions_differ_on_lensed_arcs():
    rng = np.random.default_rng(5)
    blank = make_dataset()
    sets = (MGESet.extended((0.02, -0.03), ell_comps_from(0.75, 40.0), PIXEL, MASK_RADIUS, 30),)
    source_sets = (MGESet.extended((0.05, 0.0), ell_comps_from(0.8, 10.0), PIXEL, 0.3, 5),)
    columns = blank.lens_light_columns(sets)
    lens = columns @ (3.0 * np.exp(-np.linspace(0, 6, 30)))
    image = lens + source_light_columns(blank, MASS, source_sets) @ np.full(5, 2.0)
    data = np.zeros(SHAPE)
    data[~blank.mask] = image + rng.normal(scale=NOISE, size=image.size)
    model = LensModel(
        mass=MASS, lens_light=sets, source=pixelized_source(blank, ConstantSplit(1.0))
    )
    nn = fit(make_dataset(data), model)
    pn = fit(make_dataset(data, FitSettings(positive_only=False, lp_sub_size_centre=8)), model)
    assert np.all(nn.solution.x >= 0.0)
    assert np.any(nn.solution.active_zero)
    assert np.any(pn.lens_light_intensities < 0.0)
    # the 3×Sérsic runs' solve (SPEC §8.1): lens light ≥ 0, source free. Its feasible set
    # lies between nn's and pn's, so the minimised χ² + sᵀHs + μ|x_light|² lies between
    free = fit(make_dataset(data, FitSettings(free_source=True, lp_sub_size_centre=8)), model)
    assert np.all(free.lens_light_intensities >= 0.0)
    assert np.any(free.lens_light_intensities == 0.0)
    assert np.any(free.source.fluxes < 0.0)

    def minimised(result):
        mu = result.dataset.settings.mge_diagonal
        light = result.lens_light_intensities
        return result.chi_squared + result.regularization_term + mu * light @ light

    assert minimised(pn) < minimised(free) < minimised(nn)


def test_degenerate_mesh_is_rejected_not_raised():
    dataset = make_dataset(np.ones(SHAPE))
    source = PixelizedSource(np.zeros(10), np.zeros(10), Constant(1.0))
    value, reason = figure_of_merit(dataset, LensModel(mass=MASS, source=source))
    assert value == REJECTED_LOG_LIKELIHOOD
    assert "MeshError" in reason


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_log_evidence_is_rejected_not_returned(monkeypatch, bad):
    """A numerical failure that raises nothing must not reach the sampler (SPEC §8.4)."""
    import mgelens.fit as fit_module

    class Result:
        log_evidence = bad

    monkeypatch.setattr(fit_module, "fit", lambda dataset, model, passive_start=None: Result())
    value, reason = figure_of_merit(make_dataset(), LensModel(lens_light=lens_sets()))
    assert value == REJECTED_LOG_LIKELIHOOD
    assert reason == f"log evidence is {bad}"


def test_model_without_linear_light_is_a_clear_error():
    with pytest.raises(ValueError, match="no linear light"):
        fit(make_dataset(np.ones(SHAPE)), LensModel(mass=MASS))
    with pytest.raises(ValueError, match="interpolation"):
        PixelizedSource(np.zeros(3), np.zeros(3), Constant(1.0), interpolation="cubic")

"""The smoothness prior on the MGE lens light (mgelens.light_prior): its matrix, its
evidence terms against the Gaussian marginal likelihood computed independently, and its
plumbing through LIGHT and MASS."""

import numpy as np
import pytest

from mgelens.fit import FitDataset, LensModel, MGESource, fit
from mgelens.fit_settings import FitSettings
from mgelens.geometry import ell_comps_from
from mgelens.grid import pixel_centres
from mgelens.imaging import Imaging
from mgelens.light import MGESet
from mgelens.light_prior import RIDGE, MGESmoothnessPrior, smoothness_matrix
from mgelens.mass import SIE
from mgelens.recovery import true_light_refit

PIXEL = 0.1
SHAPE = (25, 25)
NOISE = 0.02


def dataset_of(data: np.ndarray, settings: FitSettings, noise: np.ndarray | None = None):
    x, y = pixel_centres(SHAPE, PIXEL)
    psf = np.exp(-np.add.outer(*(2 * [np.arange(-2, 3) ** 2])) / (2 * 0.8**2))
    imaging = Imaging(
        data,
        np.full(SHAPE, NOISE) if noise is None else noise,
        psf / psf.sum(),
        PIXEL,
        mask=np.hypot(x, y) > 1.1,
    )
    return FitDataset.from_imaging(imaging, settings=settings)


def sets() -> tuple[MGESet, ...]:
    extended = MGESet.extended((0.01, -0.02), ell_comps_from(0.8, 30.0), PIXEL, 1.2, 12)
    return extended, MGESet.point((0.01, -0.02), (0.0, 0.0), PIXEL)


def noisy_galaxy(settings: FitSettings, seed: int = 0):
    """A smooth galaxy (the extended set with geometric intensities) plus noise."""
    blank = dataset_of(np.zeros(SHAPE), settings)
    components = sets()
    columns = blank.lens_light_columns(components[:1])
    image = np.zeros(SHAPE)
    image[~blank.mask] = columns @ np.geomspace(3.0, 0.01, columns.shape[1])
    image += np.random.default_rng(seed).normal(0.0, NOISE, SHAPE)
    return dataset_of(image, settings), components


def test_the_matrix_is_the_weighted_second_differences_of_the_fluxes():
    sigmas = np.geomspace(0.02, 1.5, 9)
    matrix, log_det = smoothness_matrix(sigmas, 250.0)
    fluxes = np.random.default_rng(1).normal(size=9)
    intensities = fluxes / sigmas**2
    expected = 250.0 * (np.sum(np.diff(fluxes, 2) ** 2) + RIDGE * np.sum(fluxes**2))
    assert intensities @ matrix @ intensities == pytest.approx(expected, rel=1e-10)
    sign, direct = np.linalg.slogdet(matrix)
    assert sign == 1
    assert log_det == pytest.approx(direct, rel=1e-9)
    linear = np.ones(9) * 0.5 + 0.1 * np.arange(9)  # no curvature: only the ridge pays
    assert (linear / sigmas**2) @ matrix @ (linear / sigmas**2) == pytest.approx(
        250.0 * RIDGE * np.sum(linear**2)
    )


def test_the_evidence_is_the_gaussian_marginal_likelihood_of_the_data():
    """With the unconstrained solve and no μ on the diagonal, ln ε with the prior is
    ln N(d; 0, C), C = N + A(λR)⁻¹Aᵀ over the penalised columns (the point set is not
    penalised, so the test fits the extended set alone)."""
    settings = FitSettings(lp_sub_size_centre=8, positive_only=False, mge_diagonal=0.0)
    dataset, components = noisy_galaxy(settings)
    extended = components[:1]
    for coefficient in (1e-2, 3.0, 300.0):
        prior = MGESmoothnessPrior(coefficient, (True,))
        result = fit(dataset, LensModel(lens_light=extended, lens_light_prior=prior))
        a = dataset.lens_light_columns(extended)
        r, _ = smoothness_matrix(extended[0].sigmas, dataset.median_inverse_variance)
        covariance = np.diag(dataset.noise_map**2) + a @ np.linalg.solve(coefficient * r, a.T)
        sign, log_det = np.linalg.slogdet(2 * np.pi * covariance)
        marginal = -0.5 * (dataset.data @ np.linalg.solve(covariance, dataset.data) + log_det)
        assert sign == 1
        assert result.log_evidence == pytest.approx(marginal, abs=1e-6 * abs(marginal))
        assert result.log_evidence == pytest.approx(
            result.log_likelihood + result.lens_light_prior.log_evidence_change
        )


def test_the_prior_smooths_the_amplitudes_and_the_evidence_picks_a_finite_lambda():
    settings = FitSettings(lp_sub_size_centre=8)
    dataset, components = noisy_galaxy(settings, seed=3)
    penalised = (True, False)
    free = fit(dataset, LensModel(lens_light=components))
    evidences, roughness = {}, {}
    for coefficient in (1e-4, 1e-1, 1e2, 1e5, 1e8):
        result = fit(
            dataset,
            LensModel(
                lens_light=components, lens_light_prior=MGESmoothnessPrior(coefficient, penalised)
            ),
        )
        fluxes = result.lens_light_intensities[:12] * components[0].sigmas ** 2
        evidences[coefficient] = result.log_evidence
        roughness[coefficient] = np.sum(np.diff(fluxes, 2) ** 2)
        assert result.chi_squared >= free.chi_squared - 1e-6
    free_fluxes = free.lens_light_intensities[:12] * components[0].sigmas ** 2
    best = max(evidences, key=evidences.get)
    assert best not in (1e-4, 1e8)  # an interior maximum: neither no prior nor a flat one
    assert roughness[best] < 0.2 * np.sum(np.diff(free_fluxes, 2) ** 2)


def test_the_prior_needs_a_positive_coefficient_and_matching_components():
    with pytest.raises(ValueError, match="positive"):
        MGESmoothnessPrior(0.0, (True,))
    settings = FitSettings(lp_sub_size_centre=8)
    dataset, components = noisy_galaxy(settings)
    with pytest.raises(ValueError, match="flags 1 components"):
        fit(
            dataset,
            LensModel(lens_light=components, lens_light_prior=MGESmoothnessPrior(1.0, (True,))),
        )
    with pytest.raises(ValueError, match="no MGE set"):
        fit(
            dataset,
            LensModel(
                lens_light=components, lens_light_prior=MGESmoothnessPrior(1.0, (False, False))
            ),
        )


def test_the_true_light_refit_drops_the_prior_with_the_light():
    """recovery.true_light_refit replaces the lens light by the truth: the prior goes with
    it, and the fitted side's ln ε keeps the prior's terms."""
    settings = FitSettings(lp_sub_size_centre=8)
    dataset, components = noisy_galaxy(settings)
    source = MGESource((MGESet((0.05, 0.0), (0.0, 0.0), np.geomspace(0.02, 0.3, 6)),))
    mass = (SIE((0.0, 0.0), 0.6, 0.8, 30.0),)
    prior = MGESmoothnessPrior(100.0, (True, False))
    model = LensModel(mass=mass, lens_light=components, source=source, lens_light_prior=prior)
    own = fit(dataset, model)
    true_light = np.zeros(SHAPE)
    true_light[~dataset.mask] = own.lens_light_image
    refit = true_light_refit(dataset, model, true_light)
    assert refit.lens_light_prior_coefficient == 100.0
    assert refit.log_evidence == pytest.approx(own.log_evidence)
    assert own.log_evidence < own.log_likelihood  # the prior's Occam terms
    without = fit(dataset, LensModel(mass=mass, source=source))  # no lens light at all
    assert refit.true_light_chi_squared <= without.chi_squared

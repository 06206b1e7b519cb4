"""The source's support (issue #32): arc pixels, reached source pixels, the restricted
linear system and its evidence, against brute-force algebra and a truth-known lens."""

import dataclasses

import numpy as np
import pytest

from mgelens.fit import FitDataset, LensModel, PixelizedSource, fit, pixelized_operator
from mgelens.fit_settings import FitSettings
from mgelens.geometry import ell_comps_from
from mgelens.grid import pixel_centres
from mgelens.imaging import Imaging
from mgelens.inversion.evidence import noise_normalization
from mgelens.light import MGESet
from mgelens.mass import SIE, ExternalShear, ray_trace
from mgelens.source.image_mesh import kmeans_centres, kmeans_weights
from mgelens.source.mesh import MeshError
from mgelens.source.regularization import Constant
from mgelens.source.support import arc_pixels, reached_source_pixels

PIXEL, SHAPE, MASK_RADIUS = 0.1, (61, 61), 3.0
MASS = (SIE((0.0, 0.0), 1.1, 0.8, 40.0), ExternalShear(0.02, -0.01))
SOURCE_CENTRE, SOURCE_SIGMA = (0.08, 0.05), 0.12
NOISE = 0.02


def _psf():
    yy, xx = np.mgrid[:5, :5] - 2
    psf = np.exp(-(xx**2 + yy**2) / (2 * 0.8**2))
    return psf / psf.sum()


def _dataset(data, settings):
    x, y = pixel_centres(SHAPE, PIXEL)
    imaging = Imaging(
        data=data,
        noise_map=np.full(SHAPE, NOISE),
        psf=_psf(),
        pixel_scale=PIXEL,
        mask=np.hypot(x, y) > MASK_RADIUS,
    )
    return FitDataset.from_imaging(imaging, settings=settings)


@pytest.fixture(scope="module")
def lens():
    """A lens whose light (one MGE set, broad in σ, reaching the 3″ mask's edge) dominates
    beyond the ring, and a compact Gaussian source (σ 0.12″): the truth known pixel by
    pixel, with Gaussian noise."""
    settings = FitSettings(lp_sub_size_centre=4, force_edge_pixels_to_zero=False)
    blank = _dataset(np.zeros(SHAPE), settings)
    sets = (MGESet.extended((0.0, 0.0), ell_comps_from(0.75, 40.0), PIXEL, MASK_RADIUS, 12),)
    intensities = 3.0 * np.exp(-(np.log(sets[0].sigmas / 0.6) ** 2) / 2.0)
    lens_light = blank.lens_light_columns(sets) @ intensities
    grid = blank.source_grid
    bx, by = ray_trace(MASS, grid.x, grid.y)
    r2 = (bx - SOURCE_CENTRE[0]) ** 2 + (by - SOURCE_CENTRE[1]) ** 2
    source = 2.0 * np.exp(-r2 / (2 * SOURCE_SIGMA**2))
    lensed = blank.source_psf_operator @ source.reshape(-1, settings.sub_size**2).mean(axis=1)
    data = np.zeros(SHAPE)
    data[~blank.mask] = lens_light + lensed + np.random.default_rng(1).normal(0, NOISE, lensed.size)
    dataset = _dataset(data, settings)
    x, y = dataset.pixel_centres
    weights = kmeans_weights(lensed, 0.2, 2.0, "2023")
    centres = kmeans_centres(x, y, weights, 300, 0)
    return dict(dataset=dataset, sets=sets, lens_light=lens_light, lensed=lensed, centres=centres)


def _model(lens, threshold, coefficient=1.0):
    arcs = None if threshold is None else arc_pixels(lens["lensed"], threshold)
    source = PixelizedSource(*lens["centres"], Constant(coefficient), arc_pixels=arcs)
    return LensModel(mass=MASS, lens_light=lens["sets"], source=source)


def test_arc_pixels_select_above_the_fraction_of_the_peak():
    adapt = np.array([0.0, 0.5, 1.0, 2.0, 4.0])
    assert arc_pixels(adapt, 0.2).tolist() == [False, False, True, True, True]
    with pytest.raises(ValueError, match=r"\(0, 1\)"):
        arc_pixels(adapt, 1.0)
    with pytest.raises(ValueError, match="no positive pixel"):
        arc_pixels(-adapt, 0.1)


def test_a_noise_floor_keeps_only_arc_pixels_above_both():
    """The relative threshold and the per-pixel floor must both be exceeded: a pixel above
    the threshold but under its own floor (here its noise is high) is dropped."""
    adapt = np.array([0.0, 0.5, 1.0, 2.0, 4.0])
    floor = np.array([0.1, 0.1, 3.0, 1.0, 1.0])
    assert arc_pixels(adapt, 0.2, floor).tolist() == [False, False, False, True, True]
    assert arc_pixels(adapt, 0.05, floor).tolist() == [False, True, False, True, True]


def test_reached_source_pixels_are_the_columns_the_arcs_weigh(lens):
    """Against the dense mapping matrix: a source pixel is reached when some arc pixel
    gives it a positive weight."""
    dataset = lens["dataset"]
    operator = pixelized_operator(dataset, MASS, _model(lens, None).source)
    arcs = arc_pixels(lens["lensed"], 0.03)
    dense = operator.mapping.toarray()
    expected = (dense[arcs] > 0).any(axis=0)
    reached = reached_source_pixels(operator.mapping, arcs)
    assert np.array_equal(reached, expected)
    assert 0 < reached.sum() < reached.size


def test_the_supported_fit_is_the_system_without_the_other_pixels(lens):
    """The unconstrained fit with a support against numpy on the dense system with the
    unreached pixels' columns (and H's rows and columns) removed: same χ², same ln ε."""
    dataset = lens["dataset"]
    free = dataclasses.replace(dataset.settings, positive_only=False)
    dataset = FitDataset.from_imaging(dataset.imaging, dataset.mask, free)
    model = _model(lens, 0.03)
    result = fit(dataset, model)
    full = pixelized_operator(dataset, MASS, dataclasses.replace(model.source, arc_pixels=None))
    kept = reached_source_pixels(full.mapping, model.source.arc_pixels)
    blurred = (full.psf_operator @ full.mapping).toarray()[:, kept]
    columns = np.hstack([dataset.lens_light_columns(lens["sets"]), blurred])
    h = full.regularization_matrix.toarray()[np.ix_(kept, kept)]
    n_lens = columns.shape[1] - h.shape[0]
    w = 1.0 / dataset.noise_map**2
    q = columns.T @ (columns * w[:, None])
    q[n_lens:, n_lens:] += h
    q[np.arange(n_lens), np.arange(n_lens)] += dataset.settings.mge_diagonal
    x = np.linalg.solve(q, columns.T @ (w * dataset.data))
    chi2 = float(np.sum((dataset.data - columns @ x) ** 2 * w))
    s = x[n_lens:]
    log_ev = -0.5 * (
        chi2
        + s @ h @ s
        + np.linalg.slogdet(q[n_lens:, n_lens:])[1]
        - np.linalg.slogdet(h)[1]
        + noise_normalization(dataset.noise_map)
    )
    assert result.chi_squared == pytest.approx(chi2, rel=1e-8)
    assert result.log_evidence == pytest.approx(log_ev, rel=1e-9)
    assert result.source.fluxes.size == kept.size
    assert np.all(result.source.fluxes[~kept] == 0.0)
    assert np.allclose(result.source.fluxes[kept], s)


def test_the_support_recovers_the_lens_light_and_the_evidence_prefers_it(lens):
    """On the truth-known lens, at the true mass and lens-light geometry: the source on the
    whole mask takes 1-2 % of the lens light (more beyond the ring), the source on the
    arcs' support leaves it within 0.3 %, and the evidence prefers the support by
    hundreds, for every regularization strength tried."""
    dataset = lens["dataset"]
    x, y = dataset.pixel_centres
    beyond = np.hypot(x, y) > 0.2
    true_light = lens["lens_light"][beyond]
    for coefficient in (0.3, 1.0, 3.0):
        whole = fit(dataset, _model(lens, None, coefficient))
        arcs = fit(dataset, _model(lens, 0.03, coefficient))
        whole_error = np.mean((whole.lens_light_image[beyond] - true_light) / true_light)
        arcs_error = np.mean((arcs.lens_light_image[beyond] - true_light) / true_light)
        assert whole_error < -0.01
        assert abs(arcs_error) < 0.003
        assert arcs.log_evidence > whole.log_evidence + 300


def test_a_noise_floor_keeps_an_adapt_images_faint_pedestal_out_of_the_support(lens):
    """An earlier source that took some smooth lens light leaves a faint pedestal (half the
    noise) in the adapt image: at a threshold below it every pixel is an arc pixel, the
    source may fill the mask and takes lens light beyond the ring; a 3 σ floor drops the
    pedestal, keeps the arcs and leaves the lens light within 0.3 %, as the threshold
    does on a clean adapt image."""
    dataset = lens["dataset"]
    x, y = dataset.pixel_centres
    beyond = np.hypot(x, y) > 0.2
    true_light = lens["lens_light"][beyond]
    adapt = lens["lensed"] + 0.5 * NOISE
    threshold = 0.25 * NOISE / adapt.max()
    model = _model(lens, None)
    errors = {}
    for label, floor in (("threshold alone", None), ("floor", np.full(adapt.size, 3 * NOISE))):
        arcs = arc_pixels(adapt, threshold, floor)
        result = fit(
            dataset,
            dataclasses.replace(model, source=dataclasses.replace(model.source, arc_pixels=arcs)),
        )
        errors[label] = np.mean((result.lens_light_image[beyond] - true_light) / true_light)
        if floor is None:
            assert arcs.all()
        else:
            assert np.array_equal(arcs, lens["lensed"] > 2.5 * NOISE)
    assert errors["threshold alone"] < -0.01
    assert abs(errors["floor"]) < 0.003


def test_a_support_no_source_pixel_reaches_is_rejected(lens):
    dataset = lens["dataset"]
    model = _model(lens, None)
    nowhere = np.zeros(dataset.data.size, dtype=bool)
    source = dataclasses.replace(model.source, arc_pixels=nowhere)
    with pytest.raises(MeshError, match="no source pixel"):
        pixelized_operator(dataset, MASS, source)


def test_hull_pixels_inside_the_support_stay_zero_under_the_anchor_rule(lens):
    """With ``force_edge_pixels_to_zero`` (SPEC §6.3) the rule applies to the supported
    pixels on the mesh's hull, and every unreached pixel is zero as well."""
    dataset = lens["dataset"]
    anchor = dataclasses.replace(dataset.settings, force_edge_pixels_to_zero=True)
    dataset = FitDataset.from_imaging(dataset.imaging, dataset.mask, anchor)
    half = dataset.pixel_centres[0] > 0.0  # "arcs" on one side: they reach part of the hull
    model = _model(lens, None)
    model = dataclasses.replace(model, source=dataclasses.replace(model.source, arc_pixels=half))
    result = fit(dataset, model)
    full = pixelized_operator(dataset, MASS, dataclasses.replace(model.source, arc_pixels=None))
    kept = reached_source_pixels(full.mapping, model.source.arc_pixels)
    edge = result.source.mesh.edge_pixels
    assert (edge & kept).any()
    assert np.all(result.source.fluxes[edge | ~kept] == 0.0)
    assert result.source.fluxes.max() > 0.0


def test_a_warm_start_carries_over_between_masses_whose_supports_differ(lens):
    """MASS warm-starts every sample's NNLS from one reference fit, while the support
    follows each sample's mass: the reference's passive set over every mesh point is cut
    to the sample's support, and the solution is the cold one."""
    dataset = lens["dataset"]
    reference = fit(dataset, _model(lens, 0.03))
    other = dataclasses.replace(
        _model(lens, 0.03), mass=(SIE((0.01, 0.0), 1.15, 0.78, 42.0), ExternalShear(0.02, -0.01))
    )
    cold = fit(dataset, other)
    assert cold.source.support.sum() != reference.source.support.sum()
    warm = fit(dataset, other, passive_start=reference.passive_set)
    assert reference.passive_set.size == reference.n_lens_light + reference.source.fluxes.size
    assert warm.log_evidence == pytest.approx(cold.log_evidence, rel=1e-10)
    np.testing.assert_allclose(warm.source.fluxes, cold.source.fluxes, atol=1e-8)


def test_a_held_support_keeps_the_solved_pixels_of_its_mass(lens):
    """LIGHT and MASS hold SPix2's support (``support_mass``): at another mass the same
    mesh points are solved as at the held one, not those the new trace would reach."""
    dataset = lens["dataset"]
    held = _model(lens, 0.03)
    moved = (SIE((0.01, 0.0), 1.15, 0.78, 42.0), ExternalShear(0.02, -0.01))
    source = dataclasses.replace(held.source, support_mass=MASS)
    at_held = fit(dataset, dataclasses.replace(held, source=source))
    at_moved = fit(dataset, dataclasses.replace(held, mass=moved, source=source))
    following = fit(dataset, dataclasses.replace(held, mass=moved))
    assert np.array_equal(at_moved.source.support, at_held.source.support)
    assert not np.array_equal(following.source.support, at_held.source.support)
    assert at_moved.log_evidence != pytest.approx(following.log_evidence)
    assert np.all(at_moved.source.fluxes[~at_held.source.support] == 0.0)


def test_held_adaptive_signals_are_those_of_their_mass_at_any_fitted_mass(lens):
    """``signals_mass`` (``slam.adaptive_signals_mass: spix2``): at the held mass the fit is
    the unheld one; at another mass H is the split matrix of the new mesh weighted by the
    signals of the held mass's trace (built here by hand), not the new trace's."""
    from mgelens.source.regularization import (
        AdaptiveBrightnessSplit,
        adaptive_pixel_signals,
        adaptive_weights,
        split_matrix,
    )

    dataset = lens["dataset"]
    regularization = AdaptiveBrightnessSplit(0.5, 3.0, 0.6, signals="weighted")
    free = PixelizedSource(*lens["centres"], regularization, adapt_image=lens["lensed"])
    held = dataclasses.replace(free, signals_mass=MASS)
    model = LensModel(mass=MASS, lens_light=lens["sets"], source=held)
    at_mass = fit(dataset, model)
    assert at_mass.log_evidence == pytest.approx(
        fit(dataset, dataclasses.replace(model, source=free)).log_evidence, rel=1e-12
    )
    moved = (SIE((0.02, -0.01), 1.13, 0.76, 43.0), ExternalShear(0.03, -0.02))
    at_moved = fit(dataset, dataclasses.replace(model, mass=moved))
    following = fit(dataset, dataclasses.replace(model, mass=moved, source=free))
    signals = adaptive_pixel_signals(
        pixelized_operator(dataset, MASS, free).weights, lens["lensed"], 0.6, "weighted"
    )
    mesh = pixelized_operator(dataset, moved, free).mesh
    expected = split_matrix(mesh, adaptive_weights(signals, 0.5, 3.0) ** 2)
    held_h = at_moved.source.regularization_matrix
    assert abs(held_h - expected).max() <= 1e-12 * abs(expected).max()
    assert abs(following.source.regularization_matrix - expected).max() > 1e-3 * abs(expected).max()
    assert at_moved.log_evidence != pytest.approx(following.log_evidence, rel=1e-9)

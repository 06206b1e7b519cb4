"""Phase LIGHT (SPEC §8.1): the lens light refitted (N×30 MGE sets and the point set, or
3 Sérsics) with the mass (SPix1) and the source (SPix2) fixed."""

from collections.abc import Sequence
from pathlib import Path

from mgelens.pipeline import models
from mgelens.pipeline.parameters import lens_parameter
from mgelens.pipeline.problem import (
    PhaseProblem,
    earlier_phases,
    imaging_files,
    kmeans_source,
    load_dataset,
)
from mgelens.pipeline.settings import LensSpec, SlamSettings
from mgelens.search.model import ParameterSpace
from mgelens.search.priors import Uniform
from mgelens.search.results import PhaseResult


def space(
    specs: Sequence[models.LightSpec],
    sp: PhaseResult,
    spix1: PhaseResult,
    spix2: PhaseResult,
    smoothness_prior: bool = False,
) -> ParameterSpace:
    """LIGHT: refit with centres U(c_SP ± 0.1″), extended ell_comps U(−0.7, 0.7),
    point-set ell_comps N(0, 0.3) on [−1, 1]; mass fixed (SPix1), source fixed (SPix2):
    2 + 2 N_sets (+ 4 with the point set) free parameters for the MGE, 2 + 4 N for N
    Sérsics (R_e U(0, 30″), n U(0.8, 5)); with ``smoothness_prior`` one more, λ of the
    MGE's smoothness prior (:data:`~mgelens.pipeline.models.SMOOTHNESS_PRIOR`)."""
    cx, cy = models.light_centre(sp)
    h = models.LIGHT_PHASE_CENTRE_HALF_WIDTH
    centre = (Uniform(cx - h, cx + h), Uniform(cy - h, cy + h))
    light = models.lens_light_parameters(specs, centre, models.LIGHT_PHASE_ELL_COMPS_PRIOR, centre)
    if smoothness_prior:
        light.append(lens_parameter(models.SMOOTHNESS, prior=models.SMOOTHNESS_PRIOR))
    return ParameterSpace(
        (
            *light,
            *models.frozen_component(spix1, models.MASS),
            *models.frozen_component(spix1, models.SHEAR),
            *models.frozen_component(spix2, models.MESH),
            *models.frozen_component(spix2, models.REGULARIZATION),
        )
    )


def problem(
    lens_dir: Path, results_dir: Path, settings: SlamSettings, lens: LensSpec
) -> PhaseProblem:
    """LIGHT: MGE refit (N×30 + point set) or 3 Sérsics, mass (SPix1) and source (SPix2)
    fixed; the MGE with its smoothness prior's λ if ``settings.lens_light_prior`` asks."""
    sp, spix1, spix2 = earlier_phases(results_dir, settings, "sp", "spix1", "spix2")
    sp.check_lens_light(settings)
    dataset, radius = load_dataset(lens_dir, settings, lens, models.light_centre(sp.result))
    kmeans, adapt_path = kmeans_source(
        dataset, results_dir, settings, spix2.source_pixels(settings)
    )
    source = kmeans.fixed(spix2.result.max_likelihood)
    specs = (
        models.sersic_specs(3)
        if settings.lens_light_model == "sersic"
        else models.mge_specs(lens.mge_sets, lens.point_set, dataset.imaging.pixel_scale, radius)
    )
    prior = settings.lens_light_prior == "smoothness"
    return PhaseProblem(
        "light",
        dataset,
        space(specs, sp.result, spix1.result, spix2.result, prior),
        models.PhaseModel(specs, source, smoothness_prior=prior),
        (*imaging_files(lens_dir), *sp.files, *spix1.files, *spix2.files, adapt_path),
        radius,
    )

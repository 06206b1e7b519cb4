"""Phase SPix2 (SPEC §8.1): lens light (SP) and mass (SPix1) fixed; the k-means source
mesh and AdaptiveBrightnessSplit regularization hyper-parameters free: 5 free
parameters, 6 with the arcs' source support (``slam.source_support: arcs``)."""

from pathlib import Path

from mgelens.pipeline import models
from mgelens.pipeline.problem import (
    PhaseInputError,
    PhaseProblem,
    earlier_phases,
    imaging_files,
    kmeans_source,
    load_dataset,
    sp_light_model,
)
from mgelens.pipeline.settings import LensSpec, SlamSettings
from mgelens.search.model import ParameterSpace
from mgelens.search.priors import Uniform
from mgelens.search.results import PhaseResult


def space(sp: PhaseResult, spix1: PhaseResult, source_support: str = "mask") -> ParameterSpace:
    """SPix2: lens light fixed (SP), mass fixed (SPix1); W_floor U(0, 1), p U(0, 20),
    λ_in, λ_out LogUniform(1e−6, 1e6), κ_s U(0, 1): 5 free parameters, and with
    ``source_support`` "arcs" the arc threshold LogUniform(1e−3, 0.3): 6."""
    hyper = {
        "mesh.weight_floor": Uniform(0.0, 1.0),
        "mesh.weight_power": Uniform(0.0, 20.0),
        "regularization.inner_coefficient": models.COEFFICIENT_PRIOR,
        "regularization.outer_coefficient": models.COEFFICIENT_PRIOR,
        "regularization.signal_scale": Uniform(0.0, 1.0),
    }
    if source_support == "arcs":
        hyper[models.ARC_THRESHOLD] = models.ARC_THRESHOLD_PRIOR
    return ParameterSpace(
        (
            *models.frozen_component(sp, models.LENS_LIGHT),
            *models.frozen_component(spix1, models.MASS),
            *models.frozen_component(spix1, models.SHEAR),
            *models.free_parameters(hyper),
        )
    )


def problem(
    lens_dir: Path, results_dir: Path, settings: SlamSettings, lens: LensSpec
) -> PhaseProblem:
    """SPix2: lens light (SP) and mass (SPix1) fixed, k-means mesh + AdaptiveBrightnessSplit
    hyper-parameters (and the arc threshold of an arcs' support) free."""
    sp, spix1 = earlier_phases(results_dir, settings, "sp", "spix1")
    sp.check_lens_light(settings)
    dataset, radius = load_dataset(lens_dir, settings, lens, models.light_centre(sp.result))
    if len(settings.source_pixel_candidates) > 1:
        raise PhaseInputError(
            f"SPix2 fits one source pixel count, but slam.source_pixels is "
            f"{list(settings.source_pixels)}: fit each count into its own folder "
            '(mgelens phase spix2 --folder spix2_n<count> --slam \'{"source_pixels": '
            "<count>, ...}') and choose with mgelens choose --source-pixels, as the workflow does"
        )
    source, adapt_path = kmeans_source(dataset, results_dir, settings, settings.source_pixels)
    return PhaseProblem(
        "spix2",
        dataset,
        space(sp.result, spix1.result, settings.source_support),
        sp_light_model(sp, source),
        (*imaging_files(lens_dir), *sp.files, *spix1.files, adapt_path),
        radius,
    )

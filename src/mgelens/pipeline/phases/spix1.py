"""Phase SPix1 (SPEC §8.1): SP's lens light fixed (intensities re-solved), SIE + shear
passed from SP, a pixelized source on the overlay mesh with one regularization
coefficient: 8 free parameters."""

from pathlib import Path

from mgelens.pipeline import models
from mgelens.pipeline.parameters import passed
from mgelens.pipeline.problem import (
    PhaseProblem,
    earlier_phases,
    imaging_files,
    load_dataset,
    positions_penalty,
    sp_light_model,
)
from mgelens.pipeline.settings import LensSpec, SlamSettings
from mgelens.search.model import ParameterSpace
from mgelens.search.results import PhaseResult
from mgelens.source.image_mesh import overlay_centres


def space(sp: PhaseResult, rule: str = "paper") -> ParameterSpace:
    """SPix1: lens light fixed at SP's max-L, SIE + shear passed from SP, one regularization
    coefficient (Constant or ConstantSplit) LogUniform(1e−6, 1e6): 8 free parameters."""
    mass = passed(sp, models.PASSED_MASS_NAMES, rule)
    coefficient = {"regularization.coefficient": models.COEFFICIENT_PRIOR}
    return ParameterSpace(
        (
            *models.frozen_component(sp, models.LENS_LIGHT),
            *models.free_parameters(mass),
            *models.free_parameters(coefficient),
        )
    )


def problem(
    lens_dir: Path, results_dir: Path, settings: SlamSettings, lens: LensSpec
) -> PhaseProblem:
    """SPix1: lens light fixed (SP), SIE + shear passed from SP, overlay mesh (8)."""
    (sp,) = earlier_phases(results_dir, settings, "sp")
    sp.check_lens_light(settings)
    dataset, radius = load_dataset(lens_dir, settings, lens, models.light_centre(sp.result))
    x, y = overlay_centres(dataset.mask, dataset.imaging.pixel_scale, settings.overlay_shape)
    source = models.MeshSourceModel(
        x, y, settings.spix1_regularization, settings.interpolation, settings.cross_offset
    )
    return PhaseProblem(
        "spix1",
        dataset,
        space(sp.result, settings.prior_passing),
        sp_light_model(sp, source),
        (*imaging_files(lens_dir), *sp.files),
        radius,
        positions_penalty(sp, settings),
    )

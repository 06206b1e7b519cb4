"""Phase SP (SPEC §8.1): the lens light (2×30 MGE, or 2 Sérsics), SIE + shear and a
1×20 MGE source, all fitted together from the anchor's priors: 17 or 21 free parameters.
SP reads no earlier phase."""

from collections.abc import Sequence
from pathlib import Path

from mgelens.pipeline import models
from mgelens.pipeline.problem import (
    PhaseProblem,
    imaging_files,
    load_dataset,
)
from mgelens.pipeline.settings import SP_MASS_CENTRES, LensSpec, SlamSettings
from mgelens.search.model import ParameterSpace
from mgelens.search.priors import Gaussian


def space(
    specs: Sequence[models.LightSpec],
    centre: tuple[float, float] = (0.0, 0.0),
    mass_centre: str = "free",
) -> ParameterSpace:
    """SP: lens light (shared centre N(c, 0.3″), ell_comps N(0, 0.3)), SIE + shear,
    1×20 source MGE (centre N(c, 0.3″)): 6 + 7 + 4 = 17 free parameters for 2 MGE sets,
    10 + 7 + 4 = 21 for 2 Sérsics. ``mass_centre`` ``"light"`` ties the SIE centre to the
    lens light's shared centre (15 or 19 free parameters; ``slam.sp_mass_centre``)."""
    wide = (Gaussian(centre[0], 0.3), Gaussian(centre[1], 0.3))
    light = models.lens_light_parameters(specs, wide, models.ELL_COMPS_PRIOR)
    source = models.geometry_parameters(
        f"{models.SOURCE}.set_0", wide, (models.ELL_COMPS_PRIOR,) * 2
    )
    if mass_centre not in SP_MASS_CENTRES:
        raise ValueError(f"mass_centre must be 'free' or 'light', got {mass_centre!r}")
    mass = models.free_parameters(models.sp_mass_priors(centre))
    result = ParameterSpace((*light, *mass, *source))
    if mass_centre == "light":
        first = light[0].name.removesuffix(".centre_x")
        for axis in ("centre_x", "centre_y"):
            result = result.tie(f"mass.{axis}", f"{first}.{axis}")
    return result


def problem(
    lens_dir: Path, results_dir: Path, settings: SlamSettings, lens: LensSpec
) -> PhaseProblem:
    """SP: 2×30 MGE lens light (or 2 Sérsics), SIE + shear, 1×20 MGE source (17 or 21)."""
    del results_dir  # the first phase reads no earlier result
    dataset, radius = load_dataset(lens_dir, settings, lens, lens.mask_centre)
    specs = (
        models.sersic_specs(2)
        if settings.lens_light_model == "sersic"
        else models.mge_specs(2, False, dataset.imaging.pixel_scale, radius)
    )
    return PhaseProblem(
        "sp",
        dataset,
        space(specs, lens.mask_centre, settings.sp_mass_centre),
        models.PhaseModel(specs, models.MGESourceModel()),
        tuple(imaging_files(lens_dir)),
        radius,
    )

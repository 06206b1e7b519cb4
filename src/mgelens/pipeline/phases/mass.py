"""Phase MASS (SPEC §8.1): EPL + shear with priors passed from SPix1 and the slope free,
lens light (LIGHT) and source (SPix2) fixed: 8 free parameters; the 3×Sérsic chain fits
LIGHT's Sérsics together with the mass."""

from pathlib import Path

from mgelens.pipeline import models
from mgelens.pipeline.parameters import passed
from mgelens.pipeline.problem import (
    PhaseProblem,
    earlier_phases,
    imaging_files,
    kmeans_source,
    load_dataset,
    positions_penalty,
)
from mgelens.pipeline.settings import LensSpec, SlamSettings
from mgelens.search.model import Parameter, ParameterSpace
from mgelens.search.results import PhaseResult


def passed_component(previous: PhaseResult, component: str, rule: str = "paper") -> list[Parameter]:
    """Parameters of ``component`` with priors passed from ``previous`` (SPEC §8.2); its
    fixed values and ties are kept."""
    own = [p for p in previous.space.parameters if p.name.startswith(component + ".")]
    priors = passed(previous, [p.name for p in own if p.prior is not None], rule)
    return [
        Parameter(p.name, prior=priors[p.name], limits=p.limits) if p.name in priors else p
        for p in own
    ]


def space(
    light: PhaseResult,
    spix1: PhaseResult,
    spix2: PhaseResult,
    rule: str = "paper",
    free_lens_light: bool = False,
) -> ParameterSpace:
    """MASS: lens light fixed (LIGHT), EPL + shear with centre, ell_comps, θ_E and shear
    passed from SPix1 and γ U(1.5, 3.0), source fixed (SPix2): 8 free parameters.

    With ``free_lens_light`` (the 3×Sérsic chain) the lens light is fitted together with
    the mass, its priors passed from LIGHT: 8 + 14 free parameters for 3 Sérsics.
    """
    from_spix1 = passed(spix1, models.PASSED_MASS_NAMES, rule)
    mass = {n: p for n, p in from_spix1.items() if n.startswith(models.MASS + ".")}
    shear = {n: p for n, p in from_spix1.items() if n.startswith(models.SHEAR + ".")}
    lens_light = (
        passed_component(light, models.LENS_LIGHT, rule)
        if free_lens_light
        else models.frozen_component(light, models.LENS_LIGHT)
    )
    return ParameterSpace(
        (
            *lens_light,
            *models.free_parameters({**mass, "mass.slope": models.SLOPE_PRIOR, **shear}),
            *models.frozen_component(spix2, models.MESH),
            *models.frozen_component(spix2, models.REGULARIZATION),
        )
    )


def problem(
    lens_dir: Path, results_dir: Path, settings: SlamSettings, lens: LensSpec
) -> PhaseProblem:
    """MASS: lens light (LIGHT) and source (SPix2's hyper-parameters, on
    ``settings.mass_pixels`` of SPix2's k-means pixels) fixed, EPL + shear (8); the 3×Sérsic
    chain fits LIGHT's Sérsics together with the mass (22)."""
    sp, spix1, spix2, light = earlier_phases(results_dir, settings, "sp", "spix1", "spix2", "light")
    light.check_lens_light(settings, prior=True)
    dataset, radius = load_dataset(lens_dir, settings, lens, models.light_centre(light.result))
    n_pixels = settings.mass_pixels(spix2.source_pixels(settings))
    kmeans, adapt_path = kmeans_source(dataset, results_dir, settings, n_pixels)
    source = kmeans.fixed(spix2.result.max_likelihood)
    earlier = (*sp.files, *spix1.files, *spix2.files, *light.files, adapt_path)
    return PhaseProblem(
        "mass",
        dataset,
        space(
            light.result,
            spix1.result,
            spix2.result,
            settings.prior_passing,
            free_lens_light=light.lens_light_kind == "sersic",
        ),
        models.PhaseModel(light.lens_light_specs, source, smoothness_prior=light.smoothness_prior),
        (*imaging_files(lens_dir), *earlier),
        radius,
        positions_penalty(sp, settings, spix1),
    )

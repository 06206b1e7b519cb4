"""Phase MASS (SPEC §8.1): EPL + shear with priors passed from SPix1 and the slope free,
lens light (LIGHT) and source (SPix2) fixed: 8 free parameters; the 3×Sérsic chain fits
LIGHT's Sérsics together with the mass."""

import dataclasses
import logging
from collections.abc import Mapping
from pathlib import Path

from mgelens.pipeline import models
from mgelens.pipeline.mesh_tuning import HYPER_PREFIXES, tuned_hyperparameters
from mgelens.pipeline.parameters import passed
from mgelens.pipeline.phases import spix2 as spix2_phase
from mgelens.pipeline.problem import (
    EarlierPhase,
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

logger = logging.getLogger(__name__)


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
    source_values: Mapping[str, float] | None = None,
) -> ParameterSpace:
    """MASS: lens light fixed (LIGHT), EPL + shear with centre, ell_comps, θ_E and shear
    passed from SPix1 and γ U(1.5, 3.0), source fixed (SPix2): 8 free parameters.

    With ``free_lens_light`` (the 3×Sérsic chain) the lens light is fitted together with
    the mass, its priors passed from LIGHT: 8 + 14 free parameters for 3 Sérsics.
    ``source_values``: the mesh and regularization values held (default SPix2's maximum
    likelihood; a mesh's own with ``slam.mass_mesh_tuning``, :func:`source_values`).
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
            *models.frozen_component(spix2, models.MESH, source_values),
            *models.frozen_component(spix2, models.REGULARIZATION, source_values),
        )
    )


def problem(
    lens_dir: Path,
    results_dir: Path,
    settings: SlamSettings,
    lens: LensSpec,
    hyperparameters: Mapping[str, float] | None = None,
) -> PhaseProblem:
    """MASS: lens light (LIGHT) and source (SPix2's hyper-parameters, or with
    ``slam.mass_mesh_tuning`` this mesh's own, on ``settings.mass_pixels`` of SPix2's
    k-means pixels) fixed, EPL + shear (8); the 3×Sérsic chain fits LIGHT's Sérsics
    together with the mass (22). ``hyperparameters``: the mesh and regularization values
    a finished run held (its ``samples.csv``), used instead of searching them again."""
    sp, spix1, spix2, light = earlier_phases(results_dir, settings, "sp", "spix1", "spix2", "light")
    light.check_lens_light(settings, prior=True)
    dataset, radius = load_dataset(lens_dir, settings, lens, models.light_centre(light.result))
    n_pixels = settings.mass_pixels(spix2.source_pixels(settings))
    kmeans, adapt_path = kmeans_source(dataset, results_dir, settings, n_pixels)
    values, tuning = source_values(
        spix2, lens_dir, results_dir, settings, lens, n_pixels, hyperparameters
    )
    source = kmeans.fixed(values)
    if tuning is not None:
        source = dataclasses.replace(
            source, description={**source.description, "mesh_tuning": tuning}
        )
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
            source_values=values,
        ),
        models.PhaseModel(light.lens_light_specs, source, smoothness_prior=light.smoothness_prior),
        (*imaging_files(lens_dir), *earlier),
        radius,
        positions_penalty(sp, settings, spix1),
    )


def source_values(
    spix2: EarlierPhase,
    lens_dir: Path,
    results_dir: Path,
    settings: SlamSettings,
    lens: LensSpec,
    n_pixels: int,
    hyperparameters: Mapping[str, float] | None = None,
) -> tuple[dict[str, float], dict | None]:
    """SPix2's maximum-likelihood values with the mesh and regularization this MASS mesh
    holds, and the record of its search (:meth:`~mgelens.pipeline.mesh_tuning.MeshTuning.
    describe`; ``None`` where SPix2's values are kept).

    SPix2's own values where ``slam.mass_mesh_tuning`` is off or the mesh is SPix2's (same
    k-means seed and pixel count); else ``hyperparameters`` if given (a finished run's),
    or those of :func:`~mgelens.pipeline.mesh_tuning.tuned_hyperparameters` on SPix2's
    problem rebuilt on this mesh.
    """
    values = dict(spix2.result.max_likelihood)
    own = spix2.record["source"]
    if not settings.mass_mesh_tuning or (
        settings.kmeans_seed == int(own["kmeans_seed"]) and n_pixels == int(own["n_pixels"])
    ):
        return values, None
    if hyperparameters is not None:
        held = {k: float(v) for k, v in hyperparameters.items() if k.startswith(HYPER_PREFIXES)}
        return {**values, **held}, {"tuned": True, "hyperparameters": held}
    tuning_problem = spix2_phase.problem(
        lens_dir, results_dir, dataclasses.replace(settings, source_pixels=n_pixels), lens
    )
    tuning = tuned_hyperparameters(tuning_problem, values)
    logger.info(
        "mesh of k-means seed %d: SPix2's hyper-parameters tuned, ln ε %.1f -> %.1f "
        "(SPix2's own mesh %.1f) in %d calls",
        settings.kmeans_seed,
        tuning.start_log_evidence,
        tuning.log_evidence,
        spix2.result.output.log_likelihoods.max(),
        tuning.n_calls,
    )
    return tuning.values, tuning.describe()

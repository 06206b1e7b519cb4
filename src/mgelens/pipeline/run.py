"""Running a SLaM phase (SPEC §8.1): lens folder + earlier phase folders in, one phase
folder out. The phases themselves are :mod:`mgelens.pipeline.phases`.

``run_phase(name, lens_dir, results_dir, settings)`` fits phase ``name`` ("sp", "spix1",
"spix2", "light", "mass") to the imaging in ``lens_dir`` (``data.fits``,
``noise_map.fits``, ``psf.fits``) and writes ``results_dir/<name>/``:

* ``result.json`` and ``samples.csv`` (:class:`~mgelens.search.results.PhaseResult`), with
  an extra ``max_likelihood_fit`` block in ``result.json``
  (:mod:`mgelens.pipeline.records`): the maximum-likelihood model, enough to rebuild the
  lens light and the mass from the JSON alone;
* ``model.fits`` (:mod:`mgelens.pipeline.products`); SPix1 also writes
  ``adapt_image.fits``, its lensed-source model, which SPix2, LIGHT and MASS use;
* ``phase.log`` (appended to on every run) and, while sampling, the sampler's checkpoint
  ``checkpoint-<hash>.pickle`` (nautilus: ``.h5``) with its JSON sidecar
  ``checkpoint-<hash>.fingerprint.json``, checked before the checkpoint is read. The hash
  covers the parameter space, sampler settings, seed, fit settings and input checksums: a
  rerun with the same inputs resumes, a rerun with changed inputs starts afresh. The
  checkpoint is deleted once the results are in.

A phase reads only earlier phases' ``result.json`` and ``samples.csv`` (and SPix1's adapt
image), so any phase can be rerun alone. Every file is written atomically, ``result.json``
last.

SP also records the multiple images of its source centre; with
``settings.positions_penalty`` SPix1 and MASS give mass models whose images do not
re-converge in the source plane a penalty instead of a fit (SPEC §12.21).

Chain (SPEC §8.1): SP (MGE lens light, SIE + shear, MGE source) → SPix1 (lens light fixed,
SIE + shear passed, overlay mesh) → SPix2 (lens light and mass fixed, k-means mesh
hyper-parameters) → LIGHT (MGE refit, mass and source fixed) → MASS (lens light and source
fixed, EPL + shear). With ``lens_light_model: sersic`` the lens light is the paper's
3×Sérsic comparison instead: 2 Sérsics in SP, SP's Sérsics subtracted as fixed light in
SPix1 and SPix2, 3 Sérsics in LIGHT, Sérsics and EPL + shear together in MASS.
"""

import dataclasses
import hashlib
import json
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mgelens.atomic import atomic_path, write_json
from mgelens.fit import FitDataset, FitError, FitResult, MGESource, figure_of_merit, fit
from mgelens.grid import pixel_centres
from mgelens.image_multiplicity import multiplicity_check
from mgelens.imaging import DATA_FILE
from mgelens.pipeline import fittable, light_bound, mass_rescan, models, products, sp_start
from mgelens.pipeline.phases import light, mass, sp, spix1, spix2
from mgelens.pipeline.problem import PhaseProblem, phase_log
from mgelens.pipeline.records import ADAPT_IMAGE_FILE, MODEL_FILE, fit_record, recorded_settings
from mgelens.pipeline.settings import PHASES, LensSpec, SlamSettings
from mgelens.provenance import command_version
from mgelens.rejection import REJECTED_LOG_LIKELIHOOD
from mgelens.search.evaluation import SPAWN, prepare_worker_process
from mgelens.search.model import ParameterSpace
from mgelens.search.posterior import SamplerOutput, pool_runs
from mgelens.search.results import RESULT_FILE, SAMPLES_FILE, PhaseResult, input_checksums
from mgelens.search.sampler import run_nested
from mgelens.search.sampler_settings import SamplerSettings
from mgelens.source.image_mesh import mask_extent_centre
from mgelens.threads import limit_threads

logger = logging.getLogger("mgelens.pipeline")


CHECKPOINT_PREFIX = "checkpoint-"


@dataclass(frozen=True, eq=False)
class PhaseLikelihood:
    """ln L (the log evidence when the source is pixelized) of a free-parameter vector.

    Samples the profiles cannot represent or the fit cannot solve return −1e99 (SPEC §8.4);
    the sampler counts them. With a positions penalty, mass models whose multiple images
    do not re-converge get the penalty instead of a fit. ``passive_start`` warm-starts
    every sample's NNLS (:func:`reference_passive_set`); it changes no value beyond
    rounding.
    """

    dataset: FitDataset
    space: ParameterSpace
    model: models.PhaseModel
    positions: models.PositionsPenalty | None = None
    passive_start: np.ndarray | None = None

    @classmethod
    def of(cls, problem: PhaseProblem) -> "PhaseLikelihood":
        """The sampler's likelihood of ``problem``, every NNLS warm-started from
        :func:`reference_passive_set`."""
        return cls(
            problem.dataset,
            problem.space,
            problem.model,
            problem.positions,
            reference_passive_set(problem),
        )

    def __call__(self, x: np.ndarray) -> float:
        values = self.space.values(x)
        try:
            lens_model = self.model.build(values)
        except models.UnphysicalSample as error:
            logger.debug("rejected sample: %s", error)
            return REJECTED_LOG_LIKELIHOOD
        if self.positions is not None:
            penalty = self.positions.log_likelihood(lens_model.mass)
            if penalty is not None:
                return penalty
        value, reason = figure_of_merit(self.dataset, lens_model, self.passive_start)
        if reason:
            logger.debug("rejected sample: %s", reason)
        return value


ISOTHERMAL_SLOPE = 2.0
"""EPL slope of the SIE, the mass model of the phases before MASS."""


REFERENCE_LIGHT_DRAWS = 16
"""Prior draws (seeded, the same in every run) whose fits' passive sets, joined, start the
NNLS of a phase that samples the lens light's shape (:func:`reference_passive_set`)."""


def reference_passive_set(problem: PhaseProblem) -> np.ndarray | None:
    """The NNLS warm start of a phase's samples: the final passive set of the fit at the
    prior medians, the union of those of :data:`REFERENCE_LIGHT_DRAWS` prior draws where
    the phase samples the lens light's shape, or ``None``.

    A free EPL slope (MASS), the one parameter whose prior is not passed from an earlier
    phase, is set to 2 instead of its prior median 2.25: the reference is then the SIE
    the earlier phases fitted.

    Every sample of a phase starts its NNLS from this set, which makes sense where each
    linear unknown means the same thing in every sample: the same lens-light or source
    Gaussian, or the source pixel of the same image-plane centre (SP, SPix1, LIGHT,
    MASS): the samples' final passive sets lie closer to the reference's than to the
    unconstrained solution's positive set (the default start), so the NNLS needs fewer
    outer iterations (docs/design_notes.md, "Warm-started solves"). Where the phase
    samples only the lens light's non-linear parameters (LIGHT), which Gaussians are
    non-zero changes from sample to sample and the medians' set shares few of them with
    the posterior's; the union of the draws' sets holds most of every sample's, and the
    NNLS drops the Gaussians it does not need first and cheaply (the source unknowns are
    its ``stable`` ones; docs/benchmarks.md, "A union of prior draws as LIGHT's warm
    start"). ``None`` where the unknowns move (SPix2's k-means mesh is recomputed per
    sample), for the unconstrained solve, or when the medians cannot be fitted.
    """
    if not (problem.dataset.settings.positive_only and problem.model.stable_unknowns):
        return None
    space = problem.space
    try:
        reference = _fitted_passive_set(problem, np.full(space.n_free, 0.5))
    except (models.UnphysicalSample, *FitError) as error:
        logger.info("NNLS warm start off: the prior medians cannot be fitted (%s)", error)
        return None
    if not _samples_only_light_shape(space.free_names):
        return reference
    union = np.zeros_like(reference)
    draws = np.random.default_rng(0).uniform(size=(REFERENCE_LIGHT_DRAWS, space.n_free))
    for unit in draws:
        try:
            union |= _fitted_passive_set(problem, unit)
        except (models.UnphysicalSample, *FitError):
            continue
    return union if union.any() else reference


def _fitted_passive_set(problem: PhaseProblem, unit: np.ndarray) -> np.ndarray:
    """Final NNLS passive set of the cold fit at unit-cube point ``unit`` (the slope, if
    free, at :data:`ISOTHERMAL_SLOPE`)."""
    values = problem.space.values(problem.space.prior_transform(unit))
    if "mass.slope" in problem.space.free_names:
        values["mass.slope"] = ISOTHERMAL_SLOPE
    return fit(problem.dataset, problem.model.build(values)).passive_set


def _samples_only_light_shape(free_names) -> bool:
    """Whether the free parameters are all the lens light's (LIGHT: mass and source
    fixed)."""
    return all(name.startswith("lens_light.") for name in free_names)


def scored_fit(problem: PhaseProblem, values: dict[str, float]) -> FitResult:
    """The fit of ``values`` as the phase's sampler scored it: the NNLS warm-started from
    :func:`reference_passive_set`. The constrained minimum is unique, so this is the fit
    from the default start to rounding, except where that start's passive blocks are too
    ill-conditioned to factorise, which the sampler's start avoided (a phase's written
    maximum and its overview's refit)."""
    return fit(problem.dataset, problem.model.build(values), reference_passive_set(problem))


def sampler_for(settings: SamplerSettings, n_free: int) -> SamplerSettings:
    """``settings`` made runnable for ``n_free`` free parameters: dynesty's live points
    are raised to 2 n_free + 2 if fewer (dynesty calls n_live ≤ 2 n_dim "extremely
    risky"; e.g. the quick profile's LIGHT phase with 6 sets and a point set), logged.
    """
    minimum = 2 * n_free + 2
    if settings.method != "nautilus" and settings.n_live < minimum:
        logger.warning(
            "n_live = %d is too few for %d free parameters: using %d",
            settings.n_live,
            n_free,
            minimum,
        )
        settings = dataclasses.replace(settings, n_live=minimum)
    return settings


def problem_fingerprint(problem: PhaseProblem, checksums: dict) -> dict:
    """Everything a phase's likelihood and priors depend on: the parameter space, the model
    (lens-light sets, source mesh, regularization, interpolation), the fit settings, hashes
    of the mask and of the pixels' weights (the noise map with any contaminant circles of
    the lens spec), the positions penalty, the input checksums and the version of the code
    that fits (:func:`~mgelens.provenance.command_version` of ``mgelens phase``)."""
    mask = np.ascontiguousarray(problem.dataset.mask)
    weights = np.ascontiguousarray(problem.dataset.inverse_variance)
    return {
        "phase": problem.name,
        "space": problem.space.to_dict(),
        "model": problem.model.describe(),
        "fit": dataclasses.asdict(problem.dataset.settings),
        "mask": hashlib.sha256(mask.tobytes() + str(mask.shape).encode()).hexdigest(),
        "weights": hashlib.sha256(weights.tobytes()).hexdigest(),
        "positions": None if problem.positions is None else problem.positions.describe(),
        "inputs": checksums,
        "version": command_version("phase"),
    }


def checkpoint_fingerprint(
    problem: PhaseProblem, sampler: SamplerSettings, seed: int, checksums: dict
) -> dict:
    """Everything a phase's sampling depends on, for naming its checkpoint: a checkpoint
    resumes only a fit of the same likelihood, priors, sampler and seed
    (:func:`problem_fingerprint`, the sampler settings and the seed)."""
    return {
        **problem_fingerprint(problem, checksums),
        "sampler": sampler.result_settings(),
        "seed": seed,
    }


def _checkpoint_paths(folder: Path, fingerprints: list[dict]) -> list[Path]:
    """One checkpoint file per run, named by the hash of its fingerprint; checkpoints of
    other fingerprints in ``folder`` are removed."""
    stems = [
        CHECKPOINT_PREFIX
        + hashlib.sha256(json.dumps(fingerprint, sort_keys=True).encode()).hexdigest()[:16]
        for fingerprint in fingerprints
    ]
    for stale in folder.glob(f"{CHECKPOINT_PREFIX}*"):
        if not any(stale.name.startswith(stem) for stem in stems):
            logger.info("removing %s: written for other inputs or settings", stale)
            stale.unlink()
    return [folder / f"{stem}.pickle" for stem in stems]


def _write_outputs(
    folder: Path, phase: PhaseResult, best: FitResult, record: dict, lens: str
) -> None:
    provenance = {"PHASE": phase.phase, "LENS": lens[:68], "PROFILE": phase.settings["profile"]}
    products.write_model_fits(folder / MODEL_FILE, best, provenance)
    if phase.phase == "spix1":
        products.write_adapt_image(folder / ADAPT_IMAGE_FILE, best)
    write_result_files(folder, phase, record)


def write_result_files(folder: Path, phase: PhaseResult, record: dict) -> None:
    """``samples.csv`` and, last, ``result.json`` with the ``max_likelihood_fit``
    ``record`` of a phase, each written atomically."""
    with atomic_path(folder / SAMPLES_FILE) as temporary:
        phase.samples_table().to_csv(temporary, index=False, float_format="%.17g")
    write_json(folder / RESULT_FILE, {**phase.summary(), "max_likelihood_fit": record})


def _sample_alone(
    likelihood: PhaseLikelihood,
    space: ParameterSpace,
    sampler: SamplerSettings,
    checkpoint: Path,
    seed: int,
    reference: np.ndarray | None,
    folder: Path,
) -> SamplerOutput:
    """One run of :func:`_sample_runs` in a worker process set up as a phase job
    (:func:`~mgelens.search.evaluation.prepare_worker_process`), its progress lines appended
    to the phase log."""
    prepare_worker_process()
    with phase_log(folder):
        return run_nested(likelihood, space, sampler, checkpoint, seed, logger.info, reference)


def _sample_runs(
    runs: list[tuple[PhaseLikelihood, ParameterSpace, Path, int, np.ndarray | None]],
    sampler: SamplerSettings,
    folder: Path,
) -> list[SamplerOutput]:
    """Sample each run ``(likelihood, space, checkpoint, seed, reference)`` with ``sampler``
    (:func:`~mgelens.search.sampler.run_nested`).

    One after the other; or, when there are several runs (MASS's source meshes) and the
    sampler has ``n_processes`` ≥ 2, up to ``n_processes`` of them side by side in worker
    processes of one thread, each run in one process (:func:`_sample_alone`) instead of
    one run at a time in a likelihood pool. Each run checkpoints and resumes on its own
    and draws the one-process run's samples (``samples.csv`` byte-identical), unlike a
    likelihood pool, which changes the random streams (docs/design_notes.md, "MASS
    meshes side by side").
    """
    n_workers = min(sampler.n_processes, len(runs))
    if n_workers < 2:
        return [
            run_nested(likelihood, space, sampler, checkpoint, seed, logger.info, reference)
            for likelihood, space, checkpoint, seed, reference in runs
        ]
    alone = dataclasses.replace(sampler, n_processes=1)
    logger.info("sampling the %d runs %d at a time, one process each", len(runs), n_workers)
    with SPAWN.Pool(n_workers) as pool:
        return pool.starmap(
            _sample_alone,
            [(likelihood, space, alone, checkpoint, seed, reference, folder)
             for likelihood, space, checkpoint, seed, reference in runs],
        )  # fmt: skip


def _solve(
    problems: list[PhaseProblem],
    folder: Path,
    settings: SlamSettings,
    lens: LensSpec,
    seed: int,
    lens_dir: Path,
    checksums: dict,
    mesh: int | None = None,
) -> PhaseResult:
    """Sample each problem (one per source-mesh realisation, :func:`chain_settings`), pool
    the runs (:func:`~mgelens.search.posterior.pool_runs`) and write the phase's files; the
    maximum-likelihood fit is that of the run holding the highest-likelihood sample.
    ``checksums`` are those of the problems' input files, recorded in the result; ``mesh``
    the index of the one MASS mesh that ``problems`` holds in a mesh job
    (:func:`run_phase`), recorded in the result's settings."""
    first = problems[0]
    sampler = sampler_for(settings.samplers[first.name], first.space.n_free)
    seeds = [seed + k for k in range(len(problems))]
    checkpoints = _checkpoint_paths(
        folder,
        [
            checkpoint_fingerprint(problem, sampler, run_seed, checksums)
            for problem, run_seed in zip(problems, seeds, strict=True)
        ],
    )
    outputs = _sample_problems(problems, sampler, seeds, checkpoints, folder, lens_dir)
    output = pool_runs(outputs)
    best_run = int(np.argmax([run.log_likelihoods.max() for run in outputs]))
    best_problem = problems[best_run]
    phase = PhaseResult(
        phase=best_problem.name,
        space=best_problem.space,
        output=output,
        settings=_phase_settings(problems, outputs, best_run, settings, lens, lens_dir, mesh, seed),
        input_checksums=checksums,
    )
    values = best_problem.space.values(output.max_likelihood())
    best = scored_fit(best_problem, values)
    record = fit_record(best, best_problem.model, values)
    if isinstance(best.model.source, MGESource):
        record["positions"] = image_positions(best, settings).describe()
    _write_outputs(folder, phase, best, record, lens_dir.name)
    for stale in folder.glob(f"{CHECKPOINT_PREFIX}*"):
        stale.unlink()
    _log_outcome(best_problem.name, lens_dir, folder, output, best)
    return phase


def _sample_problems(
    problems: list[PhaseProblem],
    sampler: SamplerSettings,
    seeds: list[int],
    checkpoints: list[Path],
    folder: Path,
    lens_dir: Path,
) -> list[SamplerOutput]:
    """One sampler run per problem (:func:`_sample_runs`), each logged as it is set up."""
    runs = []
    for problem, run_seed, checkpoint in zip(problems, seeds, checkpoints, strict=True):
        logger.info(
            "phase %s of %s: %d free parameters, %s with n_live = %d, %d image pixels%s",
            problem.name,
            lens_dir,
            problem.space.n_free,
            sampler.method,
            sampler.n_live,
            problem.dataset.data.size,
            _mesh_label(problem, len(problems)),
        )
        likelihood = PhaseLikelihood.of(problem)
        reference = None if problem.reference is None else problem.space.vector(problem.reference)
        runs.append((likelihood, problem.space, checkpoint, run_seed, reference))
    return _sample_runs(runs, sampler, folder)


def _phase_settings(
    problems: list[PhaseProblem],
    outputs: list[SamplerOutput],
    best_run: int,
    settings: SlamSettings,
    lens: LensSpec,
    lens_dir: Path,
    mesh: int | None = None,
    seed: int | None = None,
) -> dict:
    """The ``settings`` record of ``result.json``: the chain's settings, the lens spec, the
    mask radius used and the model of the run holding the highest-likelihood sample, and
    each mesh's run when MASS pooled several; a MASS mesh job's index as ``mesh`` and the
    sampler seed it started from as ``mesh_seed`` (its output's ``seed`` is the last
    attempt's: a restart that doubles the live points adds 1)."""
    best_problem = problems[best_run]
    phase_settings = {
        "profile": settings.profile,
        "lens_dir": str(lens_dir),
        "mask_radius": best_problem.mask_radius,
        "model": best_problem.model.describe(),
        "slam": settings.to_dict(),
        "lens": lens.to_dict(),
        "positions": None if best_problem.positions is None else best_problem.positions.describe(),
    }
    if len(problems) > 1:
        phase_settings["meshes"] = [
            mesh_run_record(run_problem.model.source.describe(), run, k == best_run)
            for k, (run_problem, run) in enumerate(zip(problems, outputs, strict=True))
        ]
    if mesh is not None:
        phase_settings["mesh"] = mesh
        phase_settings["mesh_seed"] = seed
    return phase_settings


def _log_outcome(
    name: str, lens_dir: Path, folder: Path, output: SamplerOutput, best: FitResult
) -> None:
    """Log the phase's end, with a warning if its sampler did not converge."""
    if not output.converged:
        logger.warning(
            "phase %s of %s did not converge (%s): %s records converged: false, and later "
            "phases refuse it unless slam.allow_unconverged is true",
            name,
            lens_dir,
            output.stop_reason,
            folder / RESULT_FILE,
        )
    logger.info(
        "phase %s done: ln Z = %.3f, max ln L = %.3f, %d calls (%d rejected), %.1f s",
        name,
        output.log_evidence,
        best.log_evidence,
        output.n_calls,
        output.n_rejected,
        output.runtime,
    )


def _kmeans_seed(problem: PhaseProblem) -> int:
    return problem.model.source.describe()["kmeans_seed"]


def _mesh_label(problem: PhaseProblem, n_meshes: int) -> str:
    if n_meshes == 1:
        return ""
    return f", source mesh k-means seed {_kmeans_seed(problem)}"


def mesh_run_record(source: dict, run: SamplerOutput, holds_best: bool) -> dict:
    """Result-file entry of one source-mesh run of a pooled phase (its samples are the
    next ``n_samples`` rows of ``samples.csv``, in the order of the entries), from the
    description of the run's source model (``source``) and its output; with
    ``mesh_tuning``, the search that gave the mesh its hyper-parameters
    (:func:`mgelens.pipeline.phases.mass.source_values`), ``None`` for SPix2's own."""
    return {
        "kmeans_seed": source["kmeans_seed"],
        "mesh_tuning": source.get("mesh_tuning"),
        "log_evidence": run.log_evidence,
        "max_log_likelihood": float(run.log_likelihoods.max()),
        "n_calls": run.n_calls,
        "n_samples": len(run.samples),
        "effective_sample_size": run.effective_sample_size,
        "median": dict(zip(run.names, run.median().tolist(), strict=True)),
        "holds_max_likelihood": holds_best,
    }


def image_positions(result: FitResult, settings: SlamSettings) -> models.PositionsPenalty:
    """Multiple images of the MGE source centre of a fit (SP) and their threshold
    (:func:`positions_of`)."""
    return positions_of(result, result.model.source.sets[0].centre, settings)


def positions_of(
    result: FitResult, source_centre: tuple[float, float], settings: SlamSettings
) -> models.PositionsPenalty:
    """The multiple images of ``source_centre`` (arcsec, source plane) under the mass of
    the fit ``result``, within its mask, and their threshold: max(factor × the images'
    own source-plane scatter, minimum) (SPEC §12.21)."""
    dataset = result.dataset
    x, y = pixel_centres(dataset.mask.shape, dataset.imaging.pixel_scale)
    x, y = np.where(dataset.mask, np.nan, x), np.where(dataset.mask, np.nan, y)
    positions = models.multiple_image_positions(result.model.mass, source_centre, x, y)
    scatter = (
        models.PositionsPenalty(positions, 0.0).separation(result.model.mass)
        if len(positions) > 1
        else 0.0
    )
    threshold = max(settings.positions_factor * scatter, settings.positions_minimum)
    return models.PositionsPenalty(positions, threshold)


def build_problem(
    name: str, lens_dir: Path, results_dir: Path, settings: SlamSettings, lens: LensSpec
) -> PhaseProblem:
    """The problem of phase ``name`` (:mod:`mgelens.pipeline.phases`).

    Raises
    ------
    ValueError
        For an unknown phase name.
    """
    if name == "sp":
        return sp.problem(lens_dir, results_dir, settings, lens)
    if name == "spix1":
        return spix1.problem(lens_dir, results_dir, settings, lens)
    if name == "spix2":
        return spix2.problem(lens_dir, results_dir, settings, lens)
    if name == "light":
        return light.problem(lens_dir, results_dir, settings, lens)
    if name == "mass":
        return mass.problem(lens_dir, results_dir, settings, lens)
    raise ValueError(f"unknown phase {name!r}; phases are {list(PHASES)}")


def run_phase(
    name: str,
    lens_dir: str | Path,
    results_dir: str | Path,
    settings: SlamSettings,
    lens: LensSpec | None = None,
    seed: int = 0,
    threads: int | None = None,
    folder_name: str | None = None,
    bound_by: tuple[str, float] | None = None,
    mesh: int | None = None,
) -> PhaseResult:
    """Run phase ``name`` of the lens in ``lens_dir``; write ``results_dir/<name>/``.

    Parameters
    ----------
    name : {"sp", "spix1", "spix2", "light", "mass"}
    lens_dir : path
        Folder with ``data.fits``, ``noise_map.fits``, ``psf.fits`` (and optionally
        ``mask.fits``, ``truth.json``).
    results_dir : path
        The lens's results folder holding one sub-folder per phase.
    settings : SlamSettings
    lens : LensSpec, optional
        What is set per lens (mask, pixel scale, MGE sets); ``LensSpec()`` if not given,
        which takes the mask radius from the folder's ``truth.json`` (mocks).
    seed : int
        Seed of the sampler.
    threads : int, optional
        numba / BLAS threads (:func:`limit_threads`); ``None`` leaves them as they are.
    folder_name : str, optional
        Write ``results_dir/<folder_name>/`` instead: a candidate LIGHT model
        (:mod:`mgelens.pipeline.model_choice`). Earlier phases are always read from
        their own folders.
    bound_by : (str, float), optional
        LIGHT only: ``(folder, threshold)`` of a more complex candidate already fitted in
        ``results_dir/<folder>/`` and the model choice's threshold. If a local search of
        this candidate's highest ln ε shows that it cannot come within the threshold of
        that candidate's ln Z (:mod:`~mgelens.pipeline.light_bound`), the phase writes the
        maximum found instead of sampling (``sampler.method`` "upper_bound"); otherwise it
        samples as usual.
    mesh : int, optional
        MASS only, with ``slam.mass_meshes`` ≥ 2: sample this one source mesh (0 … meshes
        − 1: k-means seed ``kmeans_seed + mesh``, sampler seed ``seed + mesh``, as the
        pooled phase samples it) into ``results_dir/mass_mesh<mesh>/`` (default folder),
        for :func:`mgelens.pipeline.mesh_pool.pool_meshes` to pool; the meshes are then
        separate jobs that a scheduler can run side by side.

    Returns
    -------
    PhaseResult
    """
    if name not in PHASES:
        raise ValueError(f"unknown phase {name!r}; phases are {list(PHASES)}")
    if bound_by is not None and name != "light":
        raise ValueError(f"only a LIGHT candidate can be bounded by another, not phase {name!r}")
    runs = chain_settings(name, settings)
    if mesh is not None:
        if name != "mass" or not 0 <= mesh < len(runs) or len(runs) == 1:
            raise ValueError(
                f"mesh {mesh} of phase {name!r}: only MASS with several source meshes runs "
                f"one mesh alone, mesh 0 to {settings.mass_meshes - 1} (slam.mass_meshes "
                f"is {settings.mass_meshes}); drop --mesh to run the phase whole"
            )
        runs = runs[mesh : mesh + 1]
    if folder_name is not None and (
        Path(folder_name).name != folder_name or folder_name in ("", ".", "..")
    ):
        raise ValueError(f"phase folder {folder_name!r} must be one folder name, not a path")
    if threads is not None:
        limit_threads(threads)
    lens_dir, results_dir = Path(lens_dir), Path(results_dir)
    lens = LensSpec() if lens is None else lens
    folder = results_dir / (folder_name or (name if mesh is None else mesh_folder(mesh)))
    folder.mkdir(parents=True, exist_ok=True)
    with phase_log(folder):
        problems = [build_problem(name, lens_dir, results_dir, s, lens) for s in runs]
        first = problems[0]
        fittable.check_pixels_per_parameter(
            lens_dir / DATA_FILE,
            first.dataset.imaging,
            first.dataset.mask,
            first.mask_radius,
            first.space.n_free,
        )
        checksums = input_checksums(first.inputs)
        if name == "sp" and settings.sp_start == "search":
            problems = [started_sp(first, folder, checksums)]
        if name == "spix1" and settings.spix1_rescan:
            problems = [rescanned_spix1(first, folder, checksums, settings, results_dir)]
        if bound_by is not None:
            skipped = _bounded_candidate(
                first, results_dir, bound_by, folder, settings, lens, lens_dir, checksums
            )
            if skipped is not None:
                return skipped
        run_seed = seed if mesh is None else seed + mesh
        return _solve(problems, folder, settings, lens, run_seed, lens_dir, checksums, mesh)


def _bounded_candidate(
    problem: PhaseProblem,
    results_dir: Path,
    bound_by: tuple[str, float],
    folder: Path,
    settings: SlamSettings,
    lens: LensSpec,
    lens_dir: Path,
    checksums: dict,
) -> PhaseResult | None:
    """The LIGHT candidate ``problem`` written as its local maximum, if that shows it cannot
    win against the converged candidate in ``results_dir/<bound_by[0]>/``
    (:mod:`~mgelens.pipeline.light_bound`); None (sample it) otherwise."""
    reference_folder, threshold = bound_by
    if not (results_dir / reference_folder / RESULT_FILE).is_file():
        raise FileNotFoundError(
            f"{results_dir / reference_folder / RESULT_FILE} not found: fit the LIGHT "
            f"candidate {reference_folder!r} before bounding another by it (or drop --bound-by)"
        )
    reference = PhaseResult.read(results_dir / reference_folder)
    if not reference.output.converged:
        logger.info("%s did not converge: this candidate is sampled", reference_folder)
        return None
    likelihood = PhaseLikelihood.of(problem)
    maximum = light_bound.search_maximum(likelihood, problem.space)
    values = problem.space.values(maximum.x)
    best = fit(problem.dataset, problem.model.build(values))
    # the fit without the sampler's warm-started NNLS may end on another active set; the
    # higher of the two ln ε is the bound (the lower could fall below the true maximum)
    maximum = dataclasses.replace(maximum, value=max(maximum.value, best.log_evidence))
    gap = reference.output.log_evidence - maximum.value
    if not light_bound.cannot_win(maximum, reference.output.log_evidence, threshold):
        logger.info(
            "highest ln ε found %.2f (%d calls) lies %.2f below the ln Z of %s, within the "
            "threshold %.1f + slack %.1f: this candidate is sampled",
            maximum.value,
            maximum.n_calls,
            gap,
            reference_folder,
            threshold,
            light_bound.SLACK,
        )
        return None
    output = light_bound.bounded_output(
        maximum, problem.space, reference_folder, reference.output.log_evidence
    )
    phase = PhaseResult(
        phase=problem.name,
        space=problem.space,
        output=output,
        settings=_phase_settings([problem], [output], 0, settings, lens, lens_dir),
        input_checksums=checksums,
    )
    _write_outputs(folder, phase, best, fit_record(best, problem.model, values), lens_dir.name)
    logger.info("phase light done: %s, %d calls", output.stop_reason, output.n_calls)
    return phase


def started_sp(problem: PhaseProblem, folder: Path, checksums: dict) -> PhaseProblem:
    """SP's problem with its priors passed from the arcs' start (:mod:`sp_start`), read
    from ``folder/start.json`` when it was found for the same inputs (``checksums``, of
    ``problem.inputs``) and settings. The search solves non-negatively whatever SP's
    ``positive_only`` (:meth:`~mgelens.fit.FitDataset.non_negative`). The start is the
    problem's ``reference``: a sampler with a peak check samples again if its posterior
    falls short of the start's ln L (on slacs1627-0053 one fell 83 short, in another
    mode; docs/slacs.md)."""
    fingerprint = problem_fingerprint(problem, checksums)
    dataset = problem.dataset.non_negative()
    likelihood = PhaseLikelihood(dataset, problem.space, problem.model)
    start = sp_start.read_or_search(
        folder,
        fingerprint,
        lambda: sp_start.search(
            dataset,
            problem.space,
            problem.model,
            likelihood,
            problem.mask_radius,
        ),
    )
    return dataclasses.replace(
        problem, space=sp_start.started_space(problem.space, start), reference=start.values
    )


def multiply_imaged(result: FitResult, mask_radius: float) -> bool:
    """Whether ``result``'s mass images at least half of its lensed source's signal more
    than once (:func:`~mgelens.image_multiplicity.multiplicity_check`, the quality check's
    rule; images sought within ``mask_radius`` arcsec of the mask's centre).

    A pixelized source can redraw the arcs through a mass that barely lenses them: on
    slacs1250+0523 SPix1's rescan preferred such a mass at θ_E 0.74″ (Bolton's b 1.13″) by
    176 in ln P, and the chain ended with 27 % of its lensed signal multiply imaged.
    """
    dataset = result.dataset
    x, y = dataset.pixel_centres
    check = multiplicity_check(
        result.model.mass,
        result.lensed_source_image,
        dataset.noise_map,
        np.ones(x.size, dtype=bool),
        x,
        y,
        mask_radius,
        mask_extent_centre(dataset.mask, dataset.imaging.pixel_scale),
    )
    if check.flag:
        logger.info("SPix1 rescan: %s", check.reason)
    return not check.flag


def rescanned_spix1(
    problem: PhaseProblem,
    folder: Path,
    checksums: dict,
    settings: SlamSettings,
    results_dir: Path,
) -> PhaseProblem:
    """SPix1's problem with its mass and shear priors re-centred where its own rescan of
    θ_E, or of SP's start's other polished points and its arcs' sphere
    (``results_dir/sp/start.json``, where SP searched a start; :func:`sp_start.arcs_sphere`),
    found a far better basin than SP's (:mod:`mass_rescan`; unchanged
    otherwise), read from ``folder/rescan.json`` when it was made for the same inputs
    (``checksums``), settings and start points. The rescan evaluates ln ε without the
    positions penalty, whose image positions are SP's and hold SP's mass, and moves only
    to a mass that forms several images of its source's brightest point and images most
    of its lensed source's signal more than once (:func:`multiply_imaged`); a re-centred
    problem takes those images for its positions penalty (:func:`positions_of`; MASS then
    reads them from SPix1's record), and the rescan's point is its ``reference``."""
    space = problem.space
    likelihood = PhaseLikelihood(problem.dataset, space, problem.model)
    medians = space.values(space.prior_transform(np.full(space.n_free, 0.5)))

    def fitted(values: dict) -> FitResult:
        return fit(problem.dataset, problem.model.build({**medians, **values}))

    def images(result: FitResult) -> models.PositionsPenalty:
        """The images of the fitted source's brightest point under the fit's mass."""
        brightest = result.source.mesh.points[np.argmax(result.source.fluxes)]
        return positions_of(result, tuple(brightest), settings)

    def lensed(values: dict) -> bool:
        result = fitted(values)
        return len(images(result).positions) > 1 and multiply_imaged(result, problem.mask_radius)

    start_path = Path(results_dir) / "sp" / sp_start.START_FILE
    sphere = sp_start.arcs_sphere(start_path, models.lens_light_centre(medians))
    start_points = sp_start.unchosen_polishes(start_path) + ([sphere] if sphere else [])
    fingerprint = problem_fingerprint(problem, checksums) | {"steps": mass_rescan.STEPS}
    if start_points:
        fingerprint["start_points"] = start_points
    found = mass_rescan.read_or_rescan(
        folder,
        fingerprint,
        lambda: mass_rescan.rescan(
            space,
            likelihood,
            models.lens_light_centre(medians),
            lensed,
            start_points,
        ),
    )
    if not found.moved:
        return problem
    positions = problem.positions
    if positions is not None:
        positions = images(fitted(found.values))
        logger.info("positions penalty from the rescan's mass: %s", positions.describe())
    return dataclasses.replace(
        problem,
        space=mass_rescan.recentred_space(space, found),
        reference=found.values,
        positions=positions,
    )


MESH_FOLDER_PREFIX = "mass_mesh"
"""Folder of a MASS mesh job: ``mass_mesh<index>`` (:func:`run_phase` with ``mesh``)."""


def mesh_folder(mesh: int) -> str:
    """The folder name of MASS mesh ``mesh``'s job."""
    return f"{MESH_FOLDER_PREFIX}{mesh}"


def chain_settings(name: str, settings: SlamSettings) -> list[SlamSettings]:
    """Settings of each run of phase ``name``: in MASS, one per source-mesh realisation
    (k-means seeds ``kmeans_seed`` … ``kmeans_seed + mass_meshes − 1``, SPix2's
    hyper-parameters in each), whose posteriors are pooled with equal weights; one run in
    every other phase.

    The MASS posterior of one mesh is conditional on where k-means put its 500–1500
    centres, and the mesh can move it by more than its own 3σ width
    (docs/design_notes.md, "Pooled source meshes"). Pooling reports that spread.
    """
    if name != "mass" or settings.mass_meshes == 1:
        return [settings]
    return [
        dataclasses.replace(settings, kmeans_seed=settings.kmeans_seed + k)
        for k in range(settings.mass_meshes)
    ]


def max_likelihood_problem(
    phase: PhaseResult, lens_dir: str | Path, results_dir: str | Path
) -> tuple[PhaseProblem, dict[str, float]]:
    """The problem of a finished phase's maximum-likelihood fit and that fit's values.

    :func:`scored_fit` of them is the fit of the phase's ``model.fits``: the problem is
    rebuilt from the settings recorded in ``result.json`` (in a pooled MASS phase, with the
    k-means seed of the mesh whose run holds the highest-likelihood sample, and that run's
    hyper-parameters where its mesh was tuned) and the earlier phases' files in
    ``results_dir``.
    """
    settings, lens = recorded_settings(phase.settings)
    best = [mesh for mesh in phase.settings.get("meshes", []) if mesh["holds_max_likelihood"]]
    if best:
        settings = dataclasses.replace(settings, kmeans_seed=int(best[0]["kmeans_seed"]))
    if phase.phase == "mass":  # a tuned mesh's values as its run held them, not searched again
        problem = mass.problem(
            Path(lens_dir), Path(results_dir), settings, lens, phase.max_likelihood
        )
    else:
        problem = build_problem(phase.phase, Path(lens_dir), Path(results_dir), settings, lens)
    values = problem.space.values(problem.space.vector(phase.max_likelihood))
    return problem, values

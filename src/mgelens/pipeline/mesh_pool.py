"""MASS's source meshes as separate jobs, pooled afterwards (SPEC §8.1; issue #28).

The quick profile samples MASS on ``slam.mass_meshes`` k-means source meshes and pools
the runs with equal weights (:func:`mgelens.pipeline.run.chain_settings`). Run whole, one
phase job samples the meshes one after the other. Run as mesh jobs
(``mgelens phase mass --mesh k``, :func:`~mgelens.pipeline.run.run_phase` with ``mesh``),
each mesh is sampled in its own folder ``mass_mesh<k>/`` with the seeds the whole phase
gives it, so a scheduler runs them side by side; :func:`pool_meshes` then writes
``mass/`` from those folders, without a likelihood call: the pooled posterior of the
runs, and the maximum-likelihood fit (``model.fits`` and the ``max_likelihood_fit``
record) of the mesh whose run holds the highest-likelihood sample, which that mesh's job
already wrote. The result is the whole phase's: ``samples.csv`` and ``model.fits`` byte for
byte, ``result.json`` up to the runtime; ``phase.log`` has one line, the pooling's, and
each mesh's sampling is logged in its own folder.
"""

import json
import logging
import shutil
from pathlib import Path

import numpy as np

from mgelens.atomic import atomic_path
from mgelens.pipeline.problem import phase_log
from mgelens.pipeline.records import MODEL_FILE, read_fit_record
from mgelens.pipeline.run import (
    CHECKPOINT_PREFIX,
    mesh_folder,
    mesh_run_record,
    write_result_files,
)
from mgelens.pipeline.settings import SlamSettings
from mgelens.search.posterior import pool_runs
from mgelens.search.results import RESULT_FILE, PhaseResult, input_checksums

logger = logging.getLogger("mgelens.pipeline")

POOL_JOB = "mass_pool"
"""The workflow's name of the pooling job (its log and benchmark file): it samples
nothing, so a chain's likelihood calls are its mesh jobs' (:mod:`mgelens.chain_cost`)."""


class MeshPoolError(ValueError):
    """A mesh job's folder is missing, unreadable or written for other inputs or settings."""


def pool_meshes(
    results_dir: str | Path, settings: SlamSettings, seed: int = 0, folder_name: str = "mass"
) -> PhaseResult:
    """Pool the MASS mesh jobs of ``results_dir`` into ``results_dir/<folder_name>/``
    (``result.json``, ``samples.csv``, ``model.fits``, ``phase.log``; a sampler checkpoint
    left there by an interrupted whole run is removed, as a finished phase removes its own).

    Parameters
    ----------
    results_dir : path
        The lens's results folder, holding ``mass_mesh0/`` … ``mass_mesh<K−1>/`` for
        ``K = settings.mass_meshes``.
    settings : SlamSettings
        The chain's settings; every mesh job must have been run with them.
    seed : int
        The phase's sampler seed; mesh ``k``'s run must have started from sampler seed
        ``seed + k`` (its ``mesh_seed``; a peak restart then samples with the next seeds).
    folder_name : str
        The pooled phase's folder (default ``mass``).

    Returns
    -------
    PhaseResult
        The pooled result, as written.

    Raises
    ------
    MeshPoolError
        If a mesh job's result is missing or unreadable, was written with other settings
        or seed, or for input files that have changed since (each names the folder and
        the job to rerun).
    """
    results_dir = Path(results_dir)
    if settings.mass_meshes < 2:
        raise MeshPoolError(
            f"slam.mass_meshes is {settings.mass_meshes}: MASS has one source mesh, which "
            "`mgelens phase mass` fits whole; there is nothing to pool"
        )
    folders = [results_dir / mesh_folder(k) for k in range(settings.mass_meshes)]
    runs = [_mesh_result(folder, k, settings, seed) for k, folder in enumerate(folders)]
    _check_inputs(folders, runs)
    outputs = [run.output for run in runs]
    output = pool_runs(outputs)
    best_run = int(np.argmax([run.log_likelihoods.max() for run in outputs]))
    best = runs[best_run]
    record = {k: v for k, v in best.settings.items() if k not in ("mesh", "mesh_seed")}
    record["meshes"] = [
        mesh_run_record(run.settings["model"]["source"], run.output, k == best_run)
        for k, run in enumerate(runs)
    ]
    phase = PhaseResult(
        phase=best.phase,
        space=best.space,
        output=output,
        settings=record,
        input_checksums=best.input_checksums,
    )
    fit = read_fit_record(folders[best_run])
    folder = results_dir / folder_name
    folder.mkdir(parents=True, exist_ok=True)
    with phase_log(folder):
        with atomic_path(folder / MODEL_FILE) as temporary:
            shutil.copyfile(folders[best_run] / MODEL_FILE, temporary)
        write_result_files(folder, phase, fit)
        for stale in folder.glob(f"{CHECKPOINT_PREFIX}*"):  # of a whole run, interrupted
            stale.unlink()
        logger.info(
            "phase mass pooled from the mesh jobs %s: ln Z = %.3f, max ln L = %.3f "
            "(mesh %d), %d calls; converged: %s",
            ", ".join(str(f) for f in folders),
            output.log_evidence,
            fit["log_evidence"],
            best_run,
            output.n_calls,
            output.converged,
        )
    return phase


def _mesh_result(folder: Path, mesh: int, settings: SlamSettings, seed: int) -> PhaseResult:
    """Mesh job ``mesh``'s result from ``folder``, checked against the chain's settings and
    the seed the whole phase would have given it."""
    rerun = f"rerun `mgelens phase mass --mesh {mesh}` (rule mass_mesh)"
    if not (folder / RESULT_FILE).is_file():
        raise MeshPoolError(f"{folder / RESULT_FILE} not found: {rerun}")
    try:
        result = PhaseResult.read(folder)
    except (OSError, ValueError, KeyError) as error:
        raise MeshPoolError(f"{folder}: cannot read its result ({error}); {rerun}") from error
    if result.phase != "mass" or result.settings.get("mesh") != mesh:
        raise MeshPoolError(
            f"{folder / RESULT_FILE} is not the result of MASS mesh {mesh} (phase "
            f"{result.phase!r}, mesh {result.settings.get('mesh')!r}); {rerun}"
        )
    expected = json.loads(json.dumps(settings.to_dict()))
    if result.settings.get("slam") != expected:
        raise MeshPoolError(f"{folder / RESULT_FILE} was written with other slam settings; {rerun}")
    started = result.settings.get("mesh_seed")
    if started is None:
        raise MeshPoolError(
            f"{folder / RESULT_FILE} does not record the seed its sampling started from "
            f"(written by an older mgelens); {rerun}"
        )
    if started != seed + mesh:
        raise MeshPoolError(
            f"{folder / RESULT_FILE} was sampled from seed {started}, not {seed + mesh} "
            f"(the phase's seed {seed} + mesh {mesh}); {rerun}"
        )
    if not (folder / MODEL_FILE).is_file():
        raise MeshPoolError(f"{folder / MODEL_FILE} not found: {rerun}")
    return result


def _check_inputs(folders: list[Path], runs: list[PhaseResult]) -> None:
    """Every mesh job read the same input files, and none has changed since."""
    recorded = runs[0].input_checksums
    for folder, run in zip(folders, runs, strict=True):
        if run.input_checksums != recorded:
            raise MeshPoolError(
                f"{folder / RESULT_FILE} and {folders[0] / RESULT_FILE} read different "
                "input files: rerun every MASS mesh job"
            )
    missing = [path for path in recorded if not Path(path).is_file()]
    if missing:
        raise MeshPoolError(
            f"input file {missing[0]} of the MASS mesh jobs is gone: rerun the phases "
            "before MASS and every mesh job"
        )
    changed = [p for p, digest in input_checksums(recorded).items() if recorded[p] != digest]
    if changed:
        raise MeshPoolError(
            f"input file {changed[0]} changed after the MASS mesh jobs read it: rerun every "
            "MASS mesh job"
        )

"""Nested sampling of a :class:`~mgelens.search.model.ParameterSpace` (SPEC §8.3, §8.4).

:func:`run_nested` wraps dynesty's static (``NestedSampler``) and dynamic
(``DynamicNestedSampler``) samplers, and nautilus. It adds what long fits on clusters need:

* **Reproducibility**: a fixed seed (``rstate=np.random.default_rng(seed)`` for dynesty,
  ``seed=`` for nautilus).
* **Checkpoint and automatic resume** (dynesty): dynesty writes its checkpoint every
  ``checkpoint_every`` seconds (itself through a temporary file and a rename). If the file
  exists when :func:`run_nested` starts, the sampler is restored from it (RNG state
  included) and continues, so an interrupted run finishes with the same samples and log
  evidence as an uninterrupted one. The checkpoint carries a fingerprint of the parameter
  space, the settings and the seed, and so does its JSON sidecar
  ``<stem>.fingerprint.json``, which is checked *before* the checkpoint is unpickled
  (unpickling can run code): a mismatch, or a checkpoint without its sidecar, raises
  :class:`CheckpointMismatchError` instead of loading a foreign file or silently
  continuing a different fit. The checkpoint is **kept** after a
  successful run: calling :func:`run_nested` again returns the stored run without sampling.
  Callers delete it once their result files are written if they want the space back.
  Nautilus checkpoints to ``<checkpoint stem>.h5`` (HDF5, no code), with the same sidecar:
  the sampler's state is written there atomically every ``checkpoint_every`` seconds (at
  least :data:`NAUTILUS_MIN_PROGRESS_INTERVAL`) and at the end, so a run killed while
  writing resumes from the previous checkpoint (:func:`_write_nautilus_checkpoint`), and
  the file's ``mgelens`` group carries the sampling seconds and resumes that nautilus
  itself does not keep.
* **Enough live points for nautilus**: a nautilus run keeps at least
  :data:`NAUTILUS_LIVE_PER_PARAMETER` live points per free parameter; a smaller ``n_live``
  is raised to that, with a log line, and the output records the number used.
* **Quiet progress**: no progress bar; one line every ``progress_every`` seconds through
  ``log`` (default: the ``mgelens.search`` logger at INFO level).
* **Parallel likelihoods**: ``n_processes > 1`` runs a ``multiprocessing`` pool ("spawn"
  start method). The likelihood and the parameter space are sent once to each worker at
  start-up; neither dynesty's tasks nor its checkpoint carry them (only the names of the
  module-level functions of :mod:`mgelens.search.evaluation`), so a large dataset is
  never pickled per call. The likelihood must therefore be picklable when
  ``n_processes > 1``. Each worker runs one
  numba and one BLAS thread, so ``n_processes`` workers use as many cores.
* **Rejected samples** (SPEC §8.4): the likelihood returns ``REJECTED_LOG_LIKELIHOOD``
  (−1e99) for a sample that cannot be fitted; −inf and anything below −1e99 count the same.
  Calls and rejections are counted in shared memory (right with a pool) and stored in the
  checkpoint, so the counts survive a resume.

One :func:`run_nested` runs at a time per process (:mod:`mgelens.search.evaluation`
holds the one evaluation the samplers' module-level callables forward to).
"""

import contextlib
import json
import logging
import math
import time
import traceback
import warnings
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import dynesty
import dynesty.utils
import h5py
import numpy as np
from scipy import special

from mgelens.atomic import atomic_path, write_json
from mgelens.rejection import REJECTED_LOG_LIKELIHOOD
from mgelens.search import peak_check
from mgelens.search.evaluation import (
    SPAWN,
    Evaluation,
    evaluating,
    installed_log_likelihood,
    installed_log_likelihood_nautilus,
    installed_prior_transform,
)
from mgelens.search.model import ParameterSpace
from mgelens.search.posterior import SamplerOutput
from mgelens.search.sampler_settings import SamplerSettings

LOGGER = logging.getLogger("mgelens.search")
_STATE_ATTRIBUTE = "mgelens_state"


class CheckpointMismatchError(ValueError):
    """A checkpoint belongs to a different parameter space, settings or seed."""


# -- checkpoint bookkeeping ----------------------------------------------------------------
class _RunState:
    """Counters and fingerprint carried inside dynesty's checkpoint.

    It sits on the sampler as an attribute and pickles as a plain ``dict`` snapshot taken
    when dynesty writes the checkpoint, so the counts always match the stored state.
    """

    def __init__(self, fingerprint: dict, counts, runtime_before: float, n_resumes: int):
        self.fingerprint = fingerprint
        self.counts = counts
        self.runtime_before = runtime_before
        self.n_resumes = n_resumes
        self.started = time.perf_counter()

    @property
    def runtime(self) -> float:
        return self.runtime_before + time.perf_counter() - self.started

    def snapshot(self, finished: bool = False) -> dict:
        return {
            "fingerprint": self.fingerprint,
            "n_calls": int(self.counts[0]),
            "n_rejected": int(self.counts[1]),
            "runtime": self.runtime,
            "n_resumes": self.n_resumes,
            "finished": finished,
        }

    def __reduce__(self):
        return dict, (self.snapshot(),)


def _fingerprint(
    space: ParameterSpace,
    settings: SamplerSettings,
    seed: int,
    live_reference: np.ndarray | None = None,
) -> dict:
    """What a checkpoint must match: the space, the result settings, the seed and the
    reference point among the first live points, if any."""
    content = {"space": space.to_dict(), "settings": settings.result_settings(), "seed": seed}
    if live_reference is not None:
        content["live_reference"] = [float(value) for value in live_reference]
    return json.loads(json.dumps(content))


def fingerprint_path(checkpoint: Path) -> Path:
    """The JSON sidecar of a checkpoint file: ``<stem>.fingerprint.json``."""
    return checkpoint.with_suffix(".fingerprint.json")


def _check_sidecar(checkpoint: Path, expected: dict) -> None:
    """Compare a checkpoint's JSON sidecar with ``expected`` before the checkpoint itself
    is read (a pickle can run code when loaded, so a foreign one is never unpickled)."""
    sidecar = fingerprint_path(checkpoint)
    if not sidecar.is_file():
        raise CheckpointMismatchError(
            f"checkpoint {checkpoint} has no {sidecar.name} to check it against these "
            "settings; delete it to start afresh"
        )
    try:
        stored = json.loads(sidecar.read_text())
    except (OSError, ValueError) as error:
        raise CheckpointMismatchError(
            f"{sidecar}: unreadable ({error}); delete it and {checkpoint.name} to start afresh"
        ) from error
    _check_fingerprint(checkpoint, stored, expected)


def _check_fingerprint(path: Path, stored: dict, expected: dict) -> None:
    if stored != expected:
        differing = sorted(k for k in expected if stored.get(k) != expected.get(k))
        raise CheckpointMismatchError(
            f"checkpoint {path} was written for a different {', '.join(differing)}; "
            "delete it to start afresh, or rerun with the original settings"
        )


class _ProgressLine:
    """dynesty ``print_func``: one log line at most every ``every`` seconds."""

    def __init__(self, log: Callable[[str], None], every: float, state: _RunState, method: str):
        self.log, self.every, self.state, self.method = log, every, state, method
        self.last: float | None = None

    def __call__(self, result, niter, ncall, dlogz=None, stop_val=None, nbatch=None, **_):
        now = time.perf_counter()
        if self.last is not None and now - self.last < self.every:
            return
        self.last = now
        parts = [f"{self.method}: iteration {niter}"]
        if nbatch:
            parts.append(f"batch {nbatch}")
        parts.append(f"{int(self.state.counts[0])} calls ({int(self.state.counts[1])} rejected)")
        logz, logzvar = getattr(result, "logz", None), getattr(result, "logzvar", None)
        if logz is not None and logzvar is not None:
            parts.append(f"ln Z = {logz:.6g} ± {math.sqrt(max(logzvar, 0.0)):.3g}")
        delta = getattr(result, "delta_logz", None)
        if delta is not None and dlogz is not None and math.isfinite(delta):
            parts.append(f"Δln Z = {delta:.3g} (stop < {dlogz:.3g})")
        elif stop_val is not None:
            parts.append(f"stop value {stop_val:.3g}")
        loglstar = getattr(result, "loglstar", None)
        if loglstar is not None:
            parts.append(f"ln L* = {loglstar:.6g}")
        parts.append(f"{self.state.runtime:.0f} s")
        self.log(", ".join(parts))


# -- dynesty -------------------------------------------------------------------------------
def resolve_sample_method(sample: str, n_dim: int) -> str:
    """dynesty sampling method, with "auto" resolved by dimension (see SamplerSettings)."""
    if sample != "auto":
        return sample
    if n_dim < 10:
        return "unif"
    return "rwalk" if n_dim <= 20 else "rslice"


def _new_dynesty_sampler(
    settings: SamplerSettings, n_dim: int, seed: int, pool, seeded: Callable | None = None
):
    """A new dynesty sampler; ``seeded(rstate)``, if given, returns its first live points
    [u, v, ln L] drawn with ``rstate`` (:func:`_reference_live_points`)."""
    sample = resolve_sample_method(settings.sample, n_dim)
    options = {"nlive": settings.n_live, "bound": settings.bound, "sample": sample}
    options["facc"] = settings.facc
    if sample == "rwalk":
        options["walks"] = settings.walks
    elif sample in ("slice", "rslice"):
        options["slices"] = settings.slices
    if pool is not None:
        options.update(pool=pool, queue_size=settings.queue_size or settings.n_processes)
    factory = (
        dynesty.DynamicNestedSampler
        if settings.method == "dynesty_dynamic"
        else dynesty.NestedSampler
    )
    rstate = np.random.default_rng(seed)
    if seeded is not None:
        options["live_points"] = seeded(rstate)
    with _plateau_warnings_logged_by_mgelens():
        return factory(
            installed_log_likelihood, installed_prior_transform, n_dim, rstate=rstate, **options
        )


def _reference_live_points(
    evaluation: Evaluation, n_live: int, reference: np.ndarray, log: Callable[[str], None]
) -> Callable[[np.random.Generator], list[np.ndarray]]:
    """``seeded(rstate)`` for :func:`_new_dynesty_sampler`: n_live prior draws made as
    dynesty makes them (``rstate.random((n_live, n_dim))`` through the prior transform),
    each scored with one counted call, with the lowest ln L replaced by ``reference``
    (``SamplerSettings.reference_live_point``; one more call)."""
    space = evaluation.space

    def seeded(rstate: np.random.Generator) -> list[np.ndarray]:
        u = rstate.random((n_live, space.n_free))
        v = space.prior_transform(u)
        log_l = np.array([evaluation.counted(x) for x in v])
        lowest = int(np.argmin(log_l))
        u[lowest], v[lowest] = space.unit_cube(reference), reference
        log_l[lowest] = evaluation.counted(reference)
        log(
            f"dynesty_static: the reference point (ln L {log_l[lowest]:.2f}) replaces the "
            f"lowest of the {n_live} first live points (the highest drawn: "
            f"{np.max(np.delete(log_l, lowest)):.2f})"
        )
        return [u, v, log_l]

    return seeded


@contextlib.contextmanager
def _plateau_warnings_logged_by_mgelens() -> Iterator[None]:
    """Silence dynesty's warnings about caps and likelihood plateaus: a run that stops on
    either is logged and recorded by mgelens (its stop reason, ``converged: false``)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "The sampling was stopped short", UserWarning)
        warnings.filterwarnings("ignore", "We have reached the plateau", UserWarning)
        warnings.filterwarnings("ignore", "All the initial likelihood values", RuntimeWarning)
        yield


def _run_dynesty(
    sampler, settings: SamplerSettings, progress, checkpoint: str | None, resume, calls_so_far
) -> tuple[bool, str]:
    """Run (or continue) a dynesty sampler; return (converged, stop reason). A static run
    that stopped short of ``dlogz`` without reaching a cap stopped on a likelihood plateau,
    and its reason starts with :data:`PLATEAU_STOP`; so does one whose bound update failed
    on collapsed live points (:data:`COLLAPSED_STOP`). Any other exception propagates."""
    maxcall = None if settings.max_calls is None else max(settings.max_calls - calls_so_far, 1)
    common = {
        "print_progress": True,
        "print_func": progress,
        "checkpoint_file": checkpoint,
        "checkpoint_every": settings.checkpoint_every,
        "resume": resume,
        "maxiter": settings.max_iterations,
        "maxcall": maxcall,
    }
    iterations_before, calls_before = sampler.it, sampler.ncall
    collapsed = ""
    with _plateau_warnings_logged_by_mgelens():
        try:
            _run_dynesty_quietly(sampler, settings, common)
        except IndexError as error:
            if settings.method != "dynesty_static" or not _raised_in_bound_update(error):
                raise
            sampler.add_final_live(print_progress=False)
            collapsed = f" ({COLLAPSED_STOP}: {error})"
    cap = _reached_cap(
        settings, maxcall, sampler.it - iterations_before, sampler.ncall - calls_before
    )
    if settings.method == "dynesty_dynamic":
        if cap:
            return False, f"stopped at {cap} before the dynamic stopping criterion was reached"
        return True, "dynamic stopping criterion reached"
    delta, dlogz = final_delta_log_evidence(sampler), _static_dlogz(settings)
    if delta < dlogz and not collapsed:
        return True, f"remaining Δln Z = {delta:.4g} below dlogz = {dlogz:.4g}"
    stop = f"stopped at {cap}" if cap and not collapsed else PLATEAU_STOP
    reason = f"{stop} with remaining Δln Z = {delta:.4g} above dlogz = {dlogz:.4g}"
    return False, reason + collapsed


def _raised_in_bound_update(error: BaseException) -> bool:
    """Whether ``error`` came out of dynesty's ellipsoid bounds (its k-means split of the
    live points)."""
    frames = traceback.extract_tb(error.__traceback__)
    return any(Path(frame.filename).name == "bounding.py" for frame in frames)


PLATEAU_STOP = "stopped on a likelihood plateau"
"""Start of the stop reason of a static dynesty run whose live points all reached one ln L
before its remaining Δln Z fell below ``dlogz``, or collapsed (:data:`COLLAPSED_STOP`)."""

COLLAPSED_STOP = "its live points collapsed and dynesty's bound update failed"
"""Part of the stop reason of a static dynesty run whose random walks piled its live points
onto one narrow spike of ln L: identical points give a parameter no spread, and
dynesty's k-means split of the live points (``bounding._bounding_ellipsoids``, scaled by
that spread) fails with an IndexError. The run stops there like one on a plateau: its
samples so far and the final live points are kept, it is not converged, and
``plateau_restarts`` start it afresh with more live points."""


def _reached_cap(settings: SamplerSettings, maxcall: int | None, iterations, calls) -> str:
    """The cap that ended a dynesty session ("" if none), judged on dynesty's own counts:
    dynesty stops once its session's iterations or calls pass the caps it was given. Its
    call count leaves out the first live points, so mgelens's own call counter, which
    includes them, can end below ``max_calls`` for a run that the cap stopped."""
    if settings.max_iterations is not None and iterations >= settings.max_iterations:
        return f"max_iterations = {settings.max_iterations}"
    if maxcall is not None and calls >= maxcall:
        return f"max_calls = {settings.max_calls}"
    return ""


def _static_dlogz(settings: SamplerSettings) -> float:
    """The static sampler's stopping threshold: ``dlogz`` or dynesty's default."""
    return 1e-3 * (settings.n_live - 1) + 0.01 if settings.dlogz is None else settings.dlogz


def final_delta_log_evidence(sampler) -> float:
    """Remaining Δln Z = ln(Z + L_max X) − ln Z of a finished static dynesty run, where
    it stopped: the value dynesty compared with ``dlogz`` (Z and the prior volume X at the
    last dead point, L_max the best final live point; the final live points are the last
    ``nlive`` entries of the run). A run that stopped before its first dead point (its
    first live points all at one ln L) has integrated nothing: Δln Z is infinite."""
    run = sampler.saved_run
    last = len(run["logl"]) - sampler.nlive - 1
    if last < 0:
        return math.inf
    live_max = float(np.max(run["logl"][last + 1 :]))
    return float(np.logaddexp(0.0, live_max + run["logvol"][last] - run["logz"][last]))


def _run_dynesty_quietly(sampler, settings: SamplerSettings, common: dict) -> None:
    if settings.method == "dynesty_dynamic":
        sampler.run_nested(
            nlive_init=settings.n_live,
            nlive_batch=settings.n_live,
            dlogz_init=0.01 if settings.dlogz is None else settings.dlogz,
            n_effective=settings.n_effective,
            **common,
        )
    else:
        sampler.run_nested(dlogz=settings.dlogz, **common)


def _restore_dynesty(path: Path, pool):
    """The dynesty sampler of a checkpoint whose sidecar matched."""
    try:
        return dynesty.utils.restore_sampler(str(path), pool=pool)
    except (OSError, EOFError, RuntimeError) as error:  # dynesty: RuntimeError if corrupt
        raise CheckpointMismatchError(
            f"checkpoint {path} is unreadable ({error}); delete it to start afresh"
        ) from error


def _save_dynesty(sampler, path: Path) -> None:
    with atomic_path(path) as temporary:
        dynesty.utils.save_sampler(sampler, str(temporary))


def _sample_dynesty(
    evaluation: Evaluation,
    settings: SamplerSettings,
    checkpoint_path: Path | None,
    seed: int,
    log: Callable[[str], None],
    live_reference: np.ndarray | None = None,
) -> SamplerOutput:
    space = evaluation.space
    fingerprint = _fingerprint(space, settings, seed, live_reference)
    resume = checkpoint_path is not None and checkpoint_path.exists()
    if resume:
        _check_sidecar(checkpoint_path, fingerprint)
    elif checkpoint_path is not None:
        write_json(fingerprint_path(checkpoint_path), fingerprint)
    with evaluating(evaluation, settings.n_processes) as pool:
        stored = {"n_calls": 0, "n_rejected": 0, "runtime": 0.0, "n_resumes": -1}
        if resume:
            sampler = _restore_dynesty(checkpoint_path, pool)
            stored = getattr(sampler, _STATE_ATTRIBUTE, None)
            if stored is None:
                raise CheckpointMismatchError(
                    f"checkpoint {checkpoint_path} was not written by mgelens: delete it"
                )
            _check_fingerprint(checkpoint_path, stored["fingerprint"], fingerprint)
            evaluation.counts[:] = [stored["n_calls"], stored["n_rejected"]]
            log(
                f"{settings.method}: resuming from {checkpoint_path} "
                f"({stored['n_calls']} calls so far)"
            )
        else:
            seeded = (
                None
                if live_reference is None
                else _reference_live_points(evaluation, settings.n_live, live_reference, log)
            )
            sampler = _new_dynesty_sampler(settings, space.n_free, seed, pool, seeded)
            log(f"{settings.method}: {space.n_free} free parameters, seed {seed}")
        if stored.get("finished", False):
            final = stored
        else:
            state = _RunState(
                fingerprint, evaluation.counts, stored["runtime"], stored["n_resumes"] + 1
            )
            setattr(sampler, _STATE_ATTRIBUTE, state)
            progress = _ProgressLine(log, settings.progress_every, state, settings.method)
            checkpoint = None if checkpoint_path is None else str(checkpoint_path)
            converged, reason = _run_dynesty(
                sampler, settings, progress, checkpoint, resume, stored["n_calls"]
            )
            if not converged:
                log(f"{settings.method}: WARNING {reason}: not converged")
            final = {**state.snapshot(finished=True), "converged": converged, "reason": reason}
            if checkpoint_path is not None:
                setattr(sampler, _STATE_ATTRIBUTE, final)
                _save_dynesty(sampler, checkpoint_path)
        results = sampler.results
    log_weights = results["logwt"] - special.logsumexp(results["logwt"])
    output = SamplerOutput(
        names=space.free_names,
        samples=results["samples"],
        log_weights=log_weights,
        log_likelihoods=results["logl"],
        log_evidence=float(results["logz"][-1]),
        log_evidence_error=float(results["logzerr"][-1]),
        n_calls=final["n_calls"],
        n_rejected=final["n_rejected"],
        runtime=final["runtime"],
        n_resumes=final["n_resumes"],
        method=settings.method,
        settings=settings.to_dict(),
        seed=seed,
        converged=final["converged"],
        stop_reason=final["reason"],
    )
    log(_summary_line(output))
    return output


# -- nautilus ------------------------------------------------------------------------------
def _nautilus_checkpoint(checkpoint_path: Path | None) -> Path | None:
    """Nautilus's HDF5 checkpoint beside ``checkpoint_path`` (written through h5py)."""
    return None if checkpoint_path is None else checkpoint_path.with_suffix(".h5")


_RUN_STATE_GROUP = "mgelens"
"""HDF5 group of a nautilus checkpoint holding what nautilus does not keep: the run's
sampling seconds and resumes so far (attributes ``runtime`` and ``n_resumes``)."""


def _nautilus_run_state(checkpoint: Path) -> tuple[float, int]:
    """(sampling seconds, resumes) stored in a nautilus checkpoint by
    :func:`_write_nautilus_checkpoint`; (0, 0) for a checkpoint of an mgelens that did not
    store them (its run still resumes; its earlier seconds and resumes go uncounted)."""
    with h5py.File(checkpoint, "r") as file:
        if _RUN_STATE_GROUP not in file:
            return 0.0, 0
        attributes = file[_RUN_STATE_GROUP].attrs
        return float(attributes["runtime"]), int(attributes["n_resumes"])


def _write_nautilus_checkpoint(sampler, checkpoint: Path, runtime: float, n_resumes: int) -> None:
    """Write ``sampler``'s whole state to ``checkpoint`` atomically: into a temporary
    ``.h5`` file beside it (nautilus insists on the suffix), then renamed onto it, so a run
    killed while writing keeps the previous checkpoint. ``runtime`` (sampling seconds of
    every session so far) and ``n_resumes`` go into its group :data:`_RUN_STATE_GROUP`.

    Nautilus itself, given a file, rewrites it whole after every new bound (every bound
    and network again each time; docs/benchmarks.md, "The samplers' own overheads") and
    in place, so a run stopped during a write left a file it could not resume from (on
    M2, one without its random state). The sampler therefore runs without a file, and
    this writes its state between ``Sampler.run`` calls, where it is consistent.
    """
    with atomic_path(checkpoint, suffix=".h5") as temporary:
        sampler.write(temporary, overwrite=True)
        with h5py.File(temporary, "r+") as file:
            group = file.create_group(_RUN_STATE_GROUP)
            group.attrs["runtime"] = runtime
            group.attrs["n_resumes"] = n_resumes


NAUTILUS_LIVE_PER_PARAMETER = 3
"""Fewest nautilus live points per free parameter. Below it nautilus's bounds fail and its
run is wrong without saying so, as the quick profile's 30 were for the 3×Sérsic MASS's
22 parameters (measured in docs/slam.md, "Live points per parameter")."""


def nautilus_live_points(n_live: int, n_free: int) -> int:
    """Live points of a nautilus run of ``n_free`` parameters asked for ``n_live``: at
    least :data:`NAUTILUS_LIVE_PER_PARAMETER` per parameter."""
    return max(n_live, NAUTILUS_LIVE_PER_PARAMETER * n_free)


NAUTILUS_NETWORK_MAX_ITER = 5000
"""Most training epochs of one of nautilus's neural networks (nautilus 1.0's default is
10,000). Nautilus stores each network's loss curve, one float per epoch, as one HDF5
attribute of its checkpoint, and an attribute holds at most 64 kB: a network that trained
for its 10,000 epochs (80 kB) stopped a MASS run on M2 with "object header message is too
large", and every retry with it. Networks stop earlier when their loss stops falling, so
the cap binds only on such rare long trainings."""

NAUTILUS_MIN_PROGRESS_INTERVAL = 1.0
"""Shortest stretch of a nautilus run between progress lines and checkpoint copies,
seconds: nautilus starts no likelihood call once its timeout has passed, so a zero
timeout would never advance."""


def _nautilus_progress(sampler, seconds: float) -> str:
    """Progress line; N_eff and ln Z are undefined before the first batch."""
    parts = [f"nautilus: {sampler.n_like} calls"]
    if sampler.n_like > 0:
        parts += [f"N_eff = {sampler.n_eff:.0f}", f"ln Z = {sampler.log_z:.3f}"]
    return ", ".join([*parts, f"{seconds:.0f} s"])


def _sample_nautilus(
    evaluation: Evaluation,
    settings: SamplerSettings,
    checkpoint_path: Path | None,
    seed: int,
    log: Callable[[str], None],
) -> SamplerOutput:
    import nautilus  # imported here: it loads its neural-network stack on import

    space = evaluation.space
    n_live = nautilus_live_points(settings.n_live, space.n_free)
    if n_live != settings.n_live:
        log(
            f"nautilus: n_live raised from {settings.n_live} to {n_live}, "
            f"{NAUTILUS_LIVE_PER_PARAMETER} per free parameter ({space.n_free})"
        )
        settings = replace(settings, n_live=n_live)
    filepath = _nautilus_checkpoint(checkpoint_path)
    resume_from = None
    runtime_before, n_resumes = 0.0, 0
    if filepath is not None:
        fingerprint = _fingerprint(space, settings, seed)
        if filepath.exists():
            _check_sidecar(filepath, fingerprint)
            runtime_before, n_resumes = _nautilus_run_state(filepath)
            n_resumes += 1
            resume_from = filepath
        write_json(fingerprint_path(filepath), fingerprint)
    started = time.perf_counter()
    with evaluating(evaluation, settings.n_processes) as pool:
        sampler = nautilus.Sampler(
            installed_prior_transform,
            installed_log_likelihood_nautilus,
            n_dim=space.n_free,
            n_live=settings.n_live,
            enlarge_per_dim=settings.enlarge_per_dim,
            split_threshold=settings.split_threshold,
            n_networks=settings.n_networks,
            neural_network_kwargs={"max_iter": NAUTILUS_NETWORK_MAX_ITER},
            n_batch=settings.n_batch,
            pool=pool,
            seed=seed,
            filepath=resume_from,
            resume=True,
        )
        sampler.filepath = None  # it would rewrite the file after every bound: see above
        log(f"nautilus: {space.n_free} free parameters, seed {seed}, {sampler.n_like} calls so far")
        cap = math.inf if settings.max_calls is None else settings.max_calls
        options = {
            "f_live": settings.f_live,
            "n_shell": settings.n_shell,
            "n_eff": settings.n_eff,
            "n_like_max": cap,
            "discard_exploration": settings.discard_exploration,
            "timeout": max(
                min(settings.progress_every, settings.checkpoint_every),
                NAUTILUS_MIN_PROGRESS_INTERVAL,
            ),
            "verbose": False,
        }
        converged = sampler.run(**options)
        logged = written = started
        while not converged and sampler.n_like < cap:
            now = time.perf_counter()
            if filepath is not None and now - written >= settings.checkpoint_every:
                _write_nautilus_checkpoint(
                    sampler, filepath, runtime_before + now - started, n_resumes
                )
                written = now
            if now - logged >= settings.progress_every:
                logged = now
                log(_nautilus_progress(sampler, logged - started))
            converged = sampler.run(**options)
        runtime = runtime_before + time.perf_counter() - started
        if filepath is not None:
            _write_nautilus_checkpoint(sampler, filepath, runtime, n_resumes)  # the finished run
        criteria = f"f_live {settings.f_live}, n_shell {settings.n_shell}, n_eff {settings.n_eff}"
        if converged:
            reason = f"stopping criteria reached ({criteria})"
        else:
            reason = f"stopped at max_calls = {settings.max_calls} before {criteria} were reached"
            log(f"nautilus: WARNING {reason}: not converged")
        points, log_w, log_l = sampler.posterior()
        all_log_l = np.concatenate([np.asarray(v, dtype=float) for v in sampler.log_l])
        n_calls = int(sampler.n_like)
        log_evidence = float(sampler.log_z)
    log_w = np.asarray(log_w, dtype=float)
    log_weights = log_w - special.logsumexp(log_w)
    n_eff = float(1.0 / np.sum(np.exp(2.0 * log_weights)))
    output = SamplerOutput(
        names=space.free_names,
        samples=points,
        log_weights=log_weights,
        log_likelihoods=np.maximum(log_l, REJECTED_LOG_LIKELIHOOD),
        log_evidence=log_evidence,
        log_evidence_error=math.sqrt(max(1.0 / n_eff - 1.0 / len(log_w), 0.0)),
        n_calls=n_calls,
        n_rejected=int(np.sum(all_log_l == -math.inf)),
        runtime=runtime,
        n_resumes=n_resumes,
        method=settings.method,
        settings=settings.to_dict(),
        seed=seed,
        converged=converged,
        stop_reason=reason,
    )
    log(_summary_line(output))
    return output


def _summary_line(output: SamplerOutput) -> str:
    return (
        f"{output.method}: done, ln Z = {output.log_evidence:.3f} ± "
        f"{output.log_evidence_error:.3f}, {len(output.samples)} samples "
        f"(N_eff = {output.effective_sample_size:.0f}), {output.n_calls} calls "
        f"({output.n_rejected} rejected), {output.runtime:.1f} s"
    )


def run_nested(
    log_likelihood: Callable[[np.ndarray], float],
    space: ParameterSpace,
    settings: SamplerSettings | None = None,
    checkpoint_path: str | Path | None = None,
    seed: int = 0,
    log: Callable[[str], None] | None = None,
    reference: np.ndarray | None = None,
) -> SamplerOutput:
    """Sample the posterior of ``space`` under ``log_likelihood`` and estimate ln Z.

    Parameters
    ----------
    log_likelihood : callable
        ``log_likelihood(x) -> float`` for the free-parameter vector ``x`` (order of
        ``space.free_names``; use ``space.values(x)`` for the full dictionary). Return
        ``REJECTED_LOG_LIKELIHOOD`` (−1e99) to reject a sample. Must be picklable when
        ``settings.n_processes > 1``.
    space : ParameterSpace
        Free parameters and their priors.
    settings : SamplerSettings, optional
        Sampler choice and settings (default ``SamplerSettings()``).
    checkpoint_path : str or Path, optional
        Checkpoint file (e.g. ``<phase folder>/sampler.pickle``); resumed automatically if
        it exists, kept after the run. ``None``: no checkpoint.
    seed : int
        Seed of the sampler's random generator.
    log : callable, optional
        Receives progress lines (default: ``logging.getLogger("mgelens.search").info``).
    reference : array, optional
        A free-parameter vector whose ln L a converged run must reach within
        ``settings.peak_tolerance`` (e.g. the maximum an optimiser found before sampling);
        checked after a converged run, with one likelihood call, when
        ``settings.peak_restarts`` > 0 and the point lies inside the priors' support.

    Returns
    -------
    SamplerOutput
    """
    settings = SamplerSettings() if settings is None else settings
    if space.n_free < 1:
        raise ValueError("the parameter space has no free parameter")
    log = LOGGER.info if log is None else log
    checkpoint = None if checkpoint_path is None else Path(checkpoint_path)
    if checkpoint is not None:
        checkpoint.parent.mkdir(parents=True, exist_ok=True)
    evaluation = Evaluation(log_likelihood, space, SPAWN.Array("q", 2))
    if reference is not None and not np.isfinite(space.log_prior(reference)):
        log(f"{settings.method}: the reference point lies outside the priors: not used")
        reference = None
    live_reference = reference if settings.reference_live_point else None
    output = _sample_with_plateau_restarts(
        evaluation, settings, checkpoint, seed, log, live_reference
    )
    if not (settings.peak_restarts and output.converged):
        return output  # an unconverged run (a cap, a plateau) is reported as such
    if reference is None and not settings.peak_evaluations:
        log(f"{settings.method}: no peak check (no local search, no reference point)")
        return output
    return _with_peak_restarts(
        evaluation, settings, checkpoint, seed, log, output, reference, live_reference
    )


def _sample_with_plateau_restarts(
    evaluation: Evaluation,
    settings: SamplerSettings,
    checkpoint: Path | None,
    seed: int,
    log: Callable[[str], None],
    live_reference: np.ndarray | None = None,
) -> SamplerOutput:
    """One run of ``settings.method``; a static dynesty run that stops on a plateau is
    started afresh with more live points (``plateau_restarts``). ``live_reference``: a
    point among every dynesty run's first live points
    (``SamplerSettings.reference_live_point``)."""
    if settings.method == "nautilus":
        return _sample_nautilus(evaluation, settings, checkpoint, seed, log)
    output = _sample_dynesty(evaluation, settings, checkpoint, seed, log, live_reference)
    attempts = [output]
    for attempt in range(1, settings.plateau_restarts + 1):
        if not output.stop_reason.startswith(PLATEAU_STOP):
            break
        restart = replace(settings, n_live=settings.n_live * 2**attempt, plateau_restarts=0)
        log(
            f"{settings.method}: restart {attempt} of {settings.plateau_restarts} after a "
            f"likelihood plateau, with {restart.n_live} live points and seed {seed + attempt}"
        )
        evaluation.counts[:] = [0, 0]
        output = _sample_dynesty(
            evaluation,
            restart,
            _restart_checkpoint(checkpoint, attempt),
            seed + attempt,
            log,
            live_reference,
        )
        attempts.append(output)
    return _with_restarts(attempts, settings.plateau_restarts)


def _restart_checkpoint(
    checkpoint: Path | None, attempt: int, kind: str = "restart"
) -> Path | None:
    """Checkpoint of restart ``attempt`` (``<stem>-<kind><attempt><suffix>``)."""
    if checkpoint is None:
        return None
    return checkpoint.with_name(f"{checkpoint.stem}-{kind}{attempt}{checkpoint.suffix}")


def _with_peak_restarts(
    evaluation: Evaluation,
    settings: SamplerSettings,
    checkpoint: Path | None,
    seed: int,
    log: Callable[[str], None],
    output: SamplerOutput,
    reference: np.ndarray | None,
    live_reference: np.ndarray | None,
) -> SamplerOutput:
    """Check that ``output`` (converged) holds its peak
    (:func:`_peak_gain`); while it does not, sample afresh with twice the live points, up
    to ``settings.peak_restarts`` times (a restart that does not converge ends the loop).
    A restart's gain is also at least how far its highest ln L + ln prior falls below an
    earlier attempt's: a restart that settles in a lower mode than the run it replaces
    misses the peak too, however flat its own neighbourhood (docs/slacs.md,
    slacs1451−0239). The last attempt's output, with every attempt's calls, runtimes and
    resumes summed (the checks' calls too) and its ``peak_gain``; not converged if it
    still misses the peak."""
    attempts = []
    check_calls = 0 if reference is None else 1  # the reference's one call
    reference_log_likelihood = None if reference is None else evaluation.counted(reference)
    earlier_best = None
    for attempt in range(settings.peak_restarts + 1):
        if attempt:
            restart = replace(settings, n_live=settings.n_live * 2**attempt, peak_restarts=0)
            log(
                f"{settings.method}: restart {attempt} of {settings.peak_restarts} with "
                f"{restart.n_live} live points and seed {seed + attempt}: the posterior "
                "misses its peak"
            )
            evaluation.counts[:] = [0, 0]
            output = _sample_with_plateau_restarts(
                evaluation,
                restart,
                _restart_checkpoint(checkpoint, attempt, "peak"),
                seed + attempt,
                log,
                live_reference,
            )
        gain, calls, best = _peak_gain(
            evaluation, settings, output, reference_log_likelihood, earlier_best, log
        )
        check_calls += calls
        earlier_best = best if earlier_best is None else max(earlier_best, best)
        attempts.append(replace(output, peak_gain=gain))
        if gain <= settings.peak_tolerance or not output.converged:
            break
    last = attempts[-1]
    missed = last.peak_gain > settings.peak_tolerance
    reason = last.stop_reason
    if len(attempts) > 1:
        reason += (
            f" (attempt {len(attempts)}, live points {_live_points(attempts)}: the earlier "
            "attempts missed their peak)"
        )
    if missed:
        reason += (
            f"; its peak check gained {last.peak_gain:.2f} over its best sample (more than "
            f"{settings.peak_tolerance}): the posterior misses its peak"
        )
    summed = _summed_attempts(attempts, reason)
    return replace(
        summed, n_calls=summed.n_calls + check_calls, converged=last.converged and not missed
    )


def _peak_gain(
    evaluation: Evaluation,
    settings: SamplerSettings,
    output: SamplerOutput,
    reference_log_likelihood: float | None,
    earlier_best: float | None,
    log: Callable[[str], None],
) -> tuple[float, int, float]:
    """How far the run falls short of its peak: the gain in ln L + ln prior of a local
    search from its highest-posterior sample (:func:`peak_check.peak_gain`, unless
    ``settings.peak_evaluations`` is 0), the reference point's ln L above the
    highest-likelihood sample's (the reference is the centre of the priors it passed, so
    no prior pulls the posterior away from it) and, for a restart, the earlier attempts'
    highest ln L + ln prior (``earlier_best``) above the run's; the largest gain (≥ 0),
    the search's calls and the run's highest ln L + ln prior."""
    best = float(output.log_likelihoods.max())
    gain, calls = 0.0, 0
    if settings.peak_evaluations:
        gain, calls = peak_check.peak_gain(
            evaluation.counted, evaluation.space, output, settings.peak_evaluations
        )
        log(
            f"{settings.method}: a local search from the highest-posterior sample gains "
            f"{gain:.2f} in ln L + ln prior in {calls} calls (tolerance "
            f"{settings.peak_tolerance}; highest ln L {best:.2f})"
        )
    if reference_log_likelihood is not None:
        shortfall = reference_log_likelihood - best
        log(
            f"{settings.method}: the reference point has ln L {reference_log_likelihood:.2f}, "
            f"{shortfall:+.2f} against the highest-likelihood sample (tolerance "
            f"{settings.peak_tolerance})"
        )
        gain = max(gain, shortfall)
    best_posterior = peak_check.highest_log_posterior(evaluation.space, output)[1]
    if earlier_best is not None:
        shortfall = earlier_best - best_posterior
        log(
            f"{settings.method}: the earlier attempts' highest ln L + ln prior is "
            f"{shortfall:+.2f} against this run's (tolerance {settings.peak_tolerance})"
        )
        gain = max(gain, shortfall)
    return gain, calls, best_posterior


def _with_restarts(attempts: list[SamplerOutput], plateau_restarts: int) -> SamplerOutput:
    """The last attempt's output with the calls, rejections, runtimes and resumes of every
    attempt summed, and the restarts named in its stop reason."""
    last = attempts[-1]
    if len(attempts) == 1:
        return last
    return _summed_attempts(
        attempts,
        f"{last.stop_reason} (attempt {len(attempts)} of {plateau_restarts + 1}, live "
        f"points {_live_points(attempts)}: the earlier attempts {PLATEAU_STOP})",
    )


def _live_points(attempts: list[SamplerOutput]) -> str:
    """The attempts' live points, e.g. "30, 60"."""
    return ", ".join(str(a.settings["n_live"]) for a in attempts)


def _summed_attempts(attempts: list[SamplerOutput], stop_reason: str) -> SamplerOutput:
    """The last attempt's output with every attempt's calls, rejections, runtimes and
    resumes summed, and ``stop_reason``."""
    return replace(
        attempts[-1],
        n_calls=sum(a.n_calls for a in attempts),
        n_rejected=sum(a.n_rejected for a in attempts),
        runtime=sum(a.runtime for a in attempts),
        n_resumes=sum(a.n_resumes for a in attempts),
        stop_reason=stop_reason,
    )

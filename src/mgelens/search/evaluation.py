"""The likelihood as nested samplers call it, in this process or in a pool of workers.

dynesty and nautilus call module-level functions (:func:`installed_prior_transform`,
:func:`installed_log_likelihood`, :func:`installed_log_likelihood_nautilus`) that
forward to the one :class:`Evaluation` installed here, so that neither a sampler's tasks
nor its checkpoint carry the likelihood or its data: a pool's workers receive the
evaluation once, at start-up (:func:`evaluating`). Every call is counted in shared
memory, and a likelihood of −1e99 or below is a rejected sample (SPEC §8.4).
"""

import contextlib
import math
import multiprocessing
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from mgelens.memory import keep_freed_memory
from mgelens.rejection import REJECTED_LOG_LIKELIHOOD
from mgelens.search.model import ParameterSpace
from mgelens.threads import limit_threads

SPAWN = multiprocessing.get_context("spawn")
"""Process context of every worker pool (the likelihood pool here, MASS's side-by-side
mesh runs in :mod:`mgelens.pipeline.run`): spawned workers, set up by
:func:`prepare_worker_process`."""


@dataclass(frozen=True)
class Evaluation:
    """What the module-level callables evaluate: likelihood, space and shared counters."""

    log_likelihood: Callable[[np.ndarray], float]
    space: ParameterSpace
    counts: object  # multiprocessing Array('q', 2): [calls, rejected]

    def counted(self, x: np.ndarray) -> float:
        value = float(self.log_likelihood(x))
        if math.isnan(value) or value == math.inf:
            raise FloatingPointError(
                f"log likelihood is {value} at {self.space.values(x)}; "
                f"return {REJECTED_LOG_LIKELIHOOD} to reject a sample"
            )
        rejected = value <= REJECTED_LOG_LIKELIHOOD
        with self.counts.get_lock():
            self.counts[0] += 1
            self.counts[1] += int(rejected)
        return REJECTED_LOG_LIKELIHOOD if rejected else value


_current: list[Evaluation] = []


def _install(evaluation: Evaluation | None) -> None:
    """Make ``evaluation`` the one the callables below use."""
    _current[:] = [] if evaluation is None else [evaluation]


def prepare_worker_process() -> None:
    """Set up a spawned worker process as a phase job is set up: one numba, BLAS and
    OpenMP thread, freed memory kept (:func:`mgelens.memory.keep_freed_memory`). A spawned
    worker inherits neither from its parent, and numba's default of all cores per worker
    oversubscribes the machine (docs/design_notes.md, "Worker threads")."""
    limit_threads(1)
    keep_freed_memory()


def _start_worker(evaluation: Evaluation) -> None:
    """Pool-worker initializer: :func:`prepare_worker_process`, then :func:`_install`."""
    prepare_worker_process()
    _install(evaluation)


def installed_prior_transform(u: np.ndarray) -> np.ndarray:
    return _current[0].space.prior_transform(u)


def installed_log_likelihood(x: np.ndarray) -> float:
    return _current[0].counted(x)


def installed_log_likelihood_nautilus(x: np.ndarray) -> float:
    """Nautilus takes −inf (not −1e99) for a rejected sample."""
    value = _current[0].counted(x)
    return -math.inf if value <= REJECTED_LOG_LIKELIHOOD else value


@contextlib.contextmanager
def evaluating(evaluation: Evaluation, n_processes: int) -> Iterator[object | None]:
    """Install ``evaluation`` here and, for ``n_processes > 1``, in a pool it yields."""
    if _current:
        raise RuntimeError("run_nested is already running in this process")
    _install(evaluation)
    try:
        if n_processes == 1:
            yield None
        else:
            with SPAWN.Pool(n_processes, _start_worker, (evaluation,)) as pool:
                yield pool
    finally:
        _install(None)

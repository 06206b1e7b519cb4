"""A nested-sampling run's weighted samples and what is read from them (SPEC §8.3).

:class:`SamplerOutput` is what every sampler of :mod:`mgelens.search.sampler` returns:
samples, their log weights and log likelihoods, the evidence and the run's bookkeeping.
Weighted quantiles and central credible intervals are computed here, and
:func:`pool_runs` pools runs of one parameter space into one posterior.
"""

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np

SIGMA_PROBABILITY = {1: math.erf(1.0 / math.sqrt(2.0)), 3: math.erf(3.0 / math.sqrt(2.0))}
"""Central credible-interval probabilities: 1σ = 68.27 %, 3σ = 99.73 %."""


def weighted_quantile(values: np.ndarray, weights: np.ndarray, q: float | np.ndarray) -> np.ndarray:
    """Weighted quantiles along axis 0 (inverted-CDF definition).

    The q-quantile is the smallest sample value whose cumulative normalised weight
    reaches q (numpy's ``method="inverted_cdf"`` with weights); it is always a sample
    with non-zero weight.

    Parameters
    ----------
    values : ndarray, shape (n,) or (n, m)
    weights : ndarray, shape (n,)
        Non-negative weights, not necessarily normalised.
    q : float or ndarray
        Probabilities in [0, 1].

    Returns
    -------
    ndarray, shape ``np.shape(q) + values.shape[1:]``
    """
    values = np.asarray(values, dtype=float)
    weights = np.asarray(weights, dtype=float)
    if weights.shape != values.shape[:1] or np.any(weights < 0) or not weights.sum() > 0:
        raise ValueError("weights must be non-negative, one per sample, with a positive sum")
    q = np.asarray(q, dtype=float)
    columns = values.reshape(len(values), -1)
    out = np.empty((q.size, columns.shape[1]))
    for j, column in enumerate(columns.T):
        order = np.argsort(column, kind="stable")
        cumulative = np.cumsum(weights[order])
        cumulative /= cumulative[-1]
        index = np.minimum(np.searchsorted(cumulative, q.ravel(), side="left"), len(column) - 1)
        out[:, j] = column[order][index]
    return out.reshape(q.shape + values.shape[1:])


def credible_interval(
    values: np.ndarray, weights: np.ndarray, sigma: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Central credible interval holding erf(sigma/√2) of the weight (1σ: 68.27 %)."""
    probability = math.erf(sigma / math.sqrt(2.0))
    lower, upper = weighted_quantile(
        values, weights, [(1 - probability) / 2, (1 + probability) / 2]
    )
    return lower, upper


@dataclass(frozen=True, eq=False)
class SamplerOutput:
    """Weighted posterior samples and run statistics of one nested-sampling run.

    Attributes
    ----------
    names : tuple of str
        Free-parameter names (columns of ``samples``).
    samples : ndarray, shape (n, n_free)
        Parameter values (parameter units).
    log_weights : ndarray, shape (n,)
        Natural-log posterior weights, normalised so that Σ exp = 1.
    log_likelihoods : ndarray, shape (n,)
        ln L of each sample (rejected samples: −1e99).
    log_evidence, log_evidence_error : float
        ln Z and its error (dynesty's estimate; nautilus: sqrt(1/N_eff − 1/N) from the
        importance weights).
    n_calls, n_rejected : int
        Likelihood calls and rejected samples, over all sessions of a resumed run.
    runtime : float
        Wall-clock seconds spent sampling, over all sessions.
    n_resumes : int
        How many times the run was resumed from its checkpoint.
    method : str
    settings : dict
        :meth:`~mgelens.search.sampler_settings.SamplerSettings.to_dict` of the run.
    seed : int
    converged : bool
        Whether the sampler met its stopping criterion (dynesty static: the remaining
        Δln Z below ``dlogz``; dynamic: its own criterion; nautilus: ``f_live``,
        ``n_shell`` and ``n_eff``) rather than a cap (``max_iterations``, ``max_calls``) or
        a likelihood plateau. A run that did not converge has an unreliable posterior.
    stop_reason : str
        Why the sampler stopped, in words (recorded in result files).
    peak_gain : float or None
        How far the run's peak check found it short of its peak: the gain in ln L + ln
        prior of a local search from its highest-posterior sample
        (:mod:`mgelens.search.peak_check`) or the sampler's reference point's ln L above
        its highest, the larger (``SamplerSettings.peak_restarts``); None if the run was
        not checked.
    """

    names: tuple[str, ...]
    samples: np.ndarray
    log_weights: np.ndarray
    log_likelihoods: np.ndarray
    log_evidence: float
    log_evidence_error: float
    n_calls: int
    n_rejected: int
    runtime: float
    n_resumes: int
    method: str
    settings: dict
    seed: int
    converged: bool = True
    stop_reason: str = ""
    peak_gain: float | None = None

    def __post_init__(self):
        samples = np.asarray(self.samples, dtype=float).reshape(-1, len(self.names))
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "samples", samples)
        for name in ("log_weights", "log_likelihoods"):
            array = np.asarray(getattr(self, name), dtype=float)
            if array.shape != samples.shape[:1]:
                raise ValueError(f"{name} has shape {array.shape}, expected ({len(samples)},)")
            object.__setattr__(self, name, array)

    def __eq__(self, other) -> bool:
        if not isinstance(other, SamplerOutput):
            return NotImplemented
        return all(
            np.array_equal(getattr(self, f.name), getattr(other, f.name))
            if isinstance(getattr(self, f.name), np.ndarray)
            else getattr(self, f.name) == getattr(other, f.name)
            for f in fields(self)
        )

    __hash__ = None

    @property
    def weights(self) -> np.ndarray:
        """Posterior weights, summing to 1."""
        weights = np.exp(self.log_weights - self.log_weights.max())
        return weights / weights.sum()

    @property
    def effective_sample_size(self) -> float:
        """Kish effective sample size (Σw)²/Σw²."""
        return float(1.0 / np.sum(self.weights**2))

    def median(self) -> np.ndarray:
        """Weighted posterior median of every free parameter, shape (n_free,)."""
        return weighted_quantile(self.samples, self.weights, 0.5)

    def credible_interval(self, sigma: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) of the central interval with probability erf(sigma/√2)."""
        return credible_interval(self.samples, self.weights, sigma)

    @property
    def max_likelihood_index(self) -> int:
        return int(np.argmax(self.log_likelihoods))

    def max_likelihood(self) -> np.ndarray:
        """Free-parameter vector of the highest-likelihood sample."""
        return self.samples[self.max_likelihood_index].copy()

    def statistics(self) -> dict:
        """Scalar run statistics for result files."""
        return {
            "method": self.method,
            "log_evidence": self.log_evidence,
            "log_evidence_error": self.log_evidence_error,
            "max_log_likelihood": float(self.log_likelihoods.max()),
            "n_samples": len(self.samples),
            "effective_sample_size": self.effective_sample_size,
            "n_calls": self.n_calls,
            "n_rejected": self.n_rejected,
            "runtime_s": self.runtime,
            "n_resumes": self.n_resumes,
            "seed": self.seed,
            "converged": self.converged,
            "stop_reason": self.stop_reason,
            "peak_gain": self.peak_gain,
            "settings": self.settings,
        }


def pool_runs(outputs: Sequence[SamplerOutput]) -> SamplerOutput:
    """One posterior from runs of the same parameter space under equally valid likelihoods.

    The pooled posterior is the equal-weight mixture of the runs' posteriors: every run's
    weights are normalised to 1/K of the total (K runs), so that each counts the same
    whatever its evidence. This is how the MASS phase marginalises over the k-means
    realisation of the source mesh (:func:`mgelens.pipeline.run.chain_settings`): two
    meshes are two discretisations of one source, and the difference in their ln Z is
    discretisation error, not evidence for either. Samples are concatenated run by run.

    ``log_evidence`` is the mean of the runs' ln Z and ``log_evidence_error`` adds their
    own errors (in quadrature, divided by K) to the standard deviation of the ln Z values
    (the discretisation scatter). Calls, rejections, runtimes and resumes are summed;
    method, settings and seed are the first run's. The pool converged if every run did;
    its stop reason lists each run's, and its ``peak_gain`` is the largest of the runs'
    checks (None if none was checked).

    Raises
    ------
    ValueError
        If ``outputs`` is empty or the runs have different parameters.
    """
    if not outputs:
        raise ValueError("no sampler runs to pool")
    names = outputs[0].names
    if any(output.names != names for output in outputs):
        raise ValueError(f"runs to pool have different parameters: {[o.names for o in outputs]}")
    if len(outputs) == 1:
        return outputs[0]
    k = len(outputs)
    log_weights = []
    for output in outputs:
        normalised = output.log_weights - np.logaddexp.reduce(output.log_weights)
        log_weights.append(normalised - math.log(k))
    log_evidences = np.array([output.log_evidence for output in outputs])
    errors = np.array([output.log_evidence_error for output in outputs])
    return SamplerOutput(
        names=names,
        samples=np.concatenate([output.samples for output in outputs]),
        log_weights=np.concatenate(log_weights),
        log_likelihoods=np.concatenate([output.log_likelihoods for output in outputs]),
        log_evidence=float(log_evidences.mean()),
        log_evidence_error=float(math.hypot(np.sqrt(np.sum(errors**2)) / k, log_evidences.std())),
        n_calls=sum(output.n_calls for output in outputs),
        n_rejected=sum(output.n_rejected for output in outputs),
        runtime=sum(output.runtime for output in outputs),
        n_resumes=sum(output.n_resumes for output in outputs),
        method=outputs[0].method,
        settings=outputs[0].settings,
        seed=outputs[0].seed,
        converged=all(output.converged for output in outputs),
        stop_reason="; ".join(
            f"run {k + 1}: {output.stop_reason}" for k, output in enumerate(outputs)
        ),
        peak_gain=max((o.peak_gain for o in outputs if o.peak_gain is not None), default=None),
    )

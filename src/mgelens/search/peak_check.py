"""Whether a nested-sampling run found the peak of its posterior.

A run with few live points can converge by its own criterion (Δln Z, nautilus's f_live
and n_eff) while its samples sit on the flank of a narrow, correlated ridge of ln L: the
live points never spread along the ridge to its top, and the posterior excludes the
region where ln L is highest (docs/coverage.md, independent mock L07: a MASS posterior
of γ 1.958 ± 0.013 whose best sample lies 5 below a peak at γ 1.87).

:func:`peak_gain` measures this from the run alone: a local search from the run's
highest-posterior sample, Powell's method in coordinates that whiten the run's own
posterior (its weighted covariance), so that one unit of a coordinate is one posterior
σ along a principal axis, and ridges along correlated parameters are straight lines. On a
run that found its peak, the search gains a fraction of a unit; a gain of several units
says the posterior is elsewhere than its maximum.

The search climbs ln L + ln prior, the posterior the run samples, not ln L alone. Under a
passed Gaussian prior in tension with the likelihood, the posterior's maximum lies where
the prior's pull balances the likelihood's, below ln L's own peak by as much as the prior
costs there, and a search of ln L alone would restart every run however well it sampled
(docs/slacs.md, slacs0959+4416). With uniform priors both searches are the same.
"""

from collections.abc import Callable

import numpy as np
from scipy.optimize import minimize

from mgelens.rejection import REJECTED_LOG_LIKELIHOOD
from mgelens.search.model import ParameterSpace
from mgelens.search.posterior import SamplerOutput

STEP_TOLERANCE = 0.05
"""Powell's ``xtol`` in whitened coordinates: 0.05 posterior σ."""


def highest_log_posterior(space: ParameterSpace, output: SamplerOutput) -> tuple[int, float]:
    """The index of ``output``'s sample with the highest ln L + ln prior (``space.log_prior``)
    and that value."""
    log_posteriors = output.log_likelihoods + np.array([space.log_prior(x) for x in output.samples])
    best = int(np.argmax(log_posteriors))
    return best, float(log_posteriors[best])


def peak_gain(
    log_likelihood: Callable[[np.ndarray], float],
    space: ParameterSpace,
    output: SamplerOutput,
    max_evaluations: int,
) -> tuple[float, int]:
    """How much a local search from ``output``'s highest-posterior sample raises
    ln L + ln prior, and the likelihood calls it took.

    Powell's method (at most about ``max_evaluations`` calls of ``log_likelihood``, which
    takes a free-parameter vector of ``space``) in the coordinates z of
    x = x_best + A z with A Aᵀ the weighted covariance of ``output``'s samples; the
    samples' and the search's ln prior are ``space.log_prior``; points outside the priors'
    support and rejected samples count as rejected. The gain is ≥ 0 (ln units).
    """
    best, start = highest_log_posterior(space, output)
    x_best = output.samples[best].copy()
    covariance = np.atleast_2d(np.cov(output.samples.T, aweights=output.weights))
    eigenvalues, eigenvectors = np.linalg.eigh(covariance)
    floor = 1e-12 * max(float(eigenvalues.max()), 1e-300)
    whitening = eigenvectors * np.sqrt(np.maximum(eigenvalues, floor))
    calls = 0

    def negative(z: np.ndarray) -> float:
        nonlocal calls
        x = x_best + whitening @ z
        prior = space.log_prior(x)
        if not np.isfinite(prior):
            return -REJECTED_LOG_LIKELIHOOD
        calls += 1
        return -(max(float(log_likelihood(x)), REJECTED_LOG_LIKELIHOOD) + prior)

    result = minimize(
        negative,
        np.zeros(space.n_free),
        method="Powell",
        options={"xtol": STEP_TOLERANCE, "ftol": 1e-12, "maxfev": max_evaluations},
    )
    return max(0.0, -float(result.fun) - start), calls

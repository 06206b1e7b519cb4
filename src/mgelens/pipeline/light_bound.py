"""A LIGHT candidate that cannot win the model choice, found without sampling it.

The model choice (:mod:`mgelens.pipeline.model_choice`) keeps the simplest candidate whose
Bayesian evidence ln Z lies within ``threshold`` of the highest. For any candidate,

    ln Z = ln ∫ ε(θ) π(θ) dθ ≤ max_θ ln ε(θ),

so a candidate whose highest ln ε lies more than ``threshold`` below another candidate's
ln Z cannot be chosen, and its nested-sampling run (thousands of calls) changes nothing.
Its maximum is found by a local search: Powell's method in the prior's unit cube from the
prior medians, at most :data:`SEARCH_CALLS` calls. A search may stop short of the true
maximum, so the candidate is skipped only when the maximum found lies more than
``threshold`` + :data:`SLACK` below the reference ln Z; otherwise it is sampled as usual.

On real SLACS lenses the search finds maxima 0.7–2.1 above the nested runs' own best
samples in a ninth to a quarter of their calls (docs/benchmarks.md, "LIGHT's simpler
candidates bounded by their maximum").
"""

import time
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from mgelens.search.model import ParameterSpace
from mgelens.search.posterior import SamplerOutput

SEARCH_CALLS = 1500
"""Likelihood calls of the local search for a candidate's highest ln ε."""

SLACK = 20.0
"""ln ε by which the search's maximum may fall short of the true maximum: a candidate is
skipped only when its maximum found lies ``threshold`` + SLACK below the reference ln Z."""

CUBE_MARGIN = 1e-9
"""How far inside the unit cube's faces the search evaluates ln ε."""

OUTSIDE_PENALTY = 1e6
"""ln ε per squared unit-cube distance that a point outside the cube pays."""

METHOD = "upper_bound"
"""``method`` of the :class:`~mgelens.search.posterior.SamplerOutput` of a skipped
candidate (``result.json``'s ``sampler.method``), which :class:`~mgelens.pipeline.
model_choice.Candidate` reads as "ln Z is an upper bound"."""


@dataclass(frozen=True)
class Maximum:
    """The local search's highest ln ε (``value``) at ``x`` (parameter units), after
    ``n_calls`` calls and ``runtime`` seconds."""

    x: np.ndarray
    value: float
    n_calls: int
    runtime: float


def search_maximum(likelihood, space: ParameterSpace, max_calls: int = SEARCH_CALLS) -> Maximum:
    """Powell's method on ln ε over ``space``'s unit cube from the prior medians.

    ``likelihood`` maps a parameter vector (the order of ``space.free_names``) to ln ε.
    Outside the cube (less than :data:`CUBE_MARGIN` from a face, where an unbounded
    prior's transform is infinite) the search sees ln ε at the nearest point inside, less
    :data:`OUTSIDE_PENALTY` times the squared distance, so its line searches run free:
    Powell's own bounds, tried on slacs1416+5136's X2+point, ended 117 below the
    maximum that the free search reaches.
    """
    calls = 0
    low, high = CUBE_MARGIN, 1.0 - CUBE_MARGIN

    def negative(u: np.ndarray) -> float:
        nonlocal calls
        calls += 1
        inside = np.clip(u, low, high)
        outside = float(np.sum((u - inside) ** 2))
        return -float(likelihood(space.prior_transform(inside))) + OUTSIDE_PENALTY * outside

    start = time.perf_counter()
    found = optimize.minimize(
        negative,
        np.full(space.n_free, 0.5),
        method="Powell",
        options={"maxfev": max_calls, "xtol": 1e-4, "ftol": 1e-9},
    )
    x = np.clip(found.x, low, high)
    # ln ε at the nearest point inside, which ``negative`` evaluated, without its penalty
    value = -float(found.fun) + OUTSIDE_PENALTY * float(np.sum((found.x - x) ** 2))
    return Maximum(space.prior_transform(x), value, calls, time.perf_counter() - start)


def cannot_win(maximum: Maximum, reference_log_evidence: float, threshold: float) -> bool:
    """Whether a candidate with this ``maximum`` lies out of the choice's reach of a
    candidate with ln Z ``reference_log_evidence``: maximum + threshold + :data:`SLACK` <
    the reference."""
    return maximum.value + threshold + SLACK < reference_log_evidence


def bounded_output(
    maximum: Maximum, space: ParameterSpace, reference: str, reference_log_evidence: float
) -> SamplerOutput:
    """The sampler output of a skipped candidate: one sample, the maximum found, whose
    ln ε stands as ``log_evidence`` (an upper bound of ln Z, :data:`METHOD`); ``reference``
    names the candidate whose ln Z it cannot reach."""
    return SamplerOutput(
        names=space.free_names,
        samples=maximum.x[None, :],
        log_weights=np.zeros(1),
        log_likelihoods=np.array([maximum.value]),
        log_evidence=maximum.value,
        log_evidence_error=0.0,
        n_calls=maximum.n_calls,
        n_rejected=0,
        runtime=maximum.runtime,
        n_resumes=0,
        method=METHOD,
        settings={"search_calls": SEARCH_CALLS, "slack": SLACK},
        seed=0,
        converged=True,
        stop_reason=(
            f"not sampled: its highest ln ε found, {maximum.value:.2f}, an upper bound of its "
            f"ln Z, lies {reference_log_evidence - maximum.value:.2f} below the ln Z of "
            f"{reference} ({reference_log_evidence:.2f})"
        ),
    )

"""Hyper-parameters of MASS's other source meshes, tuned to each mesh (issue #30).

SPix2 chooses the k-means weights (floor, power, the arcs' threshold) and the
regularization on the mesh of one k-means seed. Its ln ε is spiky in those values: a
change of a part in 10⁴ re-draws the k-means mesh (``slam.kmeans_seeding``), and the
evidence of the mesh jumps by tens to hundreds. SPix2's sampling ends on a mesh that fits
well; another seed's mesh under the same values is an ordinary draw, tens to hundreds
lower in ln ε, and MASS's posterior on it can lie in another basin of the mass
(docs/coverage.md, "Each mesh its own hyper-parameters").

:func:`tuned_hyperparameters` gives such a mesh its own values: a Nelder–Mead search of
SPix2's ln ε on that mesh (lens light and mass held at SPix2's, the values SPix2's
sampler saw), from SPix2's values, in the unit cube of SPix2's priors. It is
deterministic (a fixed start, simplex and call budget), so a resumed MASS phase finds
the same values and its checkpoint still applies.
"""

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from mgelens.fit import figure_of_merit
from mgelens.pipeline import models
from mgelens.pipeline.problem import PhaseProblem

TUNING_CALLS = 250
"""Most ln ε evaluations of one mesh's search (SPix2 calls; their cost is in
docs/coverage.md, "Each mesh its own hyper-parameters")."""

SIMPLEX_STEP = 0.05
"""Initial simplex: the start and one step of this size along each unit-cube axis (back
towards the centre where a step forward would leave the cube)."""

HYPER_PREFIXES = (models.MESH + ".", models.REGULARIZATION + ".")
"""The components SPix2 fits and LIGHT and MASS hold."""

UNIT_MARGIN = 1e-9
"""Unit-cube points are kept this far inside the cube, where every prior transform is
finite (a LogUniform's 0 and 1 are its bounds, a Uniform weight floor of exactly 1 is
degenerate)."""


@dataclass(frozen=True)
class MeshTuning:
    """One mesh's search.

    Attributes
    ----------
    values : dict
        SPix2's values with the free hyper-parameters replaced by the best found (the
        lens light and mass unchanged).
    start_log_evidence, log_evidence : float
        SPix2's ln ε on this mesh at SPix2's values, and at ``values``
        (≥ ``start_log_evidence``).
    n_calls : int
        ln ε evaluations made.
    """

    values: dict[str, float]
    start_log_evidence: float
    log_evidence: float
    n_calls: int

    def describe(self) -> dict:
        """The record kept beside a mesh's run in MASS's ``result.json``."""
        hyper = {k: v for k, v in self.values.items() if k.startswith(HYPER_PREFIXES)}
        return {
            "tuned": True,
            "start_log_evidence": self.start_log_evidence,
            "log_evidence": self.log_evidence,
            "n_calls": self.n_calls,
            "hyperparameters": hyper,
        }


def tuned_hyperparameters(
    problem: PhaseProblem, start: Mapping[str, float], max_calls: int = TUNING_CALLS
) -> MeshTuning:
    """The free hyper-parameters of SPix2's ``problem`` (built on the mesh to tune) that
    maximise its ln ε, searched from ``start`` (SPix2's maximum-likelihood values).

    Parameters
    ----------
    problem : PhaseProblem
        SPix2's problem on the k-means seed and pixel count of the mesh to tune; its free
        parameters are the hyper-parameters (:func:`mgelens.pipeline.phases.spix2.space`).
    start : mapping
        Values of every parameter of ``problem.space`` (SPix2's ``max_likelihood``).
    max_calls : int
        ln ε evaluations allowed.

    Returns
    -------
    MeshTuning
        The best point evaluated; ``start`` itself if nothing beat it.

    Raises
    ------
    ValueError
        If ``problem`` frees anything but the mesh and regularization, or ``max_calls``
        is below 1.
    """
    space = problem.space
    others = [n for n in space.free_names if not n.startswith(HYPER_PREFIXES)]
    if others:
        raise ValueError(f"only SPix2's hyper-parameters can be tuned, not {others}")
    if max_calls < 1:
        raise ValueError(f"max_calls must be at least 1, got {max_calls}")
    best = {"value": -np.inf, "unit": None}
    calls = 0

    def log_evidence(unit: np.ndarray) -> float:
        nonlocal calls
        calls += 1
        unit = np.clip(unit, UNIT_MARGIN, 1.0 - UNIT_MARGIN)
        values = space.values(space.prior_transform(unit))
        try:
            lens_model = problem.model.build(values)
        except models.UnphysicalSample:
            return -np.inf
        value, _ = figure_of_merit(problem.dataset, lens_model, None)
        if value > best["value"]:
            best.update(value=value, unit=unit.copy())
        return value

    start_unit = np.clip(space.unit_cube(space.vector(start)), UNIT_MARGIN, 1.0 - UNIT_MARGIN)
    start_value = log_evidence(start_unit)
    if max_calls > 1:
        steps = np.where(start_unit + SIMPLEX_STEP <= 1.0, SIMPLEX_STEP, -SIMPLEX_STEP)
        simplex = np.vstack([start_unit, start_unit + np.diag(steps)])
        minimize(
            lambda unit: -log_evidence(unit),
            start_unit,
            method="Nelder-Mead",
            options={"maxfev": max_calls - 1, "initial_simplex": simplex, "xatol": 1e-4,
                     "fatol": 0.1},
        )  # fmt: skip
    values = space.values(space.prior_transform(best["unit"]))
    return MeshTuning(
        values={**dict(start), **{k: v for k, v in values.items() if k in space.free_names}},
        start_log_evidence=float(start_value),
        log_evidence=float(best["value"]),
        n_calls=calls,
    )

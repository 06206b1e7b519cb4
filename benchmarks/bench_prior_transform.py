"""Speed of the unit-cube map of a phase's priors, which a sampler calls once per
likelihood call (``ParameterSpace.prior_transform``, SPEC §8.2).

The space is a phase's own, read from its ``result.json`` (``--result``, e.g.
``results/M1/sp/result.json``: SP's 17 passed priors, mostly truncated Gaussians), or,
without one, seventeen truncated Gaussians like SP's. Prints the median time of one call of
``prior_transform`` on a single point (the vectorised :class:`PriorTransform`), of the same
map prior by prior (each prior's own ``transform``, as before the batched map), and the
largest difference between the two over 1,000 random points (0: the same numbers).

Run from the repository root: ``python benchmarks/bench_prior_transform.py
[--result results/M1/sp/result.json]``.
"""

import argparse
import json
import math
from pathlib import Path

import numpy as np
from common import median_time, report, set_threads

from mgelens.search.model import ParameterSpace
from mgelens.search.priors import TruncatedGaussian


def sp_like_space() -> ParameterSpace:
    """Seventeen truncated Gaussians, half of them bounded on one side only."""
    return ParameterSpace.from_priors(
        {
            f"p{i}": TruncatedGaussian(0.1 * i, 0.05 + 0.01 * i, -1.0, math.inf if i % 2 else 5.0)
            for i in range(17)
        }
    )


def prior_by_prior(space: ParameterSpace, u: np.ndarray) -> np.ndarray:
    return np.array([prior.transform(value) for prior, value in zip(space.priors, u, strict=True)])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--result", type=Path, help="a phase's result.json (default: SP-like)")
    args = parser.parse_args()
    set_threads(1)
    if args.result is None:
        space = sp_like_space()
    else:
        space = ParameterSpace.from_dict(json.loads(args.result.read_text())["parameter_space"])
    report("n_free", space.n_free, "priors")
    point = np.random.default_rng(0).uniform(size=space.n_free)
    batched = median_time(lambda: space.prior_transform(point), repeats=2000) * 1e6
    single = median_time(lambda: prior_by_prior(space, point), repeats=500) * 1e6
    report("batched_us_per_call", batched, "µs")
    report("prior_by_prior_us_per_call", single, "µs")
    points = np.random.default_rng(1).uniform(size=(1000, space.n_free))
    difference = max(
        float(np.max(np.abs(space.prior_transform(u) - prior_by_prior(space, u)))) for u in points
    )
    report("max_abs_difference", difference, "parameter units")


if __name__ == "__main__":
    main()

"""CPU ms per likelihood call of one SLaM phase, on draws a sampler would make (issue #28).

``bench_phases.py`` times calls jittered around a nominal model and warm-starts every
NNLS from that model's own passive set: the cheapest calls a phase can see. This script
builds the phase's real problem from a chain's earlier results (its priors, its cached
source system, its reference passive set from the prior medians, exactly as
``mgelens phase`` does) and times the sampler's own likelihood on

* ``prior``: uniform draws from the whole prior (a nested sampler's first iterations);
* ``centre``: draws within ±5 % of the unit cube around the prior medians (its last);
* ``samples`` (with ``--samples FOLDER``): ``--draws`` rows of a finished run's
  ``FOLDER/samples.csv`` under ``--results``, evenly spaced in run order (the sampler's
  own path from the prior to the posterior, where the NNLS warm start is tested).

One numba and one BLAS thread (the jobs' thread policy). It prints ``draws_cpu_ms_<phase>_
<kind>`` (median) and ``..._mean`` per kind, and the sum of ln L over the accepted draws,
``draws_log_likelihood_sum_<phase>_<kind>``, so that two code versions can be checked to
give the same values, and ``host_yardstick_cpu_ms`` (``common.host_yardstick_ms``), the
host's speed on a fixed workload, to compare figures across hosts. Run from the
repository root, e.g.::

    python benchmarks/bench_phase_draws.py --lens-dir ../shared/data/slacs/slacs1250+0523 \\
        --results results/slacs1250+0523 --mask-radius 3.0 --phase light --mge-sets 6

``--slam`` gives the chain's settings where they differ from the profile's, e.g.
``--slam '{"source_pixels": [500, 1000]}'`` for a chain that chose its pixel count.
"""

import argparse
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd
from common import host_yardstick_ms, set_threads

from mgelens.pipeline.run import PhaseLikelihood, build_problem, reference_passive_set
from mgelens.pipeline.settings import PHASES, LensSpec, load_settings
from mgelens.rejection import REJECTED_LOG_LIKELIHOOD


def unit_draws(kind: str, n_free: int, n_draws: int, rng: np.random.Generator) -> np.ndarray:
    """Points of the unit cube: the whole prior, or ±5 % around its medians."""
    if kind == "prior":
        return rng.uniform(size=(n_draws, n_free))
    return 0.5 + 0.05 * rng.uniform(-1.0, 1.0, size=(n_draws, n_free))


def run_samples(samples: Path, names, n_draws: int) -> list[np.ndarray]:
    """Free-parameter vectors of ``n_draws`` rows of a run's samples table, evenly spaced
    in run order."""
    table = pd.read_csv(samples)
    rows = np.unique(np.linspace(0, len(table) - 1, n_draws).round().astype(int))
    return [table.iloc[i][list(names)].to_numpy(dtype=float) for i in rows]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--lens-dir", type=Path, required=True)
    parser.add_argument("--results", type=Path, required=True, help="the chain's results")
    parser.add_argument("--mask-radius", type=float, required=True, help="arcsec")
    parser.add_argument("--phase", required=True, choices=PHASES)
    parser.add_argument("--mge-sets", type=int, default=4, choices=(2, 4, 6))
    parser.add_argument("--no-point-set", action="store_true")
    parser.add_argument("--profile", default="quick", choices=("quick", "paper"))
    parser.add_argument("--draws", type=int, default=60, help="timed calls per kind")
    parser.add_argument(
        "--samples",
        default=None,
        help="a finished run's folder under --results (e.g. light_x6_point): also time "
        "the calls at its samples.csv rows",
    )
    parser.add_argument(
        "--slam",
        type=json.loads,
        default=None,
        help="the chain's slam settings as JSON, as `mgelens phase --slam` takes them",
    )
    args = parser.parse_args()
    set_threads(1)
    lens = LensSpec(
        mask_radius=args.mask_radius, mge_sets=args.mge_sets, point_set=not args.no_point_set
    )
    settings = load_settings(None, args.profile, args.slam)
    problem = build_problem(args.phase, args.lens_dir, args.results, settings, lens)
    likelihood = PhaseLikelihood(
        problem.dataset, problem.space, problem.model, None, reference_passive_set(problem)
    )
    rng = np.random.default_rng(0)
    print(f"lens: {args.lens_dir.name}  phase: {args.phase}  free: {problem.space.n_free}")
    print(f"host_yardstick_cpu_ms: {host_yardstick_ms():.1f}")
    kinds = ("prior", "centre") if args.samples is None else ("prior", "centre", "samples")
    for kind in kinds:
        if kind == "samples":
            samples = args.results / args.samples / "samples.csv"
            points = run_samples(samples, problem.space.free_names, args.draws)
        else:
            points = [
                problem.space.prior_transform(u)
                for u in unit_draws(kind, problem.space.n_free, args.draws, rng)
            ]
        likelihood(points[0])  # warm-up: compiles, fills the phase's caches
        times, values = [], []
        for point in points:
            start = time.process_time()
            values.append(likelihood(point))
            times.append(time.process_time() - start)
        accepted = np.array(values)[np.array(values) > REJECTED_LOG_LIKELIHOOD]
        name = f"{args.phase}_{kind}"
        print(f"draws_log_likelihood_sum_{name}: {accepted.sum():.6f}")
        print(f"draws_cpu_ms_{name}_mean: {1e3 * np.mean(times):.2f}")
        print(f"draws_cpu_ms_{name}: {1e3 * np.median(times):.2f}")


if __name__ == "__main__":
    main()

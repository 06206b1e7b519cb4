"""The samplers' own work per likelihood call, on a likelihood that costs nothing.

SP's sampler was chosen by this figure (docs/slam.md, "SP: nautilus with one network"):
nautilus trains neural networks for its bounds between calls, dynesty fits ellipsoids and
proposes random walks, and where a call of the likelihood costs a few milliseconds (SP
on a mock, 6–8 ms; on a real 3″ cutout about 20 ms) that work decides which sampler is
faster. The likelihood here is a correlated Gaussian in the unit cube (a numpy quadratic
form, microseconds a call), so the CPU time per call is the sampler's own.

Run from the repository root: ``python benchmarks/bench_sampler_overhead.py`` (SP's 17
parameters). It prints ``overhead_ms_<sampler>`` (CPU ms per call) and
``calls_<sampler>`` for nautilus with 1 and 4 networks (51 live points, stopped at
f_live 0.05 and 300 effective samples, the quick profile's SP) and dynesty's random walks
(60 live points, 5 steps, Δln Z < 1, the quick profile's SP before 2026-12-07).
"""

import argparse
import time

import numpy as np
from common import report, set_threads

from mgelens.pipeline.settings import profile_settings
from mgelens.search.sampler import nautilus_live_points

POSTERIOR_WIDTH = 0.01
"""Scale of the Gaussian's principal widths in the unit cube (SP's posteriors span about a
hundredth of its priors)."""


def gaussian_log_likelihood(n_dim: int, seed: int = 0):
    """ln L of a correlated Gaussian centred in the unit cube, widths about
    :data:`POSTERIOR_WIDTH`."""
    rng = np.random.default_rng(seed)
    factor = rng.normal(size=(n_dim, n_dim))
    covariance = (factor @ factor.T / n_dim + 0.1 * np.eye(n_dim)) * POSTERIOR_WIDTH**2
    precision = np.linalg.inv(covariance)
    centre = np.full(n_dim, 0.5)

    def log_likelihood(x: np.ndarray) -> float:
        offset = x - centre
        return -0.5 * float(offset @ precision @ offset)

    return log_likelihood


def run_nautilus(n_dim: int, n_networks: int) -> tuple[int, float]:
    """Calls and CPU seconds of one nautilus run with the quick profile SP's live points
    per parameter and stopping rule, and ``n_networks`` networks per bound."""
    import nautilus

    sp = profile_settings("quick").samplers["sp"]
    start = time.process_time()
    sampler = nautilus.Sampler(
        lambda u: u,
        gaussian_log_likelihood(n_dim),
        n_dim=n_dim,
        n_live=nautilus_live_points(sp.n_live, n_dim),
        n_networks=n_networks,
        seed=0,
        pass_dict=False,
    )
    sampler.run(f_live=sp.f_live, n_eff=sp.n_eff, verbose=False)
    return sampler.n_like, time.process_time() - start


def run_dynesty(n_dim: int, n_live: int) -> tuple[int, float]:
    """Calls and CPU seconds of one dynesty run (random walks of 5 steps, Δln Z < 1)."""
    import dynesty

    start = time.process_time()
    sampler = dynesty.NestedSampler(
        gaussian_log_likelihood(n_dim),
        lambda u: u,
        n_dim,
        nlive=n_live,
        bound="multi",
        sample="rwalk",
        walks=5,
        rstate=np.random.default_rng(0),
    )
    sampler.run_nested(dlogz=1.0, print_progress=False)
    return int(sum(sampler.results.ncall)), time.process_time() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dims", type=int, default=17, help="free parameters (SP: 17)")
    args = parser.parse_args()
    set_threads(1)
    runs = {
        "nautilus_1_network": lambda: run_nautilus(args.dims, 1),
        "nautilus_4_networks": lambda: run_nautilus(args.dims, 4),
        "dynesty_rwalk": lambda: run_dynesty(args.dims, 60),
    }
    for name, run in runs.items():
        calls, seconds = run()
        report(f"calls_{name}", calls, "calls")
        report(f"overhead_ms_{name}", 1e3 * seconds / calls, "CPU ms per call")


if __name__ == "__main__":
    main()

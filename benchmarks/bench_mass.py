"""Speed and memory of mass-profile deflections (run: ``python benchmarks/bench_mass.py``).

Prints ``name: value`` lines. Times are the median (``_min``: minimum) wall time in seconds
of several calls after a warm-up (which also triggers numba compilation), and the median
process CPU time summed over threads (``_cpu``), for 1e6 random
points in a 6″ box; the default EPL is q = 0.75, γ = 2.3, φ = 30°. lenstronomy's EPL is
timed on the same points when lenstronomy is importable. Memory: the peak traced by
``tracemalloc`` during one EPL call (output arrays included) and the process peak RSS.
"""

import argparse
import resource

import numba
import numpy as np
from common import peak_traced_mb, report_timings

from mgelens.mass import EPL, SIE, ExternalShear

N_POINTS = 1_000_000
AXIS_RATIO = 0.75
ANGLE = 30.0
EINSTEIN_RADIUS = 1.2
SLOPE = 2.3


def lenstronomy_epl(x: np.ndarray, y: np.ndarray):
    """A zero-argument callable running lenstronomy's EPL on (x, y), or None if unavailable.

    θ_E is converted to lenstronomy's convention (SPEC §3.3).
    """
    try:
        from lenstronomy.LensModel.lens_model import LensModel
    except ImportError:
        return None
    q, t = AXIS_RATIO, SLOPE - 1.0
    epl = EPL(einstein_radius=EINSTEIN_RADIUS, axis_ratio=q, angle=ANGLE, slope=SLOPE)
    e1, e2 = epl.ell_comps
    kwargs = {
        "theta_E": EINSTEIN_RADIUS * np.sqrt(q) * (2.0 / (1.0 + q)) ** (1.0 / t),
        "gamma": SLOPE,
        "e1": e1,
        "e2": e2,
        "center_x": 0.0,
        "center_y": 0.0,
    }
    model = LensModel(["EPL"])
    return lambda: model.alpha(x, y, [kwargs])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--threads", type=int, default=2, help="numba threads")
    parser.add_argument("--repeats", type=int, default=9, help="timed calls per figure")
    args = parser.parse_args()
    numba.set_num_threads(args.threads)

    rng = np.random.default_rng(1)
    x = rng.uniform(-3.0, 3.0, N_POINTS)
    y = rng.uniform(-3.0, 3.0, N_POINTS)
    epl = EPL(einstein_radius=EINSTEIN_RADIUS, axis_ratio=AXIS_RATIO, angle=ANGLE, slope=SLOPE)
    epl_flat = EPL(einstein_radius=EINSTEIN_RADIUS, axis_ratio=0.3, angle=ANGLE, slope=SLOPE)
    sie = SIE(einstein_radius=EINSTEIN_RADIUS, axis_ratio=AXIS_RATIO, angle=ANGLE)
    shear = ExternalShear(0.03, -0.02)

    print(f"numba_threads: {numba.get_num_threads()}")
    print(f"n_points: {N_POINTS}")
    report_timings("epl_deflections_1e6_s", lambda: epl.deflections(x, y), args.repeats)
    report_timings("epl_q0.3_deflections_1e6_s", lambda: epl_flat.deflections(x, y), args.repeats)
    report_timings("sie_deflections_1e6_s", lambda: sie.deflections(x, y), args.repeats)
    report_timings("shear_deflections_1e6_s", lambda: shear.deflections(x, y), args.repeats)
    reference = lenstronomy_epl(x, y)
    if reference is None:
        print("lenstronomy_epl_deflections_1e6_s: n/a (lenstronomy not importable)")
    else:
        report_timings("lenstronomy_epl_deflections_1e6_s", reference, args.repeats)
    print(f"epl_deflections_peak_traced_mb: {peak_traced_mb(lambda: epl.deflections(x, y)):.1f}")
    print(f"process_peak_rss_mb: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3:.0f}")


if __name__ == "__main__":
    main()

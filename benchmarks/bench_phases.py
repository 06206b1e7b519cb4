"""Milliseconds per likelihood call of each SLaM phase, and where they go (issue #28).

For one lens folder (a real SLACS cutout or a mock: data.fits, noise_map.fits, psf.fits),
builds each phase's dataset and model as the phase does (quick profile unless
``--profile paper``, one thread), evaluates calls the way a sampler makes them (the
phase's free parameters jittered around a nominal model, every dataset cache the phase
keeps), and prints

* ``call_ms_<phase>``: the median wall time of one call, without profiling (the last
  lines, one per phase), and ``call_cpu_ms_<phase>``, its CPU time (steadier on a machine
  shared with other jobs);
* ``stage_ms_<phase>_<stage>``: the median call split by stage, from a cProfile run of
  the same calls (``other`` is the rest: Python glue, the model image, the χ², and the
  profiler's own overhead);
* ``figure_of_merit_sum_<phase>``: the sum of the timed calls' figures of merit (ln ε,
  or ln L in SP), to check that two code versions or settings give the same values;
* ``host_yardstick_cpu_ms``: the host's speed on a fixed workload
  (``common.host_yardstick_ms``), to compare figures across hosts.

The nominal model is an SIE + shear at the brightest pixel within 0.5″ of the mask
centre, with θ_E from ``--einstein-radius`` (default: the mock's ``truth.json``, else
1.2″). Later phases do not read earlier results: SPix2's adapt image is the lensed source
of the SPix1 model at the nominal mass, and LIGHT and MASS keep the k-means source of
SPix2's nominal hyper-parameters (``--source-pixels`` pixels where given, as
``slam.source_pixels``; MASS's mesh with ``--mass-source-pixels`` pixels where given, as
``slam.mass_source_pixels`` does). Stages:

* ``lens_light_columns``, ``lens_light_blur``: the linear lens light's unit columns on
  their over-sampled grid, and their PSF convolution (SP and LIGHT; the SPix phases and
  MASS cache them); ``lens_light_closed_form``: the wide Gaussians' blurred columns in
  closed form (``FitSettings.lp_analytic_tolerance``);
* ``source_mge_columns``, ``source_mge_blur``: SP's source-plane MGE seen through the lens;
* ``ray_tracing``, ``border_relocation``, ``voronoi_mesh``, ``interpolation``,
  ``mapping_matrix``, ``regularization`` (with ln det H), ``kmeans`` (SPix2);
* ``data_vector``, ``curvature`` (F, with the cached Lᵀ W L), ``nnls_and_log_dets``;
* ``lens_light_prior``: with ``--lens-light-prior smoothness``, LIGHT's and MASS's
  smoothness prior on the MGE intensities (its matrix, λR added to F and its log dets;
  λ = :data:`NOMINAL_SMOOTHNESS`).

Run from the repository root::

    python benchmarks/bench_phases.py --lens-dir ../shared/data/slacs/slacs0008-0004 \\
        --mask-radius 3.0 --mge-sets 2
"""

import argparse
import cProfile
import json
import pstats
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from common import host_yardstick_ms, set_threads

from mgelens.fit import figure_of_merit, fit
from mgelens.geometry import ell_comps_from
from mgelens.grid import pixel_centres
from mgelens.pipeline import models
from mgelens.pipeline.problem import load_dataset
from mgelens.pipeline.settings import LENS_LIGHT_PRIORS, PHASES, LensSpec, profile_settings
from mgelens.source.image_mesh import floored_adapt_image, overlay_centres

NOMINAL_SMOOTHNESS = 100.0
"""λ of the LIGHT and MASS calls with ``--lens-light-prior smoothness``."""

STAGES = {
    # stage: [(file, function, caller as (file, function), or None for any caller)]
    "lens_light_columns": [
        ("light.py", "columns", ("light.py", "<listcomp>")),
        ("light.py", "columns", ("light.py", "blurred_columns")),
    ],
    "lens_light_closed_form": [
        ("light.py", "blurred_gaussian_columns", ("light.py", "blurred_columns"))
    ],
    "lens_light_blur": [("convolve.py", "blur_columns", ("light.py", "blurred_columns"))],
    "source_mge_columns": [("light.py", "columns", ("fit.py", "<listcomp>"))],
    "lens_light_prior": [
        ("light_prior.py", "system", None),
        ("light_prior.py", "add_to", None),
        ("light_prior.py", "terms", None),
    ],
    "source_mge_blur": [("convolve.py", "blur_columns", ("fit.py", "source_light_columns"))],
    "ray_tracing": [("mass.py", "ray_trace", None)],
    "border_relocation": [("border.py", "relocate_to_border", None)],
    "voronoi_mesh": [("mesh.py", "from_points", None)],
    "interpolation": [
        ("interpolate.py", "natural_neighbour_weights", ("fit.py", "pixelized_operator")),
        ("interpolate.py", "nearest_cell_weights", ("fit.py", "pixelized_operator")),
    ],
    "mapping_matrix": [("mapping.py", "mapping_matrix", ("fit.py", "pixelized_operator"))],
    "regularization": [
        ("regularization.py", "matrix", ("fit.py", "pixelized_operator")),
        ("evidence.py", "log_det_regularization", None),
    ],
    "kmeans": [("models.py", "centres", None)],
    "data_vector": [("system.py", "data_vector", None)],
    "curvature": [
        ("system.py", "curvature_matrix", None),
        ("fit.py", "curvature", None),
        ("fit.py", "lens_light_dense_terms", None),
    ],
    "nnls_and_log_dets": [("solve.py", "solve_linear_system", None)],
}


def nominal_values(centre, einstein_radius: float, mge_sets: int) -> dict[str, float]:
    """Parameter values of a plausible lens at ``centre`` (every phase picks its own)."""
    e_mass = ell_comps_from(0.8, 40.0)
    values = {
        "mass.centre_x": centre[0],
        "mass.centre_y": centre[1],
        "mass.ell_comps_1": e_mass[0],
        "mass.ell_comps_2": e_mass[1],
        "mass.einstein_radius": einstein_radius,
        "shear.gamma_1": 0.02,
        "shear.gamma_2": -0.01,
        "source.set_0.centre_x": centre[0] + 0.05,
        "source.set_0.centre_y": centre[1] - 0.03,
        "source.set_0.ell_comps_1": 0.1,
        "source.set_0.ell_comps_2": 0.05,
        "regularization.coefficient": 1.0,
        "regularization.inner_coefficient": 1.0,
        "regularization.outer_coefficient": 0.1,
        "regularization.signal_scale": 0.5,
        "mesh.weight_floor": 0.1,
        "mesh.weight_power": 2.0,
        "mesh.arc_threshold": 0.02,
        "lens_light.point.centre_x": centre[0],
        "lens_light.point.centre_y": centre[1],
        "lens_light.point.ell_comps_1": 0.0,
        "lens_light.point.ell_comps_2": 0.0,
    }
    for k in range(max(mge_sets, 2)):
        e = ell_comps_from(0.9 - 0.1 * k, 30.0 + 10.0 * k)
        prefix = f"lens_light.set_{k}"
        values |= {f"{prefix}.centre_x": centre[0], f"{prefix}.centre_y": centre[1]}
        values |= {f"{prefix}.ell_comps_1": e[0], f"{prefix}.ell_comps_2": e[1]}
    return values


JITTER = {  # what a phase's sampler moves, and by how much (absolute; relative for '*')
    "sp": {"lens_light.": 0.01, "mass.": 0.01, "shear.": 0.005, "source.": 0.01},
    "spix1": {"mass.": 0.01, "shear.": 0.005, "regularization.": "*0.1"},
    "spix2": {"mesh.": "*0.1", "regularization.": "*0.1"},
    "light": {"lens_light.": 0.01},
    "mass": {"mass.": 0.01, "shear.": 0.005},
}


def jittered(values: dict, phase: str, rng: np.random.Generator) -> dict:
    out = dict(values)
    for name, value in values.items():
        for prefix, size in JITTER[phase].items():
            if name.startswith(prefix):
                if isinstance(size, str):
                    out[name] = value * (1.0 + float(size[1:]) * rng.uniform(-1, 1))
                else:
                    out[name] = value + size * rng.uniform(-1, 1)
    return out


def brightest_centre(dataset, radius: float = 0.5) -> tuple[float, float]:
    x, y = pixel_centres(dataset.mask.shape, dataset.imaging.pixel_scale)
    used = ~dataset.mask
    x, y, data = x[used], y[used], dataset.data
    near = np.hypot(x - x.mean(), y - y.mean()) < radius
    k = np.argmax(np.where(near, data, -np.inf))
    return float(x[k]), float(y[k])


def phase_calls(lens_dir: Path, settings, lens, einstein_radius: float, n_calls: int, seed: int):
    """{phase: (dataset, PhaseModel, [values per call], passive_start or None)}."""
    rng = np.random.default_rng(seed)
    probe, _ = load_dataset(lens_dir, settings, lens, lens.mask_centre)
    centre = brightest_centre(probe)
    dataset, radius = load_dataset(lens_dir, settings, lens, centre)
    pixel = dataset.imaging.pixel_scale
    values = nominal_values(centre, einstein_radius, lens.mge_sets)
    sp_specs = models.mge_specs(2, False, pixel, radius)
    light_specs = models.mge_specs(lens.mge_sets, lens.point_set, pixel, radius)
    values[models.SMOOTHNESS] = NOMINAL_SMOOTHNESS
    prior = settings.lens_light_prior == "smoothness"
    ox, oy = overlay_centres(dataset.mask, pixel, settings.overlay_shape)
    overlay = models.MeshSourceModel(
        ox, oy, settings.spix1_regularization, settings.interpolation, settings.cross_offset
    )
    spix1 = models.PhaseModel(sp_specs, overlay)
    adapt = floored_adapt_image(fit(dataset, spix1.build(values)).lensed_source_image)
    px, py = dataset.pixel_centres
    kmeans = models.KMeansSourceModel.from_settings(px, py, adapt, settings, settings.source_pixels)
    fixed_source = kmeans.fixed(values)
    mass_pixels = settings.mass_pixels(settings.source_pixels)
    mass_source = models.KMeansSourceModel.from_settings(px, py, adapt, settings, mass_pixels)
    mass_source = mass_source.fixed(values)
    phase_models = {
        "sp": models.PhaseModel(sp_specs, models.MGESourceModel()),
        "spix1": spix1,
        "spix2": models.PhaseModel(sp_specs, kmeans),
        "light": models.PhaseModel(light_specs, fixed_source, smoothness_prior=prior),
        "mass": models.PhaseModel(light_specs, mass_source, smoothness_prior=prior),
    }
    mass_values = values | {"mass.slope": 2.0}
    calls = {}
    for phase, model in phase_models.items():
        base = mass_values if phase == "mass" else values
        dataset_copy = replace(dataset, _columns_cache={}, _source_cache={})
        passive = None
        if model.stable_unknowns and settings.fit.positive_only:
            passive = fit(dataset_copy, model.build(base)).passive_set
        draws = [jittered(base, phase, rng) for _ in range(n_calls)]
        calls[phase] = (dataset_copy, model, draws, passive)
    return calls, dataset, centre


def stage_times(profile: cProfile.Profile, n_calls: int) -> dict[str, float]:
    """Milliseconds per call of each stage of :data:`STAGES` in ``profile``."""
    stats = pstats.Stats(profile).stats
    out = {}
    for stage, entries in STAGES.items():
        total = 0.0
        for (filename, _, function), (_, _, _, cumulative, callers) in stats.items():
            for file, name, caller in entries:
                if not (filename.endswith(file) and function == name):
                    continue
                if caller is None:
                    total += cumulative
                else:
                    total += sum(
                        c[3]
                        for key, c in callers.items()
                        if key[0].endswith(caller[0]) and key[2] == caller[1]
                    )
        out[stage] = 1e3 * total / n_calls
    return out


def run(calls: dict, n_calls: int) -> tuple[dict, dict, dict, dict]:
    """Median wall and CPU ms per call, stage ms per call and the sum of the timed calls'
    figures of merit (to check that two code versions give the same values), of every
    phase."""
    timings, cpu_timings, stages, sums = {}, {}, {}, {}
    for phase, (dataset, model, values, passive) in calls.items():

        def call(v, dataset=dataset, model=model, passive=passive):
            """One sampler call: the lens model of the values, then the fit (as
            :class:`mgelens.pipeline.run.PhaseLikelihood`; SPix2's k-means included)."""
            return figure_of_merit(dataset, model.build(v), passive)

        call(values[0])  # warm-up (compiles, fills caches)
        times, cpu_times, merits = [], [], []
        for v in values:
            start, start_cpu = time.perf_counter(), time.process_time()
            merit, reason = call(v)
            times.append(time.perf_counter() - start)
            cpu_times.append(time.process_time() - start_cpu)
            if reason:
                raise RuntimeError(f"{phase}: a benchmark call was rejected: {reason}")
            merits.append(merit)
        sums[phase] = float(np.sum(merits))
        timings[phase] = 1e3 * float(np.median(times))
        cpu_timings[phase] = 1e3 * float(np.median(cpu_times))
        profile = cProfile.Profile()
        profile.enable()
        start = time.perf_counter()
        for v in values:
            call(v)
        profiled = 1e3 * (time.perf_counter() - start) / n_calls
        profile.disable()
        stage = stage_times(profile, n_calls)
        stage["other"] = profiled - sum(stage.values())
        stages[phase] = stage
    return timings, cpu_timings, stages, sums


def default_einstein_radius(lens_dir: Path) -> float:
    truth = lens_dir / "truth.json"
    if truth.is_file():
        for profile in json.loads(truth.read_text()).get("mass", []):
            if "einstein_radius" in profile.get("parameters", {}):
                return float(profile["parameters"]["einstein_radius"])
    return 1.2


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--lens-dir", type=Path, required=True)
    parser.add_argument("--mask-radius", type=float, required=True, help="arcsec")
    parser.add_argument("--profile", default="quick", choices=("quick", "paper"))
    parser.add_argument(
        "--mge-sets", type=int, default=LensSpec.mge_sets, help="LIGHT/MASS extended sets"
    )
    parser.add_argument("--no-point-set", action="store_true", help="LIGHT/MASS without it")
    parser.add_argument("--einstein-radius", type=float, help="nominal θ_E (arcsec)")
    parser.add_argument("--calls", type=int, default=15, help="timed calls per phase")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--phases", nargs="+", default=list(PHASES), choices=PHASES)
    parser.add_argument("--lens-light-prior", default="none", choices=LENS_LIGHT_PRIORS)
    parser.add_argument(
        "--source-pixels", type=int, help="k-means source pixels (slam.source_pixels)"
    )
    parser.add_argument(
        "--mass-source-pixels", type=int, help="MASS's k-means pixels (slam.mass_source_pixels)"
    )
    args = parser.parse_args()
    set_threads(args.threads)
    settings = profile_settings(args.profile)
    settings = replace(
        settings,
        source_pixels=args.source_pixels or settings.source_pixels,
        lens_light_prior=args.lens_light_prior,
        mass_source_pixels=args.mass_source_pixels,
    )
    lens = LensSpec(
        mask_radius=args.mask_radius, mge_sets=args.mge_sets, point_set=not args.no_point_set
    )
    theta_e = args.einstein_radius or default_einstein_radius(args.lens_dir)
    calls, dataset, centre = phase_calls(args.lens_dir, settings, lens, theta_e, args.calls, seed=0)
    calls = {phase: calls[phase] for phase in args.phases}
    print(
        f"lens: {args.lens_dir.name}  profile: {args.profile}  threads: {args.threads}"
        f"  lens_light_prior: {args.lens_light_prior}  source_pixels: {settings.source_pixels}"
        f"  mass_source_pixels: {settings.mass_pixels(settings.source_pixels)}"
    )
    print(f"host_yardstick_cpu_ms: {host_yardstick_ms():.1f}")
    print(
        f"n_image_pixels: {dataset.data.size}  light_sub_pixels: {dataset.light_grid.grid.x.size}"
        f"  psf: {dataset.convolver.psf.shape}  centre: ({centre[0]:.3f}, {centre[1]:.3f})"
        f"  einstein_radius: {theta_e}"
    )
    timings, cpu_timings, stages, sums = run(calls, args.calls)
    for phase in calls:
        for stage, ms in stages[phase].items():
            if ms >= 0.05 or stage == "other":
                print(f"stage_ms_{phase}_{stage}: {ms:.2f}")
    for phase in calls:
        print(f"call_cpu_ms_{phase}: {cpu_timings[phase]:.2f}")
    for phase in calls:
        print(f"figure_of_merit_sum_{phase}: {sums[phase]:.6f}")
    for phase in calls:
        print(f"call_ms_{phase}: {timings[phase]:.2f}")


if __name__ == "__main__":
    main()

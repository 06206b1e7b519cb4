"""One full log-evidence evaluation for the reference configuration R (issue #3).

R: 0.05″ pixels, circular 3.0″ mask (~11,300 pixels), 4×4 source sub-grid, 1500
k-means source pixels, adaptive cross (split) regularization, MGE 2×30 + point set 10,
EPL + shear, NNLS on. Also: NNLS off, 500 source pixels, lens-light columns cached
(the SPix/M phases keep the MGE geometry fixed), the quick profile's MASS evaluation,
mass and source fixed while the lens light moves (the LIGHT phase: the source's part of
the system is reused), peak memory, and a breakdown of one evaluation by stage so the
next optimisation goes where the time is.

Run from the repository root: ``python benchmarks/bench_likelihood.py``. ``--threads 1 2 4 8``
also times configuration R at each thread count (numba threads; BLAS keeps one), printing
``likelihood_R_threads_<n>_s``; counts above the machine's cores need
``NUMBA_NUM_THREADS=8`` in the environment, since numba fixes its pool at import.
"""

import argparse
import time
from dataclasses import replace

import numba
import numpy as np
from common import median_time, peak_memory_mb, report, set_threads

from mgelens import mass
from mgelens.convolve import convolve_image
from mgelens.fit import FitDataset, LensModel, PixelizedSource, fit, pixelized_operator
from mgelens.fit_settings import FitSettings
from mgelens.geometry import ell_comps_from
from mgelens.grid import pixel_centres, sub_grid
from mgelens.imaging import Imaging
from mgelens.inversion.evidence import log_det_regularization
from mgelens.inversion.solve import solve_linear_system
from mgelens.inversion.system import curvature_matrix, data_vector
from mgelens.light import Gaussian, MGESet
from mgelens.source.border import relocate_to_border
from mgelens.source.image_mesh import kmeans_centres, kmeans_weights
from mgelens.source.interpolate import natural_neighbour_weights
from mgelens.source.mapping import SourceWeights, mapping_matrix
from mgelens.source.mesh import VoronoiMesh
from mgelens.source.regularization import AdaptiveBrightnessSplit

PIXEL = 0.05
SHAPE = (201, 201)
RADIUS = 3.0
MASS = (
    mass.EPL(centre=(0.01, -0.02), einstein_radius=1.2, axis_ratio=0.8, angle=45.0, slope=2.1),
    mass.ExternalShear(gamma_1=0.02, gamma_2=-0.01),
)


def gaussian_psf(size: int = 21) -> np.ndarray:
    yy, xx = np.mgrid[:size, :size] - size // 2
    psf = np.exp(-(xx**2 + yy**2) / 2.0)
    return psf / psf.sum()


def mock_imaging() -> tuple[Imaging, np.ndarray]:
    """A lens with MGE-like light and a clumpy source; returns imaging and lensed source."""
    rng = np.random.default_rng(0)
    x, y = pixel_centres(SHAPE, PIXEL)
    grid = sub_grid(x.ravel(), y.ravel(), PIXEL, 4)
    light = [
        Gaussian.from_major_axis((0.01, -0.02), q, phi, s, i)
        for q, phi, s, i in [(0.8, 40, 0.05, 6.0), (0.7, 50, 0.3, 1.0), (0.75, 45, 1.2, 0.1)]
    ]
    lens = grid.bin(sum(g.image(grid.x, grid.y) for g in light)).reshape(SHAPE)
    bx, by = mass.ray_trace(MASS, grid.x, grid.y)
    clumps = [(0.05, 0.02, 0.12, 1.5), (-0.1, 0.08, 0.05, 1.0), (0.12, -0.06, 0.04, 0.8)]
    source = sum(
        i * np.exp(-((bx - cx) ** 2 + (by - cy) ** 2) / (2 * s**2)) for cx, cy, s, i in clumps
    )
    lensed = grid.bin(source).reshape(SHAPE)
    psf = gaussian_psf()
    model = convolve_image(lens + lensed, psf)
    noise = np.sqrt((model + 0.15) * 2000.0) / 2000.0
    data = model + rng.normal(size=SHAPE) * noise
    mask = np.hypot(x, y) > RADIUS
    return Imaging(data, noise, psf, PIXEL, mask, name="bench"), convolve_image(lensed, psf)


def lens_light_sets() -> tuple[MGESet, ...]:
    return (
        MGESet.extended((0.01, -0.02), ell_comps_from(0.8, 40.0), PIXEL, RADIUS),
        MGESet.extended((0.01, -0.02), ell_comps_from(0.7, 50.0), PIXEL, RADIUS),
        MGESet.point((0.01, -0.02), ell_comps_from(0.9, 0.0), PIXEL),
    )


def make_model(dataset: FitDataset, adapt: np.ndarray, n_pixels: int) -> LensModel:
    x, y = pixel_centres(SHAPE, PIXEL)
    used = ~dataset.mask
    weights = kmeans_weights(adapt, weight_floor=0.1, weight_power=2.0)
    kx, ky = kmeans_centres(x[used], y[used], weights, n_pixels, seed=1)
    regularization = AdaptiveBrightnessSplit(1.0, 0.1, 0.5)
    source = PixelizedSource(kx, ky, regularization, adapt_image=adapt)
    return LensModel(mass=MASS, lens_light=lens_light_sets(), source=source)


def inversion_system(n_pixels: int = 1500):
    """(Q, D, H, fixed_zero, n_light) of configuration R's inversion, for solver benchmarks."""
    imaging, lensed = mock_imaging()
    dataset = FitDataset.from_imaging(imaging, light_centre=(0.01, -0.02))
    model = make_model(dataset, lensed[~dataset.mask], n_pixels)
    operator = pixelized_operator(dataset, model.mass, model.source)
    lens = dataset.lens_light_columns(model.lens_light)
    args = (lens, operator.mapping)
    d = data_vector(*args, dataset.source_psf_operator, dataset.inverse_variance, dataset.data)
    q = curvature_matrix(*args, dataset.tile_plan, dataset.inverse_variance)
    n = lens.shape[1]
    q[np.arange(n), np.arange(n)] += dataset.settings.mge_diagonal
    h = operator.regularization_matrix
    q[n:, n:] += h.toarray()
    fixed_zero = np.concatenate([np.zeros(n, dtype=bool), operator.mesh.edge_pixels])
    return q, d, h, fixed_zero, n


def fresh_fit(dataset: FitDataset, model: LensModel):
    """One evaluation as a sampler sees it: the mass moves, so nothing is reused."""
    dataset._columns_cache.clear()
    dataset._source_cache.clear()
    return fit(dataset, model)


def breakdown(dataset: FitDataset, model: LensModel) -> dict[str, float]:
    """Seconds spent per stage of one evaluation (same steps as ``fit``)."""
    times: dict[str, float] = {}

    def timed(name, func, *args):
        start = time.perf_counter()
        out = func(*args)
        times[name] = times.get(name, 0.0) + time.perf_counter() - start
        return out

    source = model.source
    g = dataset.source_grid
    lens = timed("lens_light_columns", dataset.light_grid.blurred_columns, list(model.lens_light))
    bx, by = timed("ray_tracing", mass.ray_trace, model.mass, g.x, g.y)
    mx, my = timed(
        "ray_tracing", mass.ray_trace, model.mass, source.image_plane_x, source.image_plane_y
    )
    border = (bx[dataset.border], by[dataset.border])
    bx, by = timed("border_relocation", relocate_to_border, bx, by, *border)
    mx, my = timed("border_relocation", relocate_to_border, mx, my, *border)
    mesh = timed("voronoi_mesh", VoronoiMesh.from_points, mx, my)
    indptr, indices, values = timed("interpolation", natural_neighbour_weights, mesh, bx, by)
    weights = SourceWeights(indptr, indices, values, 4, mesh.n_points)
    f = timed("mapping_matrix", mapping_matrix, weights)
    h = timed("regularization", source.regularization.matrix, mesh, weights, source.adapt_image)
    b = dataset.source_psf_operator
    d = timed("data_vector", data_vector, lens, f, b, dataset.inverse_variance, dataset.data)
    c = timed("curvature", curvature_matrix, lens, f, dataset.tile_plan, dataset.inverse_variance)
    n = lens.shape[1]
    q = c.copy()
    q[np.arange(n), np.arange(n)] += 1e-3
    q[n:, n:] += h.toarray()
    fixed = np.concatenate([np.zeros(n, dtype=bool), mesh.edge_pixels])
    timed("solve_and_log_det_fh", solve_linear_system, q, d, True, fixed, slice(n, None))
    timed("log_det_h", log_det_regularization, h)
    return times


def thread_scaling(counts: list[int]) -> None:
    """Configuration R's median time at each numba thread count in ``counts``."""
    imaging, lensed = mock_imaging()
    dataset = FitDataset.from_imaging(imaging, light_centre=(0.01, -0.02))
    model = make_model(dataset, lensed[~dataset.mask], 1500)
    for n in counts:
        set_threads(n)
        report(f"likelihood_R_threads_{n}_s", median_time(lambda: fresh_fit(dataset, model)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--threads", type=int, nargs="+", default=[2], help="numba thread counts (default 2)"
    )
    args = parser.parse_args()
    available = numba.config.NUMBA_NUM_THREADS
    if max(args.threads) > available or min(args.threads) < 1:
        parser.error(
            f"thread counts must be 1..{available} (numba's pool); raise NUMBA_NUM_THREADS "
            "in the environment for more"
        )
    if len(args.threads) > 1:
        thread_scaling(args.threads)
    set_threads(args.threads[0])
    imaging, lensed = mock_imaging()
    dataset = FitDataset.from_imaging(imaging, light_centre=(0.01, -0.02))
    adapt = lensed[~dataset.mask]
    print(f"n_image_pixels: {dataset.data.size}")
    for n_pixels, label in ((1500, "R"), (500, "R500")):
        model = make_model(dataset, adapt, n_pixels)

        def full(m=model):
            return fresh_fit(dataset, m)

        def cached_lens_light(m=model):
            dataset._source_cache.clear()
            return fit(dataset, m)

        report(f"likelihood_{label}_s", median_time(full, repeats=7))
        report(f"likelihood_{label}_cached_lens_light_s", median_time(cached_lens_light))
        result = fit(dataset, model)
        print(f"log_evidence_{label}: {result.log_evidence:.3f}  chi2: {result.chi_squared:.1f}")
    # the quick profile's MASS evaluation: 500 pixels, 2×2 source sub-grid, lens light fixed
    quick = FitDataset.from_imaging(
        imaging,
        settings=replace(
            FitSettings(), sub_size=2, lp_sub_size=2, lp_sub_size_centre=8, psf_trim=1e-4
        ),
        light_centre=(0.01, -0.02),
    )
    quick_model = make_model(quick, adapt, 500)

    def quick_mass():
        quick._source_cache.clear()
        return fit(quick, quick_model)

    report("likelihood_R500_quick_cached_lens_light_s", median_time(quick_mass))
    # as the MASS phase calls it, warm-started; here from the fit's own final passive set
    # (the best case: the NNLS only checks optimality)
    passive = ~quick_mass().solution.active_zero

    def quick_mass_warm():
        quick._source_cache.clear()
        return fit(quick, quick_model, passive_start=passive)

    report("likelihood_R500_quick_warm_start_s", median_time(quick_mass_warm))
    model = make_model(dataset, adapt, 1500)
    # LIGHT-phase pattern: mass and source fixed, the lens light moves every call
    shifted = [
        replace(
            model, lens_light=tuple(replace(s, centre=(0.01 + d, -0.02)) for s in model.lens_light)
        )
        for d in (0.0, 1e-4)
    ]
    calls = iter(shifted * 20)
    report("likelihood_R_repeated_source_s", median_time(lambda: fit(dataset, next(calls))))
    pn = FitDataset.from_imaging(
        imaging, settings=replace(FitSettings(), positive_only=False), light_centre=(0.01, -0.02)
    )

    def unconstrained():
        pn._source_cache.clear()
        return fit(pn, model)

    report("likelihood_R_nnls_off_s", median_time(unconstrained, repeats=5))
    continuous = FitDataset.from_imaging(
        imaging,
        settings=replace(FitSettings(), edge_rule="continuous", force_edge_pixels_to_zero=False),
        light_centre=(0.01, -0.02),
    )
    report("likelihood_R_continuous_edges_s", median_time(lambda: fresh_fit(continuous, model), 7))
    stages = [breakdown(dataset, model) for _ in range(5)]
    for name in stages[0]:
        report(f"stage_{name}_s", float(np.median([s[name] for s in stages])))
    report("peak_memory_mb", peak_memory_mb(), "MB")


if __name__ == "__main__":
    main()

"""Calibration of the fit-quality flag (:mod:`mgelens.quality`, docs/slacs.md).

Geometries: mocks at the default observation (151×151, 0.05″, Gaussian PSF σ = 0.05″), their
noise maps and PSF-convolved lensed sources: M3 in a 2.2″ mask (101 block pairs, the
fewest for which the statistic is defined) and M1 in a SLACS-like 3.0″ mask. On each:

* white N(0, 1) residuals, and residuals correlated by a Gaussian kernel of σ = 1 and
  1.5 pixels (renormalised to unit variance: PSF-scale correlation, e.g. drizzled data);
  prints quantiles of S and z_max and the fraction of maps flagged;
* white residuals plus injected lens-light errors, residual = noise − δ/σ with δ the model's
  error: the mock MGE's Gaussians with σ_major ≥ 0.5″ too bright by a fraction f, and a
  centroid shift ε of the whole lens light (an m = 1 dipole at the centre); prints the
  fraction flagged for each amplitude.

Writes docs/images/quality_calibration.png (histograms, detection curves) and
docs/images/quality_injection.png (z_b maps of one injection of each kind).

Run from the repository root:
``PYTHONPATH=src python benchmarks/quality_calibration.py [--trials 20000]``.
"""

import argparse
import time

import numpy as np
from matplotlib.figure import Figure

from mgelens import mock_lenses, mock_light, quality, simulate
from mgelens.convolve import convolve_image
from mgelens.grid import pixel_centres
from mgelens.mask import circular

KERNELS = {"white": None, "correlated σ=1 px": 1.0, "correlated σ=1.5 px": 1.5}
OUTER_FRACTIONS = (0.0, 0.01, 0.02, 0.05, 0.1)
SHIFTS = (0.0, 0.0025, 0.005, 0.01, 0.02)
"""Arcsec centroid shifts of the lens light (pixel = 0.05″)."""


def geometry(mock, radius):
    imaging = mock.imaging
    mask = circular(imaging.data.shape, imaging.pixel_scale, radius)
    return {
        "lensed": mock.lensed_source_blurred,
        "noise": imaging.noise_map,
        "mask": mask,
        "scale": imaging.pixel_scale,
    }


def correlated(rng, shape, sigma_pixels):
    noise = rng.standard_normal(shape)
    if sigma_pixels is None:
        return noise
    size = 2 * int(np.ceil(4 * sigma_pixels)) + 1
    kernel = simulate.gaussian_psf(size, sigma_pixels)
    smoothed = convolve_image(noise, kernel, method="fft")
    return smoothed / np.sqrt(np.sum(kernel**2))


def statistic(residuals, geo):
    return quality.quality_statistic(
        residuals, geo["lensed"], geo["noise"], geo["mask"], geo["scale"]
    )


def noise_trials(geo, sigma_pixels, trials, rng):
    values = np.empty((trials, 2))
    flags = 0
    for t in range(trials):
        result = statistic(correlated(rng, geo["mask"].shape, sigma_pixels), geo)
        values[t] = result.significance, result.peak
        flags += result.flag
    return values, flags / trials


def outer_light(lens, mock, pixel_scale, minimum_sigma=0.5):
    """PSF-convolved image of the M1 Gaussians with major-axis σ ≥ ``minimum_sigma``."""
    outer = mock_light.MGELight(
        tuple(g for g in lens.light.gaussians if g.sigma / g.axis_ratio >= minimum_sigma)
    )
    x, y = pixel_centres(mock.imaging.data.shape, pixel_scale)
    return convolve_image(outer.image(x, y), mock.imaging.psf)


def shifted_light(lens, mock, pixel_scale, shift):
    x, y = pixel_centres(mock.imaging.data.shape, pixel_scale)
    light = lens.light.image(x - shift, y) - lens.light.image(x, y)
    return convolve_image(light, mock.imaging.psf)


def injection_trials(geo, error, trials, rng):
    flagged = 0
    for _ in range(trials):
        residuals = rng.standard_normal(error.shape) + error / geo["noise"]
        flagged += statistic(residuals, geo).flag
    return flagged / trials


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--trials", type=int, default=20000, help="noise maps per case")
    parser.add_argument("--injections", type=int, default=200, help="maps per injection")
    parser.add_argument("--seed", type=int, default=29)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    observation = simulate.Observation(sub_size=4, source_plane_size=41)
    lenses = {name: mock_lenses.paper_mock(name) for name in ("M1", "M3")}
    mocks = {name: simulate.simulate(lens, observation) for name, lens in lenses.items()}
    geometries = {"M3 2.2″": geometry(mocks["M3"], 2.2), "M1 3.0″": geometry(mocks["M1"], 3.0)}
    figure = Figure(figsize=(12.0, 7.0), layout="constrained")
    axes = figure.subplots(2, 3)
    for g, (name, geo) in enumerate(geometries.items()):
        info = statistic(np.zeros(geo["mask"].shape), geo)
        print(f"{name}: {info.n_blocks} blocks of {info.block_pixels}², {info.n_pixels} pixels")
        for kernel_name, sigma in KERNELS.items():
            start = time.perf_counter()
            values, rate = noise_trials(geo, sigma, args.trials, rng)
            q = np.quantile(values, [0.5, 0.99, 0.999], axis=0)
            print(
                f"  {kernel_name}: K median/99%/99.9% = {q[0, 0]:.2f}/{q[1, 0]:.2f}/"
                f"{q[2, 0]:.2f}, max K {values[:, 0].max():.2f}; z_max {q[0, 1]:.2f}/"
                f"{q[1, 1]:.2f}/{q[2, 1]:.2f}, max {values[:, 1].max():.2f}; flagged "
                f"{rate:.2e} of {args.trials} ({time.perf_counter() - start:.0f} s)"
            )
            for column in (0, 1):
                axes[column, g].hist(
                    values[:, column], bins=80, histtype="step", label=kernel_name, log=True
                )
        thresholds = (quality.COHERENCE_THRESHOLD, quality.PEAK_THRESHOLD)
        for column, (label, threshold) in enumerate(zip(("K", "z_max"), thresholds, strict=True)):
            ax = axes[column, g]
            ax.axvline(threshold, color="k", linestyle="--", label="threshold")
            ax.set_xlabel(f"{label} ({name}, {args.trials} maps each)")
            ax.set_ylabel("maps")
            ax.legend(fontsize=7)
    detection = {}
    for name, geo in geometries.items():
        lens, mock = lenses[name[:2]], mocks[name[:2]]
        outer = outer_light(lens, mock, geo["scale"])
        for f in OUTER_FRACTIONS:
            rate = injection_trials(geo, -f * outer, args.injections, rng)
            detection[(name, "outer", f)] = rate
            print(f"  {name}: outer Gaussians {100 * f:g} % too bright: flagged {rate:.3f}")
        for shift in SHIFTS:
            rate = injection_trials(
                geo, shifted_light(lens, mock, geo["scale"], shift), args.injections, rng
            )
            detection[(name, "shift", shift)] = rate
            print(f"  {name}: centroid shift {shift:g}″: flagged {rate:.3f}")
    for name in geometries:
        axes[0, 2].plot(
            [100 * f for f in OUTER_FRACTIONS],
            [detection[(name, "outer", f)] for f in OUTER_FRACTIONS],
            marker="o",
            label=name,
        )
        axes[1, 2].plot(
            [1000 * s for s in SHIFTS],
            [detection[(name, "shift", s)] for s in SHIFTS],
            marker="o",
            label=name,
        )
    axes[0, 2].set_xlabel("model's outer Gaussians (σ ≥ 0.5″) too bright [%]")
    axes[1, 2].set_xlabel("lens-light centroid shift [mas] (m = 1 dipole)")
    for ax in axes[:, 2]:
        ax.set_ylabel(f"fraction flagged ({args.injections} maps)")
        ax.set_ylim(-0.05, 1.05)
        ax.legend(fontsize=7)
    figure.savefig("docs/images/quality_calibration.png", dpi=110)

    geo, lens, mock = geometries["M1 3.0″"], lenses["M1"], mocks["M1"]
    maps = Figure(figsize=(10.0, 3.6), layout="constrained")
    panels = maps.subplots(1, 3)
    cases = {
        "white noise": np.zeros(geo["mask"].shape),
        "outer Gaussians 5 % too bright": -0.05 * outer_light(lens, mock, geo["scale"]),
        "centroid shift 0.01″": shifted_light(lens, mock, geo["scale"], 0.01),
    }
    for ax, (title, error) in zip(panels, cases.items(), strict=True):
        residuals = rng.standard_normal(error.shape) + error / geo["noise"]
        blocks = quality.judged_blocks(
            residuals, geo["lensed"], geo["noise"], geo["mask"], geo["scale"]
        )
        block = blocks.block
        result = statistic(residuals, geo)
        n_y, n_x = geo["mask"].shape
        left = -(((block - (n_x // 2) % block) % block) + 0.5 + (n_x - 1) / 2) * geo["scale"]
        bottom = -(((block - (n_y // 2) % block) % block) + 0.5 + (n_y - 1) / 2) * geo["scale"]
        width = block * geo["scale"]
        extent = (
            left,
            left + width * blocks.z.shape[1],
            bottom,
            bottom + width * blocks.z.shape[0],
        )
        image = ax.imshow(
            blocks.z / result.noise_scale,
            origin="lower",
            cmap="RdBu_r",
            vmin=-6,
            vmax=6,
            extent=extent,
        )
        ax.plot(result.worst_x, result.worst_y, "k+", markersize=12)
        ax.set_title(
            f"{title}\nS = {result.coherence:.2f}, K = {result.significance:.1f}, "
            f"z_max = {result.peak:.1f}, flag = {result.flag}",
            fontsize=9,
        )
        ax.set_xlabel("x [arcsec]")
        ax.set_ylabel("y [arcsec]")
    maps.colorbar(image, ax=panels, label="z_b / τ")
    maps.savefig("docs/images/quality_injection.png", dpi=110)


if __name__ == "__main__":
    main()

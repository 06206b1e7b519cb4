"""Calibration of the fit-quality flag when τ comes from the sky (:mod:`mgelens.quality`,
step 6; docs/slacs.md, "τ from the sky").

Geometries: the paper's mocks M1, M2 and M3 in their own masks (1.8″, 1.6″, 1.8″), where
the lensed source leaves 9–19 judged blocks and fewer than 100 block pairs, so that τ is
always the sky's. Each trial draws one noise map over the whole image (white, or
Gaussian-correlated with σ = 1 and 1.5 pixels and renormalised to unit pixel variance, as in
``quality_calibration.py``): the residuals inside the mask are that noise, the data are the
mock's noiseless image plus σ × the noise, and the sky's τ comes from those data. Prints,
for each case, the sky's τ against the residuals' own τ measured on whole noise images,
quantiles of K and z_max and the fraction of maps flagged; then the fraction flagged for
the injected lens-light errors of ``quality_calibration.py`` (white noise).

The running median of a whole image takes ~0.2 s, so the sky's τ is drawn from the first
``--sky-trials`` noise maps and paired in turn with the residuals of all ``--trials``
maps: the two regions are 0.5″ apart, 10 times the correlation length, so their noise is
independent and any pairing has the joint distribution of a single map.

Run from the repository root:
``PYTHONPATH=src python benchmarks/quality_sky_calibration.py [--trials 20000] [--sky-trials 500]``.
"""

import argparse
import time

import numpy as np
from quality_calibration import KERNELS, OUTER_FRACTIONS, SHIFTS, correlated, outer_light
from quality_calibration import shifted_light as shifted

from mgelens import mock_lenses, quality, simulate
from mgelens.mask import circular


def geometry(name):
    lens = mock_lenses.paper_mock(name)
    mock = simulate.simulate(lens, simulate.Observation(sub_size=4, source_plane_size=41))
    imaging = mock.imaging
    radius = lens.mask_radius
    return {
        "lens": lens,
        "mock": mock,
        "lensed": mock.lensed_source_blurred,
        "noise": imaging.noise_map,
        "model": mock.model,
        "mask": circular(imaging.data.shape, imaging.pixel_scale, radius),
        "sky": quality.sky_pixels(imaging.data, imaging.noise_map, imaging.pixel_scale, radius),
        "scale": imaging.pixel_scale,
        "radius": radius,
    }


def sky_map(geo, noise):
    data = geo["model"] + geo["noise"] * noise
    return quality.sky_residual_map(data, geo["noise"], geo["sky"], geo["scale"])


def sky_scales(geo, sigma_pixels, trials, rng):
    """τ of the sky for ``trials`` noise maps, and the residuals' τ of the same whole maps."""
    scales = np.empty((trials, 2))
    block = quality.block_pixels(geo["scale"])
    everywhere = np.ones(geo["mask"].shape, dtype=bool)
    for t in range(trials):
        noise = correlated(rng, geo["mask"].shape, sigma_pixels)
        sky = quality.block_residuals(sky_map(geo, noise), geo["sky"], geo["scale"], block)
        whole = quality.block_residuals(noise, everywhere, geo["scale"], block)
        scales[t] = (
            quality.noise_scale(quality.pair_differences(sky.z)),
            quality.noise_scale(quality.pair_differences(whole.z)),
        )
    return scales


def judged(geo, residuals, tau):
    """The statistic of ``residuals`` with the sky's noise scale ``tau`` (steps 2, 4, 5)."""
    blocks = quality.judged_blocks(
        residuals, geo["lensed"], geo["noise"], geo["mask"], geo["scale"]
    )
    return quality.scaled_statistic(blocks, tau, geo["scale"], "sky", n_pairs=0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--trials", type=int, default=20000, help="residual maps per case")
    parser.add_argument("--sky-trials", type=int, default=500, help="sky τ draws per case")
    parser.add_argument("--injections", type=int, default=200, help="maps per injection")
    parser.add_argument("--seed", type=int, default=30)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    for name in ("M1", "M2", "M3"):
        geo = geometry(name)
        n_blocks = judged(geo, np.zeros(geo["mask"].shape), 1.0).n_blocks
        print(f"{name} in {geo['radius']}″: {n_blocks} judged blocks, sky {geo['sky'].sum()} px")
        for kernel_name, sigma in KERNELS.items():
            start = time.perf_counter()
            scales = sky_scales(geo, sigma, args.sky_trials, rng)
            values = np.empty((args.trials, 2))
            flags = 0
            for t in range(args.trials):
                noise = correlated(rng, geo["mask"].shape, sigma)
                result = judged(geo, noise, scales[t % args.sky_trials, 0])
                values[t] = result.significance, result.peak
                flags += result.flag
            q = np.quantile(values, [0.5, 0.99, 0.999], axis=0)
            ratio = scales[:, 0] / scales[:, 1]
            print(
                f"  {kernel_name}: τ sky {scales[:, 0].mean():.3f} ± {scales[:, 0].std():.3f}, "
                f"whole-image τ {scales[:, 1].mean():.3f} (ratio {ratio.mean():.3f}); K "
                f"median/99%/99.9% = {q[0, 0]:.2f}/{q[1, 0]:.2f}/{q[2, 0]:.2f}, max "
                f"{values[:, 0].max():.2f}; z_max {q[0, 1]:.2f}/{q[1, 1]:.2f}/{q[2, 1]:.2f}, "
                f"max {values[:, 1].max():.2f}; flagged {flags / args.trials:.2e} of "
                f"{args.trials} ({time.perf_counter() - start:.0f} s)"
            )
        scales = sky_scales(geo, None, args.sky_trials, rng)[:, 0]
        errors = {f"outer Gaussians {100 * f:g} % too bright": -f for f in OUTER_FRACTIONS}
        outer = outer_light(geo["lens"], geo["mock"], geo["scale"])
        for label, fraction in errors.items():
            rate = np.mean(
                [
                    judged(
                        geo,
                        rng.standard_normal(outer.shape) + fraction * outer / geo["noise"],
                        scales[t % scales.size],
                    ).flag
                    for t in range(args.injections)
                ]
            )
            print(f"  {label}: flagged {rate:.3f}")
        for shift in SHIFTS:
            error = shifted(geo["lens"], geo["mock"], geo["scale"], shift) / geo["noise"]
            rate = np.mean(
                [
                    judged(
                        geo, rng.standard_normal(error.shape) + error, scales[t % scales.size]
                    ).flag
                    for t in range(args.injections)
                ]
            )
            print(f"  centroid shift {shift:g}″: flagged {rate:.3f}")


if __name__ == "__main__":
    main()

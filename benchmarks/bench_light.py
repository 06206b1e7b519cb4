"""Lens-light columns: MGE 2×30 + 10 Gaussians and 3 linear Sérsics, 3.0″ mask at 0.05″,
over-sampled, PSF.

Prints the median time of building all 70 PSF-convolved MGE columns (target <= 0.1 s on
2 cores), split into evaluation (over-sampled Gaussians, binned) and convolution (by the
automatic route, separable for these Gaussian PSFs, and by FFT and sparse direct
summation for comparison), and of
the 3 Sérsic columns of the 3×Sérsic comparison model. The PSF is trimmed of wings below
1e−10 of its peak, as ``FitDataset`` does.
"""

import numpy as np
from common import median_time, peak_memory_mb, report, set_threads

from mgelens.convolve import trimmed_psf
from mgelens.fit_settings import FitSettings
from mgelens.geometry import ell_comps_from
from mgelens.grid import pixel_centres
from mgelens.light import LightGrid, MGESet, Sersic


def gaussian_psf(size: int) -> np.ndarray:
    yy, xx = np.mgrid[:size, :size] - size // 2
    psf = np.exp(-(xx**2 + yy**2) / 2.0)
    return psf / psf.sum()


def main() -> None:
    set_threads(2)
    pixel_scale, radius = 0.05, 3.0
    x, y = pixel_centres((201, 201), pixel_scale)
    mask = np.hypot(x, y) > radius
    sets = [
        MGESet.extended((0.01, -0.02), ell_comps_from(0.8, 30.0), pixel_scale, radius),
        MGESet.extended((0.01, -0.02), ell_comps_from(0.6, 50.0), pixel_scale, radius),
        MGESet.point((0.0, 0.0), ell_comps_from(0.9, 10.0), pixel_scale),
    ]
    for size in (15, 21):
        psf = trimmed_psf(gaussian_psf(size), FitSettings().psf_trim)
        grid = LightGrid.from_mask(mask, psf, pixel_scale, centre=(0.0, 0.0))
        columns = np.concatenate([s.columns(grid.grid) for s in sets], axis=1)
        report(f"mge_columns_70_psf{size}_s", median_time(lambda g=grid: g.blurred_columns(sets)))
        report(
            f"mge_evaluate_70_psf{size}_s",
            median_time(lambda g=grid: [s.columns(g.grid) for s in sets]),
        )
        for method in ("auto", "fft", "direct"):  # auto: separable for this Gaussian PSF
            report(
                f"mge_convolve_70_psf{size}_{method}_s",
                median_time(
                    lambda g=grid, c=columns, m=method: g.convolver.blur_columns(c, True, m)
                ),
            )
    sersics = [
        Sersic((0.01, -0.02), ell_comps_from(q, angle), radius_e, n)
        for q, angle, radius_e, n in ((0.8, 30.0, 0.4, 4.0), (0.6, 50.0, 1.2, 1.5), (0.9, 10, 3, 1))
    ]
    report("sersic_columns_3_s", median_time(lambda g=grid: g.blurred_columns(sersics)))
    report(
        "sersic_evaluate_3_s",
        median_time(lambda g=grid: [s.columns(g.grid) for s in sersics]),
    )
    print(f"n_image_pixels: {grid.n_image_pixels}  n_sub_pixels: {grid.grid.x.size}")
    report("peak_memory_mb", peak_memory_mb(), "MB")


if __name__ == "__main__":
    main()

"""Isophote analysis of one lens: render + 40 isophotes + ellipse fits + statistics.

The lens light is the M1 mock MGE (SPEC §10.1, 16 Gaussians), rendered on a 141×141 grid
(±3.5″ at 0.05″) with the fitting over-sampling (4×4, 16×16 within 0.3″) and convolved with
the 21×21 Gaussian mock PSF (σ = 1 pixel). Prints the median wall time (target <= 2 s) and
its split into rendering and isophote analysis.
"""

import numpy as np
from common import median_time, peak_memory_mb, report, set_threads

from mgelens.isophotes import isophote_statistics, isophote_table, render_light
from mgelens.light import Gaussian

CENTRE = (0.013, -0.070)
M1 = {
    "q": [0.83, 0.77, 0.83, 0.90, 0.65, 0.64, 0.77, 0.50, 1.00, 0.79, 0.48, 0.62, 0.41, 0.18,
          0.78, 0.22],
    "phi": [-19, -19, 71, -19, -70, 4, 56, -52, 0, -80, -2, -78, 28, 49, -73, -25],
    "lg_i": [0.86, 0.91, 0.29, 0.30, -0.24, -0.48, -0.13, -0.75, -0.73, -0.76, -1.6, -1.4, -2.0,
             -2.2, -2.2, -2.4],
    "lg_sigma": [-1.8, -1.6, -1.4, -1.1, -1.0, -0.85, -0.75, -0.56, -0.25, -0.14, -0.13, 0.0018,
                 0.020, -0.19, 0.43, -0.11],
}  # fmt: skip


def gaussian_psf(size: int = 21) -> np.ndarray:
    yy, xx = np.mgrid[:size, :size] - size // 2
    psf = np.exp(-(xx**2 + yy**2) / 2.0)
    return psf / psf.sum()


def main() -> None:
    set_threads(2)
    gaussians = [
        Gaussian.from_major_axis(CENTRE, q, phi, 10.0**lg_sigma, 10.0**lg_i)
        for q, phi, lg_i, lg_sigma in zip(*M1.values(), strict=True)
    ]
    psf = gaussian_psf()

    def render():
        return render_light(gaussians, 0.05, 3.5, psf, centre=CENTRE)

    image = render()

    def analyse(image=image):
        return isophote_statistics(isophote_table(image, 0.05, centre=CENTRE))

    def one_lens():
        return analyse(render())

    report("isophotes_one_lens_s", median_time(one_lens, repeats=5))
    report("isophotes_render_s", median_time(render, repeats=5))
    report("isophotes_analysis_s", median_time(analyse, repeats=5))
    print(one_lens())
    report("peak_memory_mb", peak_memory_mb(), "MB")


if __name__ == "__main__":
    main()

"""``mgelens isophotes``: isophote table, per-lens statistics, summary JSON and figure.

Example::

    mgelens isophotes results/J0252/lens_light.fits --pixel-scale 0.05 \\
        --summary results/J0252/isophotes.json --figure results/J0252/figures/isophotes.png \\
        --out results/J0252/isophotes.csv

The image is taken as it is (e.g. the PSF-convolved lens-light model); ``--psf`` convolves
it first (for an unconvolved model image). Coordinates follow SPEC §1.1: (x, y) arcsec with
(0, 0) at the image centre, row index increasing with +y.
"""

import argparse
import logging
from pathlib import Path

import numpy as np

from mgelens.atomic import atomic_path, write_json
from mgelens.convolve import convolve_image
from mgelens.imaging import PIXSCALE_KEY, ImagingError, read_fits_image
from mgelens.isophotes import (
    IsophoteStatistics,
    brightest_pixel_centre,
    isophote_statistics,
    isophote_table,
)
from mgelens.plot import save_png
from mgelens.plot.isophotes import isophote_figure
from mgelens.summary import lens_summary

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "isophotes",
        help="isophotes of a lens-light image: q(a), PA(a), a4/a and per-lens statistics",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("image", type=Path, help="FITS image of the lens light")
    parser.add_argument(
        "--pixel-scale",
        type=float,
        help="arcsec per pixel (default: the PIXSCALE keyword of the image header)",
    )
    parser.add_argument(
        "--centre",
        type=float,
        nargs=2,
        metavar=("X", "Y"),
        help="galaxy centre in arcsec (default: the brightest pixel)",
    )
    parser.add_argument("--psf", type=Path, help="FITS PSF to convolve the image with first")
    parser.add_argument("--lens", help="lens name for the summary (default: the image file stem)")
    parser.add_argument("--summary", type=Path, help="write the per-lens summary JSON here")
    parser.add_argument("--figure", type=Path, help="write the isophote figure (PNG) here")
    parser.add_argument("--out", type=Path, required=True, help="isophote table (CSV)")
    parser.set_defaults(func=run)


def format_statistics(lens: str, statistics: IsophoteStatistics) -> str:
    """The per-lens statistics as ``name: value`` lines."""
    a4 = statistics.a4_a_extreme
    kind = "disky" if a4 > 0 else "boxy" if a4 < 0 else "undefined"
    return "\n".join(
        [
            f"lens: {lens}",
            f"isophotes_in_range: {statistics.n_isophotes} "
            f"({statistics.sma_min:g} <= a <= {statistics.sma_max:g} arcsec)",
            f"delta_q_max: {statistics.delta_q_max:.4f}",
            f"delta_pa_max_deg: {statistics.delta_pa_max:.2f}",
            f"a4_a_extreme: {a4:+.4f} ({kind})",
        ]
    )


def run(args: argparse.Namespace) -> int:
    try:
        image, header = read_fits_image(args.image)
        image = np.asarray(image, dtype=float)
        if args.pixel_scale is None:
            if PIXSCALE_KEY not in header:
                raise ValueError(
                    f"{args.image}: no {PIXSCALE_KEY} keyword in the header; pass --pixel-scale"
                )
            args.pixel_scale = float(header[PIXSCALE_KEY])
        if args.psf is not None:
            psf, _ = read_fits_image(args.psf)
            image = convolve_image(image, np.asarray(psf, dtype=float) / np.sum(psf))
    except (ImagingError, ValueError) as exc:
        logger.error("%s", exc)
        return 1
    centre = (
        tuple(args.centre)
        if args.centre is not None
        else brightest_pixel_centre(image, args.pixel_scale)
    )
    lens = args.lens or args.image.stem
    table = isophote_table(image, args.pixel_scale, centre=centre)
    statistics = isophote_statistics(table)
    with atomic_path(args.out) as temporary:
        table.to_csv(temporary, index=False)
    print(format_statistics(lens, statistics))
    if args.summary is not None:
        inputs = {
            "image": args.image,
            "psf": args.psf,
            "pixel_scale": args.pixel_scale,
            "centre": list(centre),
            "table": args.out,
        }
        write_json(args.summary, lens_summary(lens, statistics, inputs=inputs))
    if args.figure is not None:
        figure = isophote_figure(image, args.pixel_scale, table, centre=centre, title=lens)
        save_png(figure, args.figure)
    return 0

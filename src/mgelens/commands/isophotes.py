"""``mgelens isophotes``: isophote table, per-lens statistics, summary JSON and figure.

Example::

    mgelens isophotes results/J0252/lens_light.fits --pixel-scale 0.05 \\
        --summary results/J0252/isophotes.json --figure results/J0252/figures/isophotes.png \\
        --out results/J0252/isophotes.csv

The image is taken as it is (e.g. the PSF-convolved lens-light model); ``--psf`` convolves
it first (for an unconvolved model image). Coordinates follow SPEC §1.1: (x, y) arcsec with
(0, 0) at the image centre, row index increasing with +y.

With ``--phase`` instead of an image, the lens light is the maximum-likelihood lens light
(MGE or Sérsics) of a SLaM phase folder (SPEC §9: the final L/M-phase model), rendered on a
±3.5″ grid at its imaging's pixel scale (``PIXSCALE`` of the phase's ``model.fits``, the
grid the PSF is sampled on) with the fits' over-sampling and convolved with ``--psf``
(required); the centre is the first component's centre, and the
phase's mass model (q, φ with 3σ intervals, critical curve, Einstein radius, SPEC §9.3)
joins the summary and figure, and the table gains ``source_share``, the lensed-source
model's share of the fitted light around each isophote (:mod:`mgelens.source_share`,
from the phase's ``model.fits``); its value at the extreme a₄/a joins the statistics::

    mgelens isophotes --phase results/M1/mass --psf results/M1/mock/psf.fits \
        --save-image results/M1/lens_light.fits --out results/M1/isophotes.csv
"""

import argparse
import logging
import math
from pathlib import Path

import numpy as np
from astropy.io import fits

from mgelens.atomic import atomic_path, write_fits, write_json
from mgelens.commands import add_threads_argument, make_output_folders
from mgelens.convolve import convolve_image
from mgelens.imaging_input import (
    PIXSCALE_KEY,
    ImagingError,
    check_positive,
    read_fits_image,
    read_psf,
)
from mgelens.isophotes import (
    IsophoteStatistics,
    brightest_pixel_centre,
    isophote_statistics,
    isophote_table,
    mass_shape_from,
    render_light,
)
from mgelens.pipeline.records import MODEL_FILE, PhaseInputError, lens_light_profiles, mass_model
from mgelens.plot import save_png
from mgelens.plot.isophotes import isophote_figure
from mgelens.search.results import PhaseResult
from mgelens.source_share import source_share
from mgelens.summary import lens_summary
from mgelens.threads import limit_threads

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "isophotes",
        help="isophotes of a lens-light image: q(a), PA(a), a4/a and per-lens statistics",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("image", type=Path, nargs="?", help="FITS image of the lens light")
    source.add_argument("--phase", type=Path, help="SLaM phase folder whose lens light is analysed")
    parser.add_argument(
        "--pixel-scale",
        type=float,
        help="arcsec per pixel of the image (default: its PIXSCALE keyword; not with --phase)",
    )
    parser.add_argument(
        "--centre",
        type=float,
        nargs=2,
        metavar=("X", "Y"),
        help="galaxy centre in arcsec (default: the brightest pixel)",
    )
    parser.add_argument("--psf", type=Path, help="FITS PSF to convolve the image with first")
    parser.add_argument(
        "--save-image", type=Path, help="with --phase: write the rendered lens light (FITS)"
    )
    parser.add_argument("--lens", help="lens name for the summary (default: the image file stem)")
    parser.add_argument("--summary", type=Path, help="write the per-lens summary JSON here")
    parser.add_argument("--figure", type=Path, help="write the isophote figure (PNG) here")
    parser.add_argument("--out", type=Path, required=True, help="isophote table (CSV)")
    add_threads_argument(parser)
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
        + (
            []
            if math.isnan(statistics.a4_a_source_share)
            else [f"a4_a_source_share: {statistics.a4_a_source_share:.3f}"]
        )
    )


def run(args: argparse.Namespace) -> int:
    limit_threads(args.threads)
    try:
        make_output_folders(args.out, args.summary, args.figure, args.save_image)
        if args.phase is not None:
            image, centre, mass, unit = _phase_light(args)
            source = args.phase
        else:
            (image, unit), centre, mass = _image_light(args), args.centre, None
            source = args.image
    except (ImagingError, ValueError, PhaseInputError, OSError) as exc:
        logger.error("%s", exc)
        return 1
    if centre is None:
        centre = brightest_pixel_centre(image, args.pixel_scale)
    lens = args.lens or (args.phase.resolve().parent.name if args.phase else args.image.stem)
    table = isophote_table(image, args.pixel_scale, centre=tuple(centre))
    if args.phase is not None:
        table["source_share"] = _phase_source_share(args.phase, table, args.pixel_scale)
    statistics = isophote_statistics(table)
    with atomic_path(args.out) as temporary:
        table.to_csv(temporary, index=False)
    print(format_statistics(lens, statistics))
    if args.summary is not None:
        inputs = {
            "image" if args.phase is None else "phase": source,
            "psf": args.psf,
            "pixel_scale": args.pixel_scale,
            "centre": list(centre),
            "table": args.out,
        }
        write_json(args.summary, lens_summary(lens, statistics, mass, inputs=inputs))
    if args.figure is not None:
        figure = isophote_figure(
            image, args.pixel_scale, table, mass=mass, centre=tuple(centre), title=lens, unit=unit
        )
        save_png(figure, args.figure)
    return 0


def _image_light(args: argparse.Namespace) -> tuple[np.ndarray, str]:
    """The lens-light image of ``args.image`` (convolved with ``--psf`` if given) and its
    header's BUNIT ("" if none)."""
    image, header = read_fits_image(args.image)
    image = np.asarray(image, dtype=float)
    bad = int(np.count_nonzero(~np.isfinite(image)))
    if bad:
        raise ValueError(
            f"{args.image}: {bad} NaN or infinite pixel(s); isophotes need a finite image "
            "(fill or crop them, e.g. with the model's lens light: mgelens isophotes --phase)"
        )
    if args.pixel_scale is None:
        if PIXSCALE_KEY not in header:
            raise ValueError(
                f"{args.image}: no {PIXSCALE_KEY} keyword in the header; pass --pixel-scale"
            )
        label = f"{args.image}: header {PIXSCALE_KEY} (arcsec/pixel)"
        args.pixel_scale = check_positive(header[PIXSCALE_KEY], label)
    args.pixel_scale = check_positive(args.pixel_scale, "--pixel-scale (arcsec/pixel)")
    if args.psf is not None:
        image = convolve_image(image, read_psf(args.psf))
    return image, str(header.get("BUNIT", "")).strip()


def _phase_light(args: argparse.Namespace):
    """(image, centre, MassShape, BUNIT) of the lens light of the phase folder ``args.phase``."""
    if args.psf is None:
        raise ValueError("--phase needs --psf: the PSF of the lens's imaging (psf.fits)")
    if args.pixel_scale is not None:
        raise ValueError(
            "--pixel-scale does not apply with --phase: the lens light is rendered at its "
            "imaging's pixel scale (PIXSCALE of the phase's model.fits), on which the PSF "
            "is sampled"
        )
    lens_header = fits.getheader(args.phase / MODEL_FILE, extname="LENS")
    if PIXSCALE_KEY not in lens_header:
        raise ValueError(f"{args.phase / MODEL_FILE}: extension LENS has no {PIXSCALE_KEY}")
    args.pixel_scale = check_positive(lens_header[PIXSCALE_KEY], f"{MODEL_FILE} {PIXSCALE_KEY}")
    profiles = lens_light_profiles(args.phase)
    centre = profiles[0].centre
    image = render_light(profiles, args.pixel_scale, psf=read_psf(args.psf), centre=centre)
    unit = str(lens_header.get("BUNIT", "")).strip()
    if args.save_image is not None:
        header = fits.Header({PIXSCALE_KEY: args.pixel_scale, "BUNIT": unit})
        header["PHASE"] = str(args.phase)[-68:]
        write_fits(args.save_image, fits.PrimaryHDU(image.astype(np.float32), header))
    interval = PhaseResult.read(args.phase).interval(3)
    mass = mass_shape_from(
        mass_model(args.phase),
        axis_ratio_interval=interval.get("mass.axis_ratio"),
        angle_interval=interval.get("mass.angle"),
    )
    if mass.critical_curve_note is not None:
        logger.warning("%s: %s", args.phase, mass.critical_curve_note)
    return image, centre, mass, unit


def _phase_source_share(phase: Path, table, pixel_scale: float) -> np.ndarray:
    """:func:`mgelens.source_share.source_share` of ``table`` from the phase's
    ``model.fits`` (LENS, LENSED, MODEL; array centre at XCENTRE, YCENTRE)."""
    with fits.open(phase / MODEL_FILE) as hdus:
        try:
            lens, lensed, model = (hdus[name].data for name in ("LENS", "LENSED", "MODEL"))
        except KeyError as exc:
            raise PhaseInputError(
                f"{phase / MODEL_FILE}: no {exc} extension; rerun the phase to rewrite it"
            ) from None
        header = hdus["LENS"].header
        origin = (float(header.get("XCENTRE", 0.0)), float(header.get("YCENTRE", 0.0)))
        return source_share(table, lens, lensed, model, pixel_scale, origin)

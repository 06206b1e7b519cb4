"""``mgelens overview``: the per-lens overview figure (the paper's Fig. 1) of a phase.

Example::

    mgelens overview --phase results/J0252/mass --lens-dir data/slacs/J0252 \\
        --out results/J0252/figures/overview.png

Rebuilds the phase's maximum-likelihood fit from its ``result.json`` and the earlier
phases' folders beside it (:func:`~mgelens.pipeline.run.max_likelihood_problem`),
computes the tangential critical curve and caustic (SPEC §3.4) and draws data, lens
light, source plane, normalised residuals, lens-light contours with the MGE sets' q and
PA, and lensed source (:mod:`mgelens.plot.overview`). The PNG is written atomically.
"""

import argparse
import logging
from pathlib import Path

from mgelens.commands import add_threads_argument, make_output_folders, read_phase
from mgelens.fit import FitError
from mgelens.imaging_input import ImagingError
from mgelens.overview import overview_from_fit
from mgelens.pipeline.models import UnphysicalSample
from mgelens.pipeline.records import PhaseInputError, recorded_lens
from mgelens.pipeline.run import max_likelihood_problem, scored_fit
from mgelens.plot import save_png
from mgelens.plot.overview import overview_figure
from mgelens.threads import limit_threads

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "overview",
        help="six-panel overview figure of a phase's maximum-likelihood fit",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--phase", type=Path, required=True, help="phase folder, e.g. results/J0252/mass"
    )
    parser.add_argument(
        "--lens-dir",
        type=Path,
        required=True,
        help="imaging folder (data.fits, noise_map.fits, psf.fits) the phase was fitted to",
    )
    parser.add_argument("--lens", help="lens name for the title (default: the phase's parent)")
    parser.add_argument("--out", type=Path, required=True, help="output PNG")
    add_threads_argument(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    limit_threads(args.threads)
    lens = args.lens or args.phase.resolve().parent.name
    try:
        make_output_folders(args.out)
        phase = read_phase(args.phase)
        problem, values = max_likelihood_problem(phase, args.lens_dir, args.phase.parent)
        result = scored_fit(problem, values)
        overview = overview_from_fit(
            result,
            [spec.name for spec in problem.model.lens_light],
            problem.mask_radius,
            recorded_lens(phase.settings).mask_centre,
            lens=lens,
            phase=phase.phase,
        )
    except (ImagingError, PhaseInputError, UnphysicalSample, OSError) as error:
        logger.error("%s", error)
        return 1
    except (KeyError, ValueError, *FitError) as error:
        logger.error(
            "%s: cannot rebuild the fit (%s: %s); check that --lens-dir is the imaging the "
            "phase was fitted to and rerun the phase",
            args.phase,
            type(error).__name__,
            error,
        )
        return 1
    save_png(overview_figure(overview), args.out)
    logger.info("overview of %s (%s) written to %s", lens, phase.phase, args.out)
    return 0

"""``mgelens choose``: pick a lens's LIGHT model, or its source pixel count, among fitted
candidates by evidence.

Example::

    mgelens phase light --folder light_x2_point --mge-sets 2 --point-set yes ...
    mgelens phase light --folder light_x6_point --mge-sets 6 --point-set yes ...
    mgelens phase light --folder light_x2 --mge-sets 2 --point-set no ...
    mgelens choose --results results/slacs1143-0144 --candidates X2+point X6+point X2

reads ``<results>/light_<model>/result.json`` of each candidate, takes the simplest one
whose Bayesian log evidence is within ``--threshold`` (default 5) of the highest
(:mod:`mgelens.pipeline.model_choice`), copies its result.json, samples.csv, model.fits
and phase.log into ``<results>/light/`` (which MASS reads) and writes
``<results>/model_choice.json`` with every candidate's ln Z, ln ε, χ², linear unknowns
and the choice.

With ``--source-pixels`` it chooses SPix2's k-means pixel count instead
(:mod:`mgelens.pipeline.pixel_choice`)::

    mgelens phase spix2 --folder spix2_n500 --slam '{"source_pixels": 500}' ...
    mgelens phase spix2 --folder spix2_n1000 --slam '{"source_pixels": 1000}' ...
    mgelens choose --results results/slacs1103+5322 --source-pixels 500 1000

reads ``<results>/spix2_n<count>/result.json`` of each count, takes the fewest pixels
whose ln Z is within ``--threshold`` of the highest, copies that SPix2 into
``<results>/spix2/`` (which LIGHT and MASS read) and writes
``<results>/source_pixels_choice.json``.
"""

import argparse
import logging
from pathlib import Path

from mgelens.pipeline import pixel_choice
from mgelens.pipeline.model_choice import CHOICE_FILE, DEFAULT_THRESHOLD, LightModel, adopt

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "choose",
        help="choose the LIGHT model or the source pixel count of a lens among fitted "
        "candidates by Bayesian evidence",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--results", type=Path, required=True, help="results folder of the lens")
    kind = parser.add_mutually_exclusive_group(required=True)
    kind.add_argument(
        "--candidates",
        nargs="+",
        metavar="MODEL",
        help="candidate LIGHT models, X<n> or X<n>+point (folders light_x<n>[_point])",
    )
    kind.add_argument(
        "--source-pixels",
        nargs="+",
        type=int,
        metavar="N",
        help="candidate k-means source pixel counts of SPix2 (folders spix2_n<N>)",
    )
    parser.add_argument(
        "--threshold",
        type=float,
        default=DEFAULT_THRESHOLD,
        help=f"ln Z a more complex model must gain (default {DEFAULT_THRESHOLD:g})",
    )
    parser.add_argument(
        "--record",
        type=Path,
        help=f"choice record (default <results>/{CHOICE_FILE}, with --source-pixels "
        f"<results>/{pixel_choice.CHOICE_FILE})",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        if args.source_pixels:
            chosen = pixel_choice.adopt(
                args.results, args.source_pixels, args.threshold, args.record
            )
            what, name, folder = "source pixels", str(chosen.n_pixels), "spix2"
        else:
            models = [LightModel.from_label(label) for label in args.candidates]
            chosen = adopt(args.results, models, args.threshold, args.record)
            what, name, folder = "LIGHT model", chosen.label, "light"
    except (ValueError, OSError) as error:
        logger.error("choose: %s", error)
        return 1
    logger.info(
        "%s: %s %s (ln Z = %.2f) among %s; copied to %s",
        args.results,
        what,
        name,
        chosen.log_evidence,
        ", ".join(str(c) for c in args.source_pixels or args.candidates),
        args.results / folder,
    )
    return 0

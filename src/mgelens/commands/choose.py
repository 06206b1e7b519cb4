"""``mgelens choose``: pick a lens's LIGHT model among fitted candidates by evidence.

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
"""

import argparse
import logging
from pathlib import Path

from mgelens.pipeline.model_choice import CHOICE_FILE, DEFAULT_THRESHOLD, LightModel, adopt

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "choose",
        help="choose the LIGHT model of a lens among fitted candidates by Bayesian evidence",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--results", type=Path, required=True, help="results folder of the lens")
    parser.add_argument(
        "--candidates",
        nargs="+",
        required=True,
        metavar="MODEL",
        help="candidate LIGHT models, X<n> or X<n>+point (folders light_x<n>[_point])",
    )
    parser.add_argument(
        "--threshold",
        type=float,
        default=DEFAULT_THRESHOLD,
        help=f"ln Z a more complex model must gain (default {DEFAULT_THRESHOLD:g})",
    )
    parser.add_argument(
        "--record", type=Path, help=f"choice record (default <results>/{CHOICE_FILE})"
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        models = [LightModel.from_label(label) for label in args.candidates]
        chosen = adopt(args.results, models, args.threshold, args.record)
    except (ValueError, OSError) as error:
        logger.error("choose: %s", error)
        return 1
    logger.info(
        "%s: LIGHT model %s (ln Z = %.2f) among %s; copied to %s",
        args.results,
        chosen.label,
        chosen.log_evidence,
        ", ".join(args.candidates),
        args.results / "light",
    )
    return 0

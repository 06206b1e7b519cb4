"""``mgelens posterior``: the corner figure of a phase's mass and shear posterior.

Example::

    mgelens posterior --phase results/M1/mass --truth results/M1/mock/truth.json \\
        --out results/M1/figures/posterior.png

    mgelens posterior --phase results/slacs1250+0523/mass --lens slacs1250+0523 \\
        --reference-dir ../shared/data/reference --out posterior.png

Reads the phase's ``result.json`` and ``samples.csv`` and draws every sampled mass and
shear parameter's marginal and joint posterior (:mod:`mgelens.plot.posterior`), with a
mock's true values from its ``truth.json`` if ``--truth`` is given, and a real lens's
published values (Shajib 2021's slope, Bolton 2008's b_SIE) from ``--reference-dir``
(:mod:`mgelens.published`; matched by the ``--lens`` id, none for an id the tables do
not hold). The PNG is written atomically.
"""

import argparse
import json
import logging
from pathlib import Path

from mgelens.commands import make_output_folders, read_phase
from mgelens.pipeline.records import PhaseInputError
from mgelens.plot import save_png
from mgelens.plot.posterior import posterior_figure, published_references
from mgelens.published import published_values
from mgelens.recovery import true_mass_parameters

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "posterior",
        help="corner figure of a phase's mass and shear posterior",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--phase", type=Path, required=True, help="phase folder, e.g. results/J0252/mass"
    )
    parser.add_argument("--truth", type=Path, help="a mock's truth.json, to mark the truth")
    parser.add_argument(
        "--reference-dir",
        type=Path,
        help="folder of the published tables (Bolton 2008, Shajib 2021), to mark their values",
    )
    parser.add_argument(
        "--lens", help="lens id for the title and the tables (default: the phase's parent)"
    )
    parser.add_argument("--out", type=Path, required=True, help="output PNG")
    parser.set_defaults(func=run)


def _true_values(path: Path | None) -> dict | None:
    """The true mass and shear of ``truth.json`` under the phases' names (None: no path)."""
    if path is None:
        return None
    try:
        return true_mass_parameters(json.loads(path.read_text()))
    except (OSError, json.JSONDecodeError, KeyError, TypeError, ValueError) as error:
        raise PhaseInputError(
            f"{path}: cannot read the true mass ({type(error).__name__}: {error}); --truth "
            "must be a mock's truth.json as `mgelens simulate` writes it"
        ) from error


def run(args: argparse.Namespace) -> int:
    lens = args.lens or args.phase.resolve().parent.name
    try:
        make_output_folders(args.out)
        phase = read_phase(args.phase)
        truth = _true_values(args.truth)
        published = None
        if args.reference_dir is not None:
            row = published_values([lens], args.reference_dir).iloc[0]
            published = published_references(row.to_dict())
        figure = posterior_figure(phase, truth, title=lens, published=published)
    except (PhaseInputError, OSError, ValueError) as error:
        logger.error("%s", error)
        return 1
    save_png(figure, args.out)
    logger.info("posterior of %s (%s) written to %s", lens, phase.phase, args.out)
    return 0

"""``mgelens summary``: sample table and histograms from per-lens isophote summaries.

Example::

    mgelens summary results/*/isophotes.json \\
        --out-table results/summary/lenses.csv --out-figure results/summary/histograms.png

Prints the fraction of lenses with Δq_max > 0.1 or ΔPA_max > 10° (thresholds adjustable).
"""

import argparse
import logging
from pathlib import Path

from mgelens.atomic import atomic_path
from mgelens.plot import save_png
from mgelens.plot.summary import histogram_figure
from mgelens.summary import (
    DELTA_PA_THRESHOLD,
    DELTA_Q_THRESHOLD,
    complex_fraction,
    sample_table,
)

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "summary",
        help="sample table and histograms of per-lens isophote statistics",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "summaries", type=Path, nargs="+", metavar="SUMMARY.json", help="per-lens summaries"
    )
    parser.add_argument("--out-table", type=Path, required=True, help="sample table (CSV)")
    parser.add_argument("--out-figure", type=Path, required=True, help="histograms (PNG)")
    parser.add_argument(
        "--delta-q", type=float, default=DELTA_Q_THRESHOLD, help="complexity threshold on Δq"
    )
    parser.add_argument(
        "--delta-pa",
        type=float,
        default=DELTA_PA_THRESHOLD,
        help="complexity threshold on ΔPA (degrees)",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        table = sample_table(args.summaries, args.delta_q, args.delta_pa)
    except ValueError as exc:
        logger.error("%s", exc)
        return 1
    with atomic_path(args.out_table) as temporary:
        table.to_csv(temporary, index=False)
    save_png(histogram_figure(table, args.delta_q, args.delta_pa), args.out_figure)
    measured = int((table["n_isophotes"] > 0).sum())
    fraction = complex_fraction(table, args.delta_q, args.delta_pa)
    print(f"lenses: {len(table)} ({measured} with isophotes)")
    print(
        f"complex_fraction: {fraction:.3f} (delta_q > {args.delta_q:g} or "
        f"delta_pa > {args.delta_pa:g} deg)"
    )
    return 0

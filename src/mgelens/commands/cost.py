"""``mgelens cost``: what each lens's SLaM chain cost (:mod:`mgelens.chain_cost`).

Example::

    mgelens cost results/M1/benchmarks/{sp,spix1,spix2,light,mass}.tsv \\
        --out results/summary/chain_cost.csv --figure results/summary/chain_cost.png

Reads the Snakemake benchmark files of the chain's phase jobs
(``results/<lens>/benchmarks/<job>.tsv``; rule ``chain_cost`` passes every lens's SP,
SPix1, SPix2, LIGHT job or candidates and MASS) and each job's ``results/<lens>/<job>/``
record for its likelihood calls and the CPU seconds the job recorded (``cost.json``),
and writes

* ``--out``: one row per lens, CPU seconds and likelihood calls per phase, the chain's
  CPU and wall-clock minutes, peak memory, whether every phase was measured, and whether
  every CPU time is a job's own record (``cpu_exact``; else some are Snakemake's sampled
  lower bound);
* ``--figure``: CPU minutes per lens split by phase, with the sample's median, largest and
  total in the title and the whole sample's time on ``--cores`` cores at the median.

The same figures are printed. Exit code 1 with a message naming the file for a benchmark
file or record that cannot be read.
"""

import argparse
import logging
from pathlib import Path

from mgelens.atomic import atomic_path
from mgelens.chain_cost import cost_table, sample_cost
from mgelens.commands import make_output_folders
from mgelens.plot import save_png
from mgelens.plot.chain_cost import cost_figure

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "cost",
        help="CPU time and likelihood calls of each lens's SLaM chain",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("benchmarks", type=Path, nargs="+", metavar="BENCHMARK.tsv")
    parser.add_argument("--out", type=Path, required=True, help="per-lens table (CSV)")
    parser.add_argument("--figure", type=Path, required=True, help="cost figure (PNG)")
    parser.add_argument(
        "--cores",
        type=int,
        default=2,
        help="cores of the projected whole-sample time (default 2)",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        make_output_folders(args.out, args.figure)
        table = cost_table(args.benchmarks)
        sample = sample_cost(table, args.cores)
        with atomic_path(args.out) as temporary:
            table.to_csv(temporary, index=False)
        save_png(cost_figure(table, sample), args.figure)
    except (OSError, ValueError) as error:
        logger.error("cost: %s", error)
        return 1
    print(table.to_string(index=False, float_format=lambda v: f"{v:.1f}"))
    for name, value in sample.items():
        print(f"{name}: {value:.2f}" if isinstance(value, float) else f"{name}: {value}")
    return 0

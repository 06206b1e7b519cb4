"""``mgelens coverage``: posterior coverage over truth-known mocks (:mod:`mgelens.coverage`).

Example::

    mgelens coverage results/P*/recovery.json results/L*/recovery.json \\
        --out results/summary/coverage.csv --rows results/summary/coverage_lenses.csv \\
        --targets results/summary/coverage_targets.csv --figure results/summary/coverage.png \\
        --quality results/P*/quality.json results/L*/quality.json

Reads one recovery record per mock (``mgelens recovery``) and, optionally, the mocks'
quality records (``mgelens quality``, matched by their ``lens``), and writes

* ``--out``: per mass parameter, the fractions of truths inside the 1σ and 3σ intervals,
  the bias and scatter of median − truth and the median |pull|;
* ``--rows``: one row per mock and parameter, with the wall-clock and CPU seconds of the
  mock's SLaM chain (``chain_seconds``, ``chain_cpu_seconds``:
  :func:`mgelens.chain_cost.chain_seconds` of the record's folder) and, with
  ``--quality``, the checks that flag its fit (``flags``,
  :func:`mgelens.quality.flagged_checks`; empty for a mock without a quality record);
* ``--targets``: each target's fraction, goal and whether it is met, over every fit
  (``fits`` ``all``) and, with ``--quality``, over the fits no check flags (``unflagged``);
* ``--figure``: the pulls per parameter, misses named, flagged fits drawn open, targets
  listed.

The exit code is 0 whether or not the targets are met (they are in ``--targets``).
"""

import argparse
import json
import logging
from pathlib import Path

import numpy as np

from mgelens.atomic import atomic_path
from mgelens.chain_cost import chain_seconds
from mgelens.commands import make_output_folders
from mgelens.coverage import coverage_rows, coverage_table, targets_by_fits
from mgelens.plot import save_png
from mgelens.plot.coverage import coverage_figure
from mgelens.quality import flagged_checks

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "coverage",
        help="coverage of the mass posteriors over truth-known mocks",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("records", type=Path, nargs="+", metavar="RECOVERY.json")
    parser.add_argument("--out", type=Path, required=True, help="per-parameter table (CSV)")
    parser.add_argument("--rows", type=Path, required=True, help="per-mock rows (CSV)")
    parser.add_argument("--targets", type=Path, required=True, help="targets (CSV)")
    parser.add_argument("--figure", type=Path, required=True, help="pull figure (PNG)")
    parser.add_argument(
        "--quality",
        type=Path,
        nargs="+",
        default=[],
        metavar="QUALITY.json",
        help="the mocks' quality records (mgelens quality), for the flags column and the "
        "targets over unflagged fits",
    )
    parser.set_defaults(func=run)


def _write_csv(table, path: Path) -> None:
    with atomic_path(path) as temporary:
        table.to_csv(temporary, index=False)


def _flags(paths: list[Path], lenses: set[str]) -> dict[str, str]:
    """Lens → :func:`~mgelens.quality.flagged_checks` of its quality record. A record of a
    lens without a recovery record is left out with a warning (a glob over a sample's
    folders also finds its real lenses); an unreadable record, or a second one of a lens,
    is an error naming the file."""
    flags = {}
    for path in paths:
        try:
            record = json.loads(path.read_text())
            lens, checks = record["lens"], flagged_checks(record)
        except (OSError, json.JSONDecodeError) as exc:
            raise ValueError(f"{path}: {exc}") from exc
        except (KeyError, TypeError) as exc:
            raise ValueError(
                f"{path}: not a quality record of mgelens quality ({exc!r}); "
                "write it again with mgelens quality"
            ) from exc
        if lens not in lenses:
            logger.warning("%s: lens %r has no recovery record among the inputs", path, lens)
            continue
        if lens in flags:
            raise ValueError(f"{path}: a second quality record of lens {lens!r}")
        flags[lens] = checks
    return flags


def run(args: argparse.Namespace) -> int:
    try:
        make_output_folders(args.out, args.rows, args.targets, args.figure)
        records = [json.loads(path.read_text()) for path in args.records]
        rows = coverage_rows(records)
        folders = {
            record["lens"]: path.parent for record, path in zip(records, args.records, strict=True)
        }
        seconds = {lens: chain_seconds(folder) for lens, folder in folders.items()}
        cpu = {lens: chain_seconds(folder, cpu=True) for lens, folder in folders.items()}
    except (OSError, ValueError, KeyError) as exc:
        logger.error("cannot read the recovery records: %s", exc)
        return 1
    try:
        flags = _flags(args.quality, {record["lens"] for record in records})
    except ValueError as exc:  # _flags names the file of any unreadable record
        logger.error("cannot read the quality records: %s", exc)
        return 1
    rows["chain_seconds"] = rows["lens"].map(seconds)
    rows["chain_cpu_seconds"] = rows["lens"].map(cpu)
    if args.quality:
        rows["flags"] = rows["lens"].map(flags)
    table, targets = coverage_table(rows), targets_by_fits(rows)
    _write_csv(table, args.out)
    _write_csv(rows, args.rows)
    _write_csv(targets, args.targets)
    save_png(coverage_figure(rows, targets), args.figure)
    print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    print(targets.to_string(index=False))
    for name, per_lens in (("wall-clock", seconds), ("CPU", cpu)):
        times = np.array(list(per_lens.values()), dtype=float)
        if np.isfinite(times).any():
            print(
                f"chain {name} per mock: median {np.nanmedian(times) / 60:.1f} min, "
                f"range {np.nanmin(times) / 60:.1f}–{np.nanmax(times) / 60:.1f} min"
            )
    return 0

"""What a `snakemake` start costs before it runs a job: the rules' command versions
(`mgelens.provenance.command_version`, a digest of the files each command imports) and a
whole dry run of the default sample.

    python benchmarks/bench_workflow_start.py [--repeats 3]

Prints `command_digests_s` (every workflow command's digest in one process, the parse
cache cleared first, as at a snakemake start), `command_digests_uncached_s` (the same with
each file's imports parsed once per command, as before the cache) and `dry_run_s`
(`snakemake -n` of the default target, median wall time)."""

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

from common import median_time, report

from mgelens import provenance

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = sorted(
    p.stem for p in (provenance.PACKAGE_ROOT / "commands").glob("*.py") if p.stem != "__init__"
)


def digests() -> None:
    provenance._import_targets.cache_clear()
    for command in COMMANDS:
        provenance.command_digest(command)


def digests_uncached() -> None:
    for command in COMMANDS:
        provenance._import_targets.cache_clear()
        provenance.command_digest(command)


def dry_run() -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    subprocess.run(
        [sys.executable, "-m", "snakemake", "-n", "-q"], cwd=ROOT, env=env, check=True,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"{len(COMMANDS)} commands; {time.strftime('%Y-%m-%d %H:%M')}")
    report("command_digests_s", median_time(digests, args.repeats, warmup=0))
    report("command_digests_uncached_s", median_time(digests_uncached, args.repeats, warmup=0))
    report("dry_run_s", median_time(dry_run, args.repeats, warmup=1))


if __name__ == "__main__":
    main()

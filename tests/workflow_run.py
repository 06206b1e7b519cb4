"""How the tests run the workflow: snakemake as a subprocess on the repository's
Snakefile, from the repository root, with a working directory of the test's own."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
"""The repository root (holds the top-level Snakefile)."""

CHAIN_TIMEOUT = 3600
"""Seconds one mock's whole SLaM chain may take (each of M1-M3 takes 15-25 min on one
core, with the host)."""


def snakemake_command(*args: str, workdir: Path) -> list[str]:
    """Command line of snakemake on the repository's Snakefile in working directory
    ``workdir`` (run it from :data:`ROOT` with :func:`snakemake_environment`)."""
    return [
        sys.executable, "-m", "snakemake", "--snakefile", str(ROOT / "Snakefile"),
        "--directory", str(workdir), *args,
    ]  # fmt: skip


def snakemake_environment() -> dict[str, str]:
    """Environment in which the workflow's shell commands find this interpreter's
    ``mgelens`` and draw figures without a display."""
    environment = dict(os.environ, MPLBACKEND="Agg")
    environment["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{environment['PATH']}"
    return environment


def snakemake(*args: str, workdir: Path, timeout: float = 600) -> subprocess.CompletedProcess:
    """Run snakemake on the repository's Snakefile with working directory ``workdir``."""
    return subprocess.run(
        snakemake_command(*args, workdir=workdir), cwd=ROOT, capture_output=True, text=True,
        env=snakemake_environment(), timeout=timeout,
    )  # fmt: skip

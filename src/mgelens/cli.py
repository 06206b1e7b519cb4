"""Command-line interface: ``mgelens <command> ...`` (file in -> file out)."""

import argparse

from mgelens import __version__


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="mgelens", description=__doc__)
    parser.add_argument("--version", action="version", version=f"mgelens {__version__}")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``mgelens`` console script; returns the exit code."""
    build_parser().parse_args(argv)
    return 0

"""Command-line interface: ``mgelens <command> ...`` (file in -> file out).

Every module in :mod:`mgelens.commands` is one subcommand: it defines ``register(subparsers)``,
which adds its parser and sets ``func`` to a callable taking the parsed arguments and
returning an exit code. Workflow rules call these commands, so any step can be rerun by
hand without Snakemake.
"""

import argparse
import importlib
import logging
import pkgutil
import sys

from mgelens import __version__, commands


def command_names() -> list[str]:
    """Names of the available subcommands (modules of :mod:`mgelens.commands`)."""
    return sorted(m.name for m in pkgutil.iter_modules(commands.__path__))


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The argument parser; with ``only``, just that subcommand is imported (fast start)."""
    parser = argparse.ArgumentParser(
        prog="mgelens",
        description="Strong-lens modelling with an MGE lens light (He et al. 2024).",
    )
    parser.add_argument("--version", action="version", version=f"mgelens {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in [only] if only else command_names():
        importlib.import_module(f"mgelens.commands.{name}").register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``mgelens`` console script; returns the exit code."""
    argv = sys.argv[1:] if argv is None else argv
    chosen = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(chosen if chosen in command_names() else None)
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    if args.command is None:
        parser.print_help()
        return 2
    return int(args.func(args) or 0)

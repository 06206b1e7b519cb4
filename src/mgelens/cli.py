"""Command-line interface: ``mgelens <command> ...`` (file in -> file out).

Every module in :mod:`mgelens.commands` is one subcommand: it defines ``register(subparsers)``,
which adds its parser and sets ``func`` to a callable taking the parsed arguments and
returning an exit code. Workflow rules call these commands, so any step can be rerun by
hand without Snakemake.
"""

import argparse
import ast
import importlib
import logging
import pkgutil
import sys
from pathlib import Path

from mgelens import __version__, commands


def command_names() -> list[str]:
    """Names of the available subcommands (modules of :mod:`mgelens.commands`)."""
    return sorted(m.name for m in pkgutil.iter_modules(commands.__path__))


def command_help(name: str) -> str | None:
    """The one-line ``help=`` that subcommand ``name``'s ``register`` gives its parser,
    read from the module's source without importing it (the commands import numba,
    scipy and matplotlib); None if it is not a literal string there."""
    source = Path(commands.__path__[0], f"{name}.py").read_text(encoding="utf-8")
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "add_parser":
            for keyword in node.keywords:
                if keyword.arg == "help" and isinstance(keyword.value, ast.Constant):
                    return keyword.value.value
    return None


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The argument parser. With ``only``, just that subcommand is imported and
    registered; without, every subcommand is listed with its help (:func:`command_help`)
    and none is imported, so that ``mgelens --help`` starts at once."""
    parser = argparse.ArgumentParser(
        prog="mgelens",
        description="Strong-lens modelling with an MGE lens light (He et al. 2024).",
    )
    parser.add_argument("--version", action="version", version=f"mgelens {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    if only:
        importlib.import_module(f"mgelens.commands.{only}").register(subparsers)
    else:
        for name in command_names():
            subparsers.add_parser(name, help=command_help(name))
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

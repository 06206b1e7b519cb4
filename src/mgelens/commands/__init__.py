"""Subcommands of the ``mgelens`` CLI: one module each, exposing ``register(subparsers)``."""

import argparse


def add_threads_argument(parser: argparse.ArgumentParser) -> None:
    """``--threads T`` (default 1), for :func:`mgelens.threads.limit_threads`."""
    parser.add_argument(
        "--threads", type=int, default=1, metavar="T", help="numba threads (default 1)"
    )

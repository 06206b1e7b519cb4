"""Subcommands of the ``mgelens`` CLI: one module each, exposing ``register(subparsers)``."""

import argparse

from mgelens.threads import limit_threads


def add_threads_argument(parser: argparse.ArgumentParser) -> None:
    """``--threads T`` (default 1); the command calls :func:`use_threads` with it."""
    parser.add_argument(
        "--threads", type=int, default=1, metavar="T", help="numba threads (default 1)"
    )


def use_threads(args: argparse.Namespace) -> None:
    """Numba (and FFT) threads from ``--threads``, BLAS on one (:func:`limit_threads`)."""
    limit_threads(args.threads)

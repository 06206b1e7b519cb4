"""Subcommands of the ``mgelens`` CLI: one module each, exposing ``register(subparsers)``."""

import argparse
from pathlib import Path


def add_threads_argument(parser: argparse.ArgumentParser) -> None:
    """``--threads T`` (default 1), for :func:`mgelens.threads.limit_threads`."""
    parser.add_argument(
        "--threads", type=int, default=1, metavar="T", help="numba threads (default 1)"
    )


def make_output_folders(*paths: Path | None) -> None:
    """Create the folder of every output path given (``None`` skipped) before any work, so
    that an unwritable output stops a command at once.

    Raises
    ------
    OSError
        Naming the output and why its folder cannot be made (e.g. a path under a file).
    """
    for path in paths:
        if path is None:
            continue
        try:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise OSError(
                f"cannot write {path}: {error.filename}: {error.strerror or error}; choose an "
                "output path in a writable folder (not under a file)"
            ) from error


def read_phase(folder: Path):
    """The :class:`~mgelens.search.results.PhaseResult` in ``folder`` (``--phase``);
    errors name the file and the fix. (Imported here: the CLI imports this package to
    start any subcommand.)

    Raises
    ------
    mgelens.pipeline.records.PhaseInputError
        If ``result.json`` is missing or the result cannot be read.
    """
    from mgelens.pipeline.records import PhaseInputError
    from mgelens.search.results import RESULT_FILE, PhaseResult

    path = folder / RESULT_FILE
    if not path.is_file():
        raise PhaseInputError(
            f"{path} not found: --phase must be the folder of a finished phase "
            "(e.g. results/<lens>/mass)"
        )
    try:
        return PhaseResult.read(folder)
    except (OSError, KeyError, ValueError) as error:
        raise PhaseInputError(
            f"{folder}: cannot read the phase result ({type(error).__name__}: {error}); "
            "rerun the phase"
        ) from error

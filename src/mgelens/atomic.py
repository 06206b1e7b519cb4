"""Atomic file output: write under a temporary name in the target folder, then rename.

An interrupted run therefore never leaves a half-written file where a finished one is
expected (Snakemake would otherwise take it as done).
"""

import contextlib
import json
import os
import uuid
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from astropy.io import fits


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = ".tmp") -> Iterator[Path]:
    """Yield a temporary path beside ``path`` (ending in ``suffix``, for writers that
    insist on one); move it onto ``path`` if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f".{path.name}.{uuid.uuid4().hex}{suffix}")
    try:
        yield temporary
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"cannot write {type(value).__name__} to JSON")


def write_json(path: str | os.PathLike, content: dict) -> None:
    """Write ``content`` as indented JSON (NumPy scalars and arrays converted)."""
    with atomic_path(path) as temporary:
        temporary.write_text(json.dumps(content, indent=2, default=_json_default) + "\n")


def write_fits(path: str | os.PathLike, hdus: fits.HDUList | fits.PrimaryHDU) -> None:
    """Write an HDU or HDU list to ``path`` atomically."""
    with atomic_path(path) as temporary, temporary.open("wb") as stream:
        hdus.writeto(stream)

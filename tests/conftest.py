"""Shared test fixtures."""

from pathlib import Path

import pytest

SLACS_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "slacs"
"""The real SLACS cutouts: ``<repo root>/../shared/data/slacs``."""


@pytest.fixture(scope="session")
def slacs_dir() -> Path:
    """Folder of the real SLACS lenses (one sub-folder per lens); skip if absent."""
    if not SLACS_DIR.is_dir():
        pytest.skip(
            f"shared SLACS data folder is absent: expected {SLACS_DIR} "
            "(the repository's sibling shared/data/slacs)"
        )
    return SLACS_DIR

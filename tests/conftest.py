"""Shared test fixtures and the ``--recovery`` option."""

from pathlib import Path

import pytest
from workflow_run import ROOT

SLACS_DIR = ROOT.parent / "shared" / "data" / "slacs"
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


def pytest_addoption(parser):
    parser.addoption(
        "--recovery",
        action="store_true",
        help="also run the full SLaM chains of M1-M3 and the paper-mock comparison "
        "(marker 'recovery', 20 min to hours each)",
    )


def pytest_collection_modifyitems(config, items):
    """Skip the ``recovery`` tests unless ``--recovery`` is given (they exceed the suite's
    15-minute budget; README "Run it")."""
    if config.getoption("--recovery"):
        return
    skip = pytest.mark.skip(reason="full-chain recovery: run with --recovery -m recovery")
    for item in items:
        if item.get_closest_marker("recovery"):
            item.add_marker(skip)

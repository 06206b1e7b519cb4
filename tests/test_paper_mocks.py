"""The paper's mock comparison behaves as the paper's (SPEC §11, issue #31).

The comparison's nine chains take about 2.5 hours on 2 cores, so the suite checks the
tables that `snakemake -j2 --configfile config/paper_mocks.yaml` wrote, saved in
``docs/paper_mocks/`` (``mock_table.csv``, ``smoothness.csv``); the ``recovery`` test
runs the whole DAG afresh (``python -m pytest --recovery -m recovery``) and checks the
same on its own results.
"""

from pathlib import Path

import pandas as pd
import pytest
from workflow_run import ROOT, snakemake

SAVED = ROOT / "docs" / "paper_mocks"


def check_mass_behaviour(table: pd.DataFrame) -> None:
    """nn-MGE and pn-MGE hold every EPL value of M1–M3 in 3σ; 3×Sérsic misses γ for at
    least two of the three mocks (SPEC §11)."""
    for model in ("nn_mge", "pn_mge"):
        rows = table[table["model"] == model]
        assert set(rows["mock"]) == {"M1", "M2", "M3"}
        assert len(rows) == 18
        missed = rows[~rows["within_3sigma"].astype(bool)]
        assert missed.empty, missed[["mock", "parameter", "truth", "median"]].to_string()
    slope = table[(table["model"] == "sersic") & (table["parameter"] == "slope")]
    assert set(slope["mock"]) == {"M1", "M2", "M3"}
    assert (~slope["within_3sigma"].astype(bool)).sum() >= 2, slope.to_string()


def check_smoothness(table: pd.DataFrame) -> None:
    """The natural-neighbour scheme's largest jump is well under the nearest scheme's,
    under either edge rule."""
    largest = table.groupby(["scheme", "edge_rule"])["jump"].max()
    for rule in ("anchor", "continuous"):
        assert largest[("natural_neighbour", rule)] < 0.3 * largest[("nearest", rule)]


def saved(name: str) -> pd.DataFrame:
    path = SAVED / name
    if not path.is_file():
        pytest.skip(f"{path} not saved: run snakemake -j2 --configfile config/paper_mocks.yaml")
    return pd.read_csv(path)


def test_the_saved_comparison_shows_the_papers_behaviour():
    check_mass_behaviour(saved("mock_table.csv"))


def test_the_saved_smoothness_scan_separates_the_schemes():
    check_smoothness(saved("smoothness.csv"))


@pytest.mark.recovery
def test_the_comparison_dag_reproduces_the_behaviour(tmp_path: Path):
    targets = ["results/summary/mock_table.csv", "results/summary/smoothness.csv"]
    result = snakemake(
        "-j2", "--configfile=config/paper_mocks.yaml", *targets, workdir=tmp_path, timeout=6 * 3600
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    check_mass_behaviour(pd.read_csv(tmp_path / targets[0]))
    check_smoothness(pd.read_csv(tmp_path / targets[1]))

"""Tests of mgelens.summary, mgelens.plot.summary and ``mgelens summary``."""

import json
import math

import numpy as np
import pandas as pd
import pytest

from mgelens.atomic import write_json
from mgelens.cli import main
from mgelens.isophotes import IsophoteStatistics, MassShape
from mgelens.plot import save_png
from mgelens.plot.summary import histogram_figure
from mgelens.summary import (
    TABLE_COLUMNS,
    complex_fraction,
    complex_lenses,
    lens_summary,
    sample_table,
)

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

LENSES = {
    # lens: (Δq_max, ΔPA_max, extreme a4/a, n_isophotes); complex iff Δq > 0.1 or ΔPA > 10°
    "J0003": (0.12, 3.0, -0.037, 30),  # complex by Δq
    "J0001": (0.05, 12.0, 0.026, 30),  # complex by ΔPA
    "J0002": (0.05, 3.0, 0.011, 30),  # simple
    "J0004": (0.1, 10.0, -0.004, 30),  # thresholds are strict: simple
    "J0005": (0.02, math.nan, 0.015, 30),  # all isophotes round: ΔPA undefined, simple
    "J0006": (math.nan, math.nan, math.nan, 0),  # no isophotes: excluded from the fraction
}


def statistics(delta_q, delta_pa, a4, n):
    return IsophoteStatistics(delta_q, delta_pa, a4, n, n if math.isfinite(delta_pa) else 0)


@pytest.fixture
def summaries(tmp_path):
    paths = []
    for lens, values in LENSES.items():
        mass = MassShape(0.8, 45.0, critical_curve_einstein_radius=1.2) if lens == "J0001" else None
        path = tmp_path / lens / "isophotes.json"
        write_json(path, lens_summary(lens, statistics(*values), mass, {"image": "x.fits"}))
        paths.append(path)
    return paths


def test_lens_summary_is_plain_json(summaries):
    content = json.loads(summaries[-1].read_text())
    assert content["lens"] == "J0006"
    assert content["statistics"]["delta_q_max"] is None
    assert content["statistics"]["n_isophotes"] == 0
    assert content["mass"] is None
    assert "conventions" in content


def test_sample_table_has_one_row_per_lens(summaries):
    table = sample_table(summaries)
    assert list(table.columns) == list(TABLE_COLUMNS)
    assert list(table["lens"]) == sorted(LENSES)
    row = table.set_index("lens").loc["J0003"]
    assert row["delta_q_max"] == pytest.approx(0.12)
    assert row["a4_a_extreme"] == pytest.approx(-0.037)
    assert row["abs_a4_a_max"] == pytest.approx(0.037)
    assert math.isnan(row["mass_axis_ratio"])
    with_mass = table.set_index("lens").loc["J0001"]
    assert with_mass["mass_axis_ratio"] == pytest.approx(0.8)
    assert with_mass["mass_critical_curve_einstein_radius"] == pytest.approx(1.2)
    expected = {"J0001": True, "J0002": False, "J0003": True, "J0004": False, "J0005": False,
                "J0006": False}  # fmt: skip
    assert dict(zip(table["lens"], table["complex"], strict=True)) == expected


def test_complex_fraction_counts_only_lenses_with_isophotes(summaries):
    table = sample_table(summaries)
    assert complex_fraction(table) == pytest.approx(2.0 / 5.0)
    assert complex_fraction(table, delta_q_threshold=0.06) == pytest.approx(3.0 / 5.0)
    assert complex_fraction(table, delta_pa_threshold=2.0) == pytest.approx(4.0 / 5.0)
    assert math.isnan(complex_fraction(table[table["n_isophotes"] == 0]))
    flags = complex_lenses(pd.DataFrame({"delta_q_max": [0.2, np.nan], "delta_pa_max": [0, 20]}))
    assert list(flags) == [True, True]


def test_sample_table_errors_name_the_file(tmp_path, summaries):
    with pytest.raises(ValueError, match="appears in several summaries"):
        sample_table([*summaries, summaries[0]])
    bad = tmp_path / "bad.json"
    bad.write_text('{"lens": "J9"}')
    with pytest.raises(ValueError, match=r"bad\.json: not a lens summary"):
        sample_table([bad])
    with pytest.raises(ValueError, match="not found"):
        sample_table([tmp_path / "missing.json"])


def test_histogram_figure_is_written_atomically(tmp_path, summaries):
    table = sample_table(summaries)
    figure = histogram_figure(table)
    assert len(figure.axes) == 3
    assert "2/5" in figure.get_suptitle()
    assert "paper ≈ 40 % of 35" in figure.get_suptitle()
    # |a₄/a| 0.037, 0.026, 0.011, 0.004, 0.015 (and one lens without isophotes)
    assert figure.axes[2].get_title() == "max |a₄/a| < 0.02: 3/5 (paper 32/35)"
    path = tmp_path / "plots" / "histograms.png"
    save_png(figure, path)
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    assert path.stat().st_size > 10_000
    assert sorted(p.name for p in path.parent.iterdir()) == ["histograms.png"]
    empty = histogram_figure(table[table["n_isophotes"] == 0])
    assert empty.get_suptitle() == "no lens with isophotes"


def test_summary_command(tmp_path, summaries, capsys):
    table_path, figure_path = tmp_path / "out" / "lenses.csv", tmp_path / "out" / "hist.png"
    arguments = ["summary", *map(str, summaries), "--out-table", str(table_path)]
    assert main([*arguments, "--out-figure", str(figure_path)]) == 0
    table = pd.read_csv(table_path)
    assert list(table["lens"]) == sorted(LENSES)
    assert figure_path.read_bytes()[:8] == PNG_SIGNATURE
    printed = capsys.readouterr().out
    assert "complex_fraction: 0.400" in printed
    assert "lenses: 6 (5 with isophotes)" in printed
    assert main([*arguments, "--out-figure", str(figure_path), "--delta-q", "0.06"]) == 0
    assert "complex_fraction: 0.600" in capsys.readouterr().out
    missing = ["summary", str(tmp_path / "nope.json"), "--out-table", str(table_path)]
    assert main([*missing, "--out-figure", str(figure_path)]) == 1

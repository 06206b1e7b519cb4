"""Posterior coverage over truth-known mocks (mgelens.coverage): fractions, pulls and
targets on records with known answers, and the command's files."""

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from mgelens.cli import main
from mgelens.coverage import (
    FITS_ALL,
    FITS_UNFLAGGED,
    TARGETS,
    coverage_rows,
    coverage_table,
    interval_pulls,
    target_table,
    targets_by_fits,
)
from mgelens.plot.coverage import (
    PULL_LIMIT,
    coverage_figure,
    flagged_rows,
    pull_axis_limit,
    target_line,
    target_text,
)
from mgelens.quality import NO_FLAG


def entry(name, truth, median, one, three):
    """A recovery record's mass row with symmetric 1σ and 3σ half-widths."""
    return {
        "name": name,
        "truth": truth,
        "median": median,
        "error": median - truth,
        "lower_1sigma": median - one,
        "upper_1sigma": median + one,
        "within_1sigma": abs(median - truth) <= one,
        "lower_3sigma": median - three,
        "upper_3sigma": median + three,
        "within_3sigma": abs(median - truth) <= three,
    }


def records(slope_errors, theta_errors=None) -> list[dict]:
    """Mocks with γ = 2.0 + error (σ 0.02) and θ_E = 1.2 (1 + relative error) (σ 0.005)."""
    theta_errors = [0.0] * len(slope_errors) if theta_errors is None else theta_errors
    return [
        {
            "lens": f"P{k:02d}",
            "mass": [
                entry("mass.slope", 2.0, 2.0 + e, 0.02, 0.06),
                entry("mass.einstein_radius", 1.2, 1.2 * (1.0 + t), 0.005, 0.015),
                entry("shear.gamma_1", 0.03, 0.03, 0.01, 0.03),
                entry("shear.gamma_2", -0.01, -0.01, 0.01, 0.03),
            ],
        }
        for k, (e, t) in enumerate(zip(slope_errors, theta_errors, strict=True))
    ]


def test_fractions_bias_scatter_and_pulls_of_known_errors():
    errors = [0.01, -0.03, 0.05, 0.3]  # pulls 0.5, -1.5, 2.5, 15
    rows = coverage_rows(records(errors))
    slope = rows[rows["parameter"] == "mass.slope"]
    assert slope["pull"].to_numpy() == pytest.approx([0.5, -1.5, 2.5, 15.0])
    table = coverage_table(rows).set_index("parameter")
    assert table.loc["mass.slope", "n"] == 4
    assert table.loc["mass.slope", "within_1sigma"] == pytest.approx(0.25)
    assert table.loc["mass.slope", "within_3sigma"] == pytest.approx(0.75)
    assert table.loc["mass.slope", "bias"] == pytest.approx(np.mean(errors))
    assert table.loc["mass.slope", "scatter"] == pytest.approx(np.std(errors, ddof=1))
    assert table.loc["mass.slope", "median_abs_pull"] == pytest.approx(2.0)
    assert list(table.index) == [
        "mass.einstein_radius",
        "mass.slope",
        "shear.gamma_1",
        "shear.gamma_2",
    ]


def test_pull_uses_the_half_width_on_the_side_of_the_truth():
    record = {
        "lens": "A",
        "mass": [
            {
                "name": "mass.slope",
                "truth": 2.0,
                "median": 2.1,
                "error": 0.1,
                "lower_1sigma": 2.05,
                "upper_1sigma": 2.3,
                "within_1sigma": False,
                "lower_3sigma": 1.9,
                "upper_3sigma": 2.5,
                "within_3sigma": True,
            }
        ],
    }
    assert coverage_rows([record])["pull"].iloc[0] == pytest.approx(2.0)  # 0.1 / (2.1 - 2.05)
    below = json.loads(json.dumps(record))
    below["mass"][0].update(truth=2.2, error=-0.1)
    assert coverage_rows([below])["pull"].iloc[0] == pytest.approx(-0.5)  # -0.1 / 0.2


def test_targets_pass_and_fail_at_their_thresholds():
    good = records([0.0] * 19 + [0.04], [0.0] * 19 + [0.005])
    met = target_table(coverage_rows(good)).set_index("target")
    assert met["met"].all()
    assert len(met) == len(TARGETS)
    bad = records([0.0] * 17 + [0.1, 0.2, 0.3], [0.0] * 18 + [0.02, 0.03])
    missed = target_table(coverage_rows(bad)).set_index("target")
    assert not missed.loc["γ inside 3σ", "met"]  # 17/20 = 85 %
    assert missed.loc["γ inside 3σ", "fraction"] == pytest.approx(0.85)
    assert missed.loc["γ inside 3σ", "passed"] == 17
    assert missed.loc["γ₁ inside 3σ", "passed"] == 20
    assert not missed.loc["|median γ − truth| < 0.05", "met"]  # 85 % < 90 %
    assert not missed.loc["θ_E within 1 %", "met"]  # 90 % < 95 %
    assert missed.loc["γ₁ inside 3σ", "met"]
    empty = target_table(coverage_rows([]))
    assert not empty["met"].any()
    assert (empty["passed"] == 0).all()


def test_targets_over_unflagged_fits_leave_out_flagged_and_unknown_mocks():
    """Five mocks: γ missed by P01 (flagged), P02 (no quality record) and P03 (unflagged).
    Over all five, 2 of 5 inside 3σ; over the two unflagged mocks, P00 and P03, 1 of 2."""
    rows = coverage_rows(records([0.0, 0.3, 0.3, 0.3, 0.0]))
    flags = {"P00": NO_FLAG, "P01": "lensing", "P03": NO_FLAG, "P04": "singly imaged"}
    rows["flags"] = rows["lens"].map(flags)
    table = targets_by_fits(rows).set_index(["fits", "target"])
    assert table.loc[(FITS_ALL, "γ inside 3σ"), ["passed", "n"]].tolist() == [2, 5]
    assert table.loc[(FITS_UNFLAGGED, "γ inside 3σ"), ["passed", "n"]].tolist() == [1, 2]
    assert len(table) == 2 * len(TARGETS)
    np.testing.assert_array_equal(
        flagged_rows(rows[rows["parameter"] == "mass.slope"]), [0, 1, 0, 0, 1]
    )
    text = target_text(targets_by_fits(rows))
    assert "Fits that no quality check flags (2 mocks):" in text
    assert text.count("γ inside 3σ") == 2
    # without any quality record there is no unflagged block
    assert set(targets_by_fits(rows.drop(columns="flags"))["fits"]) == {FITS_ALL}
    assert set(targets_by_fits(rows.assign(flags=pd.NA))["fits"]) == {FITS_ALL}


def test_records_without_one_sigma_intervals_leave_them_unknown():
    old = records([0.01])
    for row in old[0]["mass"]:
        for key in ("lower_1sigma", "upper_1sigma", "within_1sigma"):
            del row[key]
    table = coverage_table(coverage_rows(old)).set_index("parameter")
    assert np.isnan(table.loc["mass.slope", "within_1sigma"])
    assert table.loc["mass.slope", "within_3sigma"] == 1.0


def test_command_writes_the_tables_and_the_figure(tmp_path):
    paths = []
    for record in records([0.01, -0.03, 0.3]):
        folder = tmp_path / record["lens"]
        (folder / "benchmarks").mkdir(parents=True)
        (folder / "benchmarks" / "sp.tsv").write_text("s\tmax_rss\tcpu_time\n600\t300\t590\n")
        (folder / "recovery.json").write_text(json.dumps(record))
        paths.append(str(folder / "recovery.json"))
    out = tmp_path / "summary"
    code = main(
        [
            "coverage",
            *paths,
            "--out",
            str(out / "coverage.csv"),
            "--rows",
            str(out / "rows.csv"),
            "--targets",
            str(out / "targets.csv"),
            "--figure",
            str(out / "coverage.png"),
        ]
    )
    assert code == 0
    table = pd.read_csv(out / "coverage.csv")
    assert table.set_index("parameter").loc["mass.slope", "within_3sigma"] == pytest.approx(2 / 3)
    rows = pd.read_csv(out / "rows.csv")
    assert (rows["chain_seconds"] == 600.0).all()
    assert (rows["chain_cpu_seconds"] == 590.0).all()
    assert (
        not pd.read_csv(out / "targets.csv").set_index("parameter").loc["mass.slope", "met"].all()
    )
    assert (out / "coverage.png").stat().st_size > 20_000
    figure = coverage_figure(rows, target_table(rows))
    assert "median chain 10 CPU min" in figure.texts[0].get_text()  # 590 s
    wall = coverage_figure(rows.drop(columns="chain_cpu_seconds"), target_table(rows))
    assert "median chain 10 min" in wall.texts[0].get_text()  # 600 s on older rows


def test_command_reads_the_quality_records_into_flags_and_targets(tmp_path, caplog):
    """P01, whose γ misses, is flagged by the lensing check and P02 has no quality record:
    the unflagged fits, P00 and P03, hold every γ. A record of a lens without a recovery
    record is left out with a warning; a second record of one lens and a broken file are
    refused with the file named."""
    paths, quality = [], []
    for record in records([0.01, 0.3, 0.2, -0.02]):
        folder = tmp_path / record["lens"]
        folder.mkdir()
        (folder / "recovery.json").write_text(json.dumps(record))
        paths.append(str(folder / "recovery.json"))
        check = {
            "lens": record["lens"],
            "measured": True,
            "flag": False,
            "lensing": {"flag": record["lens"] == "P01"},
            "multiplicity": {"flag": False},
        }
        if record["lens"] != "P02":
            (folder / "quality.json").write_text(json.dumps(check))
            quality.append(str(folder / "quality.json"))
    stray = tmp_path / "stray.json"
    stray.write_text(json.dumps(json.loads(Path(quality[0]).read_text()) | {"lens": "X9"}))
    out = tmp_path / "summary"
    outputs = ["--out", str(out / "coverage.csv"), "--rows", str(out / "rows.csv")]
    outputs += ["--targets", str(out / "targets.csv"), "--figure", str(out / "coverage.png")]
    assert main(["coverage", *paths, *outputs, "--quality", *quality, str(stray)]) == 0
    assert "lens 'X9' has no recovery record" in caplog.text
    for read in ({}, {"keep_default_na": False}):  # a missing record: NaN, or "" as text
        rows = pd.read_csv(out / "rows.csv", **read)
        flags = rows.drop_duplicates("lens")["flags"].tolist()
        assert flags[:2] + flags[3:] == [NO_FLAG, "lensing", NO_FLAG]
        assert pd.isna(flags[2]) or flags[2] == ""
        by_fits = targets_by_fits(rows).set_index(["fits", "target"])
        assert by_fits.loc[(FITS_UNFLAGGED, "γ inside 3σ"), ["passed", "n"]].tolist() == [2, 2]
        slope = rows[rows["parameter"] == "mass.slope"]
        np.testing.assert_array_equal(flagged_rows(slope), [0, 1, 0, 0])
    targets = pd.read_csv(out / "targets.csv").set_index(["fits", "target"])
    assert targets.loc[(FITS_ALL, "γ inside 3σ"), ["passed", "n"]].tolist() == [2, 4]
    assert targets.loc[(FITS_UNFLAGGED, "γ inside 3σ"), ["passed", "n"]].tolist() == [2, 2]
    assert targets.loc[(FITS_UNFLAGGED, "γ inside 3σ"), "met"]
    assert main(["coverage", *paths, *outputs, "--quality", quality[0], quality[0]]) == 1
    assert f"{quality[0]}: a second quality record of lens 'P00'" in caplog.text
    broken = tmp_path / "broken.json"
    broken.write_text('{"lens": "P00", ')
    assert main(["coverage", *paths, *outputs, "--quality", str(broken)]) == 1
    assert f"{broken}: Expecting" in caplog.text
    broken.write_text(json.dumps({"lens": "P00"}))
    assert main(["coverage", *paths, *outputs, "--quality", str(broken)]) == 1
    assert f"{broken}: not a quality record" in caplog.text


def test_the_figure_states_each_target_as_a_count_and_fits_its_pulls():
    """18 of 19 inside 3σ is 94.7 %: the figure says so and marks the 95 % goal missed,
    where a rounded "95 %" would read as met; the pull axis shrinks to the data but
    keeps the ±3 lines."""
    row = SimpleNamespace(
        target="γ inside 3σ", n=19, passed=18, fraction=18 / 19, goal=0.95, met=False
    )
    assert target_line(row) == "✗ γ inside 3σ: 18 of 19 (94.7%; goal ≥ 95%)"
    empty = SimpleNamespace(
        target="γ inside 3σ", n=0, passed=0, fraction=np.nan, goal=0.95, met=False
    )
    assert target_line(empty) == "✗ γ inside 3σ: 0 of 0 (no mocks; goal ≥ 95%)"
    assert pull_axis_limit(np.array([0.5, -1.2])) == 4.0
    assert pull_axis_limit(np.array([0.5, -4.4, np.nan])) == pytest.approx(5.2)
    assert pull_axis_limit(np.array([40.0])) == pytest.approx(PULL_LIMIT + 0.8)


def test_interval_pulls_put_the_3sigma_limits_at_three_however_skewed():
    """Median 1.0; intervals toward the truth: 1σ 0.1 above / 0.02 below, 3σ 0.5 above /
    0.06 below. A truth 0.05 above sits halfway to the 1σ limit (0.5); 0.3 above, halfway
    between the 1σ and 3σ limits (2.0); 0.75 above, half a 3σ width beyond (4.5, plotted
    as −4.5: median below the truth); 0.04 below, halfway from 1σ to 3σ on the short side
    (+2.0). A Gaussian posterior (σ 0.1) gives the usual pull; a record without 1σ
    limits takes 3 |d| / s₃."""
    median, truth = 1.0, np.array([1.05, 1.3, 1.75, 0.96])
    rows = pd.DataFrame(
        {
            "median": median,
            "truth": truth,
            "error": median - truth,
            "lower_1sigma": 0.98,
            "upper_1sigma": 1.1,
            "lower_3sigma": 0.94,
            "upper_3sigma": 1.5,
        }
    )
    np.testing.assert_allclose(interval_pulls(rows), [-0.5, -2.0, -4.5, 2.0])
    outside = (truth < 0.94) | (truth > 1.5)
    np.testing.assert_array_equal(np.abs(interval_pulls(rows)) > 3, outside)
    gaussian = pd.DataFrame(
        {"median": [0.0], "truth": [-0.25], "error": [0.25], "lower_1sigma": [-0.1],
         "upper_1sigma": [0.1], "lower_3sigma": [-0.3], "upper_3sigma": [0.3]}
    )  # fmt: skip
    np.testing.assert_allclose(interval_pulls(gaussian), [2.5])
    older = gaussian.assign(lower_1sigma=np.nan, upper_1sigma=np.nan)
    np.testing.assert_allclose(interval_pulls(older), [2.5])

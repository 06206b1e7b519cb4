"""What a lens's chain cost (mgelens.chain_cost, ``mgelens cost``): the benchmark files of
the chain's jobs summed per phase, the sampler calls of the phase records (SP's start
included), jobs outside the chain left out, incomplete chains marked, and the sample's
median, largest and projected time."""

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from mgelens.chain_cost import JobCost, chain_seconds, cost_row, cost_table, job_costs, sample_cost
from mgelens.plot.chain_cost import cost_figure

HEADER = "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"


def _benchmark(folder, job, rows):
    """A Snakemake benchmark file: rows of (wall s, MB, CPU s)."""
    (folder / "benchmarks").mkdir(parents=True, exist_ok=True)
    lines = [f"{s}\t0:00:00\t{rss}\t0\t0\t0\t0\t0\t50\t{cpu}\n" for s, rss, cpu in rows]
    (folder / "benchmarks" / f"{job}.tsv").write_text(HEADER + "".join(lines))


def _record(folder, job, calls):
    (folder / job).mkdir(parents=True, exist_ok=True)
    (folder / job / "result.json").write_text(json.dumps({"sampler": {"n_calls": calls}}))


def _lens(tmp_path, name="L1", light=("light_x6_point", "light_x2"), mass=True):
    """A lens folder with every phase (LIGHT as ``light`` candidates), SP's start record
    and two jobs outside the chain."""
    folder = tmp_path / "results" / name
    jobs = {"sp": (100.0, 300.0, 95.0, 20_000), "spix1": (40.0, 200.0, 39.0, 6_000),
            "spix2": (50.0, 250.0, 48.0, 1_000), "mass": (200.0, 500.0, 190.0, 7_200)}  # fmt: skip
    if not mass:
        del jobs["mass"]
    for index, job in enumerate(light):
        jobs[job] = (60.0 + index, 400.0, 55.0 + index, 5_000 + index)
    for job, (wall, rss, cpu, calls) in jobs.items():
        _benchmark(folder, job, [(wall, rss, cpu)])
        _record(folder, job, calls)
    (folder / "sp" / "start.json").write_text(json.dumps({"start": {"n_calls": 9_440}}))
    _benchmark(folder, "choose_light", [(1.0, 100.0, 1.0)])
    _benchmark(folder, "simulate_mock", [(5.0, 100.0, 5.0)])
    return folder


def test_job_costs_sum_each_phase_and_leave_out_jobs_outside_the_chain(tmp_path):
    folder = _lens(tmp_path)
    costs = job_costs(folder)
    assert [cost.job for cost in costs] == [
        "sp", "spix1", "spix2", "light_x2", "light_x6_point", "mass",
    ]  # fmt: skip
    assert costs[0] == JobCost("sp", "sp", 100.0, 95.0, 300.0, 29_440.0)  # the start's calls
    row = cost_row("L1", costs)
    assert row["light_cpu_s"] == pytest.approx(55.0 + 56.0)  # both candidates
    assert row["light_calls"] == 5_000 + 5_001
    assert row["chain_cpu_min"] == pytest.approx((95 + 39 + 48 + 55 + 56 + 190) / 60)
    assert row["chain_wall_min"] == pytest.approx((100 + 40 + 50 + 60 + 61 + 200) / 60)
    assert row["max_rss_mb"] == 500.0
    assert row["complete"]
    assert chain_seconds(folder) == pytest.approx(100 + 40 + 50 + 60 + 61 + 200)


def test_repeats_add_up_and_a_missing_record_leaves_the_calls_unknown(tmp_path):
    folder = tmp_path / "L2"
    _benchmark(folder, "spix1", [(10.0, 200.0, 9.0), (12.0, 250.0, 11.0)])
    (cost,) = job_costs(folder)
    assert (cost.wall_s, cost.cpu_s, cost.max_rss_mb) == (22.0, 20.0, 250.0)
    assert np.isnan(cost.calls)
    assert np.isnan(chain_seconds(tmp_path / "nothing"))


def test_a_chain_without_mass_is_incomplete_and_the_sample_counts_the_complete_ones(tmp_path):
    folders = [_lens(tmp_path, "A"), _lens(tmp_path, "B", light=("light",)),
               _lens(tmp_path, "C", mass=False), tmp_path / "results" / "D"]  # fmt: skip
    table = cost_table(folders)
    assert list(table["lens"]) == ["A", "B", "C", "D"]
    assert list(table["complete"]) == [True, True, False, False]
    assert np.isnan(table.loc[2, "mass_cpu_s"])
    assert np.isnan(table.loc[3, "chain_cpu_min"])
    sample = sample_cost(table, cores=2)
    a, b = table["chain_cpu_min"].iloc[:2]
    assert sample["n_complete"] == 2
    assert sample["n_lenses"] == 4
    assert sample["median_cpu_min"] == pytest.approx((a + b) / 2)
    assert (sample["max_cpu_min"], sample["max_lens"]) == (pytest.approx(a), "A")
    assert sample["total_cpu_h"] == pytest.approx((a + b) / 60)
    assert sample["projected_wall_h"] == pytest.approx(4 * (a + b) / 2 / 60 / 2)
    with pytest.raises(ValueError, match="cores"):
        sample_cost(table, cores=0)
    assert sample_cost(table.iloc[2:], cores=2) == {"n_complete": 0, "n_lenses": 2}


def test_a_broken_benchmark_file_is_named(tmp_path):
    folder = tmp_path / "L3"
    (folder / "benchmarks").mkdir(parents=True)
    (folder / "benchmarks" / "sp.tsv").write_text("s\th:m:s\n12\t0:00:12\n")
    with pytest.raises(ValueError, match=r"sp\.tsv.*cpu_time"):
        job_costs(folder)


def test_the_figure_has_one_bar_per_lens_in_core_minutes(tmp_path):
    table = cost_table([_lens(tmp_path, "A"), _lens(tmp_path, "C", mass=False)])
    figure = cost_figure(table, sample_cost(table, cores=2))
    (ax,) = figure.axes
    assert ax.get_xlabel() == "CPU time of the SLaM chain (core-minutes)"
    assert [t.get_text() for t in ax.get_yticklabels()] == ["A", "C (incomplete)"]
    widths = [patch.get_width() for patch in ax.patches]
    assert sum(widths) == pytest.approx(table["chain_cpu_min"].sum())
    assert "1 complete chains of 2" in ax.get_title()


def test_the_command_writes_the_table_and_figure_and_names_a_bad_file(tmp_path):
    folder = _lens(tmp_path, "A")
    out, figure = tmp_path / "summary" / "cost.csv", tmp_path / "summary" / "cost.png"
    command = [sys.executable, "-m", "mgelens", "cost", str(folder / "mass" / "result.json"),
               "--out", str(out), "--figure", str(figure), "--cores", "4"]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    table = pd.read_csv(out)
    assert list(table["lens"]) == ["A"]
    assert table["sp_calls"].iloc[0] == 29_440
    assert figure.stat().st_size > 10_000
    assert "cores: 4" in done.stdout
    (folder / "benchmarks" / "mass.tsv").write_text("not a benchmark\n")
    failed = subprocess.run(command, capture_output=True, text=True, check=False)
    assert failed.returncode == 1
    assert "mass.tsv" in failed.stderr

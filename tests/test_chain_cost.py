"""What a lens's chain cost (mgelens.chain_cost, ``mgelens cost``): the benchmark files of
the chain's jobs summed per phase, the sampler calls of the phase records (SP's start
included where SP started from it), unmeasured (NA) jobs and missing phases making a
chain incomplete, the sample's median, largest and projected time, and bad files named."""

import hashlib
import json
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pytest

from mgelens.chain_cost import JobCost, chain_seconds, cost_table, job_cost, sample_cost
from mgelens.pipeline.job_cost import COST_FILE, process_cost
from mgelens.plot.chain_cost import cost_figure

HEADER = "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"
JOBS = {"sp": (100.0, 300.0, 95.0, 20_000), "spix1": (40.0, 200.0, 39.0, 6_000),
        "spix2": (50.0, 250.0, 48.0, 1_000), "light_x6_point": (60.0, 400.0, 55.0, 5_000),
        "light_x2": (61.0, 400.0, 56.0, 5_001), "mass": (200.0, 500.0, 190.0, 7_200)}  # fmt: skip
"""job: (wall s, peak MB, CPU s, sampler calls)."""


def _benchmark(folder, job, rows):
    """A Snakemake benchmark file: rows of (wall s, MB, CPU s), "NA" where given so."""
    (folder / "benchmarks").mkdir(parents=True, exist_ok=True)
    lines = [f"{s}\t0:00:00\t{rss}\t0\t0\t0\t0\t0\t50\t{cpu}\n" for s, rss, cpu in rows]
    path = folder / "benchmarks" / f"{job}.tsv"
    path.write_text(HEADER + "".join(lines))
    return path


def _record(folder, job, calls, sp_start="search"):
    (folder / job).mkdir(parents=True, exist_ok=True)
    record = {"sampler": {"n_calls": calls}, "settings": {"slam": {"sp_start": sp_start}}}
    (folder / job / "result.json").write_text(json.dumps(record))


def _lens(tmp_path, name="L1", jobs=tuple(JOBS), sp_start="search"):
    """A lens folder with ``jobs`` measured and recorded, SP's start record, and files of
    jobs outside the chain; returns the chain's benchmark files."""
    folder = tmp_path / "results" / name
    paths = []
    for job in jobs:
        wall, rss, cpu, calls = JOBS[job]
        paths.append(_benchmark(folder, job, [(wall, rss, cpu)]))
        _record(folder, job, calls, sp_start)
    (folder / "sp").mkdir(parents=True, exist_ok=True)
    (folder / "sp" / "start.json").write_text(json.dumps({"start": {"n_calls": 9_440}}))
    _benchmark(folder, "choose_light", [(1.0, 100.0, 1.0)])
    _benchmark(folder, "simulate_mock", [(5.0, 100.0, 5.0)])
    return paths


def test_each_phase_sums_its_jobs_and_sp_counts_its_start(tmp_path):
    paths = _lens(tmp_path)
    assert job_cost(paths[0]) == JobCost("L1", "sp", "sp", 100.0, 95.0, 300.0, 29_440.0, False)
    row = cost_table(paths).iloc[0]
    assert row["lens"] == "L1"
    assert row["light_cpu_s"] == pytest.approx(55.0 + 56.0)  # both candidates
    assert row["light_calls"] == 5_000 + 5_001
    assert row["chain_cpu_min"] == pytest.approx((95 + 39 + 48 + 55 + 56 + 190) / 60)
    assert row["chain_wall_min"] == pytest.approx((100 + 40 + 50 + 60 + 61 + 200) / 60)
    assert row["max_rss_mb"] == 500.0
    assert row["complete"]
    assert not row["cpu_exact"]  # no job recorded its own CPU time
    # jobs outside the chain (choose_light, simulate_mock) are not the chain's time
    assert chain_seconds(paths[0].parents[1]) == pytest.approx(100 + 40 + 50 + 60 + 61 + 200)
    cpu = chain_seconds(paths[0].parents[1], cpu=True)
    assert cpu == pytest.approx(row["chain_cpu_min"] * 60)
    assert np.isnan(chain_seconds(tmp_path / "nothing"))


def test_only_the_files_given_count_and_a_prior_started_sp_leaves_its_old_start_out(tmp_path):
    """A lens whose sheet now pins X6 + point keeps its old X2 file; the workflow passes
    the current jobs only. An SP sampled from the anchor priors does not count a
    start.json left from an earlier search."""
    jobs = ("sp", "spix1", "spix2", "light_x6_point", "mass")
    paths = _lens(tmp_path, jobs=jobs, sp_start="prior")
    _benchmark(paths[0].parents[1], "light_x2", [(61.0, 400.0, 56.0)])
    row = cost_table(paths).iloc[0]
    assert row["light_cpu_s"] == 55.0
    assert row["sp_calls"] == 20_000


def test_repeats_add_up_and_a_missing_record_leaves_the_calls_unknown(tmp_path):
    path = _benchmark(tmp_path / "L2", "spix1", [(10.0, 200.0, 9.0), (12.0, 250.0, 11.0)])
    cost = job_cost(path)
    assert (cost.wall_s, cost.cpu_s, cost.max_rss_mb) == (22.0, 20.0, 250.0)
    assert np.isnan(cost.calls)
    (tmp_path / "L2" / "spix1").mkdir()
    (tmp_path / "L2" / "spix1" / "result.json").write_text('{"sampler": {"n_calls": 7}}')
    assert job_cost(path).calls == 7  # only SP's record needs its settings


def test_an_unmeasured_or_missing_phase_makes_the_chain_incomplete(tmp_path):
    """Snakemake writes NA when a job ended before its first sample: its CPU time is
    unknown, not zero, and its NA memory does not hide the other jobs' peak."""
    complete = _lens(tmp_path, "A")
    unmeasured = _lens(tmp_path, "B")
    _benchmark(unmeasured[0].parents[1], "sp", [(3.0, "NA", "NA")])
    without_mass = _lens(tmp_path, "C", jobs=tuple(JOBS)[:-1])
    table = cost_table([*complete, *unmeasured, *without_mass])
    assert list(table["lens"]) == ["A", "B", "C"]
    assert list(table["complete"]) == [True, False, False]
    assert np.isnan(table.loc[1, "sp_cpu_s"])
    assert np.isnan(table.loc[1, "chain_cpu_min"])
    assert np.isnan(chain_seconds(unmeasured[0].parents[1], cpu=True))
    assert chain_seconds(unmeasured[0].parents[1]) == pytest.approx(3 + 40 + 50 + 60 + 61 + 200)
    assert table.loc[1, "max_rss_mb"] == 500.0
    assert np.isnan(table.loc[2, "mass_cpu_s"])
    sample = sample_cost(table, cores=2)
    a = table.loc[0, "chain_cpu_min"]
    assert sample == pytest.approx(
        {
            "n_complete": 1,
            "n_lenses": 3,
            "median_cpu_min": a,
            "max_cpu_min": a,
            "max_lens": "A",
            "total_cpu_h": a / 60,
            "projected_wall_h": 3 * a / 60 / 2,
            "cores": 2,
        }
    )
    with pytest.raises(ValueError, match="cores"):
        sample_cost(table, cores=0)
    assert sample_cost(table.iloc[1:], cores=2) == {"n_complete": 0, "n_lenses": 2}


@pytest.mark.parametrize(
    ("content", "message"),
    [("s\th:m:s\n12\t0:00:12\n", "cpu_time"), ("", "not a Snakemake benchmark file")],
)
def test_a_broken_benchmark_file_is_named_with_the_fix(tmp_path, content, message):
    (tmp_path / "L3" / "benchmarks").mkdir(parents=True)
    path = tmp_path / "L3" / "benchmarks" / "sp.tsv"
    path.write_text(content)
    with pytest.raises(ValueError, match=rf"sp\.tsv.*{message}.*rerun its phase"):
        job_cost(path)


def _cost_record(folder, job, cpu_s, result=None):
    """``job``'s cost.json with ``cpu_s``, for ``result`` (default: its result.json)."""
    result = (folder / job / "result.json").read_bytes() if result is None else result
    record = {"cpu_s": cpu_s, "wall_s": cpu_s, "result_sha256": hashlib.sha256(result).hexdigest()}
    (folder / job / COST_FILE).write_text(json.dumps(record))


def test_a_jobs_own_cpu_record_replaces_the_sampled_time_only_where_it_is_its_results(
    tmp_path,
):
    """A job's ``cost.json`` for its ``result.json`` gives its CPU seconds; one written
    for another result (an earlier run's) does not; an unreadable one is named."""
    paths = _lens(tmp_path)
    folder = paths[0].parents[1]
    _cost_record(folder, "sp", 123.5)
    cost = job_cost(paths[0])
    assert (cost.cpu_s, cost.wall_s, cost.cpu_exact) == (123.5, 100.0, True)
    row = cost_table(paths).iloc[0]
    assert row["sp_cpu_s"] == 123.5
    assert not row["cpu_exact"]  # the other jobs have only Snakemake's samples
    for job in tuple(JOBS)[1:]:
        _cost_record(folder, job, JOBS[job][2] + 1.0)
    table = cost_table(paths)
    row = table.iloc[0]
    assert row["cpu_exact"]
    (ax,) = cost_figure(table, sample_cost(table, cores=2)).axes
    assert [t.get_text() for t in ax.get_yticklabels()] == ["L1"]  # exact: no mark
    assert row["chain_cpu_min"] == pytest.approx((123.5 + 39 + 48 + 55 + 56 + 190 + 5) / 60)
    assert chain_seconds(folder, cpu=True) == pytest.approx(row["chain_cpu_min"] * 60)
    _cost_record(folder, "sp", 123.5, result=b"an earlier run's result")
    assert job_cost(paths[0]) == JobCost("L1", "sp", "sp", 100.0, 95.0, 300.0, 29_440.0, False)
    (folder / "sp" / COST_FILE).write_text(json.dumps({"cpu_s": 1.0}))
    with pytest.raises(ValueError, match=r"sp/cost\.json.*rerun the phase"):
        job_cost(paths[0])


def test_the_process_cost_counts_cpu_time_not_waiting():
    """CPU seconds grow by the time a loop computes and not by the time the process
    sleeps; wall seconds grow by both."""
    started = time.perf_counter()
    before = process_cost(started)
    time.sleep(0.3)
    slept = process_cost(started)
    end = time.process_time() + 0.3
    while time.process_time() < end:
        pass
    busy = process_cost(started)
    assert slept["cpu_s"] - before["cpu_s"] < 0.1
    assert slept["wall_s"] - before["wall_s"] >= 0.29
    assert busy["cpu_s"] - slept["cpu_s"] == pytest.approx(0.3, abs=0.05)
    assert busy["max_rss_mb"] > 10.0


def test_a_broken_start_record_is_named(tmp_path):
    paths = _lens(tmp_path)
    (paths[0].parents[1] / "sp" / "start.json").write_text(json.dumps({"values": None}))
    with pytest.raises(ValueError, match=r"start\.json.*rerun phase sp"):
        job_cost(paths[0])
    with pytest.raises(ValueError, match="not a benchmark file of a SLaM phase job"):
        job_cost(paths[0].with_name("choose_light.tsv"))


def test_the_figure_has_one_bar_per_lens_in_core_minutes(tmp_path):
    table = cost_table([*_lens(tmp_path, "A"), *_lens(tmp_path, "C", jobs=tuple(JOBS)[:-1])])
    figure = cost_figure(table, sample_cost(table, cores=2))
    (ax,) = figure.axes
    assert ax.get_xlabel() == "CPU time of the SLaM chain (core-minutes)"
    # no job of either recorded its own CPU time: Snakemake's sampled lower bounds
    assert [t.get_text() for t in ax.get_yticklabels()] == ["A (CPU ≥)", "C (incomplete) (CPU ≥)"]
    widths = [patch.get_width() for patch in ax.patches]
    assert sum(widths) == pytest.approx(table["chain_cpu_min"].sum())
    assert "1 complete chains of 2" in ax.get_title()


def test_the_command_writes_the_table_and_figure_and_names_a_bad_file(tmp_path):
    paths = _lens(tmp_path, "A")
    out, figure = tmp_path / "summary" / "cost.csv", tmp_path / "summary" / "cost.png"
    command = [sys.executable, "-m", "mgelens", "cost", *map(str, paths),
               "--out", str(out), "--figure", str(figure), "--cores", "4"]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    table = pd.read_csv(out)
    assert list(table["lens"]) == ["A"]
    assert table["sp_calls"].iloc[0] == 29_440
    assert figure.stat().st_size > 10_000
    assert "cores: 4" in done.stdout
    paths[-1].write_text("not a benchmark\n")
    failed = subprocess.run(command, capture_output=True, text=True, check=False)
    assert failed.returncode == 1
    assert "mass.tsv" in failed.stderr

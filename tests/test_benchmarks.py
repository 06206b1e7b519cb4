"""The benchmark scripts still run on today's models.

``benchmarks/bench_phases.py`` builds every phase's model from nominal parameter values
of its own; when a phase gains a parameter (SPix2's arc threshold with the arcs'
support) the script must gain it too, or the issue #28 figures can no longer be
measured. One call per phase on a real SLACS cutout with a small mask keeps this cheap.
"""

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PHASES = ("sp", "spix1", "spix2", "light", "mass")


@pytest.mark.slow
def test_bench_phases_times_every_phase_of_a_real_lens(slacs_dir):
    lens_dir = slacs_dir / "slacs1103+5322"
    if not lens_dir.is_dir():
        pytest.skip(f"{lens_dir} is absent")
    run = subprocess.run(
        [
            sys.executable,
            str(ROOT / "benchmarks" / "bench_phases.py"),
            "--lens-dir",
            str(lens_dir),
            "--mask-radius",
            "1.6",
            "--einstein-radius",
            "1.0",
            "--calls",
            "1",
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    figures = dict(re.findall(r"^call_ms_(\w+): ([0-9.]+)$", run.stdout, flags=re.MULTILINE))
    assert set(figures) == set(PHASES)
    assert all(float(ms) > 0 for ms in figures.values())
    stages = re.findall(r"^stage_ms_spix2_kmeans: ([0-9.]+)$", run.stdout, flags=re.MULTILINE)
    assert len(stages) == 1
    assert float(stages[0]) > 0


def test_bench_phase_draws_takes_a_runs_samples_evenly_in_run_order(tmp_path, monkeypatch):
    """``--samples``: the rows are spread over the whole run, first and last included,
    each in the free parameters' order whatever the table's column order."""
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    from bench_phase_draws import run_samples

    names = ("b", "a")
    table = tmp_path / "samples.csv"
    table.write_text("weight,a,b\n" + "".join(f"0.1,{i},{10 * i}\n" for i in range(11)))
    points = run_samples(table, names, 6)
    assert [p.tolist() for p in points] == [[10.0 * i, float(i)] for i in (0, 2, 4, 6, 8, 10)]
    assert len(run_samples(table, names, 40)) == 11

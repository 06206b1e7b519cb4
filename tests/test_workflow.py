"""Snakemake workflow: dry runs, lint, config errors, sample sheets and a real mock run.

Snakemake runs as a subprocess from the repository root with ``-d <tmp dir>``, so nothing
is written into the repository.
"""

import functools
import json
import re
import time
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from astropy.io import fits
from snakemake.exceptions import WorkflowError
from snakemake.utils import validate
from workflow_run import CHAIN_TIMEOUT, ROOT, snakemake

from mgelens import cli, mock_lenses
from mgelens import simulate as sim
from mgelens.coverage import TARGETS
from mgelens.pipeline.settings import PHASES, settings_from_mapping
from mgelens.quality import NO_FLAG, flagged_checks
from mgelens.recovery import true_mass_parameters
from mgelens.sheet import read_sample_sheet


def job_counts(output: str) -> dict[str, int]:
    """The "Job stats" table of a dry run as {rule: count}."""
    table = output.split("Job stats:")[1]
    return {m[1]: int(m[2]) for m in re.finditer(r"^(\w+)\s+(\d+)$", table, re.MULTILINE)}


def test_dry_run_of_the_default_sample_makes_m1_to_m3(tmp_path):
    result = snakemake("-n", workdir=tmp_path)
    assert result.returncode == 0, result.stderr
    counts = job_counts(result.stdout + result.stderr)
    assert counts["simulate_mock"] == 3
    assert counts["preview"] == 3
    # the default target is the whole DAG: five phases and isophotes per lens, summary
    assert counts["phase"] == 6  # SP, SPix2
    assert counts["phase_spix1"] == 3  # SPix1, which also writes the adapt image
    # MASS: each of the quick profile's two source meshes its own job, then their pool
    assert counts["mass_mesh"] == 6
    assert counts["pool_mass"] == 3
    assert counts["phase_light"] == 3  # the sheet pins M1-M3's LIGHT model
    assert "choose_light" not in counts
    assert counts["isophotes"] == 3
    assert counts["fit_quality"] == 3
    assert counts["overview"] == 3
    assert counts["recovery"] == 3
    assert counts["recovery_table"] == 1
    assert counts["coverage"] == 1
    assert counts["smoothness"] == 1  # Appendix A scan of M1
    assert counts["summary"] == 1
    assert counts["all"] == 1
    assert not list(tmp_path.iterdir()) or {p.name for p in tmp_path.iterdir()} <= {".snakemake"}


def test_dry_run_of_one_lens_slam_chain_runs_five_phases(tmp_path):
    result = snakemake("-n", "-p", "results/M2/mass/result.json", workdir=tmp_path)
    assert result.returncode == 0, result.stderr
    output = result.stdout + result.stderr
    counts = job_counts(output)
    assert counts["phase"] == 2
    assert counts["phase_spix1"] == counts["phase_light"] == counts["pool_mass"] == 1
    assert counts["mass_mesh"] == 2
    assert counts["simulate_mock"] == 1
    for phase in ("sp", "spix1", "spix2", "light", "mass"):
        assert f"mgelens phase {phase} " in output
    for mesh in (0, 1):
        assert (
            "mgelens phase mass --lens-dir results/M2/mock --results results/M2 --threads 1 "
            f"--mask-radius 1.6 --mesh {mesh} --seed 0 --slam" in output
        )
    assert (
        "mgelens phase mass --pool-meshes --lens-dir results/M2/mock --results results/M2 "
        "--seed 0 --slam" in output
    )
    # the sheet's mask radius reaches every phase, its MGE complexity and point set the
    # LIGHT phase that reads them, and the config's slam: section goes as JSON
    assert output.count("--mask-radius 1.6") == 6
    assert output.count("--mge-sets 4 --point-set yes") == 1
    assert (
        "mgelens phase light --lens-dir results/M2/mock --results results/M2 --threads 1 "
        "--mask-radius 1.6 --mge-sets 4 --point-set yes" in output
    )
    assert output.count("""--slam '{"profile": "quick"}'""") == 7
    assert output.count("--point-set yes --seed 0 --slam") == 1
    assert output.count("--seed 0") == 7  # the config's sampler_seed
    # SPix1's adapt image is a declared output and an input of SPix2, LIGHT and MASS
    assert output.count("results/M2/spix1/adapt_image.fits") >= 4
    # mocks first (a lens cannot start without its mock), then
    # earlier phases first (SP highest), so every lens's SP starts early
    priorities = dict(re.findall(r"phase=(\w+)\n\s+priority: (\d+)", output))
    assert priorities == {
        "sp": "5",
        "spix1": "4",
        "spix2": "3",
        "light": "2",
        "mass_mesh0": "1",
        "mass_mesh1": "1",
    }
    assert re.search(r"rule simulate_mock:(\n\s+\w+:.*)*\n\s+priority: 6", output)


def test_dry_run_of_the_population_sample(tmp_path):
    result = snakemake("-n", "--configfile", "config/population.yaml", workdir=tmp_path)
    assert result.returncode == 0, result.stderr
    counts = job_counts(result.stdout + result.stderr)
    assert counts["simulate_mock"] == counts["preview"] == mock_lenses.POPULATION_SIZE
    assert "smoothness" not in counts  # no M1 in the population


def test_the_three_arcsec_samples_fit_1000_source_pixels():
    """The SLACS-like samples (3.0″ masks) replace the quick profile's 500 source pixels
    with 1,000 (docs/coverage.md, "Compact clumps under 500 source pixels"); the default
    sample, M1–M3, keeps the profile's."""
    default = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())["slam"]
    assert settings_from_mapping(default).source_pixels == 500
    for name in ("coverage", "population", "paper", "slacs"):
        sample = yaml.safe_load((ROOT / "config" / f"{name}.yaml").read_text())["slam"]
        assert settings_from_mapping({**default, **sample}).source_pixels == 1000, name


def test_a_list_of_source_pixel_counts_fits_spix2_per_count_and_chooses(tmp_path):
    """`slam: source_pixels: [500, 1000]`: SPix2 once per count into `spix2_n<count>/`
    (its --slam carrying that count), rule choose_source_pixels between them, LIGHT and
    MASS after it with the list, and every candidate's benchmark in the chain cost."""
    config = tmp_path / "pixels.yaml"
    config.write_text("slam:\n  source_pixels: [1000, 500]\n")
    result = snakemake("-n", "-p", "--configfile", str(config), workdir=tmp_path)
    assert result.returncode == 0, result.stderr
    output = result.stdout + result.stderr
    counts = job_counts(output)
    commands = [line.removeprefix("Shell command: ") for line in output.splitlines()]
    assert counts["spix2_candidate"] == 6
    assert counts["choose_source_pixels"] == 3
    assert counts["phase"] == 3  # SP of M1–M3 (MASS: rules mass_mesh and pool_mass)
    for n in (500, 1000):
        line = next(
            line
            for line in commands
            if line.startswith("mgelens phase spix2")
            and "--results results/M2 " in line
            and f"--folder spix2_n{n} " in line
        )
        assert json.loads(re.search(r"--slam '([^']*)'", line)[1])["source_pixels"] == n
    assert (
        "mgelens choose --results results/M2 --source-pixels 500 1000 --threshold 5.0 "
        "--record results/M2/source_pixels_choice.json" in output
    )
    for phase in ("sp", "light", "mass"):
        line = next(
            line
            for line in commands
            if line.startswith(f"mgelens phase {phase} ") and "--results results/M2 " in line
        )
        assert json.loads(re.search(r"--slam '([^']*)'", line)[1])["source_pixels"] == [1000, 500]
    cost = next(line for line in commands if line.startswith("mgelens cost "))
    assert "results/M2/benchmarks/spix2_n500.tsv results/M2/benchmarks/spix2_n1000.tsv" in cost
    assert "results/M2/benchmarks/spix2.tsv" not in cost


def test_dry_run_of_the_slacs_sample_reads_the_data_in_place(tmp_path, slacs_dir):
    result = snakemake("-n", "--configfile", "config/slacs.yaml", workdir=tmp_path)
    assert result.returncode == 0, result.stderr
    counts = job_counts(result.stdout + result.stderr)
    assert counts["preview"] == 61
    assert "simulate_mock" not in counts
    assert str(slacs_dir / "slacs0252+0039" / "data.fits") in result.stdout + result.stderr


def test_a_real_lenss_mask_and_info_files_are_phase_inputs(tmp_path):
    """Fits read a real lens's optional mask.fits and info.json: editing them reruns."""
    from mgelens.imaging import Imaging

    folder = tmp_path / "data" / "R1"
    shape = (21, 21)
    psf = np.zeros((3, 3))
    psf[1, 1] = 1.0
    mask = np.zeros(shape, dtype=bool)
    mask[0, 0] = True
    Imaging(np.zeros(shape), np.ones(shape), psf, 0.05, mask=mask).to_fits(folder)
    (folder / "info.json").write_text('{"pixel_scale_arcsec": 0.05}')
    (tmp_path / "sheet.tsv").write_text(SHEET_HEADER + "R1\treal\t\tR1\t0.5\t2\tno\t0.2\t0.6\n")
    config = tmp_path / "config.yaml"
    config.write_text(f"samples: {tmp_path / 'sheet.tsv'}\ndata_dir: {tmp_path / 'data'}\n")
    result = snakemake(
        "results/R1/sp/result.json", "-n", "--configfile", str(config), workdir=tmp_path
    )
    assert result.returncode == 0, result.stdout + result.stderr
    inputs = re.search(r"rule phase:\n(?:.*\n)*?\s+input: (.*)", result.stdout + result.stderr)[1]
    assert str(folder / "mask.fits") in inputs
    assert str(folder / "info.json") in inputs


def test_a_contaminants_file_reaches_every_phase_as_option_and_input(tmp_path):
    """The sheet's `contaminants` file goes to every phase (`--contaminants`) and is an
    input of the phases, the overview and the quality check, so editing it reruns them;
    an absent file stops the run naming the column."""
    from mgelens.imaging import Imaging

    shape = (21, 21)
    psf = np.zeros((3, 3))
    psf[1, 1] = 1.0
    Imaging(np.zeros(shape), np.ones(shape), psf, 0.05).to_fits(tmp_path / "data" / "R1")
    circles = tmp_path / "R1 neighbours.txt"
    circles.write_text("0.2 0.1 0.1\n")
    header = SHEET_HEADER.replace("\n", "\tcontaminants\n")
    (tmp_path / "sheet.tsv").write_text(
        header + f"R1\treal\t\tR1\t0.5\t2\tno\t0.2\t0.6\t{circles}\n"
    )
    config = tmp_path / "config.yaml"
    config.write_text(f"samples: {tmp_path / 'sheet.tsv'}\ndata_dir: {tmp_path / 'data'}\n")
    targets = [f"results/R1/{name}" for name in ("quality.json", "figures/overview.png")]
    targets.append("results/R1/figures/preview.png")
    result = snakemake(*targets, "-n", "-p", "--configfile", str(config), workdir=tmp_path)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    # every phase (MASS: its two mesh jobs) and the preview
    assert output.count(f"--contaminants '{circles}'") == len(PHASES) + 2
    inputs = re.findall(r"rule (\w+):\n(?:.*\n)*?\s+input: (.*)", output)
    reading = {rule for rule, files in inputs if str(circles) in files}
    assert reading >= {"phase", "phase_light", "overview", "fit_quality", "preview"}
    circles.unlink()
    result = snakemake(*targets, "-n", "--configfile", str(config), workdir=tmp_path)
    assert result.returncode != 0
    assert "lens 'R1': contaminants file" in result.stdout + result.stderr
    assert "fix the `contaminants` column" in result.stdout + result.stderr


def test_sampler_seed_reaches_every_phase(tmp_path):
    """Another sampler_seed puts that seed on every phase's command line (so changing it
    reruns the chains: their params change)."""
    result = snakemake(
        "-n", "-p", "results/M3/mass/result.json", "--config", "sampler_seed=7", workdir=tmp_path
    )
    assert result.returncode == 0, result.stderr
    output = result.stdout + result.stderr
    assert output.count("--seed 7") == 7  # MASS: its two mesh jobs and their pool
    assert "--seed 0" not in output


def test_noise_seed_rows_simulate_other_noise_realisations(tmp_path):
    """A sheet row with a noise seed simulates its paper mock with `--noise-seed`; rows
    without one keep the mock's own noise (the same command as before the column)."""
    (tmp_path / "sheet.tsv").write_text(
        SHEET_HEADER.replace("\n", "\tnoise_seed\n")
        + "M2\tmock\tM2\t\t1.6\t4\tyes\t0.35\t1.1\t\n"
        + "M2n11\tmock\tM2\t\t1.6\t4\tyes\t0.35\t1.1\t11\n"
    )
    (tmp_path / "config.yaml").write_text(f"samples: {tmp_path / 'sheet.tsv'}\n")
    result = snakemake(
        "-n", "-p", "results/M2n11/mock/data.fits", "results/M2/mock/data.fits",
        "--configfile", str(tmp_path / "config.yaml"), workdir=tmp_path,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    output = result.stdout + result.stderr
    assert "mgelens simulate --mock M2 --noise-seed 11 --name M2n11 " in output
    assert "mgelens simulate --mock M2 --name M2 " in output


def test_lint_is_clean(tmp_path):
    result = snakemake("--lint", workdir=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Congratulations, your workflow is in a good condition" in result.stdout + result.stderr


SHEET_HEADER = "lens\tkind\tmock\tinput\tmask_radius\tmge_sets\tpoint_set\tz_lens\tz_source\n"


@pytest.mark.parametrize(
    ("config", "sheet", "message"),
    [
        ("population_seed: -1\n", None, "population_seed"),
        ("sampler_seed: -1\n", None, "sampler_seed"),
        ("samples: missing.tsv\n", None, "missing.tsv not found"),
        ("slam:\n  source_pixel: 500\n", None, "config: unknown key slam.source_pixel"),
        ("slam:\n  samplers: {mass: {n_live: 1}}\n", None, "slam.samplers.mass.n_live must be"),
        ("data_dir: /nowhere\n", "R1\treal\t\tslacsX\t3.0\t2\tno\t0.2\t0.6\n",
         "real lens 'R1': data.fits, noise_map.fits, psf.fits not found in /nowhere/slacsX"),
        ("slam:\n  mge_sets: 6\n", None,
         "slam.mge_sets is set per lens, not in slam: settings: give it with --mge-sets, "
         "or the sample sheet's mge_sets column"),
        ("slam:\n  sub_size: 2\n", None,
         "slam.sub_size is a fit setting: give it as slam.fit.sub_size"),
        ("", "M1\tmock\tM1\t\t1.8\t4\tyes\t0.28\n", "sheet.tsv: Error validating row 0"),
    ],
)  # fmt: skip
def test_bad_configuration_stops_with_a_message_naming_the_value(tmp_path, config, sheet, message):
    if sheet is not None:
        (tmp_path / "sheet.tsv").write_text(SHEET_HEADER + sheet)
        config += f"samples: {tmp_path / 'sheet.tsv'}\n"
    (tmp_path / "config.yaml").write_text(config)
    result = snakemake("-n", "--configfile", str(tmp_path / "config.yaml"), workdir=tmp_path)
    assert result.returncode != 0
    assert message in result.stdout + result.stderr


def test_coverage_config_fits_population_and_independent_mocks(tmp_path):
    """config/coverage.yaml: 38 population mocks and 12 independent (lenstronomy) mocks,
    at 201 pixels, each through the chain and its recovery, gathered by rule coverage."""
    result = snakemake("-n", "-p", "--configfile=config/coverage.yaml", workdir=tmp_path)
    assert result.returncode == 0, result.stderr
    output = result.stdout + result.stderr
    counts = job_counts(output)
    assert counts["simulate_mock"] == counts["recovery"] == counts["fit_quality"] == 50
    assert counts["coverage"] == 1
    # the study counts its targets again over the fits that no quality check flags
    assert "--quality results/P00/quality.json" in output
    assert "mgelens simulate --independent-index 11 --population-seed 2024 --name L11 " in output
    assert "--image-size 201" in output
    slam = re.findall(r"--slam '([^']*)'", output)
    assert slam
    assert all(json.loads(s) == {"profile": "quick", "source_pixels": 1000} for s in slam)


def test_comma_separated_sheet_is_named_with_the_fix(tmp_path):
    (tmp_path / "sheet.csv").write_text(SHEET_HEADER.replace("\t", ","))
    (tmp_path / "config.yaml").write_text(f"samples: {tmp_path / 'sheet.csv'}\n")
    result = snakemake("-n", "--configfile", str(tmp_path / "config.yaml"), workdir=tmp_path)
    assert result.returncode != 0
    output = result.stdout + result.stderr
    assert f"sample sheet {tmp_path / 'sheet.csv'} has no `lens` column" in output
    assert "tab-separated" in output


def test_a_header_only_sheet_stops_the_dry_run(tmp_path):
    (tmp_path / "sheet.tsv").write_text(SHEET_HEADER)
    (tmp_path / "config.yaml").write_text(f"samples: {tmp_path / 'sheet.tsv'}\n")
    result = snakemake("-n", "--configfile", str(tmp_path / "config.yaml"), workdir=tmp_path)
    assert result.returncode != 0
    assert f"sample sheet {tmp_path / 'sheet.tsv'} lists no lens" in result.stdout + result.stderr


def test_a_target_of_a_lens_not_in_the_sheet_names_the_sheet_and_its_lenses(tmp_path):
    result = snakemake("-n", "results/X9/mass/result.json", workdir=tmp_path)
    assert result.returncode != 0
    sheet = ROOT / "config" / "lenses.tsv"
    message = f"lens 'X9' is not in the sample sheet {sheet}, whose lenses are M1, M2, M3"
    assert message in result.stdout + result.stderr


def test_the_paper_mock_comparison_is_nine_rows_each_with_its_lens_light_model(tmp_path):
    targets = [f"results/{lens}/sp/result.json" for lens in ("M1", "M1_pn", "M1_sersic")]
    result = snakemake(
        "-n", "-p", "--configfile=config/paper_mocks.yaml", *targets, workdir=tmp_path
    )
    assert result.returncode == 0, result.stderr
    output = result.stdout + result.stderr
    slam = (
        '--slam \'{{"fit": {{"positive_only": {}}}, "lens_light_model": "{}", '
        '"profile": "quick", "sp_start": "search"}}\''
    )
    assert "--results results/M1 " in output
    assert slam.format("true", "mge") in output
    assert slam.format("false", "mge") in output
    sersic = '"fit": {"free_source": true, "positive_only": true}, "lens_light_model": "sersic"'
    assert f'--slam \'{{{sersic}, "profile": "quick", "sp_start": "search"}}\'' in output
    whole = snakemake("-n", "--configfile", "config/paper_mocks.yaml", workdir=tmp_path)
    counts = job_counts(whole.stdout + whole.stderr)
    assert counts["simulate_mock"] == 9
    assert counts["phase"] == 18  # SP and SPix2 (MASS: rules mass_mesh and pool_mass)
    assert counts["mass_mesh"] == 18
    assert counts["pool_mass"] == 9
    assert counts["mock_study"] == counts["smoothness"] == 1
    sheet = pd.read_csv(ROOT / "config" / "paper_mocks.tsv", sep="\t")
    assert (
        sorted(sheet.groupby("mock")["lens_light"].apply(sorted).tolist())
        == [["nn_mge", "pn_mge", "sersic"]] * 3
    )


def test_a_lens_light_column_and_a_slam_lens_light_setting_contradict(tmp_path):
    header = SHEET_HEADER.replace("point_set\t", "point_set\tlens_light\t")
    (tmp_path / "sheet.tsv").write_text(
        header + "M1\tmock\tM1\t\t1.8\t4\tyes\tpn_mge\t0.28\t0.98\n"
    )
    config = f"samples: {tmp_path / 'sheet.tsv'}\nslam:\n  fit: {{positive_only: false}}\n"
    (tmp_path / "config.yaml").write_text(config)
    result = snakemake("-n", "--configfile", str(tmp_path / "config.yaml"), workdir=tmp_path)
    assert result.returncode != 0
    assert "slam.fit.positive_only contradicts the `lens_light` column" in (
        result.stdout + result.stderr
    )


@pytest.mark.parametrize(
    ("section", "key", "slam"),
    [
        (
            "  samplers:\n    mass: {n_live: 80}\n",
            '"n_live"',
            """{"profile": "quick", "samplers": {"mass": {"n_live": 80}}}""",
        ),
        (
            "  mass_source_pixels: 1000\n",
            '"mass_source_pixels"',
            """{"mass_source_pixels": 1000, "profile": "quick"}""",
        ),
        (
            "  adaptive_signals_mass: fitted\n",
            '"adaptive_signals_mass"',
            """{"adaptive_signals_mass": "fitted", "profile": "quick"}""",
        ),
        (
            "  mass_mesh_tuning: false\n",
            '"mass_mesh_tuning"',
            """{"mass_mesh_tuning": false, "profile": "quick"}""",
        ),
    ],
)
def test_settings_of_mass_alone_reach_mass_only(tmp_path, section, key, slam):
    """One phase's sampler settings, ``mass_source_pixels``, ``mass_mesh_tuning`` and
    ``adaptive_signals_mass`` go to MASS's --slam only."""
    (tmp_path / "config.yaml").write_text("slam:\n" + section)
    result = snakemake(
        "results/M1/mass/result.json", "-n", "-p", "--configfile",
        str(tmp_path / "config.yaml"), workdir=tmp_path,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    output = result.stdout + result.stderr
    # MASS's two mesh jobs and their pool (quoted: the temporary folder's name holds the words)
    assert output.count(key) == 3
    assert f"--slam '{slam}'" in output


def test_source_support_reaches_the_phases_from_spix2_on(tmp_path):
    """``source_support``, ``arc_noise_floor`` and ``kmeans_seeding`` change SPix2's model,
    so SPix2, LIGHT and MASS get them, and SP and SPix1 keep their --slam (and their
    results)."""
    (tmp_path / "config.yaml").write_text(
        "slam:\n  source_support: arcs\n  kmeans_seeding: systematic\n  arc_noise_floor: 3\n"
    )
    result = snakemake(
        "results/M1/mass/result.json", "-n", "-p", "--configfile",
        str(tmp_path / "config.yaml"), workdir=tmp_path,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    commands = [line.split("mgelens phase ")[1] for line in result.stdout.splitlines()
                if "mgelens phase " in line]  # fmt: skip
    with_support = {line.split()[0] for line in commands if '"source_support": "arcs"' in line}
    assert with_support == {"spix2", "light", "mass"}
    seeded = {line.split()[0] for line in commands if '"kmeans_seeding": "systematic"' in line}
    assert seeded == {"spix2", "light", "mass"}
    floored = {line.split()[0] for line in commands if '"arc_noise_floor": 3' in line}
    assert floored == {"spix2", "light", "mass"}
    assert len(commands) == 7  # MASS: two mesh jobs and their pool


SCHEMAS = ROOT / "workflow" / "schemas"


@pytest.mark.parametrize(
    ("config", "path"),
    [
        ({"samples": "x.tsv", "mock": {"image_size": 150}}, "image_size"),
        ({"samples": "x.tsv", "mock": {"sub_size": 0}}, "sub_size"),
        ({"samples": "x.tsv", "unknown_key": 3}, "unknown_key"),
        ({"data_dir": "x"}, "samples"),
    ],
)
def test_config_schema_rejects_bad_values(config, path):
    with pytest.raises(WorkflowError, match=path):
        validate(config, str(SCHEMAS / "config.schema.yaml"))


def test_config_schema_fills_the_paper_defaults():
    config = {"samples": "config/lenses.tsv"}
    validate(config, str(SCHEMAS / "config.schema.yaml"))
    assert config["mock"] == {"image_size": 151, "sub_size": 16}
    assert config["data_dir"] == "../shared/data/slacs"


@pytest.mark.parametrize(
    ("row", "message"),
    [
        ("X1\tmock\tM7\t\t1.8\t4\tyes\t0.2\t0.6", "'M7' does not match"),
        ("X1\tmock\tM1\t\t1.8\t3\tyes\t0.2\t0.6", "3 is not valid under any of the given schemas"),
        ("X1\tmock\tM1\t\t1.8\tmany\tyes\t0.2\t0.6", "'many' is not valid under any of the given"),
        ("X1\tmock\t\t\t1.8\t4\tyes\t0.2\t0.6", "'mock' is a required property"),
        ("X1\treal\t\t\t1.8\t4\tyes\t0.2\t0.6", "'input' is a required property"),
        ("X1\treal\tM1\tdir\t1.8\t4\tyes\t0.2\t0.6", "should not be valid"),
        ("X1\tmock\tM1\t\t1.8\t4\tmaybe\t0.2\t0.6", "'maybe' is not one of"),
        ("X 1\tmock\tM1\t\t1.8\t4\tyes\t0.2\t0.6", "'X 1' does not match"),
        ("X1\tmock\tM1\t\t1.8\t4\tyes\t0.2\t0.6\t-3", "-3 is less than the minimum of 0"),
        ("X1\tmock\tP4\t\t3.0\t4\tyes\t0.2\t0.6\t11", "'P4' does not match '^M[1-3]$'"),
        ("X1\treal\t\tdir\t3.0\t4\tyes\t0.2\t0.6\t11", "'mock' is a required property"),
    ],
)  # fmt: skip
def test_sample_sheet_schema_rejects_bad_rows(tmp_path, row, message):
    header = SHEET_HEADER if row.count("\t") == 8 else SHEET_HEADER.replace("\n", "\tnoise_seed\n")
    (tmp_path / "sheet.tsv").write_text(header + row + "\n")
    sheet = read_sample_sheet(tmp_path / "sheet.tsv")
    with pytest.raises(WorkflowError) as error:
        validate(sheet, str(SCHEMAS / "lenses.schema.yaml"))
    assert message in str(error.value)


@pytest.mark.parametrize("sheet", ["lenses.tsv", "population.tsv", "slacs.tsv", "paper.tsv"])
def test_shipped_sample_sheets_are_valid(sheet):
    validate(read_sheet(sheet), str(SCHEMAS / "lenses.schema.yaml"))


def test_rule_outputs_are_the_simulator_files():
    rules = (ROOT / "workflow" / "rules" / "mocks.smk").read_text()
    declared = set(re.findall(r'"results/\{lens\}/mock/([\w.]+)"', rules))
    assert declared == set(sim.MOCK_FILES.values())


def test_conda_environment_of_the_rules_mirrors_pyproject():
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    environment = yaml.safe_load((ROOT / "workflow" / "envs" / "mgelens.yaml").read_text())
    conda = {d.replace(" ", "") for d in environment["dependencies"]}
    assert conda - {"pip", "python>=3.11"} == {
        d.replace(" ", "") for d in pyproject["project"]["dependencies"]
    }
    assert (ROOT / "workflow" / "envs" / "mgelens.post-deploy.sh").is_file()


def read_sheet(name: str) -> pd.DataFrame:
    return read_sample_sheet(ROOT / "config" / name).reset_index(drop=True)


def test_sample_sheets_agree_with_the_mock_recipes():
    paper = read_sheet("lenses.tsv").set_index("lens")
    assert list(paper.index) == ["M1", "M2", "M3"]
    for name, row in paper.iterrows():
        assert row["mock"] == name
        table = mock_lenses.PAPER_MOCKS[name]
        assert (row["z_lens"], row["z_source"]) == (table.z_lens, table.z_source)
        assert row["mask_radius"] == table.mask_radius
    population = read_sheet("population.tsv")
    assert len(population) == mock_lenses.POPULATION_SIZE
    for index, row in population.iterrows():
        lens = mock_lenses.population_lens(index)
        assert row["lens"] == row["mock"] == lens.name
        assert row["z_lens"] == pytest.approx(lens.z_lens, abs=1e-4)
        assert row["z_source"] == pytest.approx(lens.z_source, abs=1e-4)


def test_slacs_sheet_lists_every_shared_lens_with_its_redshifts(slacs_dir):
    sheet = read_sheet("slacs.tsv")
    folders = sorted(p.name for p in slacs_dir.iterdir() if (p / "info.json").is_file())
    assert sorted(sheet["lens"]) == folders
    assert (sheet["input"] == sheet["lens"]).all()
    assert (sheet["mask_radius"] == 3.0).all()
    for _, row in sheet.iterrows():
        info = json.loads((slacs_dir / row["input"] / "info.json").read_text())
        assert (row["z_lens"], row["z_source"]) == (info["z_lens"], info["z_source"])


def test_paper_sheet_is_the_pyautolens_groups_41_lenses_with_boltons_redshifts(slacs_dir):
    reference = slacs_dir.parent / "reference"
    if not reference.is_dir():
        pytest.skip(f"published reference tables absent: expected {reference}")
    sheet = read_sheet("paper.tsv").set_index("lens")
    etherington = pd.read_csv(reference / "etherington_slacs_data_table.csv")
    assert sorted(sheet.index) == sorted(etherington["lens_name"])
    assert len(sheet) == 41
    bolton = pd.read_csv(reference / "bolton2008_table4_table5.csv").set_index("Name1")
    for lens, row in sheet.iterrows():
        published = bolton.loc["J" + lens.removeprefix("slacs")]
        assert (row["z_lens"], row["z_source"]) == (published["zFG1"], published["zBG1"])
        assert (slacs_dir / row["input"] / "data.fits").is_file()
    assert (sheet["mge_sets"] == "auto").all()
    assert (sheet["point_set"] == "auto").all()


def _light_choice_sample(tmp_path, extra_config: str = "") -> Path:
    """Three real-layout lenses: A chooses among X2+point, X6+point and X2, B among X2+point
    and X2, C pins X4; B's sheet gives a pixel scale. Returns the config file."""
    from mgelens.imaging import Imaging

    shape = (41, 41)
    psf = np.zeros((3, 3))
    psf[1, 1] = 1.0
    for lens in ("A", "B", "C"):
        Imaging(np.zeros(shape), np.ones(shape), psf, 0.05).to_fits(tmp_path / "data" / lens)
    rows = [
        "A\treal\t\tA\t0.8\tauto\tauto\t0.2\t0.6\t",
        "B\treal\t\tB\t0.8\t2\tauto\t0.2\t0.6\t0.05",
        "C\treal\t\tC\t0.8\t4\tno\t0.2\t0.6\t",
    ]
    header = SHEET_HEADER.replace("\n", "\tpixel_scale\n")
    (tmp_path / "sheet.tsv").write_text(header + "\n".join(rows) + "\n")
    config = tmp_path / "config.yaml"
    config.write_text(
        f"samples: {tmp_path / 'sheet.tsv'}\ndata_dir: {tmp_path / 'data'}\n"
        "model_choice_threshold: 3.5\n" + extra_config
    )
    return config


def test_every_light_candidate_sampled_without_the_bound(tmp_path):
    config = _light_choice_sample(tmp_path, "model_choice_bound: false\n")
    result = snakemake(
        "results/A/mass/result.json", "-n", "-p", "--configfile", str(config), workdir=tmp_path
    )
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    assert job_counts(output)["light_candidate"] == 3
    assert "--bound-by" not in output


def test_light_models_chosen_by_evidence_and_a_sheet_pixel_scale(tmp_path):
    """`auto` rows fit each candidate LIGHT into its folder and choose among them; pinned
    rows fit LIGHT once; a `pixel_scale` cell reaches every phase and the preview."""
    config = _light_choice_sample(tmp_path)
    targets = [f"results/{lens}/mass/result.json" for lens in "ABC"]
    result = snakemake(
        *targets, "results/B/figures/preview.png", "-n", "-p", "--configfile", str(config),
        workdir=tmp_path,
    )  # fmt: skip
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    counts = job_counts(output)
    assert counts["light_candidate"] == 3 + 2
    assert counts["choose_light"] == 2
    assert counts["phase_light"] == 1
    bound = "--bound-by light_x6_point --bound-threshold 3.5"
    for folder, options in [
        ("light_x2_point", f"--mge-sets 2 --point-set yes --folder light_x2_point {bound}"),
        ("light_x6_point", "--mge-sets 6 --point-set yes --folder light_x6_point"),
        ("light_x2", f"--mge-sets 2 --point-set no --folder light_x2 {bound}"),
    ]:
        assert f"mgelens phase light --lens-dir {tmp_path / 'data' / 'A'} " in output
        assert f"{options} --seed 0" in output
        # the candidate with the most linear unknowns is fitted first and bounds the others
        job = re.search(rf"input: ([^\n]*)\n\s+output: results/A/{folder}/result.json", output)
        assert ("results/A/light_x6_point/result.json" in job.group(1)) == (bound in options)
    assert "--folder light_x2 --bound-by light_x2_point --bound-threshold 3.5" in output
    assert "--candidates X2+point X6+point X2 --threshold 3.5" in output
    assert "--results results/B --candidates X2+point X2 --threshold 3.5" in output
    assert "--results results/C --threads 1 --mask-radius 0.8 --mge-sets 4 --point-set no" in output
    # B's pixel scale: SP, SPix1, SPix2, two LIGHT candidates, MASS's two meshes, the preview
    assert output.count("--pixel-scale 0.05") == 8
    # the candidates of a lens are LIGHT phases with its priority
    priorities = dict(re.findall(r"phase=(light\w*)\n\s+priority: (\d+)", output))
    assert set(priorities.values()) == {"2"}


def test_preview_of_a_real_lens(tmp_path, slacs_dir):
    out = tmp_path / "preview.png"
    assert cli.main(["preview", str(slacs_dir / "slacs0252+0039"), "--out", str(out)]) == 0
    assert out.read_bytes().startswith(b"\x89PNG")
    assert out.stat().st_size < 300_000


def test_preview_shows_the_contaminant_circles_as_masked(tmp_path):
    """The preview greys a sheet's contaminant circles as the fits treat them: the masked
    count in its title grows by the circle's pixels."""
    from mgelens.commands.preview import preview_figure
    from mgelens.imaging import Imaging

    shape = (41, 41)
    psf = np.zeros((3, 3))
    psf[1, 1] = 1.0
    noise = np.ones(shape)
    noise[:3, :3] = 1e8
    Imaging(np.ones(shape), noise, psf, 0.05).to_fits(tmp_path / "R1")
    circles = tmp_path / "circles.txt"
    circles.write_text("0.3 -0.2 0.2\n")
    titles = [
        preview_figure(tmp_path / "R1", circles=c)._suptitle.get_text()
        for c in ((), ((0.3, -0.2, 0.2),))
    ]
    assert "9 masked" in titles[0]
    assert "58 masked" in titles[1]  # 49 pixel centres within 4 pixels of the circle's
    out = tmp_path / "preview.png"
    arguments = ["preview", str(tmp_path / "R1"), "--out", str(out), "--contaminants"]
    assert cli.main([*arguments, str(circles)]) == 0
    circles.write_text("0.3 -0.2\n")
    assert cli.main([*arguments, str(circles)]) == 1


def test_preview_of_a_missing_folder_names_it(tmp_path, caplog):
    folder = tmp_path / "nothing"
    assert cli.main(["preview", str(folder), "--out", str(tmp_path / "p.png")]) == 1
    assert f"{folder}: imaging folder not found" in caplog.text


@pytest.mark.slow
def test_simulate_mock_and_preview_run_end_to_end(tmp_path):
    repo_outputs = {name: (ROOT / name).exists() for name in ("results", "logs", ".snakemake")}
    (tmp_path / "small.yaml").write_text("mock:\n  image_size: 61\n  sub_size: 4\n")
    target = "results/M1/figures/preview.png"
    result = snakemake(target, "-c2", "--configfile", str(tmp_path / "small.yaml"),
                       workdir=tmp_path)  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    folder = tmp_path / "results" / "M1" / "mock"
    assert {p.name for p in folder.iterdir()} == set(sim.MOCK_FILES.values())
    truth = json.loads((folder / "truth.json").read_text())
    assert truth["observation"]["image_size"] == 61
    assert truth["observation"]["sub_size"] == 4
    assert truth["signal_to_noise"]["source_max"] == pytest.approx(50.0, abs=1e-6)
    data = fits.getdata(folder / "data.fits")
    assert data.shape == (61, 61)
    assert np.isfinite(data).all()
    assert (tmp_path / target).stat().st_size > 10_000
    for rule in ("simulate_mock", "preview"):
        assert (tmp_path / "logs" / "M1" / f"{rule}.log").is_file()
        benchmark = tmp_path / "results" / "M1" / "benchmarks" / f"{rule}.tsv"
        assert benchmark.read_text().startswith("s\t")
    assert "written to results/M1/mock" in (tmp_path / "logs/M1/simulate_mock.log").read_text()
    assert {name: (ROOT / name).exists() for name in repo_outputs} == repo_outputs
    assert snakemake(target, "-n", "--configfile", str(tmp_path / "small.yaml"),
                     workdir=tmp_path).stdout.count("rule ") == 0  # fmt: skip


SMOKE_CONFIG = """\
samples: {sheet}
mock:
  image_size: 71
  sub_size: 4
slam:
  profile: quick
  allow_unconverged: true
  sp_start: prior
  spix1_rescan: false
  source_pixels: 120
  overlay_shape: [12, 12]
  samplers:
    sp: {{max_calls: 300}}
    spix1: {{max_iterations: 30}}
    spix2: {{max_iterations: 20}}
    light: {{max_iterations: 30}}
    mass: {{max_calls: 250}}
"""
"""A one-lens sample with every sampler capped (SP and MASS are the quick profile's
nautilus): the DAG's plumbing, not a lens model, so each phase builds on unconverged
earlier phases. SP samples the anchor's priors and SPix1 does not rescan SP's mass: the
quick profile's start search (9,440 likelihood calls, 80 s of this test) and the rescan
(which moves this unconverged SP's mass: 3,121 calls, 93 s) have their own tests in
test_sp_start.py, test_mass_rescan.py and test_pipeline.py. After SP's 300 calls, still
among its first prior draws, MASS's mass (capped too) can have no closed tangential
critical curve within ±3″: the isophotes and quality jobs then leave its critical-curve
columns empty and flag it, and the DAG goes on."""


@pytest.mark.slow
def test_default_target_runs_the_whole_dag_and_reruns_one_phase(tmp_path):
    """`snakemake` (default target) on a small one-lens mock: mock, preview, the five
    phases, isophotes of the MASS lens light, the overview and posterior figures, the
    summary and the chain's cost. After
    deleting the MASS result, asking for it reruns only the pooling of MASS's mesh jobs,
    which writes the same bytes, so the next default run redoes only the cost table.
    (Snakemake does not rebuild a missing intermediate file on its own while the files made
    from it are present.)"""
    (tmp_path / "sheet.tsv").write_text(SHEET_HEADER + "M1\tmock\tM1\t\t1.4\t2\tno\t0.28\t0.98\n")
    config = tmp_path / "smoke.yaml"
    config.write_text(SMOKE_CONFIG.format(sheet=tmp_path / "sheet.tsv"))
    result = snakemake("-c2", "--configfile", str(config), workdir=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    lens = tmp_path / "results" / "M1"
    for phase in ("sp", "spix1", "spix2", "light", "mass_mesh0", "mass_mesh1"):
        assert (lens / phase / "result.json").is_file()
        cap = "max_calls" if phase == "sp" or phase.startswith("mass") else "max_iterations"
        assert f"stopped at {cap}" in (lens / phase / "phase.log").read_text()
        assert (lens / "benchmarks" / f"{phase}.tsv").read_text().startswith("s\t")
    # MASS's two meshes were jobs of their own, pooled into mass/
    assert "phase mass pooled from the mesh jobs" in (lens / "mass" / "phase.log").read_text()
    assert len(json.loads((lens / "mass" / "result.json").read_text())["settings"]["meshes"]) == 2
    assert (lens / "spix1" / "adapt_image.fits").is_file()
    summary = json.loads((lens / "isophotes.json").read_text())
    mass = json.loads((lens / "mass" / "result.json").read_text())["max_likelihood"]
    assert summary["mass"]["axis_ratio"] == pytest.approx(mass["mass.axis_ratio"])
    assert summary["inputs"]["phase"] == "results/M1/mass"
    assert fits.getdata(lens / "lens_light.fits").shape == (141, 141)
    table = pd.read_csv(tmp_path / "results" / "summary" / "lenses.csv")
    assert list(table["lens"]) == ["M1"]
    assert list(table["light_chosen_by"]) == ["sheet"]  # the sheet pins X2 without point set
    assert pd.read_csv(tmp_path / "results" / "summary" / "light_models.csv").empty
    assert (tmp_path / "results" / "summary" / "histograms.png").stat().st_size > 10_000
    assert (lens / "figures" / "overview.png").stat().st_size > 10_000
    assert (lens / "figures" / "posterior.png").stat().st_size > 20_000
    cost = pd.read_csv(tmp_path / "results" / "summary" / "chain_cost.csv").iloc[0]
    assert cost["lens"] == "M1"
    assert bool(cost["complete"])
    assert bool(cost["cpu_exact"])  # every phase job recorded its own CPU time
    jobs = {"mass": ("mass_mesh0", "mass_mesh1", "mass_pool")}
    for phase in ("sp", "spix1", "spix2", "light", "mass"):
        recorded = 0.0
        for job in jobs.get(phase, (phase,)):
            benchmark = pd.read_csv(lens / "benchmarks" / f"{job}.tsv", sep="\t").iloc[0]
            folder = lens / ("mass" if job == "mass_pool" else job)
            cpu = json.loads((folder / "cost.json").read_text())["cpu_s"]
            # Snakemake samples the CPU time, to the process's exit (the record is written
            # before the interpreter shuts down, about a second); one thread cannot exceed wall
            assert benchmark["cpu_time"] - 1.5 <= cpu <= 1.05 * benchmark["s"] + 1.0
            recorded += cpu
        assert cost[f"{phase}_cpu_s"] == pytest.approx(recorded)
    n_calls = json.loads((lens / "mass" / "result.json").read_text())["sampler"]["n_calls"]
    assert cost["mass_calls"] == n_calls
    assert (tmp_path / "results" / "summary" / "chain_cost.png").stat().st_size > 10_000
    assert "--truth results/M1/mock/truth.json" in result.stdout + result.stderr
    recovery = json.loads((lens / "recovery.json").read_text())
    assert {row["name"] for row in recovery["mass"]} >= {"mass.einstein_radius", "mass.slope"}
    assert set(recovery["criteria"]) == {
        "einstein_radius_within_2_percent",
        "epl_within_3sigma",
        "lens_light_within_5_percent",
        "isophotes_within_tolerance",
    }
    # the 71-pixel mock (±1.75″) cannot hold the true isophotes out to 3″, so none is
    # compared and the criterion fails; the record and the figure are still written
    isophotes = recovery["isophotes"]
    assert isophotes["n_radii"] == 21
    assert isophotes["n_compared"] < isophotes["n_radii"]
    assert recovery["criteria"]["isophotes_within_tolerance"] is False
    assert (lens / "figures" / "isophote_recovery.png").stat().st_size > 20_000
    split = recovery["light_split"]
    assert split
    refit = recovery["true_light_refit"]
    assert np.isfinite(refit["delta_log_evidence"])
    assert refit["n_lens_light_intensities"] > 0
    assert all(np.isfinite(row["total_error"]) for row in split)
    recovered = pd.read_csv(tmp_path / "results" / "summary" / "recovery.csv")
    assert list(recovered["lens"]) == ["M1"]
    covered = pd.read_csv(
        tmp_path / "results" / "summary" / "coverage_lenses.csv", keep_default_na=False
    )
    checks = flagged_checks(json.loads((lens / "quality.json").read_text()))
    assert set(covered["flags"]) == {checks}
    coverage_targets = pd.read_csv(tmp_path / "results" / "summary" / "coverage_targets.csv")
    unflagged = coverage_targets[coverage_targets["fits"] == "unflagged"]
    assert len(unflagged) == len(TARGETS)
    assert (unflagged["n"] == int(checks == NO_FLAG)).all()
    assert recovered["mass.slope.truth"].iloc[0] == pytest.approx(2.1)
    targets = pd.read_csv(tmp_path / "results" / "summary" / "recovery_targets.csv")
    light_ten, light_five, isophote_target = (row for _, row in targets.iterrows())
    mean_error = abs(recovered["lens_light.mean"].iloc[0])
    assert (light_ten["n"], light_ten["passed"]) == (1, int(mean_error < 0.10))
    assert (light_five["n"], light_five["passed"]) == (1, int(mean_error < 0.05))
    assert (isophote_target["n"], isophote_target["passed"]) == (1, 0)  # not all radii compared
    scan = pd.read_csv(tmp_path / "results" / "summary" / "smoothness.csv")
    assert set(zip(scan["scheme"], scan["edge_rule"], strict=True)) == {
        ("natural_neighbour", "anchor"), ("nearest", "anchor"),
        ("natural_neighbour", "continuous"), ("nearest", "continuous"),
    }  # fmt: skip
    assert (tmp_path / "results" / "summary" / "smoothness.png").stat().st_size > 20_000
    report = snakemake(f"--configfile={config}", "--report", "report.html", workdir=tmp_path)
    assert report.returncode == 0, report.stdout + report.stderr
    assert "ERROR/" not in report.stdout + report.stderr  # a caption docutils cannot render
    html = (tmp_path / "report.html").read_text()
    for figure in ("preview.png", "overview.png", "posterior.png", "histograms.png",
                   "smoothness.png",
                   "lens_light_nn_mge.png", "mock_table.md",
                   "isophote_recovery.png", "coverage.png", "chain_cost.png"):  # fmt: skip
        assert figure in html
    table3 = pd.read_csv(tmp_path / "results" / "summary" / "mock_table.csv")
    assert set(table3["parameter"]) == {
        "centre_x", "centre_y", "einstein_radius", "axis_ratio", "angle", "slope",
    }  # fmt: skip
    assert set(table3["model"]) == {"nn_mge"}
    assert (tmp_path / "results" / "summary" / "lens_light_nn_mge.png").stat().st_size > 20_000

    # the same data written again (new timestamp, same bytes) reruns nothing: Snakemake
    # compares the checksums of inputs up to 1 MB (README, "Lens models: the SLaM chain")
    data = lens / "mock" / "data.fits"
    content = data.read_bytes()
    time.sleep(1.0)  # newer than every result even on a file system of 1 s timestamps
    data.write_bytes(content)
    assert data.stat().st_mtime > (lens / "mass" / "result.json").stat().st_mtime
    again = snakemake("-n", f"--configfile={config}", workdir=tmp_path)
    assert "Nothing to be done" in again.stdout + again.stderr, again.stdout + again.stderr

    (lens / "mass" / "result.json").unlink()
    target = "results/M1/mass/result.json"
    rerun = snakemake("-c2", f"--configfile={config}", target, workdir=tmp_path)
    assert rerun.returncode == 0, rerun.stdout + rerun.stderr
    # the mesh jobs' results are there: only their pool runs again
    assert job_counts(rerun.stdout + rerun.stderr) == {"pool_mass": 1, "total": 1}
    assert "mgelens phase mass --pool-meshes " in rerun.stdout + rerun.stderr
    after = snakemake("-n", f"--configfile={config}", workdir=tmp_path)
    counts = job_counts(after.stdout + after.stderr)
    # the pool wrote the same bytes (its runtime is the mesh jobs'), so what reads MASS's
    # result stays; only the cost table, which reads the pool's benchmark file, is redone
    assert counts == {"chain_cost": 1, "all": 1, "total": 2}


# The whole SLaM chain of one paper mock with the default (quick) configuration:
# `snakemake results/<mock>/recovery.json` runs exactly the jobs that `snakemake -j2`
# runs for that lens (mock, SP, SPix1, SPix2, LIGHT, MASS, recovery), and its record is
# held to SPEC §11's criteria. Each chain takes 15-25 minutes on one core, M1's alone
# more than the suite's 15-minute budget on a slower host (README "Run it"), so they
# carry the `recovery` marker and run only with `python -m pytest --recovery -m recovery`.
CHAIN_LENSES = [pytest.param(lens, marks=pytest.mark.recovery) for lens in ("M1", "M2", "M3")]


@pytest.fixture(scope="session")
def run_chain(tmp_path_factory):
    """``run_chain(lens)``: the working directory of ``lens``'s whole chain, run once."""

    @functools.cache
    def run(lens: str) -> Path:
        workdir = tmp_path_factory.mktemp(f"{lens}-chain")
        target = f"results/{lens}/recovery.json"
        result = snakemake("-c1", target, workdir=workdir, timeout=CHAIN_TIMEOUT)
        assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
        return workdir

    return run


@pytest.fixture(scope="module", params=CHAIN_LENSES)
def chain_recovery(request, run_chain) -> dict:
    """The recovery record (``mgelens recovery``) of one mock's quick-profile chain."""
    record = run_chain(request.param) / "results" / request.param / "recovery.json"
    return json.loads(record.read_text())


@pytest.mark.recovery
def test_chain_sp_lands_in_the_true_mass_basin_of_m1(run_chain):
    """SP hands its maximum-likelihood SIE + shear on to every later phase (priors,
    positions penalty, fixed lens-light geometry), so it must find the true basin.

    The truth is an EPL (γ = 2.1, q = 0.8, φ = 45°, centre (0.013, −0.070)) without
    shear. With 36 live points the quick SP from the anchor's priors stopped in a false
    mode (q 0.65, shear 0.067, centre y −0.004, max ln L −39,655); with the profile's 60
    it reached q 0.80, shear 0.006, centre (0.014, −0.074) and θ_E 1.187 (max ln L
    −7,019). The quick profile now starts SP from the lensed arcs (``sp_start: search``;
    dynesty: 19,293 calls, max ln L −7,024) and samples it with nautilus with one
    network: 7,001 calls, max ln L −7,018.1, q 0.802, θ_E 1.187 (docs/slam.md, "SP:
    nautilus with one network").
    """
    results = run_chain("M1") / "results" / "M1"
    sp = json.loads((results / "sp" / "result.json").read_text())
    truth = true_mass_parameters(json.loads((results / "mock" / "truth.json").read_text()))
    best = sp["max_likelihood"]
    for name, tolerance in (("axis_ratio", 0.05), ("centre_x", 0.02), ("centre_y", 0.02)):
        assert best[f"mass.{name}"] == pytest.approx(truth[f"mass.{name}"], abs=tolerance)
    assert best["mass.einstein_radius"] == pytest.approx(truth["mass.einstein_radius"], rel=0.03)
    assert best["shear.magnitude"] < 0.03
    assert sp["max_log_likelihood"] > -20_000


def test_chain_recovers_every_epl_parameter_within_3_sigma(chain_recovery):
    missed = [row for row in chain_recovery["mass"] if not row["within_3sigma"]]
    assert not missed
    names = {row["name"] for row in chain_recovery["mass"]}
    assert {"mass.einstein_radius", "mass.slope", "mass.axis_ratio", "mass.angle"} <= names
    assert chain_recovery["criteria"]["epl_within_3sigma"] is True


def test_chain_recovers_the_einstein_radius_within_2_percent(chain_recovery):
    assert abs(chain_recovery["einstein_radius_relative_error"]) < 0.02
    assert chain_recovery["criteria"]["einstein_radius_within_2_percent"] is True


def test_chain_models_the_light_of_every_annulus_inside_the_mask(chain_recovery):
    """Lens light plus lensed source, as a fraction of the true lens light in each annulus
    of about 0.3″ inside the mask: the data are fitted to the noise, so the sum is right
    even where the split between lens light and source is not."""
    totals = [row["total_error"] for row in chain_recovery["light_split"]]
    assert len(totals) >= 5
    assert max(abs(total) for total in totals) < 0.05


def test_chain_lens_light_scores_at_least_as_well_as_the_true_one(chain_recovery):
    """The MASS fit against the same model with the true lens light fixed: the search did
    not stop short of the truth (Δ ln ε < 0), whatever the lens-light error."""
    assert chain_recovery["true_light_refit"]["delta_log_evidence"] < 0.0


@pytest.mark.xfail(
    strict=True,
    reason="SPEC §11's lens light within 5 % is unmet: the MGE and the source trade 5-50 % "
    "of the lens light where the lensed source is brighter (docs/slam.md, 'The lens light'). "
    "At MASS's best model the chain gives +22 %, +5 %, -10 % (M1-M3); none of the source "
    "and MGE priors tried, each with its strength chosen by the evidence, brings all three "
    "within 10 % (docs/recovery.md, 'Candidates for identifying the split'). The arcs' "
    "source support (slam.source_support: arcs) takes population mock P04 from -57 % to "
    "-0.1 % and P02 from -37 % to +9 %, and is the quick profile's default since it brought "
    "P05-P07 within 3 %, but on M1-M3 it gives +32 %, +24 % and -19 % (docs/recovery.md, "
    "'The support becomes the quick profile's default')",
)
def test_chain_recovers_the_lens_light_within_5_percent(chain_recovery):
    assert chain_recovery["criteria"]["lens_light_within_5_percent"] is True


def test_posterior_figure_marks_a_mocks_truth_or_a_real_lenses_published_values(tmp_path):
    """Rule posterior passes a mock its truth.json and a real lens the reference folder
    (when the published tables are there), so each figure has what it can be held to."""
    from mgelens.imaging import Imaging

    shape = (21, 21)
    psf = np.zeros((3, 3))
    psf[1, 1] = 1.0
    Imaging(np.zeros(shape), np.ones(shape), psf, 0.05).to_fits(tmp_path / "data" / "R1")
    (tmp_path / "sheet.tsv").write_text(
        SHEET_HEADER
        + "R1\treal\t\tR1\t0.5\t2\tno\t0.2\t0.6\nM1\tmock\tM1\t\t1.4\t2\tno\t0.28\t0.98\n"
    )
    reference = tmp_path / "reference"
    reference.mkdir()
    for name in ("bolton2008_table5_sie.csv", "shajib2021_slacs_powerlaw_tdcosmo2020.csv"):
        (reference / name).write_text("name\n")
    config = tmp_path / "config.yaml"
    config.write_text(
        f"samples: {tmp_path / 'sheet.tsv'}\ndata_dir: {tmp_path / 'data'}\n"
        f"reference_dir: {reference}\n"
    )
    targets = [f"results/{lens}/figures/posterior.png" for lens in ("R1", "M1")]
    result = snakemake(*targets, "-n", "-p", "--configfile", str(config), workdir=tmp_path)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    commands = [line for line in output.splitlines() if "mgelens posterior" in line]
    by_lens = {re.search(r"--lens (\w+)", line).group(1): line for line in commands}
    assert f"--reference-dir {reference}" in by_lens["R1"]
    assert "--truth" not in by_lens["R1"]
    assert "--truth results/M1/mock/truth.json" in by_lens["M1"]
    assert "--reference-dir" not in by_lens["M1"]

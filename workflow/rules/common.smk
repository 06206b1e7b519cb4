"""Sample sheet, configuration checks, wildcard constraints and path helpers.

Every helper is a named function (no lambdas in rules). Relative paths in the config
(`samples`, `data_dir`) are relative to the repository root, the folder of the
top-level Snakefile, so `snakemake -d <elsewhere>` finds them too.
"""

import json
import os
import re
import shlex
from pathlib import Path
from types import SimpleNamespace

import pandas as pd
from snakemake.exceptions import WorkflowError
from snakemake.utils import validate

from mgelens.imaging import INFO_FILE, MASK_FILE
from mgelens.mock_study import MODELS as MOCK_STUDY_MODELS
from mgelens.mock_study import PAPER_MOCKS
from mgelens.pipeline.model_choice import candidates as light_candidates
from mgelens.pipeline.pixel_choice import FOLDER_PREFIX as SPIX2_PREFIX
from mgelens.pipeline.pixel_choice import folder as spix2_folder
from mgelens.pipeline.mesh_pool import POOL_JOB
from mgelens.pipeline.run import MESH_FOLDER_PREFIX, mesh_folder
from mgelens.provenance import command_version
from mgelens.pipeline.settings import SettingsError, settings_from_mapping
from mgelens.sheet import SheetError, read_sample_sheet


validate(config, schema="../schemas/config.schema.yaml")
try:  # stop before building the DAG if the slam: section is wrong, naming the key
    CONFIG_SETTINGS = settings_from_mapping(config["slam"], origin="config")
except SettingsError as error:
    raise WorkflowError(str(error)) from None

REPO = Path(workflow.basedir)

LENS_LIGHT_SETTINGS = {
    "nn_mge": {"lens_light_model": "mge", "fit": {"positive_only": True}},
    "pn_mge": {"lens_light_model": "mge", "fit": {"positive_only": False}},
    "sersic": {"lens_light_model": "sersic", "fit": {"positive_only": True, "free_source": True}},
}
"""slam: settings of each value of the sheet's `lens_light` column (empty: nn_mge)."""


def repo_path(value: str) -> Path:
    """``value`` as a path; relative paths are taken from the repository root."""
    path = Path(value).expanduser()
    return path if path.is_absolute() else Path(os.path.normpath(REPO / path))


def sample_sheet(path: Path) -> pd.DataFrame:
    """The sample sheet (:func:`mgelens.sheet.read_sample_sheet`), indexed by lens id."""
    if not path.is_file():
        raise WorkflowError(
            f"sample sheet {path} not found: set `samples` in the config to a .tsv file "
            f"(relative paths start at the repository root {REPO})"
        )
    try:
        return read_sample_sheet(path)
    except SheetError as error:
        raise WorkflowError(str(error)) from None


SAMPLE_SHEET = repo_path(config["samples"])
LENSES = sample_sheet(SAMPLE_SHEET)
try:
    validate(LENSES, schema="../schemas/lenses.schema.yaml")
except WorkflowError as error:
    raise WorkflowError(f"sample sheet {SAMPLE_SHEET}: {error}") from None
DATA_DIR = repo_path(config["data_dir"])
if "lens_light" in LENSES.columns:
    _column_keys = {key for s in LENS_LIGHT_SETTINGS.values() for key in s if key != "fit"}
    _column_fit_keys = {key for s in LENS_LIGHT_SETTINGS.values() for key in s["fit"]}
    _config_fit = config["slam"].get("fit") or {}
    _light_keys = [key for key in sorted(_column_keys) if key in config["slam"]] + [
        f"fit.{key}" for key in sorted(_column_fit_keys) if key in _config_fit
    ]
    if _light_keys:
        raise WorkflowError(
            f"config: slam.{_light_keys[0]} contradicts the `lens_light` column of the sample "
            f"sheet {SAMPLE_SHEET}, which sets it per lens ({', '.join(LENS_LIGHT_SETTINGS)}); "
            "remove it from the config's slam: section or the column from the sheet"
        )


def lens_light_model_name(lens: str) -> str:
    """The lens's `lens_light` cell (nn_mge where the column or the cell is empty)."""
    if "lens_light" not in LENSES.columns or pd.isna(LENSES.loc[lens, "lens_light"]):
        return "nn_mge"
    return LENSES.loc[lens, "lens_light"]


def lens_row(lens: str) -> pd.Series:
    """The sheet's row of a lens. A target of a lens that the sheet does not list (one of
    another sample?) stops here, naming the sheet and its lenses: the `lens` wildcard
    takes any id, so that the rules reach this check instead of "No rule to produce"."""
    if lens not in LENSES.index:
        raise WorkflowError(
            f"lens {lens!r} is not in the sample sheet {SAMPLE_SHEET}, whose lenses are "
            f"{', '.join(LENSES.index)}; add a row for it, or give its sample's config "
            "with --configfile"
        )
    return LENSES.loc[lens]


def real_input_folder(lens: str) -> Path:
    """Input folder of a real lens: its `input` column, under `data_dir` if relative."""
    folder = Path(lens_row(lens)["input"]).expanduser()
    return folder if folder.is_absolute() else DATA_DIR / folder


def contaminant_file(lens: str) -> Path | None:
    """The lens's `contaminants` file (relative to the repository root), or None."""
    row = lens_row(lens)
    if "contaminants" not in row or pd.isna(row["contaminants"]):
        return None
    return repo_path(row["contaminants"])


def check_real_inputs() -> None:
    """Stop early, naming sheet, lens and folder, if a real lens's input folder is absent
    or a lens's contaminants file is."""
    for lens in LENSES.index[LENSES["kind"] == "real"]:
        folder = real_input_folder(lens)
        missing = [f for f in ("data.fits", "noise_map.fits", "psf.fits") if not (folder / f).is_file()]
        if missing:
            raise WorkflowError(
                f"{SAMPLE_SHEET}: real lens {lens!r}: {', '.join(missing)} not found in {folder}; "
                f"set `data_dir` in the config (now {config['data_dir']!r}, relative to "
                f"{REPO}) or fix the `input` column of the sheet"
            )
    for lens in LENSES.index:
        path = contaminant_file(lens)
        if path is not None and not path.is_file():
            raise WorkflowError(
                f"{SAMPLE_SHEET}: lens {lens!r}: contaminants file {path} not found; fix the "
                f"`contaminants` column (relative to {REPO}) or leave it empty"
            )


check_real_inputs()



def other_than(ids) -> str:
    """Regular expression of a lens id (one path part) other than the given ids."""
    ids = list(ids)
    if not ids:
        return "[^/]+"
    return f"(?!(?:{'|'.join(re.escape(i) for i in ids)})/)[^/]+"


MOCK_LENSES = other_than(LENSES.index[LENSES["kind"] == "real"])
"""Lens ids the mock rules take: any but the real lenses' (unknown ids reach lens_row)."""


wildcard_constraints:
    lens="[^/]+",


def is_mock(lens: str) -> bool:
    return lens_row(lens)["kind"] == "mock"


def imaging_folder(lens: str) -> str:
    """Folder holding data.fits, noise_map.fits and psf.fits of a lens."""
    return f"results/{lens}/mock" if is_mock(lens) else str(real_input_folder(lens))


def mock_folder(wildcards) -> str:
    return f"results/{wildcards.lens}/mock"


def lens_imaging_folder(wildcards) -> str:
    return imaging_folder(wildcards.lens)


def imaging_files(wildcards) -> dict:
    """data, noise_map and psf files of a lens (mock: made by rule simulate_mock), a real
    lens's optional mask.fits and info.json (pixel scale), which the fits read too, and
    the sheet's contaminants file."""
    folder = imaging_folder(wildcards.lens)
    files = {name: f"{folder}/{name}.fits" for name in ("data", "noise_map", "psf")}
    if not is_mock(wildcards.lens):
        for name, file in (("mask", MASK_FILE), ("info", INFO_FILE)):
            if (Path(folder) / file).is_file():
                files[name] = f"{folder}/{file}"
    contaminants = contaminant_file(wildcards.lens)
    if contaminants is not None:
        files["contaminants"] = str(contaminants)
    return files


def contaminants_option(wildcards) -> str:
    """` --contaminants <file>` from the sheet's `contaminants` column, if the lens has
    one; else ``""``."""
    path = contaminant_file(wildcards.lens)
    return "" if path is None else f" --contaminants {shlex.quote(str(path))}"


def pixel_scale_option(wildcards) -> str:
    """` --pixel-scale <arcsec>` from the sheet's `pixel_scale` column, if the lens has one
    (a folder without info.json whose data header has no pixel scale); else ``""``."""
    row = lens_row(wildcards.lens)
    if "pixel_scale" not in row or pd.isna(row["pixel_scale"]):
        return ""
    return f" --pixel-scale {row['pixel_scale']}"


def preview_inputs(wildcards) -> dict:
    """Files the preview of a lens reads: the imaging, plus the truth of a mock."""
    files = imaging_files(wildcards)
    if is_mock(wildcards.lens):
        folder = imaging_folder(wildcards.lens)
        for name in ("lens_light_blurred", "lensed_source_blurred", "source"):
            files[name] = f"{folder}/{name}.fits"
        files["truth"] = f"{folder}/truth.json"
    return files


def simulate_recipe(wildcards) -> str:
    """CLI arguments naming the mock of a lens: a paper mock, a population lens or an
    independent (lenstronomy) mock."""
    recipe = lens_row(wildcards.lens)["mock"]
    seed = f"--population-seed {config['population_seed']}"
    if recipe.startswith("P"):
        return f"--population-index {int(recipe[1:])} {seed}"
    if recipe.startswith("L"):
        return f"--independent-index {int(recipe[1:])} {seed}"
    noise_seed = lens_row(wildcards.lens).get("noise_seed")
    if noise_seed is None or pd.isna(noise_seed):
        return f"--mock {recipe}"
    return f"--mock {recipe} --noise-seed {int(noise_seed)}"


def simulate_mem_mb(wildcards, attempt) -> int:
    return 1500 * attempt


def preview_mem_mb(wildcards, attempt) -> int:
    return 1000 * attempt


def isophote_inputs(wildcards) -> dict:
    """The final (MASS) phase of a lens, whose lens light is analysed (SPEC §9), and its PSF."""
    folder = f"results/{wildcards.lens}/mass"
    return {
        "result": f"{folder}/result.json",
        "model": f"{folder}/model.fits",
        "psf": imaging_files(wildcards)["psf"],
    }


def isophote_summaries(wildcards) -> list[str]:
    """Per-lens isophote summaries gathered by the sample summary (every lens)."""
    return [f"results/{lens}/isophotes.json" for lens in LENSES.index]


def quality_inputs(wildcards) -> dict:
    """The MASS phase's result and model.fits, and the imaging of a lens (read for its noise
    map, pixel scale and mask)."""
    folder = f"results/{wildcards.lens}/mass"
    files = imaging_files(wildcards)
    return {"result": f"{folder}/result.json", "model": f"{folder}/model.fits", **files}


def summary_inputs(wildcards) -> dict:
    """Everything the sample summary reads per lens (isophote summary, quality record, LIGHT
    model choice, MASS result, samples and model) and the published tables that exist (:func:`reference_tables`)."""
    lenses = list(LENSES.index)
    return {
        "summaries": isophote_summaries(wildcards),
        "quality": [f"results/{lens}/quality.json" for lens in lenses],
        "choices": [f"results/{lens}/model_choice.json" for lens in CHOSEN_LIGHT_LENSES],
        "mass": [
            f"results/{lens}/mass/{name}"
            for lens in lenses
            for name in ("result.json", "samples.csv", "model.fits")
        ],
        "reference": reference_tables(),
    }


REFERENCE_DIR = repo_path(config["reference_dir"])
REFERENCE_FILES = ("bolton2008_table5_sie.csv", "shajib2021_slacs_powerlaw_tdcosmo2020.csv")


def reference_tables() -> list[str]:
    """The published tables in `reference_dir` (none if the folder is absent: the summary
    then writes NaN for them and says so in its log)."""
    return [str(REFERENCE_DIR / name) for name in REFERENCE_FILES if (REFERENCE_DIR / name).is_file()]


def chain_cost_inputs(wildcards) -> list[str]:
    """The benchmark files of every lens's chain jobs (SP, SPix1, SPix2 or its candidates,
    its LIGHT job or candidates, MASS or its mesh jobs and their pool) that the chain_cost
    step sums (mgelens.chain_cost), for the config's and the sheet's current models only,
    not files left from another configuration."""
    files = []
    for lens in LENSES.index:
        models = lens_light_models(lens)
        light = ["light"] if len(models) == 1 else [model.folder for model in models]
        jobs = ["sp", "spix1", *SPIX2_JOBS, *light, *MASS_JOBS]
        files += [f"results/{lens}/benchmarks/{job}.tsv" for job in jobs]
    return files


MOCK_LENS_IDS = list(LENSES.index[LENSES["kind"] == "mock"])
"""The sheet's mock lenses, in sheet order."""


def recovery_records(wildcards) -> list[str]:
    """Per-mock recovery records gathered into results/summary/recovery.csv."""
    return [f"results/{lens}/recovery.json" for lens in MOCK_LENS_IDS]


def mock_quality_records(wildcards) -> list[str]:
    """Per-mock quality records (rule fit_quality), whose flags the coverage study reads."""
    return [f"results/{lens}/quality.json" for lens in MOCK_LENS_IDS]


SMOOTHNESS_MOCK = "M1"
"""The paper mock of the Appendix A scan (rule smoothness)."""
SMOOTHNESS_LENSES = list(
    LENSES.index[(LENSES["kind"] == "mock") & (LENSES["mock"] == SMOOTHNESS_MOCK)]
)
"""Lenses of the sheet simulated as that mock; the scan reads the first one's folder."""


def smoothness_inputs(wildcards) -> dict:
    """The mock folder's files that rule smoothness reads."""
    folder = f"results/{SMOOTHNESS_LENSES[0]}/mock"
    names = ("data", "noise_map", "psf", "lensed_source_blurred")
    return {
        **{name: f"{folder}/{name}.fits" for name in names},
        "truth": f"{folder}/truth.json",
    }


def smoothness_folder(wildcards) -> str:
    return f"results/{SMOOTHNESS_LENSES[0]}/mock"


def smoothness_mask_radius(wildcards) -> float:
    """The scanned lens's mask radius from the sheet, as its phases use."""
    return float(lens_row(SMOOTHNESS_LENSES[0])["mask_radius"])


PAPER_MOCK_FITS = [
    (lens, LENSES.loc[lens, "mock"], lens_light_model_name(lens))
    for lens in LENSES.index[(LENSES["kind"] == "mock") & LENSES["mock"].isin(PAPER_MOCKS)]
]
"""(lens, mock, lens-light model) of every sheet row that fits a paper mock (rule
mock_study)."""
PAPER_MOCK_MODELS = [m for m in MOCK_STUDY_MODELS if any(f[2] == m for f in PAPER_MOCK_FITS)]
"""Lens-light models among them, in the paper's order: one Figure 5-7 each."""


def mock_study_inputs(wildcards) -> list[str]:
    """What the mock study (rule mock_study) reads of each paper-mock fit, its recovery
    record, MASS result and model image, and its mock's data, true lens light and truth."""
    names = (
        "recovery.json", "mass/result.json", "mass/model.fits", "mock/data.fits",
        "mock/lens_light_blurred.fits", "mock/truth.json",
    )  # fmt: skip
    return [f"results/{lens}/{name}" for lens, _, _ in PAPER_MOCK_FITS for name in names]


def mock_study_fits(wildcards) -> str:
    return " ".join(f"--fit {lens} {mock} {model}" for lens, mock, model in PAPER_MOCK_FITS)


def all_targets() -> list[str]:
    """Default target: previews, overview and posterior figures, the sample summary and its figures
    (which need every lens's SLaM chain, isophotes and quality record), what each chain
    cost (rule chain_cost), and, if the sample
    has mocks, the table of their recovered truth and their posterior coverage and, if
    one of them is M1, the Appendix A smoothness scan."""
    targets = [f"results/{lens}/figures/preview.png" for lens in LENSES.index]
    targets += [f"results/{lens}/figures/overview.png" for lens in LENSES.index]
    targets += [f"results/{lens}/figures/posterior.png" for lens in LENSES.index]
    if (LENSES["kind"] == "mock").any():
        targets += ["results/summary/recovery.csv", "results/summary/coverage.png"]
    if SMOOTHNESS_LENSES:
        targets.append("results/summary/smoothness.png")
    if PAPER_MOCK_FITS:
        targets.append("results/summary/mock_table.csv")
    summary = (
        "lenses.csv",
        "light_models.csv",
        "histograms.png",
        "einstein_radii.png",
        "residual_mosaic.png",
        "chain_cost.csv",
        "chain_cost.png",
    )
    return targets + [f"results/summary/{name}" for name in summary]


# SLaM phases (workflow/rules/slam.smk)

PHASES = ["sp", "spix1", "spix2", "light", "mass"]
LIGHT_FOLDERS = "light_x[0-9]+(?:_point)?"
"""Folders of LIGHT candidates (mgelens.pipeline.model_choice.LightModel.folder)."""
SPIX2_FOLDERS = f"{SPIX2_PREFIX}[0-9]+"
"""Folders of SPix2 candidates (mgelens.pipeline.pixel_choice.folder)."""
SOURCE_PIXELS = CONFIG_SETTINGS.source_pixel_candidates
"""The k-means pixel counts of the config: one, or the candidates that rule
choose_source_pixels compares by SPix2's evidence (mgelens.pipeline.pixel_choice)."""
CHOSEN_PIXELS = len(SOURCE_PIXELS) > 1
SPIX2_JOBS = [spix2_folder(n) for n in SOURCE_PIXELS] if CHOSEN_PIXELS else ["spix2"]
"""The SPix2 jobs of every lens: one per candidate count, or `spix2` itself."""
MESH_JOBS = (
    [mesh_folder(k) for k in range(CONFIG_SETTINGS.mass_meshes)]
    if CONFIG_SETTINGS.mass_meshes > 1
    else []
)
"""MASS's source-mesh jobs of every lens (rule mass_mesh, `mass_mesh<k>`), which rule
pool_mass pools into `mass/` (mgelens.pipeline.mesh_pool); none where MASS has one mesh
(rule phase fits it whole)."""
MESH_FOLDERS = "|".join(MESH_JOBS) or "(?!)"
MASS_JOBS = [*MESH_JOBS, POOL_JOB] if MESH_JOBS else ["mass"]
"""The MASS jobs of every lens whose benchmark files the chain's cost sums."""


wildcard_constraints:
    phase=f"{'|'.join(PHASES)}|{LIGHT_FOLDERS}|{SPIX2_FOLDERS}|{MESH_FOLDERS}",


def lens_light_models(lens: str):
    """The LIGHT models of a lens: one if its sheet row pins `mge_sets` and `point_set`,
    else the candidates that rule choose_light compares (mgelens.pipeline.model_choice)."""
    row = lens_row(lens)
    return light_candidates(row["mge_sets"], row["point_set"])


CHOSEN_LIGHT_LENSES = [lens for lens in LENSES.index if len(lens_light_models(lens)) > 1]
"""Lenses whose LIGHT model is chosen by evidence (a sheet row with `auto`)."""
CHOSEN_LIGHT = (
    f"(?:{'|'.join(re.escape(lens) for lens in CHOSEN_LIGHT_LENSES)})"
    if CHOSEN_LIGHT_LENSES
    else "(?!)"
)
"""Lens ids of rules light_candidate and choose_light; rule phase_light takes the others."""
PINNED_LIGHT = other_than(CHOSEN_LIGHT_LENSES)


def phase_inputs(wildcards) -> dict:
    """Imaging files of the lens, the result files of the phases before this one and, after
    SPix1, SPix1's adapt image. A LIGHT candidate (`light_x<n>[_point]`) needs what LIGHT
    needs, an SPix2 candidate (`spix2_n<count>`) what SPix2 needs."""
    files = imaging_files(wildcards)
    phase = phase_name(wildcards)
    earlier = PHASES[: PHASES.index(phase)]
    for name in earlier:
        files[name] = f"results/{wildcards.lens}/{name}/result.json"
    if "spix1" in earlier:
        files["adapt_image"] = f"results/{wildcards.lens}/spix1/adapt_image.fits"
    reference = light_bound_reference(wildcards)
    if reference is not None:
        files["bound_by"] = f"results/{wildcards.lens}/{reference}/result.json"
    return files


def overview_inputs(wildcards) -> dict:
    """Files the overview figure reads to rebuild the MASS fit: MASS's result, samples and
    model, and what the MASS phase itself read (:func:`phase_inputs`: the imaging, the
    earlier phases' results and SPix1's adapt image)."""
    files = phase_inputs(SimpleNamespace(lens=wildcards.lens, phase="mass"))
    folder = f"results/{wildcards.lens}/mass"
    files["result"] = f"{folder}/result.json"
    files["samples"] = f"{folder}/samples.csv"
    files["model"] = f"{folder}/model.fits"
    return files


def posterior_inputs(wildcards) -> dict:
    """Files the posterior figure reads: MASS's result and samples, and a mock's truth or a
    real lens's published tables that exist (:func:`reference_tables`)."""
    folder = f"results/{wildcards.lens}/mass"
    files = {"result": f"{folder}/result.json", "samples": f"{folder}/samples.csv"}
    if is_mock(wildcards.lens):
        files["truth"] = f"{imaging_folder(wildcards.lens)}/truth.json"
    elif tables := reference_tables():
        files["reference"] = tables
    return files


def posterior_marks(wildcards, input) -> str:
    """` --truth <truth.json>` for a mock, ` --reference-dir <folder>` for a real lens with
    the published tables (else nothing: the figure has no published values)."""
    if "truth" in input.keys():
        return f" --truth {input.truth}"
    if "reference" in input.keys():
        return f" --reference-dir {shlex.quote(str(REFERENCE_DIR))}"
    return ""


def overview_mem_mb(wildcards, attempt) -> int:
    return 3000 * attempt


def light_model_of(wildcards):
    """The LIGHT model a `phase` wildcard stands for: a candidate folder's, or the pinned one."""
    models = lens_light_models(wildcards.lens)
    if wildcards.phase == "light":
        return models[0]
    return next(m for m in models if m.folder == wildcards.phase)


def light_bound_reference(wildcards) -> str | None:
    """Folder of the LIGHT candidate that bounds this one (`mgelens phase --bound-by`): the
    lens's candidate with the most linear unknowns, fitted first, for each of its other
    candidates when `model_choice_bound` is on; None for every other phase."""
    if not (config["model_choice_bound"] and wildcards.phase.startswith("light_")):
        return None
    largest = max(lens_light_models(wildcards.lens), key=lambda m: (m.mge_sets, m.point_set))
    return None if largest.folder == wildcards.phase else largest.folder


def phase_options(wildcards) -> str:
    """Per-lens CLI options from the sample sheet: the mask radius, pixel scale and
    contaminants file, and for
    LIGHT (the only phase that reads them) the MGE sets and point set of the pinned model
    or of the candidate; a candidate's folder or a MASS mesh job's mesh; then the config's
    sampler seed."""
    row = lens_row(wildcards.lens)
    options = f"--mask-radius {row['mask_radius']}{pixel_scale_option(wildcards)}"
    options += contaminants_option(wildcards)
    if wildcards.phase.startswith("light"):
        model = light_model_of(wildcards)
        point = "yes" if model.point_set else "no"
        options += f" --mge-sets {model.mge_sets} --point-set {point}"
    if wildcards.phase in MESH_JOBS:
        options += f" --mesh {wildcards.phase.removeprefix(MESH_FOLDER_PREFIX)}"
    elif wildcards.phase != phase_name(wildcards):
        options += f" --folder {wildcards.phase}"
    reference = light_bound_reference(wildcards)
    if reference is not None:
        options += f" --bound-by {reference} --bound-threshold {config['model_choice_threshold']}"
    return options + f" --seed {config['sampler_seed']}"


def light_candidate_results(wildcards) -> list[str]:
    """result.json of each LIGHT candidate of a lens (rule choose_light)."""
    return [
        f"results/{wildcards.lens}/{model.folder}/result.json"
        for model in lens_light_models(wildcards.lens)
    ]


def light_candidate_labels(wildcards) -> str:
    return " ".join(model.label for model in lens_light_models(wildcards.lens))


_FROM_SPIX2 = ("spix2", "light", "mass")
PHASE_SETTINGS = {
    "mass_source_pixels": ("mass",),
    "mass_mesh_tuning": ("mass",),
    "adaptive_signals_mass": ("mass",),
    "source_support": _FROM_SPIX2,
    "arc_noise_floor": _FROM_SPIX2,
    "kmeans_seeding": _FROM_SPIX2,
    "lens_light_prior": ("light", "mass"),
}
"""slam: settings that reach only the phases listed, so that changing one reruns those
phases (and the phases after them) only: MASS's own mesh settings and its adaptive signals
(LIGHT's mass is SPix2's, whose signals it holds either way), the k-means mesh's and the
source support's from SPix2 on, and the MGE intensities' prior in LIGHT and MASS."""


def phase_settings(wildcards) -> str:
    """The config's slam: section as JSON, with the lens's `lens_light` settings
    (:func:`lens_light_settings`) and the sampler settings of this phase only, so that
    changing one phase's sampler reruns that phase (and the phases after it) only; the
    settings of :data:`PHASE_SETTINGS` go to their phases only, likewise. An SPix2
    candidate (`spix2_n<count>`) gets its own count as `source_pixels`."""
    light = lens_light_settings(wildcards.lens)
    section = {**config["slam"], **light}
    fit = {**(config["slam"].get("fit") or {}), **light.get("fit", {})}
    if fit:
        section["fit"] = fit
    samplers = section.pop("samplers", None) or {}
    phase = phase_name(wildcards)
    for key, phases in PHASE_SETTINGS.items():
        if phase not in phases:
            section.pop(key, None)
    if phase in samplers:
        section["samplers"] = {phase: samplers[phase]}
    if wildcards.phase.startswith(SPIX2_PREFIX):
        section["source_pixels"] = int(wildcards.phase.removeprefix(SPIX2_PREFIX))
    return json.dumps(section, sort_keys=True)


def lens_light_settings(lens: str) -> dict:
    """The slam: settings of the lens's `lens_light` cell ({} without that column, so that
    a sheet without it keeps the config's settings and its phases' --slam unchanged)."""
    if "lens_light" not in LENSES.columns:
        return {}
    return dict(LENS_LIGHT_SETTINGS[lens_light_model_name(lens_row(lens)["lens"])])


def phase_name(wildcards) -> str:
    """The SLaM phase a `phase` wildcard runs: `light` for a LIGHT candidate's folder,
    `spix2` for an SPix2 candidate's, `mass` for a MASS mesh job's."""
    if wildcards.phase.startswith("light"):
        return "light"
    if wildcards.phase in MESH_JOBS:
        return "mass"
    if wildcards.phase.startswith(SPIX2_PREFIX):
        return "spix2"
    return wildcards.phase


def mesh_job_results(wildcards) -> dict:
    """result.json of each MASS mesh job of a lens (rule pool_mass)."""
    return {job: f"results/{wildcards.lens}/{job}/result.json" for job in MESH_JOBS}


def spix2_candidate_results(wildcards) -> list[str]:
    """result.json of each SPix2 candidate of a lens (rule choose_source_pixels)."""
    return [f"results/{wildcards.lens}/{job}/result.json" for job in SPIX2_JOBS]


def phase_priority(wildcards) -> int:
    """Earlier phases first (SP highest): with more lenses than cores, every lens's SP, the
    longest phase, starts before any chain's later phases, so no late SP sets the tail."""
    return len(PHASES) - PHASES.index(phase_name(wildcards))


def phase_mem_mb(wildcards, attempt) -> int:
    return 4000 * attempt

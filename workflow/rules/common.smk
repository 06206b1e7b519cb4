"""Sample sheet, configuration checks, wildcard constraints and path helpers.

Every helper is a named function (no lambdas in rules). Relative paths in the config
(`samples`, `data_dir`) are relative to the repository root, the folder of the
top-level Snakefile, so `snakemake -d <elsewhere>` finds them too.
"""

import json
import os
import re
from pathlib import Path
from types import SimpleNamespace

import pandas as pd
from snakemake.exceptions import WorkflowError
from snakemake.utils import validate

from mgelens.imaging import INFO_FILE, MASK_FILE
from mgelens.provenance import code_version
from mgelens.pipeline.settings import SettingsError, settings_from_mapping
from mgelens.sheet import SheetError, read_sample_sheet


validate(config, schema="../schemas/config.schema.yaml")
try:  # stop before building the DAG if the slam: section is wrong, naming the key
    settings_from_mapping(config["slam"], origin="config")
except SettingsError as error:
    raise WorkflowError(str(error)) from None
SHEET_SETTINGS = ("mask_radius", "mge_sets", "point_set")
"""slam: fields that the sample sheet sets per lens (columns of the same names)."""
_sheet_keys = [key for key in SHEET_SETTINGS if key in config["slam"]]
if _sheet_keys:
    raise WorkflowError(
        f"config: slam.{_sheet_keys[0]} is set per lens "
        f"by the sample sheet's column of that name ({', '.join(SHEET_SETTINGS)}); "
        "remove it from the config's slam: section and edit the sheet instead"
    )

REPO = Path(workflow.basedir)
MGELENS_VERSION = code_version()  # version + source digest: any library edit reruns


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


def check_real_inputs() -> None:
    """Stop early, naming sheet, lens and folder, if a real lens's input folder is absent."""
    for lens in LENSES.index[LENSES["kind"] == "real"]:
        folder = real_input_folder(lens)
        missing = [f for f in ("data.fits", "noise_map.fits", "psf.fits") if not (folder / f).is_file()]
        if missing:
            raise WorkflowError(
                f"{SAMPLE_SHEET}: real lens {lens!r}: {', '.join(missing)} not found in {folder}; "
                f"set `data_dir` in the config (now {config['data_dir']!r}, relative to "
                f"{REPO}) or fix the `input` column of the sheet"
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
    """data, noise_map and psf files of a lens (mock: made by rule simulate_mock), and a
    real lens's optional mask.fits and info.json (pixel scale), which the fits read too."""
    folder = imaging_folder(wildcards.lens)
    files = {name: f"{folder}/{name}.fits" for name in ("data", "noise_map", "psf")}
    if not is_mock(wildcards.lens):
        for name, file in (("mask", MASK_FILE), ("info", INFO_FILE)):
            if (Path(folder) / file).is_file():
                files[name] = f"{folder}/{file}"
    return files


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
    """CLI arguments naming the mock of a lens: a paper mock or a population lens."""
    recipe = lens_row(wildcards.lens)["mock"]
    if recipe.startswith("P"):
        return f"--population-index {int(recipe[1:])} --population-seed {config['population_seed']}"
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


def recovery_records(wildcards) -> list[str]:
    """Per-mock recovery records gathered into results/summary/recovery.csv."""
    return [f"results/{lens}/recovery.json" for lens in LENSES.index[LENSES["kind"] == "mock"]]


def all_targets() -> list[str]:
    """Default target: previews and overview figures, the sample summary (which needs every
    lens's SLaM chain and isophotes) and, if the sample has mocks, the table of their
    recovered truth."""
    targets = [f"results/{lens}/figures/preview.png" for lens in LENSES.index]
    targets += [f"results/{lens}/figures/overview.png" for lens in LENSES.index]
    if (LENSES["kind"] == "mock").any():
        targets.append("results/summary/recovery.csv")
    return targets + ["results/summary/lenses.csv", "results/summary/histograms.png"]


# SLaM phases (workflow/rules/slam.smk)

PHASES = ["sp", "spix1", "spix2", "light", "mass"]


wildcard_constraints:
    phase="|".join(PHASES),


def phase_inputs(wildcards) -> dict:
    """Imaging files of the lens, the result files of the phases before this one and, after
    SPix1, SPix1's adapt image."""
    files = imaging_files(wildcards)
    earlier = PHASES[: PHASES.index(wildcards.phase)]
    for name in earlier:
        files[name] = f"results/{wildcards.lens}/{name}/result.json"
    if "spix1" in earlier:
        files["adapt_image"] = f"results/{wildcards.lens}/spix1/adapt_image.fits"
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


def overview_mem_mb(wildcards, attempt) -> int:
    return 3000 * attempt


def phase_options(wildcards) -> str:
    """Per-lens CLI options from the sample sheet: the mask radius, and for LIGHT (the only
    phase that reads them) the MGE sets and point set; then the config's sampler seed."""
    row = lens_row(wildcards.lens)
    options = f"--mask-radius {row['mask_radius']}"
    if wildcards.phase == "light":
        options += f" --mge-sets {row['mge_sets']} --point-set {row['point_set']}"
    return options + f" --seed {config['sampler_seed']}"


def phase_settings(wildcards) -> str:
    """The config's slam: section as JSON, with the sampler settings of this phase only, so
    that changing one phase's sampler reruns that phase (and the phases after it) only."""
    section = dict(config["slam"])
    samplers = section.pop("samplers", None) or {}
    if wildcards.phase in samplers:
        section["samplers"] = {wildcards.phase: samplers[wildcards.phase]}
    return json.dumps(section, sort_keys=True)


def phase_priority(wildcards) -> int:
    """Earlier phases first (SP highest): with more lenses than cores, every lens's SP, the
    longest phase, starts before any chain's later phases, so no late SP sets the tail."""
    return len(PHASES) - PHASES.index(wildcards.phase)


def phase_mem_mb(wildcards, attempt) -> int:
    return 4000 * attempt

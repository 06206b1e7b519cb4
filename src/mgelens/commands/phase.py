"""``mgelens phase``: run one SLaM phase of one lens (SPEC §8).

Example::

    mgelens phase sp --lens-dir results/M1/mock --results results/M1 --threads 2
    mgelens phase mass --lens-dir ../shared/data/slacs/slacs0252+0039 \\
        --results results/slacs0252+0039 --config config/config.yaml --profile paper \\
        --mask-radius 3.0 --mge-sets 2 --point-set yes

The phase reads the imaging of ``--lens-dir`` and the earlier phases' folders under
``--results``, and writes ``<results>/<phase>/`` (result.json, samples.csv, model.fits,
phase.log, cost.json with the job's CPU seconds (:mod:`mgelens.pipeline.job_cost`); spix1
also adapt_image.fits). Settings: the ``--profile`` defaults ("quick"
unless the ``slam:`` settings say otherwise), then the ``slam:`` section of ``--config``,
then ``--slam`` (the same content as JSON; the workflow passes its config's section this
way). What is set per lens (:class:`~mgelens.pipeline.settings.LensSpec`, the sample
sheet's columns) comes from ``--mask-radius`` (default: the folder's ``truth.json``),
``--mask-centre``, ``--pixel-scale``, ``--contaminants`` (a text file of circles),
``--mge-sets`` (default 4) and ``--point-set`` (default yes). A LIGHT candidate given
``--bound-by`` is not sampled when it cannot win the model choice against that folder's
candidate (:mod:`mgelens.pipeline.light_bound`). MASS's source meshes can run as separate
jobs, ``--mesh k`` for each, then ``--pool-meshes`` (:mod:`mgelens.pipeline.mesh_pool`).
"""

import argparse
import json
import logging
import time
from pathlib import Path

from mgelens import threads
from mgelens.commands import make_output_folders
from mgelens.imaging_input import ImagingError
from mgelens.mask import read_contaminant_circles
from mgelens.memory import keep_freed_memory
from mgelens.pipeline import records
from mgelens.pipeline.job_cost import write_job_cost
from mgelens.pipeline.mesh_pool import pool_meshes
from mgelens.pipeline.model_choice import DEFAULT_THRESHOLD
from mgelens.pipeline.run import mesh_folder, run_phase
from mgelens.pipeline.settings import (
    MGE_SET_CHOICES,
    PHASES,
    PROFILES,
    LensSpec,
    SettingsError,
    load_settings,
)
from mgelens.search.results import RESULT_FILE

logger = logging.getLogger("mgelens.pipeline")


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "phase",
        help="run one SLaM phase (sp, spix1, spix2, light, mass) of one lens",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("phase", choices=PHASES, help="phase to run")
    parser.add_argument(
        "--lens-dir",
        type=Path,
        required=True,
        help="folder with data.fits, noise_map.fits, psf.fits",
    )
    parser.add_argument(
        "--results",
        type=Path,
        required=True,
        help="results folder of the lens (one sub-folder per phase)",
    )
    parser.add_argument(
        "--folder",
        metavar="NAME",
        help="phase folder under --results (default: the phase's name); the workflow "
        "writes each candidate LIGHT model to light_<model>",
    )
    parser.add_argument("--config", type=Path, help="YAML file with a `slam:` settings section")
    parser.add_argument(
        "--slam",
        type=_json_mapping,
        default={},
        metavar="JSON",
        help='a `slam:` section as JSON, e.g. \'{"samplers": {"mass": {"n_live": 80}}}\'',
    )
    parser.add_argument("--profile", choices=sorted(PROFILES), help="speed profile (default quick)")
    parser.add_argument("--threads", type=int, default=1, help="numba/BLAS threads (default 1)")
    parser.add_argument("--seed", type=int, default=0, help="sampler seed (default 0)")
    parser.add_argument("--mask-radius", type=float, help="mask radius in arcsec")
    parser.add_argument(
        "--mask-centre",
        type=float,
        nargs=2,
        default=(0.0, 0.0),
        metavar=("X", "Y"),
        help="mask centre in arcsec, also the centre of SP's priors (default 0 0)",
    )
    parser.add_argument(
        "--pixel-scale",
        type=float,
        help="arcsec per image pixel (default: the folder's info.json, else the data header)",
    )
    parser.add_argument(
        "--contaminants",
        type=Path,
        metavar="FILE",
        help="text file of circles `x y radius` (arcsec) whose pixels the fit treats as "
        "contaminants, for neighbours the noise map does not mark",
    )
    parser.add_argument(
        "--mge-sets",
        type=int,
        choices=MGE_SET_CHOICES,
        default=LensSpec.mge_sets,
        help=f"MGE sets of the light phase (default {LensSpec.mge_sets})",
    )
    parser.add_argument(
        "--point-set",
        choices=("yes", "no"),
        default="yes" if LensSpec.point_set else "no",
        help="add the point set (light phase)",
    )
    parser.add_argument(
        "--bound-by",
        metavar="FOLDER",
        help="light only: a more complex LIGHT candidate already fitted in <results>/FOLDER; "
        "this candidate is not sampled if a local search of its highest ln ε shows that it "
        "cannot come within --bound-threshold of FOLDER's ln Z (it writes that maximum, "
        "an upper bound of its ln Z)",
    )
    parser.add_argument(
        "--mesh",
        type=int,
        metavar="K",
        help="mass only, with slam.mass_meshes >= 2: sample source mesh K alone into "
        "<results>/mass_mesh<K> (seeds as the whole phase gives it); --pool-meshes pools them",
    )
    parser.add_argument(
        "--pool-meshes",
        action="store_true",
        help="mass only: write <results>/mass from the mesh jobs' folders mass_mesh<k> "
        "(same settings and --seed), without sampling",
    )
    parser.add_argument(
        "--bound-threshold",
        type=float,
        default=DEFAULT_THRESHOLD,
        help=f"the model choice's ln Z threshold for --bound-by (default {DEFAULT_THRESHOLD})",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    started = time.perf_counter()
    try:
        threads.limit_threads(args.threads)
        keep_freed_memory()
        settings = load_settings(args.config, args.profile, args.slam)
        lens = LensSpec(
            mask_radius=args.mask_radius,
            mask_centre=tuple(args.mask_centre),
            pixel_scale=args.pixel_scale,
            mge_sets=args.mge_sets,
            point_set=args.point_set == "yes",
            contaminants=read_contaminant_circles(args.contaminants) if args.contaminants else (),
        )
        if args.pool_meshes:
            if args.phase != "mass" or args.mesh is not None:
                raise ValueError(
                    "--pool-meshes pools MASS's mesh jobs: use it with phase mass, no --mesh"
                )
            folder = args.folder or "mass"
            pool_meshes(args.results, settings, args.seed, folder)
            write_job_cost(args.results / folder, started)
            return 0
        folder = args.folder or (args.phase if args.mesh is None else mesh_folder(args.mesh))
        make_output_folders(args.results / folder / RESULT_FILE)
        run_phase(
            args.phase,
            args.lens_dir,
            args.results,
            settings,
            lens,
            seed=args.seed,
            folder_name=folder,
            bound_by=None if args.bound_by is None else (args.bound_by, args.bound_threshold),
            mesh=args.mesh,
        )
        write_job_cost(args.results / folder, started)
    except (SettingsError, ImagingError, records.PhaseInputError, ValueError, OSError) as error:
        logger.error("phase %s: %s", args.phase, error)
        return 1
    return 0


def _json_mapping(text: str) -> dict:
    """argparse type: a JSON object."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError as error:
        raise argparse.ArgumentTypeError(f"--slam is not valid JSON: {error}") from error
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError("--slam must be a JSON object")
    return value

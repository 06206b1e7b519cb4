"""``mgelens smoothness``: ln ε against the mass slope on a mock (the paper's Appendix A).

Example::

    mgelens smoothness --lens-dir results/M1/mock --out results/summary/smoothness.png \\
        --table results/summary/smoothness.csv

Reads a mock folder written by ``mgelens simulate`` (``data.fits``, ``noise_map.fits``,
``psf.fits``, ``lensed_source_blurred.fits`` and ``truth.json``), fixes every parameter at
its truth in a circular mask of ``--mask-radius`` (default: the mock's own), the source
mesh (``--source-pixels`` k-means centres weighted by the true lensed source, seed
``--mesh-seed``) and the regularization (λ = 1), and evaluates ln ε with NNLS at
γ_true ± ``--half-range`` in steps of ``--step`` for natural-neighbour interpolation +
cross regularization and nearest-cell mapping + neighbour regularization, each under the
anchor's and the continuous edge rules (:mod:`mgelens.smoothness`). Writes the figure,
the table (one row per scheme, edge rule and slope: ``scheme, edge_rule, slope,
log_evidence, jump``) and prints each curve's largest, 95th-percentile and median jump.
"""

import argparse
import json
import logging
from pathlib import Path

from mgelens.atomic import atomic_path
from mgelens.commands import add_threads_argument, make_output_folders
from mgelens.imaging import Imaging
from mgelens.imaging_input import ImagingError, read_fits_image
from mgelens.mask import circular
from mgelens.mass import EPL
from mgelens.plot import save_png
from mgelens.plot.smoothness import smoothness_figure
from mgelens.simulate import mass_from_truth
from mgelens.smoothness import (
    HALF_RANGE,
    STEP,
    appendix_a_table,
    jump_summary,
    mock_dataset,
    scan_model,
)
from mgelens.threads import limit_threads

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "smoothness",
        help="ln ε against the mass slope on a mock, for two source schemes (Appendix A)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--lens-dir", type=Path, required=True, help="mock folder (truth.json)")
    parser.add_argument("--out", type=Path, required=True, help="figure (PNG)")
    parser.add_argument("--table", type=Path, required=True, help="scan table (CSV)")
    parser.add_argument(
        "--source-pixels", type=int, default=500, help="k-means source pixels (default 500)"
    )
    parser.add_argument("--mesh-seed", type=int, default=1, help="k-means seed (default 1)")
    parser.add_argument(
        "--mask-radius",
        type=float,
        help="radius of the circular fit mask, arcsec (default: truth.json's mask_radius)",
    )
    parser.add_argument("--step", type=float, default=STEP, help=f"γ step (default {STEP})")
    parser.add_argument(
        "--half-range",
        type=float,
        default=HALF_RANGE,
        help=f"γ half-range about the truth (default {HALF_RANGE})",
    )
    add_threads_argument(parser)
    parser.set_defaults(func=run)


def _checked(args: argparse.Namespace) -> str | None:
    """Why the numeric options are unusable, or None."""
    if args.mask_radius is not None and not args.mask_radius > 0:
        return f"--mask-radius {args.mask_radius}: give a positive radius in arcsec"
    if args.source_pixels < 3:
        return f"--source-pixels {args.source_pixels}: give at least 3"
    if not args.step > 0 or not args.half_range >= 2 * args.step:
        return (
            f"--step {args.step} and --half-range {args.half_range}: give a positive step "
            "and a half-range of at least two steps"
        )
    return None


def run(args: argparse.Namespace) -> int:
    limit_threads(args.threads)
    problem = _checked(args)
    if problem:
        logger.error("smoothness: %s", problem)
        return 2
    truth_path = args.lens_dir / "truth.json"
    try:
        make_output_folders(args.out, args.table)
        truth = json.loads(truth_path.read_text())
        mass = next((p for p in mass_from_truth(truth) if isinstance(p, EPL)), None)
        if mass is None:
            raise ValueError(f"{truth_path} holds no EPL mass: the scan varies an EPL slope")
        imaging = Imaging.from_folder(args.lens_dir)
        radius = float(truth["mask_radius"] if args.mask_radius is None else args.mask_radius)
        mask = circular(imaging.shape, imaging.pixel_scale, radius)
        adapt, _ = read_fits_image(args.lens_dir / "lensed_source_blurred.fits")
        dataset = mock_dataset(imaging, mask, tuple(mass.centre))
        model = scan_model(dataset, mass, adapt[~mask], radius, args.source_pixels, args.mesh_seed)
    except (OSError, KeyError, ValueError, ImagingError) as exc:
        logger.error("smoothness scan of %s: %s", args.lens_dir, exc)
        return 1
    table = appendix_a_table(imaging, mask, model, args.step, args.half_range)
    with atomic_path(args.table) as temporary:
        table.to_csv(temporary, index=False)
    save_png(smoothness_figure(table, mass.slope, truth.get("name", "")), args.out)
    print(jump_summary(table).to_string(index=False, float_format="%.3f"))
    return 0

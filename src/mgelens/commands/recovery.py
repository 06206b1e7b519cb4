"""``mgelens recovery``: how well a phase recovered a mock's truth (SPEC §11).

Example::

    mgelens recovery --lens-dir results/M1/mock --phase results/M1/mass \\
        --out results/M1/recovery.json

Compares the phase's posterior with the true mass parameters of ``truth.json`` (median,
3σ interval, θ_E relative error) and the phase's PSF-convolved lens light (``model.fits``
extension LENS) with the mock's ``lens_light_blurred.fits`` inside the fit mask beyond
0.2″ of the lens centre. The light split compares, in annuli of about 0.3″, the lens
light, the lensed source (LENSED against ``lensed_source_blurred.fits``) and their sum,
each error as a fraction of the true lens light there: a lens-light error that the
source error cancels is light the fit moved between the MGE and the source. The
true-light refit scores the phase's maximum-likelihood model again with its lens light
replaced by ``lens_light_blurred.fits`` (only the source re-solved): a negative Δ ln ε
means the data prefer the fitted lens light to the true one. With ``--isophotes`` (the
table of ``mgelens isophotes --phase``), the fitted lens light's q, PA and a₄/a over
0.5–2.5″ are scored against the same isophote analysis of ``lens_light_blurred.fits``
about the true light centre (:mod:`mgelens.isophote_recovery`), and
``--isophote-figure`` draws both profiles. Prints
tables and writes the record as JSON; the exit code is 0 whether or not the criteria
hold (they are in the JSON under ``criteria``).

``--table`` gathers records into one CSV row per lens instead, and ``--out-targets``
counts the mocks that meet the lens-light targets (``mgelens.recovery.LIGHT_TARGETS``)::

    mgelens recovery --table results/*/recovery.json --out results/summary/recovery.csv \\
        --out-targets results/summary/recovery_targets.csv
"""

import argparse
import json
import logging
from pathlib import Path

import numpy as np
import pandas as pd
from astropy.io import fits

from mgelens.atomic import atomic_path, write_json
from mgelens.commands import add_threads_argument
from mgelens.imaging_input import ImagingError, read_fits_image
from mgelens.isophote_recovery import (
    PROFILE_COLUMNS,
    IsophoteRecovery,
    isophote_recovery,
    true_light_centre,
)
from mgelens.isophotes import TABLE_COLUMNS, isophote_table
from mgelens.mask import circular
from mgelens.pipeline.records import MODEL_FILE, recorded_lens
from mgelens.pipeline.run import max_likelihood_problem, reference_passive_set
from mgelens.plot import save_png
from mgelens.plot.isophote_recovery import isophote_recovery_figure
from mgelens.recovery import (
    lens_light_recovery,
    light_split_profile,
    light_target_table,
    mass_recovery,
    recovery_summary,
    recovery_table,
    split_annulus_edges,
    true_light_refit,
    true_mass_parameters,
)
from mgelens.search.results import PhaseResult
from mgelens.threads import limit_threads

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "recovery",
        help="compare a phase's mass posterior and lens light with a mock's truth",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--lens-dir", type=Path, help="mock folder (truth.json)")
    parser.add_argument("--phase", type=Path, help="phase folder, e.g. results/M1/mass")
    parser.add_argument("--lens", help="lens name (default: the phase folder's parent)")
    parser.add_argument(
        "--isophotes",
        type=Path,
        help="isophote table of the phase's lens light (mgelens isophotes --phase); scores "
        "it against the same analysis of lens_light_blurred.fits",
    )
    parser.add_argument(
        "--isophote-figure", type=Path, help="with --isophotes: fitted against true isophotes (PNG)"
    )
    parser.add_argument(
        "--table", type=Path, nargs="+", metavar="RECOVERY.json", help="records to gather"
    )
    parser.add_argument(
        "--out", type=Path, required=True, help="recovery record (JSON) or, with --table, CSV"
    )
    parser.add_argument(
        "--out-targets",
        type=Path,
        help="with --table: the lens-light targets over the records (CSV, light_target_table)",
    )
    add_threads_argument(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    limit_threads(args.threads)
    if args.table:
        return _gather(args.table, args.out, args.out_targets)
    if args.lens_dir is None or args.phase is None:
        logger.error("recovery needs --lens-dir and --phase (or --table to gather records)")
        return 1
    lens = args.lens or args.phase.resolve().parent.name
    try:
        truth = json.loads((args.lens_dir / "truth.json").read_text())
        phase = PhaseResult.read(args.phase)
        mass = mass_recovery(truth, phase)
        true_light, _ = read_fits_image(args.lens_dir / "lens_light_blurred.fits")
        true_source, _ = read_fits_image(args.lens_dir / "lensed_source_blurred.fits")
        with fits.open(args.phase / MODEL_FILE) as model:
            model_light, model_source = (np.array(model[name].data) for name in ("LENS", "LENSED"))
        pixel_scale = float(truth["observation"]["pixel_scale"])
        mask_centre = recorded_lens(phase.settings).mask_centre
        radius = float(phase.settings["mask_radius"])
        mask = circular(true_light.shape, pixel_scale, radius, mask_centre)
        true_mass = true_mass_parameters(truth)
        centre = (true_mass["mass.centre_x"], true_mass["mass.centre_y"])
        light = lens_light_recovery(true_light, model_light, mask, pixel_scale, centre)
        split = light_split_profile(
            true_light, true_source, model_light, model_source, mask, pixel_scale, centre,
            split_annulus_edges(radius),
        )  # fmt: skip
        problem, values = max_likelihood_problem(phase, args.lens_dir, args.phase.parent)
        refit = true_light_refit(
            problem.dataset,
            problem.model.build(values),
            true_light,
            reference_passive_set(problem),
        )
        isophotes = None
        if args.isophotes is not None:
            isophotes = _isophote_recovery(args, lens, truth, true_light, pixel_scale)
    except (OSError, KeyError, ValueError, ImagingError) as exc:
        logger.error("recovery of %s: %s", lens, exc)
        return 1
    record = recovery_summary(lens, mass, light, split, refit, isophotes)
    write_json(args.out, record)
    print(f"{'parameter':22s} {'truth':>9s} {'median':>9s} {'3σ interval':>22s}  ok")
    for row in mass:
        interval = f"({row.lower_3sigma:.4g}, {row.upper_3sigma:.4g})"
        print(
            f"{row.name:22s} {row.truth:9.4g} {row.median:9.4g} {interval:>22s}  "
            f"{'yes' if row.within_3sigma else 'NO'}"
        )
    print(
        f"lens light beyond {light.inner_radius:g}″: mean {light.mean:+.3f}, "
        f"95 % |·| < {light.p95_abs:.3f}, max |·| {light.max_abs:.3f}"
    )
    print("light split (errors as fractions of the true lens light in each annulus):")
    header = ("annulus ″", "lens light", "source", "total", "source/lens")
    print(" ".join(f"{h:>{w}s}" for h, w in zip(header, (12, 10, 8, 8, 11), strict=True)))
    for row in split:
        print(
            f"{row.inner_radius:5.2f}–{row.outer_radius:4.2f} {row.lens_light_error:+10.3f} "
            f"{row.lensed_source_error:+8.3f} {row.total_error:+8.3f} "
            f"{row.source_to_lens_ratio:11.2f}"
        )
    prior = refit.lens_light_prior_coefficient
    print(
        f"true lens light refit: Δχ² = {refit.delta_chi_squared:+.1f} against "
        f"{refit.n_lens_light_intensities} non-zero lens-light intensities, "
        f"Δ ln ε = {refit.delta_log_evidence:+.1f} (< 0: the data prefer the fitted lens light)"
        + (
            ""
            if prior is None
            else f"; the fitted light under the smoothness prior, λ = {prior:.3g}"
        )
    )
    if isophotes is not None:
        _print_isophotes(isophotes)
    print("criteria:", ", ".join(f"{k} {v}" for k, v in record["criteria"].items()))
    return 0


def _isophote_recovery(args, lens, truth, true_light, pixel_scale) -> IsophoteRecovery:
    """Score ``args.isophotes`` against the isophotes of the true PSF-convolved lens light,
    and draw the figure if asked."""
    fitted = pd.read_csv(args.isophotes)
    missing = sorted(set(TABLE_COLUMNS) - set(fitted.columns))
    if missing:
        raise ValueError(
            f"{args.isophotes}: not an isophote table (no columns {', '.join(missing)}); "
            "make it with mgelens isophotes --phase"
        )
    true = isophote_table(true_light, pixel_scale, centre=true_light_centre(truth))
    result = isophote_recovery(fitted, true)
    if result.n_compared < result.n_radii:
        half_width = 0.5 * true_light.shape[1] * pixel_scale
        logger.warning(
            "isophotes of %s compared at %d of %d radii over 0.5-2.5 arcsec: the fitted or the "
            "true table does not reach them all (the true image spans +-%.2f arcsec; the "
            "isophote levels need the light out to 3 arcsec)",
            lens, result.n_compared, result.n_radii, half_width,
        )  # fmt: skip
    if args.isophote_figure is not None:
        profile = pd.DataFrame(result.profile, columns=list(PROFILE_COLUMNS), dtype=float)
        save_png(isophote_recovery_figure(fitted, true, profile, lens), args.isophote_figure)
    return result


def _print_isophotes(result: IsophoteRecovery) -> None:
    def shown(value, digits):
        return "n/a" if value is None else f"{value:.{digits}f}"

    print(
        f"isophotes over 0.5–2.5″ ({result.n_compared} of {result.n_radii} radii compared): "
        f"max |Δq| {shown(result.max_abs_axis_ratio_error, 3)}, "
        f"max |ΔPA| {shown(result.max_abs_angle_error, 2)}°, "
        f"max |Δa4/a| {shown(result.max_abs_a4_error, 4)}"
    )


def _gather(paths: list[Path], out: Path, out_targets: Path | None) -> int:
    try:
        records = [json.loads(path.read_text()) for path in paths]
        table = recovery_table(records)
    except (OSError, json.JSONDecodeError, KeyError) as exc:
        logger.error("cannot gather recovery records: %s", exc)
        return 1
    with atomic_path(out) as temporary:
        table.to_csv(temporary, index=False)
    print(table.to_string(index=False))
    if out_targets is not None:
        targets = light_target_table(table)
        with atomic_path(out_targets) as temporary:
            targets.to_csv(temporary, index=False)
        print(targets.to_string(index=False))
    return 0

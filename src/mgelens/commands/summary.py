"""``mgelens summary``: sample table and figures from the per-lens results.

Example::

    mgelens summary results/*/isophotes.json --reference-dir ../shared/data/reference \\
        --out-table results/summary/lenses.csv --out-figure results/summary/histograms.png \\
        --out-einstein results/summary/einstein_radii.png \\
        --out-mosaic results/summary/residual_mosaic.png \\
        --out-slopes results/summary/slopes.png \\
        --out-light-models results/summary/light_models.csv

Each ``results/<lens>/isophotes.json`` comes with ``results/<lens>/quality.json`` and
``results/<lens>/mass/`` (``result.json``, ``samples.csv``, ``model.fits``), which the
table's fit columns and the mosaic read (:func:`mgelens.summary.lens_table`), and, for a
lens whose LIGHT model was chosen by evidence, ``results/<lens>/model_choice.json``
(every candidate into ``--out-light-models``, :func:`mgelens.summary.light_model_table`).
Prints the fraction of lenses with Δq_max > 0.1 or ΔPA_max > 10° (thresholds
adjustable), the models chosen by evidence, the number of flagged fits and the slopes of
our θ_E^LT against the published values, and our slopes against Shajib's
(:func:`mgelens.published.slope_differences`).
"""

import argparse
import json
import logging
from pathlib import Path

from mgelens.atomic import atomic_path
from mgelens.pipeline.records import MODEL_FILE
from mgelens.plot import save_png
from mgelens.plot.comparison import einstein_radius_figure, slope_figure
from mgelens.plot.mosaic import read_panel, residual_mosaic
from mgelens.plot.summary import histogram_figure
from mgelens.published import SLOPE_TENSION, slope_differences, slope_text, slope_through_origin
from mgelens.search.results import names_a_prior_edge
from mgelens.summary import (
    DELTA_PA_THRESHOLD,
    DELTA_Q_THRESHOLD,
    MASS_PHASE,
    QUALITY_FILE,
    complex_fraction,
    lens_table,
    light_model_table,
)

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "summary",
        help="sample table and histograms of per-lens isophote statistics",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "summaries", type=Path, nargs="+", metavar="SUMMARY.json", help="per-lens summaries"
    )
    parser.add_argument("--out-table", type=Path, required=True, help="sample table (CSV)")
    parser.add_argument("--out-figure", type=Path, required=True, help="histograms (PNG)")
    parser.add_argument(
        "--out-einstein", type=Path, required=True, help="θ_E against published models (PNG)"
    )
    parser.add_argument(
        "--out-mosaic", type=Path, required=True, help="residual mosaic with quality flags (PNG)"
    )
    parser.add_argument(
        "--out-slopes", type=Path, help="our slopes against Shajib et al. 2021's (PNG)"
    )
    parser.add_argument(
        "--out-light-models",
        type=Path,
        help="every LIGHT candidate of the lenses whose model was chosen by evidence (CSV)",
    )
    parser.add_argument(
        "--reference-dir",
        type=Path,
        help="folder of the published tables (shared/data/reference); without it, or if "
        "it is absent, the published columns are NaN",
    )
    parser.add_argument(
        "--delta-q", type=float, default=DELTA_Q_THRESHOLD, help="complexity threshold on Δq"
    )
    parser.add_argument(
        "--delta-pa",
        type=float,
        default=DELTA_PA_THRESHOLD,
        help="complexity threshold on ΔPA (degrees)",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        table = lens_table(args.summaries, args.reference_dir, args.delta_q, args.delta_pa)
        panels = [
            read_panel(
                Path(source).parent / MASS_PHASE / MODEL_FILE,
                lens,
                label,
                json.loads((Path(source).parent / QUALITY_FILE).read_text()),
            )
            for lens, label, source in table[["lens", "light_model", "source"]].itertuples(
                index=False
            )
        ]
        chosen_by_evidence = table[table["light_chosen_by"] == "evidence"]
        candidates = light_model_table(  # lens_table has read and checked these choices
            (lens, Path(source).parent)
            for lens, source in chosen_by_evidence[["lens", "source"]].itertuples(index=False)
        )
    except (OSError, KeyError, ValueError) as exc:
        logger.error("%s", exc)
        return 1
    with atomic_path(args.out_table) as temporary:
        table.to_csv(temporary, index=False)
    if args.out_light_models is not None:
        with atomic_path(args.out_light_models) as temporary:
            candidates.to_csv(temporary, index=False)
    save_png(histogram_figure(table, args.delta_q, args.delta_pa), args.out_figure)
    save_png(einstein_radius_figure(table), args.out_einstein)
    if args.out_slopes is not None:
        save_png(slope_figure(table), args.out_slopes)
    save_png(residual_mosaic(panels), args.out_mosaic)
    measured = int((table["n_isophotes"] > 0).sum())
    fraction = complex_fraction(table, args.delta_q, args.delta_pa)
    print(f"lenses: {len(table)} ({measured} with isophotes)")
    print(
        f"complex_fraction: {fraction:.3f} (delta_q > {args.delta_q:g} or "
        f"delta_pa > {args.delta_pa:g} deg)"
    )
    chosen = chosen_by_evidence["light_model"]
    print(f"light_models_chosen: {chosen.value_counts().to_dict()} ({len(chosen)} by evidence)")
    for name in ("quality", "singly_imaged"):
        flags = table[f"{name}_flag"]
        print(f"{name}_flagged: {int(flags.sum())} of {int(flags.notna().sum())} measured")
    print(f"lensing_flagged: {int(table['lensing_flag'].sum())} of {len(table)}")
    unconverged = table.loc[table["mass_converged"].eq(False), "lens"]
    print(f"mass_unconverged: {len(unconverged)} of {len(table)} {list(unconverged)}")
    at_edge = table.loc[names_a_prior_edge(table["prior_edge"]), "lens"]
    print(f"prior_edge: {len(at_edge)} of {int(table['prior_edge'].notna().sum())} {list(at_edge)}")
    for name, column in (("bolton", "bolton_b_sie"), ("shajib", "shajib_theta_e")):
        fit = slope_through_origin(table[column], table["theta_e_lt"])
        print(f"theta_e_lt_vs_{name}: {slope_text(*fit)}")
    slopes = slope_differences(table)
    if slopes.empty:
        print("slope_vs_shajib: 0 lenses")
    else:
        print(
            f"slope_vs_shajib: {len(slopes)} {'lens' if len(slopes) == 1 else 'lenses'}, "
            f"mean difference {slopes['difference'].mean():+.3f}, beyond "
            f"{SLOPE_TENSION:g} sigma: "
            f"{', '.join(slopes.loc[slopes['tension'], 'lens']) or 'none'}"
        )
    return 0

"""``mgelens mockstudy``: the paper's mock comparison, Table 3 and Figures 5–7 (SPEC §11).

Example::

    mgelens mockstudy --fit M1 M1 nn_mge --fit M1_pn M1 pn_mge --fit M1_sersic M1 sersic \\
        --results results --out-table results/summary/mock_table.csv \\
        --out-markdown results/summary/mock_table.md \\
        --out-annuli results/summary/mock_light_annuli.csv --figures-dir results/summary

Each ``--fit LENS MOCK MODEL`` names a lens row whose chain has run: its recovery record
``<results>/LENS/recovery.json`` (``mgelens recovery``), its MASS phase
``<results>/LENS/mass/`` (``result.json``, ``model.fits``) and its mock folder
``<results>/LENS/mock/`` (``data.fits``, ``lens_light_blurred.fits``, ``truth.json``);
MOCK is M1, M2 or M3 and MODEL nn_mge, pn_mge or sersic. Writes

* ``--out-table``: Table 3, one row per fit and EPL parameter (columns ``lens, mock,
  model, parameter, truth, median, lower_3sigma, upper_3sigma, within_3sigma``);
* ``--out-markdown``: the same as markdown beside the paper's rows, misses marked ✗;
* ``--out-annuli``: the lens-light, lensed-source and total errors per annulus;
* ``--figures-dir``: ``lens_light_<model>.png`` for each model, one column per fit.
"""

import argparse
import json
import logging
from pathlib import Path

import numpy as np
from astropy.io import fits

from mgelens.atomic import atomic_path
from mgelens.commands import make_output_folders
from mgelens.imaging_input import ImagingError, read_fits_image
from mgelens.mask import circular
from mgelens.mock_study import (
    MODELS,
    PAPER_MOCKS,
    annulus_table,
    markdown_table,
    mock_table,
    relative_difference,
)
from mgelens.pipeline.records import MODEL_FILE, recorded_lens
from mgelens.plot import save_png
from mgelens.plot.mock_study import LightPanel, lens_light_figure
from mgelens.search.results import PhaseResult

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "mockstudy",
        help="Table 3 and Figures 5-7 of the paper's mock comparison",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--fit",
        nargs=3,
        action="append",
        required=True,
        metavar=("LENS", "MOCK", "MODEL"),
        help="a fitted lens row, its paper mock and its lens-light model (repeat)",
    )
    parser.add_argument("--results", type=Path, default=Path("results"), help="results folder")
    parser.add_argument("--out-table", type=Path, required=True, help="Table 3 (CSV)")
    parser.add_argument("--out-markdown", type=Path, required=True, help="Table 3 (markdown)")
    parser.add_argument("--out-annuli", type=Path, required=True, help="errors per annulus (CSV)")
    parser.add_argument(
        "--figures-dir", type=Path, required=True, help="folder of lens_light_<model>.png"
    )
    parser.set_defaults(func=run)


def _checked_fits(entries: list[list[str]]) -> list[dict]:
    fits_ = []
    for lens, mock, model in entries:
        if mock not in PAPER_MOCKS:
            raise ValueError(f"--fit {lens} {mock} {model}: the mock must be one of {PAPER_MOCKS}")
        if model not in MODELS:
            raise ValueError(f"--fit {lens} {mock} {model}: the model must be one of {MODELS}")
        fits_.append({"lens": lens, "mock": mock, "model": model})
    return fits_


def _panel(results: Path, lens: str, mock: str) -> LightPanel:
    """The images of one fit's figure column (see :class:`LightPanel`)."""
    folder = results / lens
    phase = PhaseResult.read(folder / "mass")
    truth = json.loads((folder / "mock" / "truth.json").read_text())
    pixel_scale = float(truth["observation"]["pixel_scale"])
    true_light, _ = read_fits_image(folder / "mock" / "lens_light_blurred.fits")
    data, _ = read_fits_image(folder / "mock" / "data.fits")
    with fits.open(folder / "mass" / MODEL_FILE) as model:
        light, residuals = (np.array(model[name].data, float) for name in ("LENS", "NRESID"))
    radius = float(phase.settings["mask_radius"])
    centre = recorded_lens(phase.settings).mask_centre
    mask = circular(true_light.shape, pixel_scale, radius, centre)
    return LightPanel(
        label=f"{lens} ({mock})",
        relative=relative_difference(light, true_light, mask),
        residuals=np.where(mask, np.nan, residuals),
        source=np.where(mask, np.nan, data - light),
        pixel_scale=pixel_scale,
        radius=radius,
    )


def run(args: argparse.Namespace) -> int:
    try:
        entries = _checked_fits(args.fit)
        make_output_folders(args.out_table, args.out_markdown, args.out_annuli)
        args.figures_dir.mkdir(parents=True, exist_ok=True)
        for entry in entries:
            path = args.results / entry["lens"] / "recovery.json"
            entry["recovery"] = json.loads(path.read_text())
        table = mock_table(entries)
        annuli = annulus_table(entries)
        panels = {
            model: [
                _panel(args.results, e["lens"], e["mock"])
                for e in sorted(entries, key=lambda e: (e["mock"], e["lens"]))
                if e["model"] == model
            ]
            for model in MODELS
        }
    except (OSError, KeyError, ValueError, ImagingError) as exc:
        logger.error("mock study: %s", exc)
        return 1
    with atomic_path(args.out_table) as temporary:
        table.to_csv(temporary, index=False)
    with atomic_path(args.out_annuli) as temporary:
        annuli.to_csv(temporary, index=False)
    markdown = markdown_table(table)
    with atomic_path(args.out_markdown) as temporary:
        Path(temporary).write_text(markdown)
    for model, model_panels in panels.items():
        if model_panels:
            figure = lens_light_figure(model, model_panels)
            save_png(figure, args.figures_dir / f"lens_light_{model}.png")
    print(markdown)
    return 0

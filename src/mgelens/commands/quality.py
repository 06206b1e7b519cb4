"""``mgelens quality``: fit-quality flag of a phase (coherent lens-light residuals).

Example::

    mgelens quality --phase results/M1/mass --lens-dir results/M1/mock \\
        --out results/M1/quality.json

Reads the phase's ``model.fits`` (NRESID, LENSED), its fit mask (``mask_radius`` and
``lens.mask_centre`` of ``result.json``, combined with the lens folder's ``mask.fits`` if
any), the lens's data (for the sky's τ beyond the fit circle, step 6 of
:mod:`mgelens.quality`) and noise map, and writes the statistic as JSON::

    {"lens": ..., "phase": ..., "mgelens_version": ..., "measured": true, "flag": false,
     "coherence": S, "significance": K, "peak": z_max, "n_outlier_blocks": ...,
     "noise_scale": τ, "coherence_white": ..., "worst_x": ..., "worst_y": ...,
     "n_pixels": ..., "n_blocks": ..., "n_pairs": ..., "block_pixels": k,
     "block_arcsec": ..., "noise_scale_from": "residuals" | "sky" | "",
     "sky_noise_scale": ..., "n_sky_pairs": ..., "coherence_threshold": ...,
     "peak_threshold": ..., "inputs": {...}}

(worst_x, worst_y in arcsec: the used-pixel centroid of the block of largest |z_b|),
under ``lensing`` the check of :func:`mgelens.quality.lensing_check` of the phase's
maximum-likelihood mass against the fit circle and its first lens-light component's centre,
and under ``multiplicity`` how much of the lensed source's signal that mass images more
than once (:func:`mgelens.image_multiplicity.multiplicity_check`: ``multiply_imaged_fraction``,
``n_pixels``, ``flag`` below one half, ``reason``).
Exit code 1 with a one-line error for missing or inconsistent inputs.
"""

import argparse
import functools
import logging
from pathlib import Path

import numpy as np
from astropy.io import fits

from mgelens import CONVENTIONS_VERSION, __version__
from mgelens.atomic import write_json
from mgelens.grid import pixel_centres
from mgelens.image_multiplicity import multiplicity_check
from mgelens.imaging import MASK_FILE, Imaging
from mgelens.imaging_input import ImagingError, read_fits_mask
from mgelens.mask import circular, contaminants
from mgelens.pipeline.fittable import informative_pixels
from mgelens.pipeline.records import (
    MODEL_FILE,
    fit_record_of,
    light_components,
    masses_from_record,
    read_result_record,
    recorded_lens,
)
from mgelens.quality import lensing_check, quality_statistic, sky_pixels, sky_residual_map
from mgelens.search.results import RESULT_FILE

logger = logging.getLogger(__name__)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "quality",
        help="flag coherent lens-light residuals of a phase (model.fits)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--phase", type=Path, required=True, help="phase folder, e.g. results/M1/mass"
    )
    parser.add_argument(
        "--lens-dir", type=Path, help="imaging folder (default: lens_dir of result.json)"
    )
    parser.add_argument("--lens", help="lens name (default: the phase folder's parent)")
    parser.add_argument("--out", type=Path, required=True, help="quality record (JSON)")
    parser.set_defaults(func=run)


def read_residual_images(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """NRESID and LENSED of a ``model.fits``.

    Raises
    ------
    ValueError
        Naming the file and the missing extension.
    """
    with fits.open(path) as hdus:
        names = [hdu.name for hdu in hdus]
        missing = [name for name in ("NRESID", "LENSED") if name not in names]
        if missing:
            raise ValueError(
                f"{path}: no {' or '.join(missing)} extension (has {', '.join(names)}); "
                "rerun the phase to write a complete model.fits"
            )
        return np.array(hdus["NRESID"].data, dtype=float), np.array(
            hdus["LENSED"].data, dtype=float
        )


def run(args: argparse.Namespace) -> int:
    lens = args.lens or args.phase.resolve().parent.name
    try:
        result = read_result_record(args.phase)
        settings = result["settings"]
        spec = recorded_lens(settings)
        lens_dir = args.lens_dir or Path(settings["lens_dir"])
        circle = functools.partial(_circle, float(settings["mask_radius"]), spec.mask_centre)
        # the sheet's pixel scale, if the fit had one
        imaging = Imaging.from_folder(lens_dir, pixel_scale=spec.pixel_scale, mask_from=circle)
        if spec.contaminants:  # as the fit saw them
            imaging = contaminants(imaging, spec.contaminants)
        nresid, lensed = read_residual_images(args.phase / MODEL_FILE)
        mask_file = lens_dir / MASK_FILE
        sky = sky_pixels(
            imaging.data,
            imaging.noise_map,
            imaging.pixel_scale,
            float(settings["mask_radius"]),
            spec.mask_centre,
            excluded=read_fits_mask(mask_file) if mask_file.is_file() else None,
        )
        statistic = quality_statistic(
            nresid,
            lensed,
            imaging.noise_map,
            imaging.mask,
            imaging.pixel_scale,
            sky_residuals=sky_residual_map(
                imaging.data, imaging.noise_map, sky, imaging.pixel_scale
            ),
        )
        fitted = fit_record_of(result, args.phase / RESULT_FILE)
        light = light_components(fitted)[0]
        mass = masses_from_record(fitted)
        mask_radius = float(settings["mask_radius"])
        lensing = lensing_check(
            mass, mask_radius, spec.mask_centre, light_centre=tuple(light["centre"])
        )
        x, y = pixel_centres(imaging.shape, imaging.pixel_scale)
        multiplicity = multiplicity_check(
            mass,
            lensed,
            imaging.noise_map,
            informative_pixels(imaging, imaging.mask),
            x,
            y,
            mask_radius,
            spec.mask_centre,
        )
    except (OSError, KeyError, ValueError, ImagingError) as exc:
        logger.error("quality of %s: %s", lens, exc)
        return 1
    record = {
        "lens": lens,
        "phase": args.phase.name,
        "mgelens_version": __version__,
        "conventions": CONVENTIONS_VERSION,
        **statistic.to_dict(),
        "lensing": lensing.to_dict(),
        "multiplicity": multiplicity.to_dict(),
        "inputs": {"model": str(args.phase / MODEL_FILE), "lens_dir": str(lens_dir)},
    }
    write_json(args.out, record)
    state = "not measured" if not statistic.measured else ("FLAG" if statistic.flag else "ok")
    print(
        f"{lens}: {state}; K = {statistic.significance:.2f} (S = {statistic.coherence:.3f}), "
        f"z_max = {statistic.peak:.2f} at ({statistic.worst_x:.2f}, {statistic.worst_y:.2f})″, "
        f"{statistic.n_blocks} blocks, {statistic.n_pixels} pixels, τ = "
        f"{statistic.noise_scale:.3f} from the {statistic.noise_scale_from or 'nothing'} "
        f"({statistic.n_pairs} residual pairs, {statistic.n_sky_pairs} sky pairs)"
    )
    if lensing.flag:
        print(f"{lens}: LENSING FLAG: {lensing.reason}")
    if multiplicity.multiply_imaged_fraction is not None:
        print(
            f"{lens}: {multiplicity.multiply_imaged_fraction:.0%} of the lensed source's signal "
            f"({multiplicity.n_pixels} pixels above the noise) is multiply imaged"
        )
    if multiplicity.flag:
        print(f"{lens}: SINGLY IMAGED FLAG: {multiplicity.reason}")
    return 0


def _circle(radius, centre, shape, pixel_scale) -> np.ndarray:
    return circular(shape, pixel_scale, radius, centre)

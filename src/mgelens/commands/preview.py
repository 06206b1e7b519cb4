"""``mgelens preview``: a PNG overview of an imaging folder (mock or real).

Example::

    mgelens preview results/M1/mock --out results/M1/figures/preview.png

A mock folder (one holding ``truth.json``, written by ``mgelens simulate``) gives five
panels: data, noise map, lens light and lensed source (both after the PSF, with the
tangential critical curve) and the unlensed source (with the caustic). Any other folder
of the SLACS layout (``data.fits``, ``noise_map.fits``, ``psf.fits``) gives data, noise
map and S/N; pixels with noise > 1e3 (the SLACS masked-pixel sentinel) are shown grey,
and so are the circles of ``--contaminants`` (the sample sheet's column), as the fits
treat them. All images are drawn with ``origin="lower"``: +x right, +y up (SPEC §1.1).
"""

import argparse
import json
import logging
from pathlib import Path

import matplotlib
import numpy as np
from astropy.io import fits
from matplotlib import colors
from matplotlib.figure import Figure

from mgelens.atomic import atomic_path
from mgelens.commands import add_threads_argument
from mgelens.imaging import Imaging
from mgelens.mask import contaminants, read_contaminant_circles
from mgelens.mass import caustic, tangential_critical_curve
from mgelens.simulate import MOCK_FILES, mass_from_truth
from mgelens.threads import limit_threads

logger = logging.getLogger("mgelens.preview")

MASKED_NOISE = 1e3
"""Noise values above this mark excluded pixels (SLACS sentinel 1e8)."""

DPI = 80


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "preview",
        help="PNG overview of a mock or real imaging folder",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("folder", metavar="DIR", help="imaging folder (mock or real)")
    parser.add_argument("--out", required=True, metavar="PNG", help="output PNG file")
    parser.add_argument(
        "--pixel-scale",
        type=float,
        help="arcsec per pixel (default: the folder's info.json, else the data header)",
    )
    parser.add_argument(
        "--contaminants",
        type=Path,
        metavar="FILE",
        help="text file of circles `x y radius` (arcsec) shown as masked, as the fits "
        "treat them (the sample sheet's contaminants column)",
    )
    add_threads_argument(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    limit_threads(args.threads)
    try:
        circles = read_contaminant_circles(args.contaminants) if args.contaminants else ()
        figure = preview_figure(args.folder, args.pixel_scale, circles)
        with atomic_path(args.out) as temporary:
            figure.savefig(temporary, format="png", dpi=DPI)
    except (ValueError, OSError) as error:
        logger.error("%s", error)
        return 1
    logger.info("preview of %s written to %s", args.folder, args.out)
    return 0


def preview_figure(
    folder: str | Path,
    pixel_scale: float | None = None,
    circles: tuple[tuple[float, float, float], ...] = (),
) -> Figure:
    """The preview figure of an imaging folder (see the module docstring); ``pixel_scale``
    (arcsec) as in :meth:`~mgelens.imaging.Imaging.from_folder`; contaminant ``circles``
    (x, y, radius in arcsec) shown masked, as the fits treat them."""
    folder = Path(folder)
    imaging = Imaging.from_folder(folder, pixel_scale=pixel_scale)
    if circles:
        imaging = contaminants(imaging, circles)
    truth_path = folder / MOCK_FILES["truth"]
    if truth_path.is_file():
        return _mock_figure(folder, imaging, json.loads(truth_path.read_text()))
    return _real_figure(imaging)


def _extent(shape: tuple[int, int], pixel_scale: float, centre=(0.0, 0.0)) -> list[float]:
    """imshow extent (pixel edges, arcsec) of a grid centred on ``centre``."""
    half_x, half_y = shape[1] * pixel_scale / 2.0, shape[0] * pixel_scale / 2.0
    return [centre[0] - half_x, centre[0] + half_x, centre[1] - half_y, centre[1] + half_y]


def _show(figure, axis, image, extent, title, norm=None, cmap="viridis", unit="e⁻/s"):
    shown = axis.imshow(image, origin="lower", extent=extent, norm=norm, cmap=cmap)
    axis.set_title(title, fontsize=10)
    axis.set_xlabel("x [arcsec]")
    figure.colorbar(shown, ax=axis, shrink=0.85, label=unit)
    return shown


def _data_norm(data: np.ndarray, noise: np.ndarray) -> colors.Normalize:
    """asinh stretch: linear up to about the typical noise, logarithmic above."""
    used = noise < MASKED_NOISE
    return colors.AsinhNorm(
        linear_width=float(np.median(noise[used])),
        vmin=float(np.percentile(data[used], 0.5)),
        vmax=float(np.max(data[used])),
    )


def _masked(image: np.ndarray, noise: np.ndarray) -> np.ma.MaskedArray:
    return np.ma.masked_where(noise >= MASKED_NOISE, image)


def _grey_bad(name: str) -> colors.Colormap:
    return matplotlib.colormaps[name].with_extremes(bad="0.6")


def _real_figure(imaging: Imaging) -> Figure:
    data, noise = imaging.data, imaging.noise_map
    extent = _extent(imaging.shape, imaging.pixel_scale)
    figure = Figure(figsize=(12.0, 3.6), layout="constrained")
    axes = figure.subplots(1, 3)
    _show(
        figure,
        axes[0],
        _masked(data, noise),
        extent,
        "data",
        _data_norm(data, noise),
        _grey_bad("viridis"),
    )
    _show(
        figure,
        axes[1],
        _masked(noise, noise),
        extent,
        "noise map",
        colors.LogNorm(),
        _grey_bad("magma"),
    )
    _show(
        figure,
        axes[2],
        _masked(data / noise, noise),
        extent,
        "S/N",
        colors.Normalize(vmin=-3.0),
        _grey_bad("viridis"),
        unit="",
    )
    axes[0].set_ylabel("y [arcsec]")
    masked = int(np.count_nonzero(noise >= MASKED_NOISE))
    figure.suptitle(
        f"{imaging.name}: {imaging.shape[1]}×{imaging.shape[0]} pixels of "
        f"{imaging.pixel_scale}″, {masked} masked (grey)"
    )
    return figure


def _mock_figure(folder: Path, imaging: Imaging, truth: dict) -> Figure:
    data, noise = imaging.data, imaging.noise_map
    extent = _extent(imaging.shape, imaging.pixel_scale)
    lens_light = fits.getdata(folder / MOCK_FILES["lens_light_blurred"])
    lensed_source = fits.getdata(folder / MOCK_FILES["lensed_source_blurred"])
    with fits.open(folder / MOCK_FILES["source"]) as hdul:
        source, header = np.asarray(hdul[0].data), hdul[0].header
    source_extent = _extent(
        source.shape, header["PIXSCALE"], (header["XCENTRE"], header["YCENTRE"])
    )
    figure = Figure(figsize=(19.0, 3.6), layout="constrained")
    axes = figure.subplots(1, 5)
    _show(figure, axes[0], data, extent, "data", _data_norm(data, noise))
    _show(figure, axes[1], noise, extent, "noise map", cmap="magma")
    _show(
        figure,
        axes[2],
        lens_light,
        extent,
        "lens light ⊗ PSF",
        colors.LogNorm(vmin=1e-3 * lens_light.max()),
    )
    _show(figure, axes[3], lensed_source, extent, "lensed source ⊗ PSF", cmap="inferno")
    _show(figure, axes[4], source, source_extent, "source plane", cmap="inferno")
    axes[0].set_ylabel("y [arcsec]")
    mass = mass_from_truth(truth)
    try:
        axes[3].plot(*tangential_critical_curve(mass), color="cyan", lw=0.8)
        axes[4].plot(*caustic(mass), color="cyan", lw=0.8)
    except ValueError as error:
        logger.warning("no critical curve drawn: %s", error)
    for axis, limits in ((axes[3], extent), (axes[4], source_extent)):
        axis.set_xlim(limits[0], limits[1])
        axis.set_ylim(limits[2], limits[3])
    epl = next(m for m in truth["mass"] if m["type"] in ("EPL", "SIE"))["parameters"]
    figure.suptitle(
        f"{truth['name']}: θ_E = {epl['einstein_radius']:.2f}″, q = {epl['axis_ratio']:.2f}, "
        f"φ = {epl['angle']:.0f}°, γ = {epl.get('slope', 2.0):.2f}; "
        f"{truth['source']['model']} source ({truth['source'].get('kind', 'image')}), "
        f"max source S/N {truth['signal_to_noise']['source_max']:.1f}"
    )
    return figure

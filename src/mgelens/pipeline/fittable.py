"""Refusals of inputs a phase cannot fit, before any sampling (ISSUE 33, docs/reliability.md).

A phase fits the pixels inside its circular mask. Each check below raises
:class:`~mgelens.imaging_input.ImagingError` naming the lens's ``data.fits`` and the fix, so
``mgelens phase`` stops with one line and writes no ``result.json``:

* the circle must lie inside the image (:func:`check_circle_inside`);
* the data inside it must hold light (:func:`check_signal`);
* it must hold enough pixels per free parameter (:func:`check_pixels_per_parameter`).

Pixels whose noise marks a contaminant (above :data:`mgelens.mask.SLACS_NOISE_THRESHOLD`,
the SLACS sentinel is 1e8) carry no information and count for neither of the last two.
"""

from pathlib import Path

import numpy as np

from mgelens.imaging import Imaging
from mgelens.imaging_input import ImagingError
from mgelens.mask import SLACS_NOISE_THRESHOLD, largest_inside_radius

MIN_SIGNAL_TO_NOISE = 5.0
"""Smallest integrated signal-to-noise ratio Σd / √Σσ² of the informative pixels inside the
mask that a phase fits. Data without light give N(0, 1), so 5 refuses them (all-zero or
mis-scaled data give about 0), far below any lens measured (docs/design_notes.md,
"Fittable data"). The integrated ratio is used rather than the peak pixel's: the peak
of pure noise over the 10⁴ pixels of a 3″ mask reaches 4–5σ."""

MIN_PIXELS_PER_PARAMETER = 10
"""Fewest informative pixels inside the mask per free (non-linear) parameter of a phase:
fewer, and the data cannot constrain the model (a 0.08″ mask holds 9 pixels for SP's 17
parameters); real masks hold hundreds per parameter."""


def informative_pixels(imaging: Imaging, mask: np.ndarray) -> np.ndarray:
    """Bool map of the pixels a fit uses (``mask`` False) that are not contaminant
    sentinels (noise at most :data:`~mgelens.mask.SLACS_NOISE_THRESHOLD`)."""
    return ~mask & (imaging.noise_map <= SLACS_NOISE_THRESHOLD)


def integrated_signal_to_noise(imaging: Imaging, mask: np.ndarray) -> float:
    """Σd / √Σσ² over :func:`informative_pixels` (0 if there are none)."""
    used = informative_pixels(imaging, mask)
    if not used.any():
        return 0.0
    return float(imaging.data[used].sum() / np.sqrt(np.sum(imaging.noise_map[used] ** 2)))


def check_circle_inside(
    data_file: Path,
    shape: tuple[int, int],
    pixel_scale: float,
    radius: float,
    centre: tuple[float, float],
) -> None:
    """Raise unless the mask circle (arcsec) lies inside the image of ``data_file``."""
    largest = largest_inside_radius(shape, pixel_scale, centre)
    if radius > largest + 1e-9:
        raise ImagingError(
            f"{data_file}: the {radius:g}″ mask centred at {tuple(centre)}″ reaches beyond "
            f"the {shape[1]}×{shape[0]}-pixel image ({shape[1] * pixel_scale:g}″ × "
            f"{shape[0] * pixel_scale:g}″); use a mask radius of at most {largest:.4g}″ "
            "(--mask-radius, or the sample sheet's mask_radius) or a larger cutout",
            component="mask",
        )


def check_signal(data_file: Path, imaging: Imaging, mask: np.ndarray, radius: float) -> None:
    """Raise if the data inside the mask hold no light (:data:`MIN_SIGNAL_TO_NOISE`)."""
    ratio = integrated_signal_to_noise(imaging, mask)
    if ratio < MIN_SIGNAL_TO_NOISE:
        raise ImagingError(
            f"{data_file}: no signal inside the {radius:g}″ mask: integrated S/N "
            f"{ratio:.3g} < {MIN_SIGNAL_TO_NOISE:g} (data all zero, or the wrong file, HDU "
            "or unit?); check the data and noise map, or centre the mask on the lens",
            component="data",
        )


def check_pixels_per_parameter(
    data_file: Path, imaging: Imaging, mask: np.ndarray, radius: float, n_free: int
) -> None:
    """Raise if the mask holds fewer than :data:`MIN_PIXELS_PER_PARAMETER` informative
    pixels per free parameter."""
    n_pixels = int(informative_pixels(imaging, mask).sum())
    needed = MIN_PIXELS_PER_PARAMETER * n_free
    if n_pixels < needed:
        raise ImagingError(
            f"{data_file}: the {radius:g}″ mask holds {n_pixels} usable pixels, fewer than "
            f"the {needed} needed for {n_free} free parameters ({MIN_PIXELS_PER_PARAMETER} "
            "per parameter); enlarge the mask radius",
            component="mask",
        )

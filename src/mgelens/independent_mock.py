"""Mocks whose images are formed by independent software (lenstronomy), in the folder
layout and truth conventions of :mod:`mgelens.simulate` (SPEC §10).

Mocks that mgelens both simulates and fits share its conventions and its mistakes. Here
lenstronomy does the physics of image formation: the EPL and shear deflections, the ray
tracing, the light profiles, the sub-pixel sampling and the PSF convolution. mgelens only
draws the parameters, sets the source brightness and adds the noise (SPEC §10.4 steps 4–5,
the same definitions as every other mock), and writes the folder. ``truth.json`` records
the mass in mgelens conventions (PyAutoGalaxy θ_E, q, φ counter-clockwise from +x, shear
(γ₁, γ₂)), converted to lenstronomy's by :func:`lenstronomy_mass` (SPEC §2.1, §3.2, §3.3),
and the light profiles as lenstronomy keyword arguments.

lenstronomy is an optional dependency (extra ``independent``); :func:`require_lenstronomy`
names the install command when it is missing.

Lens ``L{index:02d}`` of a population seed is drawn from ``default_rng([seed, index, 10])``
(its source from stream 11, its noise from stream 12), over a wider range than the
population mocks of :func:`mgelens.mock_lenses.population_lens`, so that shallow and steep
slopes, strong shear and flat lenses all occur:

* mass: EPL centre N(0, 0.02″) per axis; θ_E ~ U(0.8, 1.6)″; γ ~ U(1.75, 2.45);
  q ~ U(0.55, 0.95); φ = outer light PA + N(0, 10°); shear |γ| ~ U(0, 0.1) at an
  angle U(0°, 180°).
* lens light: six concentric elliptical Gaussians (lenstronomy ``GAUSSIAN_ELLIPSE``),
  dispersions log-spaced from 0.04″ to 2.4″; q from U(0.6, 0.95) for the innermost to
  that + U(−0.2, 0.15) for the outermost (clipped to [0.5, 0.97]) and PA from U(0°, 180°)
  twisting by N(0, 20°) (clipped to ±45°), both linear in ln σ; peak brightness of each
  Gaussian ∝ a Sérsic profile (n ~ U(3, 5), R_e ~ logU(0.8, 2.5)″) at its dispersion,
  scaled so that the mean surface brightness on the circle of radius 1″ is
  logU(24, 100) e⁻ s⁻¹ arcsec⁻² (0.06–0.25 e⁻ s⁻¹ per 0.05″ pixel, as the population).
* source: an elliptical Sérsic (R ~ U(0.08, 0.25)″, n ~ U(0.8, 2.5), q ~ U(0.5, 0.9))
  with 2–4 round Gaussian clumps (σ ~ U(0.02, 0.06)″, 0.05–0.3″ from its centre, peak
  U(0.2, 0.6) × the Sérsic's at R), placed 0.05–0.15″ from the caustic centre.
* z_lens ~ U(0.1, 0.35), z_source = z_lens + U(0.2, 0.7); fit mask radius 3.0″.
"""

import dataclasses
import importlib
import math
from dataclasses import dataclass

import numpy as np

import mgelens
from mgelens.mass import EPL, ExternalShear
from mgelens.mock_lenses import DEFAULT_POPULATION_SEED, POPULATION_MASK_RADIUS, random_shear
from mgelens.simulate import (
    BRIGHTNESS_UNIT,
    FILE_DESCRIPTIONS,
    MOCK_FILES,
    MockImaging,
    Observation,
    expose,
    mass_dict,
    signal_to_noise_record,
)

LENS_STREAM, SOURCE_STREAM, NOISE_STREAM = 10, 11, 12
"""Third seed word of the lens, source and noise draws of lens ``L<i>``."""

N_LIGHT_GAUSSIANS = 6
LIGHT_SIGMA_RANGE = (0.04, 2.4)
"""Arcsec: dispersions (lenstronomy's √(σ_major σ_minor)) of the lens-light Gaussians."""

FWHM_PER_SIGMA = 2.0 * math.sqrt(2.0 * math.log(2.0))

_MAX_POINTS_PER_TILE = 2**20
"""Sub-pixel evaluations per lenstronomy call (bounds its memory)."""


class MissingDependency(RuntimeError):
    """An optional package that a requested feature needs is not installed."""


def require_lenstronomy():
    """The ``lenstronomy`` package, or :class:`MissingDependency` naming how to install it."""
    try:
        return importlib.import_module("lenstronomy")
    except ImportError as exc:
        raise MissingDependency(
            "independent mocks (L<i>) are simulated with lenstronomy, which is not installed: "
            'pip install -e ".[independent]"'
        ) from exc


@dataclass(frozen=True)
class IndependentLens:
    """An independent mock before image formation.

    Attributes
    ----------
    name, recipe : str
    mass : (EPL, ExternalShear)
        In mgelens conventions (:mod:`mgelens.mass`).
    light : tuple of dict
        lenstronomy ``GAUSSIAN_ELLIPSE`` keyword arguments (``amp`` = total flux of the
        Gaussian in e⁻ s⁻¹, as lenstronomy integrates over the pixel area).
    light_centre : (x, y) arcsec
    source : tuple of (str, dict)
        lenstronomy light-model names and keyword arguments, unit-free (scaled to the
        target S/N at simulation).
    seed : tuple of int
        Entropy of the noise generator.
    z_lens, z_source, mask_radius : float
    """

    name: str
    recipe: str
    mass: tuple[EPL, ExternalShear]
    light: tuple[dict, ...]
    light_centre: tuple[float, float]
    source: tuple[tuple[str, dict], ...]
    seed: tuple[int, int, int]
    z_lens: float
    z_source: float
    mask_radius: float


def lenstronomy_mass(mass) -> tuple[list[str], list[dict]]:
    """lenstronomy ``LensModel`` names and keyword arguments of mgelens EPL and shear.

    θ_E^{LT} = θ_E^{AG} √q (2/(1 + q))^{1/(γ−1)} (SPEC §3.3); (e1, e2) = f (cos 2φ, sin 2φ),
    f = (1 − q)/(1 + q) (SPEC §2.1); the shear components are the same numbers (SPEC §3.2).
    """
    names, kwargs = [], []
    for profile in mass:
        if isinstance(profile, EPL):
            q, slope = profile.axis_ratio, profile.slope
            e1, e2 = profile.ell_comps
            names.append("EPL")
            kwargs.append(
                {
                    "theta_E": profile.einstein_radius
                    * math.sqrt(q)
                    * (2.0 / (1.0 + q)) ** (1.0 / (slope - 1.0)),
                    "gamma": slope,
                    "e1": e1,
                    "e2": e2,
                    "center_x": profile.centre[0],
                    "center_y": profile.centre[1],
                }
            )
        elif isinstance(profile, ExternalShear):
            names.append("SHEAR")
            kwargs.append(
                {"gamma1": profile.gamma_1, "gamma2": profile.gamma_2, "ra_0": 0.0, "dec_0": 0.0}
            )
        else:
            raise ValueError(f"no lenstronomy counterpart for {type(profile).__name__}")
    return names, kwargs


def _ell_comps(axis_ratio: float, angle: float) -> tuple[float, float]:
    f = (1.0 - axis_ratio) / (1.0 + axis_ratio)
    return f * math.cos(math.radians(2.0 * angle)), f * math.sin(math.radians(2.0 * angle))


def _sersic_shape(radius: np.ndarray, effective_radius: float, index: float) -> np.ndarray:
    b = 2.0 * index - 1.0 / 3.0
    return np.exp(-b * ((radius / effective_radius) ** (1.0 / index) - 1.0))


def _random_light(centre, rng: np.random.Generator) -> tuple[tuple[dict, ...], float]:
    """Unit-scaled twisted Gaussians and the target brightness at 1″ (see module docstring)."""
    sigmas = np.geomspace(*LIGHT_SIGMA_RANGE, N_LIGHT_GAUSSIANS)
    weight = np.linspace(0.0, 1.0, N_LIGHT_GAUSSIANS)  # linear in ln σ
    q_inner = rng.uniform(0.6, 0.95)
    q_outer = float(np.clip(q_inner + rng.uniform(-0.2, 0.15), 0.5, 0.97))
    pa_inner = rng.uniform(0.0, 180.0)
    twist = float(np.clip(rng.normal(0.0, 20.0), -45.0, 45.0))
    sersic_index = rng.uniform(3.0, 5.0)
    effective_radius = float(np.exp(rng.uniform(np.log(0.8), np.log(2.5))))
    brightness_at_1 = float(np.exp(rng.uniform(np.log(24.0), np.log(100.0))))
    peaks = _sersic_shape(sigmas, effective_radius, sersic_index)
    gaussians = []
    for sigma, w, peak in zip(sigmas, weight, peaks, strict=True):
        e1, e2 = _ell_comps(q_inner + w * (q_outer - q_inner), pa_inner + w * twist)
        gaussians.append(
            {
                "amp": float(peak * 2.0 * np.pi * sigma**2),
                "sigma": float(sigma),
                "e1": e1,
                "e2": e2,
                "center_x": centre[0],
                "center_y": centre[1],
            }
        )
    return tuple(gaussians), brightness_at_1


def _scaled_light(gaussians, centre, brightness_at_1) -> tuple[dict, ...]:
    """The Gaussians scaled so that their mean surface brightness on the 1″ circle about
    ``centre`` (by lenstronomy, per arcsec²) is ``brightness_at_1``."""
    model, kwargs = _light_model(tuple(("GAUSSIAN_ELLIPSE", g) for g in gaussians))
    angles = np.linspace(0.0, 2.0 * np.pi, 64, endpoint=False)
    mean = np.mean(
        model.surface_brightness(centre[0] + np.cos(angles), centre[1] + np.sin(angles), kwargs)
    )
    factor = brightness_at_1 / float(mean)
    return tuple({**g, "amp": g["amp"] * factor} for g in gaussians)


def _random_source(centre, rng: np.random.Generator) -> tuple[tuple[str, dict], ...]:
    radius = rng.uniform(0.08, 0.25)
    index = rng.uniform(0.8, 2.5)
    e1, e2 = _ell_comps(rng.uniform(0.5, 0.9), rng.uniform(0.0, 180.0))
    profiles = [
        (
            "SERSIC_ELLIPSE",
            {
                "amp": 1.0,
                "R_sersic": float(radius),
                "n_sersic": float(index),
                "e1": e1,
                "e2": e2,
                "center_x": centre[0],
                "center_y": centre[1],
            },
        )
    ]
    for _ in range(int(rng.integers(2, 5))):
        distance, angle = rng.uniform(0.05, 0.3), rng.uniform(0.0, 2.0 * np.pi)
        sigma = rng.uniform(0.02, 0.06)
        peak = rng.uniform(0.2, 0.6)  # × the Sérsic's brightness at R (amp = 1 there)
        profiles.append(
            (
                "GAUSSIAN",
                {
                    "amp": float(peak * 2.0 * np.pi * sigma**2),
                    "sigma": float(sigma),
                    "center_x": float(centre[0] + distance * np.cos(angle)),
                    "center_y": float(centre[1] + distance * np.sin(angle)),
                },
            )
        )
    return tuple(profiles)


def independent_lens(index: int, population_seed: int = DEFAULT_POPULATION_SEED) -> IndependentLens:
    """Lens ``index`` of the independent mocks of ``population_seed`` (module docstring).

    Drawing needs lenstronomy: it sets the light's brightness and finds the caustic
    centre (the source-plane image of the mass centre) by ray shooting.
    """
    if not (isinstance(index, int | np.integer) and index >= 0):
        raise ValueError(f"independent mock index must be an integer >= 0, got {index!r}")
    rng = np.random.default_rng([population_seed, index, LENS_STREAM])
    centre = (float(rng.normal(0.0, 0.02)), float(rng.normal(0.0, 0.02)))
    light, brightness_at_1 = _random_light(centre, rng)
    outer_angle = 0.5 * math.degrees(math.atan2(light[-1]["e2"], light[-1]["e1"]))
    shear = random_shear(rng)
    mass = (
        EPL(
            centre=centre,
            einstein_radius=float(rng.uniform(0.8, 1.6)),
            axis_ratio=float(rng.uniform(0.55, 0.95)),
            angle=float(np.mod(outer_angle + rng.normal(0.0, 10.0), 180.0)),
            slope=float(rng.uniform(1.75, 2.45)),
        ),
        shear,
    )
    z_lens = float(rng.uniform(0.1, 0.35))
    z_source = z_lens + float(rng.uniform(0.2, 0.7))
    light = _scaled_light(light, centre, brightness_at_1)
    source_rng = np.random.default_rng([population_seed, index, SOURCE_STREAM])
    offset, direction = source_rng.uniform(0.05, 0.15), source_rng.uniform(0.0, 2.0 * np.pi)
    caustic = caustic_centre(mass)
    source_centre = (
        caustic[0] + offset * np.cos(direction),
        caustic[1] + offset * np.sin(direction),
    )
    return IndependentLens(
        name=f"L{index:02d}",
        recipe=f"independent mock {index} of seed {population_seed}: images formed by "
        "lenstronomy; twisted Gaussian lens light, EPL + shear mass, Sérsic + clumps source",
        mass=mass,
        light=light,
        light_centre=centre,
        source=_random_source(source_centre, source_rng),
        seed=(int(population_seed), int(index), NOISE_STREAM),
        z_lens=z_lens,
        z_source=z_source,
        mask_radius=POPULATION_MASK_RADIUS,
    )


def caustic_centre(mass) -> tuple[float, float]:
    """Source-plane position of the mass centre by lenstronomy's ray shooting: the mean
    over 16 points on a 10⁻³″ circle about it (as :func:`mgelens.mock_lenses.caustic_centre`)."""
    require_lenstronomy()
    from lenstronomy.LensModel.lens_model import LensModel

    names, kwargs = lenstronomy_mass(mass)
    angles = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
    x = mass[0].centre[0] + 1e-3 * np.cos(angles)
    y = mass[0].centre[1] + 1e-3 * np.sin(angles)
    beta_x, beta_y = LensModel(names).ray_shooting(x, y, kwargs)
    return float(np.mean(beta_x)), float(np.mean(beta_y))


def _light_model(profiles):
    require_lenstronomy()
    from lenstronomy.LightModel.light_model import LightModel

    return LightModel([name for name, _ in profiles]), [kwargs for _, kwargs in profiles]


def _tile_starts(n: int, tile: int) -> list[int]:
    """Starts of square tiles of side ``tile`` covering 0..n−1 (the last one flush with the
    end, overlapping its neighbour)."""
    return sorted({min(start, n - tile) for start in range(0, n, tile)})


def _unconvolved(shape, pixel_scale, sub_size, lens_model, light_model, lens_kwargs, kwargs):
    """Pixel values (sub-pixel means, per pixel) of a light seen through a lens, formed by
    lenstronomy's ImageModel on square tiles (its sub-grid needs square frames); no lens
    model = the light unlensed."""
    from lenstronomy.Data.imaging_data import ImageData
    from lenstronomy.Data.psf import PSF
    from lenstronomy.ImSim.image_model import ImageModel

    n = shape[0]
    if shape[1] != n:
        raise ValueError(f"independent mocks need a square image, got {shape}")
    tile = min(n, max(1, math.isqrt(_MAX_POINTS_PER_TILE) // sub_size))
    out = np.empty(shape)
    numerics = {"supersampling_factor": sub_size}
    for row in _tile_starts(n, tile):
        for col in _tile_starts(n, tile):
            data = ImageData(
                image_data=np.zeros((tile, tile)),
                transform_pix2angle=np.diag([pixel_scale, pixel_scale]),
                ra_at_xy_0=(col - (n - 1) / 2.0) * pixel_scale,
                dec_at_xy_0=(row - (n - 1) / 2.0) * pixel_scale,
            )
            if lens_model is None:
                model = ImageModel(
                    data,
                    PSF(psf_type="NONE"),
                    lens_light_model_class=light_model,
                    kwargs_numerics=numerics,
                )
                values = model.image(kwargs_lens_light=kwargs, unconvolved=True)
            else:
                model = ImageModel(
                    data,
                    PSF(psf_type="NONE"),
                    lens_model_class=lens_model,
                    source_model_class=light_model,
                    kwargs_numerics=numerics,
                )
                values = model.image(
                    kwargs_lens=lens_kwargs, kwargs_source=kwargs, unconvolved=True
                )
            out[row : row + tile, col : col + tile] = values
    return out


def simulate_independent(
    lens: IndependentLens, observation: Observation | None = None
) -> MockImaging:
    """Form the images of ``lens`` with lenstronomy, then scale the source to the target
    S/N and add noise as :func:`mgelens.simulate.simulate` does (SPEC §10.4).

    Light is formed on the image grid padded by half the PSF on every side, convolved by
    lenstronomy's FFT pixel-kernel convolution with its Gaussian kernel
    (``kernel_util.kernel_gaussian``, FWHM = 2.3548 ``psf_sigma``) and cropped.

    Raises
    ------
    MissingDependency
        Without lenstronomy.
    """
    lenstronomy = require_lenstronomy()
    from lenstronomy.ImSim.Numerics.convolution import PixelKernelConvolution
    from lenstronomy.LensModel.lens_model import LensModel
    from lenstronomy.Util import kernel_util

    observation = Observation() if observation is None else observation
    scale, sub = observation.pixel_scale, observation.sub_size
    kernel = kernel_util.kernel_gaussian(
        observation.psf_size, scale, FWHM_PER_SIGMA * observation.psf_sigma
    )
    kernel = kernel / kernel.sum()
    pad = observation.psf_size // 2
    padded = (observation.image_size + 2 * pad,) * 2
    inner = (slice(pad, pad + observation.image_size),) * 2
    names, lens_kwargs = lenstronomy_mass(lens.mass)
    lens_model = LensModel(names)
    light_model, light_kwargs = _light_model(tuple(("GAUSSIAN_ELLIPSE", g) for g in lens.light))
    source_model, source_kwargs = _light_model(lens.source)
    lens_light = _unconvolved(padded, scale, sub, None, light_model, None, light_kwargs)
    lensed_unit = _unconvolved(
        padded, scale, sub, lens_model, source_model, lens_kwargs, source_kwargs
    )
    convolution = PixelKernelConvolution(kernel, convolution_type="fft")
    lens_blurred = convolution.convolution2d(lens_light)[inner]
    source_blurred_unit = convolution.convolution2d(lensed_unit)[inner]
    lens_light, lensed_unit = lens_light[inner], lensed_unit[inner]
    exposed = expose(lens_blurred, lensed_unit, source_blurred_unit, observation, lens.seed)
    amplitude = exposed.amplitude
    plane = _source_plane(lens, observation, source_model, source_kwargs) * amplitude
    truth = _truth(
        lens,
        observation,
        lenstronomy.__version__,
        amplitude=amplitude,
        lens_light=lens_light,
        source_blurred=exposed.lensed_source_blurred,
        noise_map=exposed.noise_map,
        model=exposed.model,
        lens_names=names,
        lens_kwargs=lens_kwargs,
    )
    return exposed.imaging(lens.name, kernel, observation, lens_light, lens_blurred, plane, truth)


def source_plane_centre(lens: IndependentLens) -> tuple[float, float]:
    """Centre of the source's main (Sérsic) component, arcsec."""
    kwargs = lens.source[0][1]
    return kwargs["center_x"], kwargs["center_y"]


def _source_plane(lens, observation, source_model, source_kwargs) -> np.ndarray:
    """Unit source on the saved source-plane grid, per image pixel (× Δ²)."""
    n = observation.source_plane_size
    axis = (np.arange(n) - (n - 1) / 2.0) * observation.source_plane_pixel_scale
    centre = source_plane_centre(lens)
    x, y = np.meshgrid(axis + centre[0], axis + centre[1])
    values = source_model.surface_brightness(x.ravel(), y.ravel(), source_kwargs)
    return np.asarray(values).reshape(n, n) * observation.pixel_scale**2


def _truth(
    lens,
    observation,
    version,
    *,
    amplitude,
    lens_light,
    source_blurred,
    noise_map,
    model,
    lens_names,
    lens_kwargs,
) -> dict:
    """The ``truth.json`` content of an independent mock (keys as for the other mocks)."""
    caustic = caustic_centre(lens.mass)
    centre = source_plane_centre(lens)
    return {
        "name": lens.name,
        "recipe": lens.recipe,
        "conventions_version": mgelens.CONVENTIONS_VERSION,
        "mgelens_version": mgelens.__version__,
        "simulated_with": f"lenstronomy {version}",
        "units": f"surface brightness in {BRIGHTNESS_UNIT} per image pixel; arcsec; degrees "
        "counter-clockwise from +x",
        "observation": dataclasses.asdict(observation),
        "seed": list(lens.seed),
        "z_lens": lens.z_lens,
        "z_source": lens.z_source,
        "mask_radius": lens.mask_radius,
        "lens_light": {
            "model": "lenstronomy",
            "profiles": [{"type": "GAUSSIAN_ELLIPSE", "kwargs": g} for g in lens.light],
            "centre": list(lens.light_centre),
            "form": "lenstronomy GAUSSIAN_ELLIPSE: amp/(2 pi sigma^2) exp(-(q x'^2 + y'^2/q)/"
            "(2 sigma^2)), amp the total flux in e-/s, sigma the geometric-mean dispersion",
            "total_flux_in_field": float(lens_light.sum()),
        },
        "mass": [mass_dict(profile) for profile in lens.mass],
        "lenstronomy_mass": {"models": lens_names, "kwargs": lens_kwargs},
        "source": {
            "model": "lenstronomy",
            "profiles": [{"type": name, "kwargs": kwargs} for name, kwargs in lens.source],
            "centre": list(centre),
            "amplitude": amplitude,
            "amplitude_meaning": "surface brightness = amplitude x the lenstronomy profiles "
            "(pixel values = surface brightness per arcsec^2 x pixel area)",
            "caustic_centre": list(caustic),
            "offset_from_caustic_centre": float(
                np.hypot(centre[0] - caustic[0], centre[1] - caustic[1])
            ),
        },
        "signal_to_noise": signal_to_noise_record(source_blurred, model, noise_map),
        "source_plane": {
            "pixel_scale": observation.source_plane_pixel_scale,
            "shape": [observation.source_plane_size] * 2,
            "centre": list(centre),
        },
        "files": {
            key: {"name": MOCK_FILES[key], "content": FILE_DESCRIPTIONS[key]} for key in MOCK_FILES
        },
    }

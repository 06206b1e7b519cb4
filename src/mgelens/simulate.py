"""Image formation of the mocks (SPEC §10.4), their truth and their folders.

Conventions (SPEC §1.1, §2.1): coordinates (x, y) in arcsec, native arrays of shape
(n_y, n_x) with the row index increasing with +y, angles in degrees counter-clockwise
from +x, axis ratio q = minor/major. Surface brightness is in e⁻ s⁻¹ per image pixel
(Δ = 0.05″ by default), also for the unlensed source image.

:func:`simulate` forms the images of a :class:`~mgelens.mock_lenses.MockLens` (the
paper's mocks and the population, :mod:`mgelens.mock_lenses`; their light and sources,
:mod:`mgelens.mock_light` and :mod:`mgelens.mock_sources`):

1. Lens light and lensed source are evaluated on an s×s sub-grid (s = 16) of every pixel
   and averaged (the sub-grid of a regular image is the image grid at spacing Δ/s).
2. Their sum m is convolved with a Gaussian PSF (σ = 0.05″, 21×21 kernel, unit sum).
3. The source amplitude is set by bisection so that max_i (PSF ⊗ source)_i / σ_i = 50.
4. data = Poisson((m + b) t)/t − b with exposure t = 2000 s and sky b = 0.15 e⁻ s⁻¹;
   noise map σ = sqrt((m + b) t)/t from the noise-free model m.

:func:`write_mock` writes the folder (:data:`MOCK_FILES`) with ``truth.json``.
"""

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
from astropy.io import fits

import mgelens
from mgelens.atomic import write_fits, write_json
from mgelens.convolve import convolve_image
from mgelens.imaging import Imaging
from mgelens.mass import EPL, SIE, ExternalShear, mass_from_dict, ray_trace
from mgelens.mock_lenses import MockLens
from mgelens.mock_light import MGELight
from mgelens.mock_sources import ImageSource, ProceduralSource

BRIGHTNESS_UNIT = "electron/s"
"""FITS ``BUNIT`` of every image written (per image pixel)."""

MOCK_FILES = {
    "data": "data.fits",
    "noise_map": "noise_map.fits",
    "psf": "psf.fits",
    "model": "model.fits",
    "lens_light": "lens_light.fits",
    "lens_light_blurred": "lens_light_blurred.fits",
    "lensed_source": "lensed_source.fits",
    "lensed_source_blurred": "lensed_source_blurred.fits",
    "source": "source.fits",
    "truth": "truth.json",
}
"""Files of a mock folder (keys are also the ``files`` entries of ``truth.json``)."""

FILE_DESCRIPTIONS = {
    "data": "noisy image, e-/s per pixel: Poisson((model + sky) t)/t - sky",
    "noise_map": "1-sigma noise sqrt((model + sky) t)/t, e-/s per pixel",
    "psf": "Gaussian PSF kernel, unit sum",
    "model": "noise-free image = lens_light_blurred + lensed_source_blurred",
    "lens_light": "lens light averaged over the sub-grid, before the PSF",
    "lens_light_blurred": "lens light convolved with the PSF",
    "lensed_source": "lensed source averaged over the sub-grid, before the PSF",
    "lensed_source_blurred": "lensed source convolved with the PSF",
    "source": "unlensed source, e-/s per image pixel, on the source-plane grid of the header "
    "(PIXSCALE arcsec/pixel, centre XCENTRE, YCENTRE arcsec)",
    "truth": "every parameter of the mock",
}


# --------------------------------------------------------------------------------------
# observation


@dataclass(frozen=True)
class Observation:
    """Grid, PSF, noise and S/N settings of a mock (defaults: SPEC §10.4).

    Attributes
    ----------
    image_size : int
        Image is ``image_size`` × ``image_size`` pixels; odd, so (0, 0) is a pixel centre.
    pixel_scale : float
        Δ in arcsec/pixel.
    sub_size : int
        s: each pixel is the mean of s × s sub-pixel evaluations (lens light and source).
    psf_sigma : float
        Gaussian PSF dispersion in arcsec.
    psf_size : int
        The PSF kernel is ``psf_size`` × ``psf_size`` pixels (odd).
    exposure_time : float
        t in seconds.
    sky : float
        Sky level b in e⁻ s⁻¹ per pixel (added, Poisson-sampled, subtracted).
    signal_to_noise : float
        Target max_i (PSF ⊗ source)_i / σ_i.
    source_plane_pixel_scale : float
        Pixel of the saved unlensed source image, arcsec.
    source_plane_size : int
        The unlensed source image is this many pixels square, centred on the source.
    """

    image_size: int = 151
    pixel_scale: float = 0.05
    sub_size: int = 16
    psf_sigma: float = 0.05
    psf_size: int = 21
    exposure_time: float = 2000.0
    sky: float = 0.15
    signal_to_noise: float = 50.0
    source_plane_pixel_scale: float = 0.01
    source_plane_size: int = 241

    def __post_init__(self):
        for name in ("image_size", "psf_size", "source_plane_size"):
            value = getattr(self, name)
            if not (isinstance(value, int | np.integer) and value >= 3 and value % 2 == 1):
                raise ValueError(f"{name} must be an odd integer >= 3, got {value!r}")
        if not (isinstance(self.sub_size, int | np.integer) and self.sub_size >= 1):
            raise ValueError(f"sub_size must be an integer >= 1, got {self.sub_size!r}")
        for name in (
            "pixel_scale",
            "psf_sigma",
            "exposure_time",
            "signal_to_noise",
            "source_plane_pixel_scale",
        ):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if not self.sky >= 0.0:
            raise ValueError(f"sky must be >= 0 e-/s per pixel, got {self.sky!r}")

    def psf(self) -> np.ndarray:
        """The PSF kernel (psf_size × psf_size, unit sum)."""
        return gaussian_psf(self.psf_size, self.psf_sigma / self.pixel_scale)


def gaussian_psf(size: int, sigma_pixels: float) -> np.ndarray:
    """Circular Gaussian kernel evaluated at pixel centres, normalised to unit sum.

    Parameters
    ----------
    size : int
        Odd kernel size in pixels; the peak is the central pixel.
    sigma_pixels : float
        Dispersion in pixels.
    """
    if size % 2 != 1 or sigma_pixels <= 0.0:
        raise ValueError(f"need an odd size and sigma > 0, got {size}, {sigma_pixels}")
    offsets = np.arange(size) - size // 2
    profile = np.exp(-0.5 * (offsets / sigma_pixels) ** 2)
    kernel = np.outer(profile, profile)
    return kernel / kernel.sum()


class Profile(Protocol):
    """Anything with a surface brightness ``image(x, y)`` at points (x, y), arcsec."""

    def image(self, x: np.ndarray, y: np.ndarray) -> np.ndarray: ...


def oversampled_image(
    profile: Profile,
    shape: tuple[int, int],
    pixel_scale: float,
    sub_size: int,
    origin: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """Pixel averages of ``profile`` over a uniform s × s sub-grid (SPEC §1.3).

    The sub-pixels of a regular grid form the regular grid of spacing Δ/s, so sub-pixel
    (a, b) of pixel (r, c) is fine-grid node (r s + a, c s + b). The image is evaluated a
    band of rows at a time (≈ 5·10⁵ points), which bounds the memory. Profiles with an
    ``image_on_grid(x_axis, y_axis)`` method (values on the outer grid of two 1D axes,
    shape (n_y, n_x)) are evaluated through it; others through ``image(x, y)``.

    Parameters
    ----------
    profile : Profile
    shape : (n_y, n_x)
    pixel_scale : float
        Δ in arcsec.
    sub_size : int
        s.
    origin : (x0, y0)
        Grid origin in arcsec (SPEC §1.1).
    """
    n_y, n_x = shape
    s = int(sub_size)
    step = pixel_scale / s
    fine_x = (np.arange(n_x * s) - (n_x * s - 1) / 2.0) * step + origin[0]
    rows_per_band = max(1, 2**19 // (n_x * s * s))
    on_grid = getattr(profile, "image_on_grid", None)
    out = np.empty(shape)
    for start in range(0, n_y, rows_per_band):
        stop = min(start + rows_per_band, n_y)
        fine_y = (np.arange(start * s, stop * s) - (n_y * s - 1) / 2.0) * step + origin[1]
        if on_grid is None:
            x, y = np.meshgrid(fine_x, fine_y)
            values = np.asarray(profile.image(x.ravel(), y.ravel()), dtype=float)
        else:
            values = on_grid(fine_x, fine_y)
        out[start:stop] = values.reshape(stop - start, s, n_x, s).mean(axis=(1, 3))
    return out


def noise_map_from(model: np.ndarray, exposure_time: float, sky: float) -> np.ndarray:
    """σ = sqrt((m + b) t)/t in e⁻ s⁻¹ per pixel for a noise-free model m (SPEC §10.4)."""
    return np.sqrt((np.asarray(model) + sky) * exposure_time) / exposure_time


def noisy_data(
    model: np.ndarray, exposure_time: float, sky: float, rng: np.random.Generator
) -> np.ndarray:
    """One noise realisation Poisson((m + b) t)/t − b of a non-negative model m."""
    counts = rng.poisson((np.asarray(model) + sky) * exposure_time)
    return counts / exposure_time - sky


def source_amplitude(
    lens_blurred: np.ndarray,
    source_blurred: np.ndarray,
    exposure_time: float,
    sky: float,
    signal_to_noise: float,
    relative_tolerance: float = 1e-12,
) -> float:
    """Factor A with max_i A s_i / σ_i(A) = target, σ from m = lens + A s (bisection).

    The maximum S/N grows monotonically with A (A s / sqrt(L + A s + b) does), so the
    root is unique. ``source_blurred`` must have a positive maximum.
    """
    peak = float(np.max(source_blurred))
    if not peak > 0.0:
        raise ValueError("the lensed source is zero everywhere: it misses the image")
    unit = source_blurred / peak

    def snr(amplitude: float) -> float:
        noise = noise_map_from(lens_blurred + amplitude * unit, exposure_time, sky)
        return float(np.max(amplitude * unit / noise))

    low, high = 0.0, 1.0
    while snr(high) < signal_to_noise:
        low, high = high, 2.0 * high
        if high > 1e30:
            raise ValueError(f"cannot reach S/N {signal_to_noise}: check exposure and sky")
    while high - low > relative_tolerance * high:
        middle = 0.5 * (low + high)
        if snr(middle) < signal_to_noise:
            low = middle
        else:
            high = middle
    return 0.5 * (low + high) / peak


# --------------------------------------------------------------------------------------
# image formation


@dataclass(frozen=True, eq=False)
class MockImaging:
    """A simulated data set with its noise-free components (native 2D arrays, e⁻ s⁻¹/pix).

    Attributes
    ----------
    imaging : Imaging
        Data, noise map and PSF.
    model : ndarray
        Noise-free data = ``lens_light_blurred + lensed_source_blurred``.
    lens_light, lensed_source : ndarray
        Pixel averages over the sub-grid, before the PSF.
    lens_light_blurred, lensed_source_blurred : ndarray
        The same after the PSF.
    source : ndarray
        Unlensed scaled source on the source-plane grid described in ``truth``.
    truth : dict
        Every parameter (written as ``truth.json``).
    """

    imaging: Imaging
    model: np.ndarray
    lens_light: np.ndarray
    lens_light_blurred: np.ndarray
    lensed_source: np.ndarray
    lensed_source_blurred: np.ndarray
    source: np.ndarray
    truth: dict


@dataclass(frozen=True, eq=False)
class Exposure:
    """The images of a mock once its source is scaled to the target S/N and the noise is
    drawn (SPEC §10.4 steps 3–4); e⁻ s⁻¹ per pixel."""

    amplitude: float
    lensed_source: np.ndarray
    lensed_source_blurred: np.ndarray
    model: np.ndarray
    noise_map: np.ndarray
    data: np.ndarray

    def imaging(self, name, psf, observation, lens_light, lens_light_blurred, source, truth):
        """The :class:`MockImaging` of these images with the lens light, the scaled
        source-plane image and the truth."""
        imaging = Imaging(
            self.data, self.noise_map, psf, observation.pixel_scale, name=name,
            unit=BRIGHTNESS_UNIT,
        )  # fmt: skip
        return MockImaging(
            imaging=imaging,
            model=self.model,
            lens_light=lens_light,
            lens_light_blurred=lens_light_blurred,
            lensed_source=self.lensed_source,
            lensed_source_blurred=self.lensed_source_blurred,
            source=source,
            truth=truth,
        )


def expose(
    lens_light_blurred: np.ndarray,
    lensed_unit: np.ndarray,
    source_blurred_unit: np.ndarray,
    observation: Observation,
    seed,
) -> Exposure:
    """Scale the unit lensed source (before and after the PSF) so that its peak S/N is the
    observation's, add it to the blurred lens light, and draw the noise from
    ``default_rng(seed)`` (SPEC §10.4 steps 3–4)."""
    amplitude = source_amplitude(
        lens_light_blurred,
        source_blurred_unit,
        observation.exposure_time,
        observation.sky,
        observation.signal_to_noise,
    )
    source_blurred = amplitude * source_blurred_unit
    model = lens_light_blurred + source_blurred
    noise_map = noise_map_from(model, observation.exposure_time, observation.sky)
    rng = np.random.default_rng(seed)
    data = noisy_data(model, observation.exposure_time, observation.sky, rng)
    return Exposure(amplitude, amplitude * lensed_unit, source_blurred, model, noise_map, data)


@dataclass(frozen=True)
class LensedSource:
    """A source seen through a lens: image(θ) = source(β(θ)), β = θ − α(θ)."""

    source: ProceduralSource | ImageSource
    mass: tuple

    def image(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return self.source.image(*ray_trace(self.mass, x, y))


def simulate(lens: MockLens, observation: Observation | None = None) -> MockImaging:
    """Form the image of ``lens`` (SPEC §10.4): over-sampled light, PSF, S/N scaling, noise.

    Light is evaluated on the image grid padded by half the PSF size on every side,
    convolved and cropped, so border pixels receive the PSF-scattered light from beyond
    the field as in a real cutout (no zero-padding edge darkening).
    """
    observation = Observation() if observation is None else observation
    scale, sub = observation.pixel_scale, observation.sub_size
    psf = observation.psf()
    pad = observation.psf_size // 2
    padded = (observation.image_size + 2 * pad,) * 2
    inner = (slice(pad, pad + observation.image_size),) * 2
    lens_light = oversampled_image(lens.light, padded, scale, sub)
    lensed_unit = oversampled_image(LensedSource(lens.source, lens.mass), padded, scale, sub)
    lens_blurred = convolve_image(lens_light, psf)[inner]
    source_blurred_unit = convolve_image(lensed_unit, psf)[inner]
    lens_light, lensed_unit = lens_light[inner], lensed_unit[inner]
    exposed = expose(lens_blurred, lensed_unit, source_blurred_unit, observation, lens.seed)
    amplitude = exposed.amplitude
    plane_scale = observation.source_plane_pixel_scale
    plane_shape = (observation.source_plane_size, observation.source_plane_size)
    source_plane = amplitude * oversampled_image(
        lens.source, plane_shape, plane_scale, 4, origin=lens.source.centre
    )
    truth = _truth(
        lens,
        observation,
        amplitude=amplitude,
        lens_light=lens_light,
        source_blurred=exposed.lensed_source_blurred,
        noise_map=exposed.noise_map,
        model=exposed.model,
        source_plane=source_plane,
    )
    return exposed.imaging(
        lens.name, psf, observation, lens_light, lens_blurred, source_plane, truth
    )


def _truth(
    lens, observation, *, amplitude, lens_light, source_blurred, noise_map, model, source_plane
) -> dict:
    """The ``truth.json`` content of a simulated mock."""
    scale = observation.pixel_scale
    light = lens.light.to_dict()
    if isinstance(lens.light, MGELight):
        light["total_flux_analytic"] = lens.light.total_flux(scale)
    light["total_flux_in_field"] = float(lens_light.sum())
    offset = np.subtract(lens.source.centre, lens.caustic_centre)
    bright = source_plane > 0.02 * source_plane.max()
    plane_axis = (np.arange(source_plane.shape[0]) - (source_plane.shape[0] - 1) / 2.0) * (
        observation.source_plane_pixel_scale
    )
    plane_x, plane_y = np.meshgrid(plane_axis, plane_axis)
    return {
        "name": lens.name,
        "recipe": lens.recipe,
        "conventions_version": mgelens.CONVENTIONS_VERSION,
        "mgelens_version": mgelens.__version__,
        "units": f"surface brightness in {BRIGHTNESS_UNIT} per image pixel; arcsec; degrees "
        "counter-clockwise from +x",
        "observation": dataclasses.asdict(observation),
        "seed": lens.seed,
        "z_lens": lens.z_lens,
        "z_source": lens.z_source,
        "mask_radius": lens.mask_radius,
        "lens_light": light,
        "mass": [mass_dict(profile) for profile in lens.mass],
        "source": {
            **lens.source.to_dict(),
            "amplitude": amplitude,
            "amplitude_meaning": "surface brightness = amplitude x the profile or image above",
            "caustic_centre": list(lens.caustic_centre),
            "offset_from_caustic_centre": float(np.hypot(*offset)),
            "extent": float(2.0 * np.max(np.hypot(plane_x, plane_y)[bright])),
            "extent_meaning": "diameter (arcsec) of the circle about the source centre that "
            "holds every source-plane pixel above 2% of the peak",
        },
        "signal_to_noise": signal_to_noise_record(source_blurred, model, noise_map),
        "source_plane": {
            "pixel_scale": observation.source_plane_pixel_scale,
            "shape": list(source_plane.shape),
            "centre": list(lens.source.centre),
        },
        "files": {
            key: {"name": MOCK_FILES[key], "content": FILE_DESCRIPTIONS[key]} for key in MOCK_FILES
        },
    }


def signal_to_noise_record(
    source_blurred: np.ndarray, model: np.ndarray, noise_map: np.ndarray
) -> dict:
    """The ``truth.json`` entry of a mock's peak S/N, of its source and of all its light."""
    return {
        "source_max": float(np.max(source_blurred / noise_map)),
        "data_max": float(np.max(model / noise_map)),
        "definition": "max over pixels of the noise-free PSF-convolved component / noise",
    }


def mass_dict(profile) -> dict:
    """The ``truth.json`` entry of a mass profile: its record (``to_dict``) and derived
    values (ell_comps of an EPL or SIE; magnitude and angle of a shear)."""
    entry = profile.to_dict()
    if isinstance(profile, EPL | SIE):
        entry["ell_comps"] = list(profile.ell_comps)
    if isinstance(profile, ExternalShear):
        entry["magnitude"] = profile.magnitude
        entry["angle"] = profile.angle
    return entry


def mass_from_truth(truth: dict) -> list:
    """Rebuild the mass profiles recorded in a ``truth.json`` content."""
    return [mass_from_dict(entry) for entry in truth["mass"]]


def write_mock(mock: MockImaging, folder: str | os.PathLike) -> Path:
    """Write a mock's files (:data:`MOCK_FILES`) into ``folder``, each atomically.

    ``data.fits``, ``noise_map.fits`` and ``psf.fits`` use the layout of the real SLACS
    folders (:meth:`mgelens.imaging.Imaging.to_fits`); ``truth.json`` is written last.
    """
    folder = Path(folder)
    mock.imaging.to_fits(folder)
    scale = mock.imaging.pixel_scale
    for key in (
        "model",
        "lens_light",
        "lens_light_blurred",
        "lensed_source",
        "lensed_source_blurred",
    ):
        _write_image(folder / MOCK_FILES[key], getattr(mock, key), scale)
    plane = mock.truth["source_plane"]
    _write_image(folder / MOCK_FILES["source"], mock.source, plane["pixel_scale"], plane["centre"])
    write_json(folder / MOCK_FILES["truth"], mock.truth)
    return folder


def _write_image(path: Path, image: np.ndarray, pixel_scale: float, centre=(0.0, 0.0)) -> None:
    header = fits.Header()
    header["PIXSCALE"] = (float(pixel_scale), "[arcsec/pixel]")
    header["XCENTRE"] = (float(centre[0]), "[arcsec] x of the array centre")
    header["YCENTRE"] = (float(centre[1]), "[arcsec] y of the array centre")
    header["BUNIT"] = BRIGHTNESS_UNIT
    write_fits(path, fits.PrimaryHDU(data=np.asarray(image, dtype=np.float64), header=header))

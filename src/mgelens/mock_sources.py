"""Unlensed sources of the mocks (SPEC §10.3): procedural galaxies (exponential discs with
a logarithmic spiral modulation and Gaussian clumps, :func:`procedural_source`) or any 2D
image with its pixel scale (:class:`ImageSource`, bilinear interpolation, zero outside).

Coordinates are source-plane (x, y) in arcsec; brightness is unit-free until the
simulation scales it to the target S/N (:func:`mgelens.simulate.source_amplitude`).
"""

import dataclasses
import os
from dataclasses import dataclass, field
from math import atan2, cos, exp, log, sqrt
from pathlib import Path

import numpy as np
from astropy.io import fits
from numba import prange

from mgelens._jit import njit
from mgelens.grid import flat_points
from mgelens.mock_light import EXPONENT_CUTOFF

SOURCE_KINDS = ("spiral", "clumpy", "merger")


@njit(parallel=True, fastmath=True)
def _procedural_source_kernel(x, y, discs, clumps):
    """Sum of spiral discs and circular Gaussian clumps at source-plane points.

    ``discs`` rows: (x_c, y_c, q, cos φ, sin φ, h, I₀, A, m/tan p, arm phase (rad), m);
    ``clumps`` rows: (x_c, y_c, 1/(2σ²), I). Disc terms beyond 30 scale lengths
    (e^−30 ≈ 1e−13 of the centre) are dropped.
    """
    out = np.zeros(x.size)
    for i in prange(x.size):
        total = 0.0
        for d in range(discs.shape[0]):
            dx = x[i] - discs[d, 0]
            dy = y[i] - discs[d, 1]
            xp = dx * discs[d, 3] + dy * discs[d, 4]
            yp = (-dx * discs[d, 4] + dy * discs[d, 3]) / discs[d, 2]
            rh = sqrt(xp * xp + yp * yp) / discs[d, 5]
            if rh > 30.0:
                continue
            disc = discs[d, 6] * exp(-rh)
            if discs[d, 7] != 0.0 and rh > 1e-9:
                phase = discs[d, 10] * atan2(yp, xp) - discs[d, 8] * log(rh) - discs[d, 9]
                disc *= 1.0 + discs[d, 7] * (1.0 - exp(-rh * rh)) * cos(phase)
            total += disc
        for c in range(clumps.shape[0]):
            dx = x[i] - clumps[c, 0]
            dy = y[i] - clumps[c, 1]
            exponent = (dx * dx + dy * dy) * clumps[c, 2]
            if exponent < EXPONENT_CUTOFF:
                total += clumps[c, 3] * exp(-exponent)
        out[i] = total
    return out


# --------------------------------------------------------------------------------------
# sources


@dataclass(frozen=True)
class SpiralDisc:
    """Exponential disc with an m-arm logarithmic spiral modulation.

    In the disc plane (x′ along the projected major axis, y′/q deprojected), with polar
    coordinates (r, ϑ) and h = ``scale_length``:

        I = I₀ e^{−r/h} [1 + A (1 − e^{−(r/h)²}) cos(m ϑ − (m/tan p) ln(r/h) − ϕ)],

    whose arms follow r = h exp[tan p (ϑ − ϕ/m − 2πk/m)] (pitch angle p). A ≤ 1 keeps
    I ≥ 0; the arms fade inside r ≈ h.
    """

    centre: tuple[float, float]
    axis_ratio: float
    angle: float
    scale_length: float
    intensity: float = 1.0
    arm_amplitude: float = 0.0
    pitch_angle: float = 20.0
    arm_phase: float = 0.0
    n_arms: int = 2

    def __post_init__(self):
        if not (0.0 < self.axis_ratio <= 1.0 and self.scale_length > 0.0):
            raise ValueError("disc axis_ratio must be in (0, 1] and scale_length > 0")
        if not 0.0 <= self.arm_amplitude <= 1.0:
            raise ValueError(f"arm_amplitude must be in [0, 1], got {self.arm_amplitude}")
        if not 0.0 < self.pitch_angle < 90.0:
            raise ValueError(f"pitch_angle must be in (0, 90) degrees, got {self.pitch_angle}")

    def row(self) -> list[float]:
        phi = np.deg2rad(self.angle)
        return [
            self.centre[0],
            self.centre[1],
            self.axis_ratio,
            float(np.cos(phi)),
            float(np.sin(phi)),
            self.scale_length,
            self.intensity,
            self.arm_amplitude,
            self.n_arms / float(np.tan(np.deg2rad(self.pitch_angle))),
            float(np.deg2rad(self.arm_phase)),
            float(self.n_arms),
        ]

    def arm_point(self, radius: float, arm: int) -> tuple[float, float]:
        """(x, y) arcsec of the crest of arm ``arm`` at disc-plane radius ``radius``."""
        theta = (
            np.log(radius / self.scale_length) / np.tan(np.deg2rad(self.pitch_angle))
            + (np.deg2rad(self.arm_phase) + 2.0 * np.pi * arm) / self.n_arms
        )
        xp, yp = radius * np.cos(theta), self.axis_ratio * radius * np.sin(theta)
        phi = np.deg2rad(self.angle)
        return (
            float(self.centre[0] + xp * np.cos(phi) - yp * np.sin(phi)),
            float(self.centre[1] + xp * np.sin(phi) + yp * np.cos(phi)),
        )


@dataclass(frozen=True)
class Clump:
    """Circular Gaussian knot I exp(−d²/(2σ²)); σ in arcsec."""

    centre: tuple[float, float]
    sigma: float
    intensity: float


@dataclass(frozen=True)
class ProceduralSource:
    """Source made of spiral discs and clumps (SPEC §10.3); unit-free before scaling.

    Attributes
    ----------
    kind : str
        "spiral", "clumpy" or "merger" (how it was drawn, see :func:`procedural_source`).
    centre : (x, y) arcsec
        Placement point (disc centre, or the mid-point of a merger's two discs).
    discs, clumps : tuples of :class:`SpiralDisc` and :class:`Clump`
    """

    kind: str
    centre: tuple[float, float]
    discs: tuple[SpiralDisc, ...]
    clumps: tuple[Clump, ...] = ()

    def image(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Surface brightness at source-plane points (x, y), arcsec."""
        x_flat, y_flat, shape = flat_points(x, y)
        discs = np.array([d.row() for d in self.discs], dtype=float).reshape(-1, 11)
        clumps = np.array(
            [
                [c.centre[0], c.centre[1], 1.0 / (2.0 * c.sigma**2), c.intensity]
                for c in self.clumps
            ],
            dtype=float,
        ).reshape(-1, 4)
        return _procedural_source_kernel(x_flat, y_flat, discs, clumps).reshape(shape)

    def to_dict(self) -> dict:
        return {"model": "procedural", **dataclasses.asdict(self)}


@dataclass(frozen=True, eq=False)
class ImageSource:
    """A 2D image as the source: bilinear interpolation, zero outside.

    Attributes
    ----------
    pixels : ndarray (n_y, n_x)
        Surface brightness (any unit: the amplitude is set by the S/N), row index
        increasing with +y like every mgelens array.
    pixel_scale : float
        Arcsec per source-image pixel.
    centre : (x, y) arcsec
        Source-plane position of the image centre (pixel centres follow SPEC §1.1 with
        this origin).
    path : str
        File the image came from (recorded in the truth), "" if none.
    """

    pixels: np.ndarray = field(repr=False)
    pixel_scale: float
    centre: tuple[float, float] = (0.0, 0.0)
    path: str = ""

    def __post_init__(self):
        pixels = np.asarray(self.pixels, dtype=float)
        if pixels.ndim != 2 or min(pixels.shape) < 2:
            raise ValueError(f"source image must be 2D and at least 2×2, got {pixels.shape}")
        if not np.all(np.isfinite(pixels)):
            raise ValueError(f"source image {self.path or ''} contains NaN or inf")
        if not self.pixel_scale > 0.0:
            raise ValueError(f"source pixel scale must be > 0 arcsec, got {self.pixel_scale}")
        object.__setattr__(self, "pixels", pixels)

    def image(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Bilinear interpolation between pixel centres; 0 beyond the outermost centres."""
        n_y, n_x = self.pixels.shape
        col = (np.asarray(x) - self.centre[0]) / self.pixel_scale + (n_x - 1) / 2.0
        row = (np.asarray(y) - self.centre[1]) / self.pixel_scale + (n_y - 1) / 2.0
        inside = (col >= 0.0) & (col <= n_x - 1) & (row >= 0.0) & (row <= n_y - 1)
        c0 = np.clip(np.floor(col), 0, n_x - 2).astype(np.intp)
        r0 = np.clip(np.floor(row), 0, n_y - 2).astype(np.intp)
        fc = np.clip(col - c0, 0.0, 1.0)
        fr = np.clip(row - r0, 0.0, 1.0)
        p = self.pixels
        value = (1.0 - fr) * ((1.0 - fc) * p[r0, c0] + fc * p[r0, c0 + 1]) + fr * (
            (1.0 - fc) * p[r0 + 1, c0] + fc * p[r0 + 1, c0 + 1]
        )
        return np.where(inside, value, 0.0)

    def to_dict(self) -> dict:
        return {
            "model": "image",
            "path": self.path,
            "shape": list(self.pixels.shape),
            "pixel_scale": self.pixel_scale,
            "centre": list(self.centre),
            "interpolation": "bilinear between pixel centres, zero outside",
        }


def load_source_image(path: str | os.PathLike) -> np.ndarray:
    """Read a 2D source image from a FITS file (first 2D image HDU) or a ``.npy`` file.

    Arrays are used as stored: row index = +y, as astropy reads FITS files.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: source image not found; give a .fits or .npy file")
    if path.suffix.lower() == ".npy":
        pixels = np.load(path, allow_pickle=False)
    elif path.suffix.lower() in {".fits", ".fit", ".fts"} or path.name.lower().endswith(".fits.gz"):
        with fits.open(path) as hdul:
            images = [h.data for h in hdul if h.data is not None and np.ndim(h.data) == 2]
            if not images:
                raise ValueError(f"{path}: no 2D image HDU found")
            pixels = np.array(images[0], dtype=float)
    else:
        raise ValueError(f"{path}: unknown source image format; use .fits or .npy")
    pixels = np.asarray(pixels, dtype=float)
    if pixels.ndim != 2:
        raise ValueError(f"{path}: source image must be 2D, got shape {pixels.shape}")
    return pixels


def procedural_source(kind: str, centre: tuple[float, float], rng: np.random.Generator):
    """Random SLACS-like source of total extent ≈ 1.0–1.5″ placed at ``centre``.

    * "spiral": one disc, h ~ U(0.12, 0.18)″, q ~ U(0.5, 0.9), two arms with amplitude
      U(0.5, 0.8) and pitch U(15°, 30°), 3–4 clumps (σ 0.02–0.04″, 0.3–0.7 I₀) on the arms.
    * "clumpy": a disc with h ~ U(0.15, 0.2)″, weaker arms (0.3–0.6) and 5–6 brighter
      knots (0.6–1.2 I₀) on the arms.
    * "merger": two discs (h ~ U(0.08, 0.12)″, second 0.5–1 times as bright, weak arms)
      0.35–0.55″ apart about ``centre``, and 3–6 tidal clumps along a curved tail
      leaving the second disc.
    """
    if kind not in SOURCE_KINDS:
        raise ValueError(f"unknown source kind {kind!r}; choose one of {', '.join(SOURCE_KINDS)}")
    centre = (float(centre[0]), float(centre[1]))
    if kind == "merger":
        separation = rng.uniform(0.35, 0.55)
        direction = rng.uniform(0.0, 2.0 * np.pi)
        half = 0.5 * separation * np.array([np.cos(direction), np.sin(direction)])
        first = _random_disc(tuple(centre + half), rng, (0.08, 0.12), (0.0, 0.3), 1.0)
        second = _random_disc(
            tuple(centre - half), rng, (0.08, 0.12), (0.0, 0.3), rng.uniform(0.5, 1.0)
        )
        bend = rng.choice([-1.0, 1.0]) * rng.uniform(1.5, 3.0)
        steps = np.sort(rng.uniform(0.15, 0.45, rng.integers(3, 7)))
        clumps = tuple(
            Clump(
                (
                    float(second.centre[0] + s * np.cos(direction + np.pi + bend * s)),
                    float(second.centre[1] + s * np.sin(direction + np.pi + bend * s)),
                ),
                float(rng.uniform(0.02, 0.035)),
                float(rng.uniform(0.3, 0.6) * second.intensity),
            )
            for s in steps
        )
        return ProceduralSource(kind, centre, (first, second), clumps)
    strong = kind == "spiral"
    scale_range = (0.12, 0.18) if strong else (0.15, 0.2)
    disc = _random_disc(centre, rng, scale_range, (0.5, 0.8) if strong else (0.3, 0.6), 1.0)
    n_clumps = rng.integers(3, 5) if strong else rng.integers(5, 7)
    brightness = (0.3, 0.7) if strong else (0.6, 1.2)
    clumps = tuple(
        Clump(
            disc.arm_point(rng.uniform(0.8, 2.5) * disc.scale_length, int(rng.integers(2))),
            float(rng.uniform(0.02, 0.04)),
            float(rng.uniform(*brightness)),
        )
        for _ in range(n_clumps)
    )
    return ProceduralSource(kind, centre, (disc,), clumps)


def _random_disc(centre, rng, scale_range, arm_range, intensity) -> SpiralDisc:
    return SpiralDisc(
        centre=(float(centre[0]), float(centre[1])),
        axis_ratio=float(rng.uniform(0.5, 0.9)),
        angle=float(rng.uniform(0.0, 180.0)),
        scale_length=float(rng.uniform(*scale_range)),
        intensity=float(intensity),
        arm_amplitude=float(rng.uniform(*arm_range)),
        pitch_angle=float(rng.uniform(15.0, 30.0)),
        arm_phase=float(rng.uniform(0.0, 360.0)),
    )

"""The mock lens systems before image formation: the paper's mocks M1–M3 (SPEC §10) and a
SLACS-like population.

Randomness: every draw comes from ``numpy.random.default_rng`` seeded explicitly. A paper
mock with seed k draws its source from ``default_rng([k, 1])`` and its noise from
``default_rng(k)`` (k = 1, 2, 3 for M1, M2, M3), or from ``default_rng(n)`` with a noise
seed n. Population lens i of a population with seed S draws its lens from
``default_rng([S, i, 0])``, its source from ``default_rng([S, i, 1])`` and its noise
from ``default_rng([S, i, 2])``, so a lens does not depend on how many others are drawn.
"""

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mgelens.light import sersic_constant
from mgelens.mass import EPL, ExternalShear, ray_trace
from mgelens.mock_light import IsophoteLight, MGELight, Transition
from mgelens.mock_sources import SOURCE_KINDS, ImageSource, ProceduralSource, procedural_source

logger = logging.getLogger(__name__)

SOURCE_STREAM = 1
"""Second seed word of the source draws of a paper mock: ``default_rng([seed, 1])``."""

# --------------------------------------------------------------------------------------
# mocks


@dataclass(frozen=True)
class MockLens:
    """Everything that defines a mock lens system, before image formation.

    Attributes
    ----------
    name : str
        "M1", "P07", ...
    recipe : str
        How it was made (free text recorded in the truth).
    light : MGELight or IsophoteLight
    mass : tuple of mass profiles
        EPL and optionally ExternalShear (:mod:`mgelens.mass`).
    source : ProceduralSource or ImageSource
        Unit-free; :func:`simulate` scales it to the target S/N.
    caustic_centre : (x, y) arcsec
        Source-plane image of the mass centre, about which the source was placed.
    seed : int or tuple of int
        Entropy of the noise generator ``default_rng(seed)``.
    z_lens, z_source : float
    mask_radius : float
        Fit mask radius in arcsec (recorded for the fits).
    """

    name: str
    recipe: str
    light: MGELight | IsophoteLight
    mass: tuple
    source: ProceduralSource | ImageSource
    caustic_centre: tuple[float, float]
    seed: int | tuple[int, ...]
    z_lens: float
    z_source: float
    mask_radius: float

    def with_source(self, source: ProceduralSource | ImageSource) -> "MockLens":
        return dataclasses.replace(self, source=source)


@dataclass(frozen=True)
class PaperMock:
    """One of the paper's mocks: SPEC §10.1 lens-light MGE and §10.2 EPL mass (no shear).

    Angles are degrees CCW from +x; ``log_sigmas`` are lg of the mgefit major-axis σ in
    arcsec; ``log_intensities`` lg of the peak surface brightness in e⁻ s⁻¹ pix⁻¹.
    """

    name: str
    lens: str
    centre: tuple[float, float]
    axis_ratios: tuple[float, ...]
    angles: tuple[float, ...]
    log_intensities: tuple[float, ...]
    log_sigmas: tuple[float, ...]
    einstein_radius: float
    mass_axis_ratio: float
    mass_angle: float
    slope: float
    z_lens: float
    z_source: float
    mask_radius: float
    seed: int
    source_kind: str

    def light(self) -> MGELight:
        return MGELight.from_table(
            self.centre, self.axis_ratios, self.angles, self.log_intensities, self.log_sigmas
        )

    def mass(self) -> EPL:
        return EPL(
            centre=self.centre,
            einstein_radius=self.einstein_radius,
            axis_ratio=self.mass_axis_ratio,
            angle=self.mass_angle,
            slope=self.slope,
        )


# fmt: off
PAPER_MOCKS = {
    "M1": PaperMock(
        name="M1",
        lens="SDSSJ0252+0039",
        centre=(0.013, -0.070),
        axis_ratios=(0.83, 0.77, 0.83, 0.90, 0.65, 0.64, 0.77, 0.50,
                     1.00, 0.79, 0.48, 0.62, 0.41, 0.18, 0.78, 0.22),
        angles=(-19, -19, 71, -19, -70, 4, 56, -52, 0, -80, -2, -78, 28, 49, -73, -25),
        log_intensities=(0.86, 0.91, 0.29, 0.30, -0.24, -0.48, -0.13, -0.75,
                         -0.73, -0.76, -1.6, -1.4, -2.0, -2.2, -2.2, -2.4),
        log_sigmas=(-1.8, -1.6, -1.4, -1.1, -1.0, -0.85, -0.75, -0.56,
                    -0.25, -0.14, -0.13, 0.0018, 0.020, -0.19, 0.43, -0.11),
        einstein_radius=1.2,
        mass_axis_ratio=0.80,
        mass_angle=45.0,
        slope=2.1,
        z_lens=0.28,
        z_source=0.98,
        mask_radius=1.8,
        seed=1,
        source_kind="spiral",
    ),
    "M2": PaperMock(
        name="M2",
        lens="SDSSJ0330-0020",
        centre=(0.048, 0.017),
        axis_ratios=(0.82, 0.64, 1.0, 0.60, 0.62, 0.91, 0.58, 0.34,
                     1.00, 0.46, 0.59, 0.76, 0.21, 0.30, 0.44, 0.48),
        angles=(65, -64, 0, -78, -23, 65, -55, 84, 0, -66, -89, -40, -81, 7, 65, -47),
        log_intensities=(1.0, 0.69, 0.26, 0.14, -0.47, -0.19, -0.63, -1.1,
                         -1.1, -0.86, -1.1, -1.1, -2.3, -2.3, -1.8, -1.7),
        log_sigmas=(-1.7, -1.4, -1.1, -1.1, -0.91, -0.72, -0.72, -0.78,
                    -0.25, -0.50, -0.23, -0.11, -0.15, 0.018, 0.18, 0.22),
        einstein_radius=1.0,
        mass_axis_ratio=0.77,
        mass_angle=60.0,
        slope=1.9,
        z_lens=0.35,
        z_source=1.1,
        mask_radius=1.6,
        seed=2,
        source_kind="clumpy",
    ),
    "M3": PaperMock(
        name="M3",
        lens="SDSSJ1205+4910",
        centre=(-0.001, -0.034),
        axis_ratios=(0.92, 1.0, 0.85, 0.62, 0.84, 0.70, 0.73, 0.66, 0.58, 0.67, 0.36, 0.84),
        angles=(-63, -90, -24, 27, -62, -25, -18, -70, -25, 8, -31, -28),
        log_intensities=(0.78, 1.1, 0.71, -0.65, -0.24, 0.077, -0.015, -1.1,
                         -0.61, -0.90, -1.4, -1.2),
        log_sigmas=(-1.8, -1.3, -0.98, -0.86, -0.68, -0.75, -0.44, -0.22,
                    -0.17, 0.085, 0.082, -1.2),
        einstein_radius=1.1,
        mass_axis_ratio=0.75,
        mass_angle=30.0,
        slope=2.0,
        z_lens=0.22,
        z_source=0.48,
        mask_radius=1.8,
        seed=3,
        source_kind="merger",
    ),
}
"""The paper's mocks (SPEC §10.1–10.2); sources S1–S3 are procedural stand-ins (§10.3)."""
# fmt: on


def caustic_centre(mass: Sequence) -> tuple[float, float]:
    """Source-plane position of the first profile's centre (the caustics' centre).

    Taken as the mean ray-traced position of 16 points on a 10⁻³″ circle about the
    centre: exact for deflections that are odd about the centre (EPL, SIE) plus any
    linear field (shear), and it avoids the centre itself, where the EPL deflection is
    singular for γ > 2.
    """
    angles = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
    x = mass[0].centre[0] + 1e-3 * np.cos(angles)
    y = mass[0].centre[1] + 1e-3 * np.sin(angles)
    beta_x, beta_y = ray_trace(mass, x, y)
    return float(np.mean(beta_x)), float(np.mean(beta_y))


def _placed_source(kind: str, centre: tuple[float, float], rng: np.random.Generator):
    """Procedural source 0.05–0.15″ from ``centre`` in a random direction (SPEC §10.3)."""
    offset = rng.uniform(0.05, 0.15)
    direction = rng.uniform(0.0, 2.0 * np.pi)
    placed = (centre[0] + offset * np.cos(direction), centre[1] + offset * np.sin(direction))
    return procedural_source(kind, placed, rng)


def paper_mock(name: str, seed: int | None = None, noise_seed: int | None = None) -> MockLens:
    """The paper's mock ``name`` ("M1", "M2" or "M3"), optionally with other seeds.

    The seed (default 1, 2, 3) drives the noise (``default_rng(seed)``) and the procedural
    source (``default_rng([seed, 1])``). ``noise_seed`` replaces the seed of the noise
    alone: the same lens and source seen through another Poisson realisation, the test of
    whether a fit's miss is the noise image's (``MockLens.seed`` is the noise seed).
    """
    if name not in PAPER_MOCKS:
        raise ValueError(f"unknown mock {name!r}; choose one of {', '.join(PAPER_MOCKS)}")
    table = PAPER_MOCKS[name]
    seed = table.seed if seed is None else int(seed)
    noise = seed if noise_seed is None else int(noise_seed)
    if noise < 0:
        raise ValueError(f"noise_seed must be >= 0, got {noise}")
    mass = (table.mass(),)
    centre = caustic_centre(mass)
    source = _placed_source(table.source_kind, centre, np.random.default_rng([seed, SOURCE_STREAM]))
    seeds = "" if noise == seed else f"; source seed {seed}, noise seed {noise}"
    return MockLens(
        name=name,
        recipe=f"paper mock {name}: lens light = mgefit MGE of {table.lens} (SPEC 10.1), "
        f"EPL mass (SPEC 10.2), procedural {table.source_kind} source{seeds}",
        light=table.light(),
        mass=mass,
        source=source,
        caustic_centre=centre,
        seed=noise,
        z_lens=table.z_lens,
        z_source=table.z_source,
        mask_radius=table.mask_radius,
    )


DEFAULT_POPULATION_SEED = 2024
POPULATION_SIZE = 38
POPULATION_MASK_RADIUS = 3.0


def random_shear(rng: np.random.Generator, max_magnitude: float = 0.1) -> ExternalShear:
    """External shear of magnitude U(0, ``max_magnitude``) at an angle U(0°, 180°), drawn
    in that order from ``rng``."""
    magnitude = rng.uniform(0.0, max_magnitude)
    angle = np.deg2rad(rng.uniform(0.0, 180.0))
    return ExternalShear(
        gamma_1=float(magnitude * np.cos(2.0 * angle)),
        gamma_2=float(magnitude * np.sin(2.0 * angle)),
    )


def population_lens(index: int, population_seed: int = DEFAULT_POPULATION_SEED) -> MockLens:
    """Lens ``index`` of a SLACS-like mock population (named ``P{index:02d}``).

    Distributions (drawn from ``default_rng([population_seed, index, 0])``):

    * mass: EPL centre N(0, 0.02″) per axis; θ_E ~ U(0.8, 1.6)″; γ ~ N(2.08, 0.1)
      clipped to [1.8, 2.4]; q ~ N(0.75, 0.1) clipped to [0.5, 0.95]; φ = outer light PA
      + N(0, 10°); external shear |γ| ~ U(0, 0.1) at an angle U(0°, 180°).
    * light (:class:`IsophoteLight`, same centre as the mass): Sérsic n ~ U(3, 5),
      R_e ~ logU(0.8, 2.5)″, surface brightness at a = 1″ ~ logU(0.06, 0.25) e⁻ s⁻¹ pix⁻¹;
      q from U(0.6, 0.95) inside to that + U(−0.2, 0.15) outside (clipped to
      [0.5, 0.97]); PA from U(0°, 180°) twisting by N(0, 20°) clipped to ±45°; a₄/a from
      U(−0.02, 0.025) inside to U(−0.02, 0.025) outside; each transition at a radius
      logU(0.5, 2.0)″ with width U(0.5, 0.9) in ln a. Draws whose isophotes would not
      nest are redrawn.
    * source: kind uniform over spiral / clumpy / merger, placed 0.05–0.15″ from the
      caustic centre (``default_rng([population_seed, index, 1])``).
    * z_lens ~ U(0.1, 0.35), z_source = z_lens + U(0.2, 0.7); fit mask radius 3.0″.

    The noise uses ``default_rng([population_seed, index, 2])``.
    """
    if not (isinstance(index, int | np.integer) and index >= 0):
        raise ValueError(f"population index must be an integer >= 0, got {index!r}")
    rng = np.random.default_rng([population_seed, index, 0])
    centre = (float(rng.normal(0.0, 0.02)), float(rng.normal(0.0, 0.02)))
    light = _random_isophote_light(centre, rng)
    shear = random_shear(rng)
    mass = (
        EPL(
            centre=centre,
            einstein_radius=float(rng.uniform(0.8, 1.6)),
            axis_ratio=float(np.clip(rng.normal(0.75, 0.1), 0.5, 0.95)),
            angle=float(np.mod(light.angle.outer + rng.normal(0.0, 10.0), 180.0)),
            slope=float(np.clip(rng.normal(2.08, 0.1), 1.8, 2.4)),
        ),
        shear,
    )
    z_lens = float(rng.uniform(0.1, 0.35))
    z_source = z_lens + float(rng.uniform(0.2, 0.7))
    source_rng = np.random.default_rng([population_seed, index, 1])
    kind = str(source_rng.choice(SOURCE_KINDS))
    centre_source = caustic_centre(mass)
    return MockLens(
        name=f"P{index:02d}",
        recipe=f"population lens {index} of seed {population_seed}: isophote lens light, "
        f"EPL + shear mass, procedural {kind} source",
        light=light,
        mass=mass,
        source=_placed_source(kind, centre_source, source_rng),
        caustic_centre=centre_source,
        seed=(int(population_seed), int(index), 2),
        z_lens=z_lens,
        z_source=z_source,
        mask_radius=POPULATION_MASK_RADIUS,
    )


def _random_isophote_light(centre, rng: np.random.Generator) -> IsophoteLight:
    n = float(rng.uniform(3.0, 5.0))
    effective_radius = float(np.exp(rng.uniform(np.log(0.8), np.log(2.5))))
    brightness_1 = float(np.exp(rng.uniform(np.log(0.06), np.log(0.25))))
    intensity = brightness_1 * float(
        np.exp(sersic_constant(n) * ((1.0 / effective_radius) ** (1.0 / n) - 1.0))
    )
    while True:
        q_inner = rng.uniform(0.6, 0.95)
        q_outer = np.clip(q_inner + rng.uniform(-0.2, 0.15), 0.5, 0.97)
        angle_inner = rng.uniform(0.0, 180.0)
        twist = np.clip(rng.normal(0.0, 20.0), -45.0, 45.0)
        transitions = [
            (float(np.exp(rng.uniform(np.log(0.5), np.log(2.0)))), float(rng.uniform(0.5, 0.9)))
            for _ in range(3)
        ]
        try:
            return IsophoteLight(
                centre=centre,
                intensity=intensity,
                effective_radius=effective_radius,
                sersic_index=n,
                axis_ratio=Transition(float(q_inner), float(q_outer), *transitions[0]),
                angle=Transition(float(angle_inner), float(angle_inner + twist), *transitions[1]),
                a4=Transition(
                    float(rng.uniform(-0.02, 0.025)),
                    float(rng.uniform(-0.02, 0.025)),
                    *transitions[2],
                ),
            )
        except ValueError:
            logger.debug("isophote draw does not nest; drawing again")


def with_image_source(lens: MockLens, pixels: np.ndarray, pixel_scale: float, path="") -> MockLens:
    """``lens`` with its procedural source replaced by an image at the same position."""
    centre = lens.source.centre
    return lens.with_source(ImageSource(pixels, pixel_scale, centre, str(path)))

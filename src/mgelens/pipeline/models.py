"""Parameter spaces of the five SLaM phases and the mapping of a values dict onto profiles.

Parameter names (stable, dotted; SPEC §8.1):

* lens light, one MGE set per ``<set>`` = ``set_0``, ``set_1``, ... (30 Gaussians) or
  ``point`` (10 Gaussians): ``lens_light.<set>.centre_x``, ``.centre_y``, ``.ell_comps_1``,
  ``.ell_comps_2``. The extended sets share one centre: the centres of ``set_1``, ... are
  tied to those of ``set_0``. The point set has its own centre.
  The 3×Sérsic alternative (SPEC §2.3, §8.1) uses ``sersic_0``, ``sersic_1``, ... instead,
  each with ``.effective_radius`` (arcsec) and ``.sersic_index`` besides the four above;
  their centres are tied to ``sersic_0``'s. Every intensity is solved linearly.
* mass: ``mass.centre_x``, ``mass.centre_y``, ``mass.ell_comps_1``, ``mass.ell_comps_2``,
  ``mass.einstein_radius`` and, for the EPL, ``mass.slope`` (without it the profile is the
  SIE); external shear ``shear.gamma_1``, ``shear.gamma_2``.
* SP source MGE: ``source.set_0.centre_x``, ... (20 Gaussians, σ 0.01″–1.0″).
* pixelized source: ``regularization.coefficient`` (constant schemes) or
  ``regularization.inner_coefficient``, ``.outer_coefficient``, ``.signal_scale``
  (AdaptiveBrightnessSplit); k-means mesh ``mesh.weight_floor``, ``mesh.weight_power``
  and, with the arcs' support, ``mesh.arc_threshold``.
* lens-light prior (``slam.lens_light_prior: smoothness``, LIGHT and MASS):
  ``lens_light.smoothness``, λ of :mod:`mgelens.light_prior`.

Coordinates in arcsec, ell_comps = (f cos 2φ, f sin 2φ) with φ CCW from +x (SPEC §2.1).
Every phase's space also lists the parameters it keeps fixed (at an earlier phase's
maximum-likelihood values), so a result file describes its whole model.
"""

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from scipy import optimize

from mgelens.fit import LensModel, MGESource, PixelizedSource
from mgelens.light import MGESet, Sersic, log_spaced_sigmas
from mgelens.light_prior import MGESmoothnessPrior
from mgelens.mass import EPL, SIE, SLOPE_RANGE, ExternalShear, ray_trace
from mgelens.pipeline.parameters import lens_parameter
from mgelens.search.model import Parameter
from mgelens.search.priors import Gaussian, LogUniform, Prior, TruncatedGaussian, Uniform
from mgelens.search.results import PhaseResult
from mgelens.source import support
from mgelens.source.image_mesh import hilbert_order, kmeans_centres, kmeans_weights
from mgelens.source.regularization import AdaptiveBrightnessSplit, Constant, ConstantSplit

LENS_LIGHT, MASS, SHEAR, SOURCE = "lens_light", "mass", "shear", "source"
MESH, REGULARIZATION = "mesh", "regularization"
ARC_THRESHOLD = f"{MESH}.arc_threshold"
ARC_THRESHOLD_PRIOR = LogUniform(1e-3, 0.3)
"""SPix2's prior on the source support's arc threshold (fraction of the adapt image's peak)."""
SMOOTHNESS = f"{LENS_LIGHT}.smoothness"
SMOOTHNESS_PRIOR = LogUniform(1e-3, 1e7)
"""LIGHT's prior on λ of the lens light's smoothness prior (:mod:`mgelens.light_prior`)."""

SOURCE_MGE_SIGMAS = log_spaced_sigmas(0.01, 1.0, 20)
"""σ (arcsec) of the SP source MGE: 20 Gaussians from 0.01″ to 1.0″ (SPEC §2.4)."""

ELL_COMPS_PRIOR = TruncatedGaussian(0.0, 0.3, -1.0, 1.0)
"""Anchor ell_comps prior, N(0, 0.3) on [−1, 1] (SPEC §2.4, §3.1)."""
LIGHT_PHASE_ELL_COMPS_PRIOR = Uniform(-0.7, 0.7)
"""ell_comps of the extended sets in the LIGHT phase (SPEC §8.1)."""
LIGHT_PHASE_CENTRE_HALF_WIDTH = 0.1
"""LIGHT-phase centres are U(c_SP ± 0.1″) (SPEC §8.1)."""
SERSIC_PRIORS = {"effective_radius": Uniform(0.0, 30.0), "sersic_index": Uniform(0.8, 5.0)}
"""Anchor priors of a linear Sérsic's R_e (arcsec) and n (autogalaxy ``linear/sersic.yaml``)."""
EINSTEIN_RADIUS_PRIOR = Uniform(0.0, 8.0)
SHEAR_PRIOR = Uniform(-0.2, 0.2)
SLOPE_PRIOR = Uniform(1.5, 3.0)
COEFFICIENT_PRIOR = LogUniform(1e-6, 1e6)

PASSED_MASS_NAMES = (
    "mass.centre_x",
    "mass.centre_y",
    "mass.ell_comps_1",
    "mass.ell_comps_2",
    "mass.einstein_radius",
    "shear.gamma_1",
    "shear.gamma_2",
)
"""Parameters passed SP → SPix1 and SPix1 → MASS (SIE → EPL: the shared ones, SPEC §8.2)."""


class UnphysicalSample(ValueError):
    """Parameter values the profiles cannot represent (e.g. an EPL slope ≥ 3)."""


# -- lens light -------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class LightSetSpec:
    """One MGE set of the lens light: its name (``set_<k>`` or ``point``) and fixed σ.

    ``sigmas`` are the anchor's minor-axis dispersions in arcsec (SPEC §2.2).
    """

    name: str
    sigmas: np.ndarray

    @property
    def prefix(self) -> str:
        return f"{LENS_LIGHT}.{self.name}"

    def component(self, values: Mapping[str, float]) -> MGESet:
        """The set with centre and ell_comps from ``values``."""
        centre, ell_comps = _centre_and_ell_comps(values, self.prefix)
        return MGESet(centre, ell_comps, self.sigmas)

    def describe(self) -> dict:
        return {"name": self.name, "kind": "mge", "n_gaussians": int(self.sigmas.size)}


@dataclass(frozen=True)
class SersicSpec:
    """One elliptical Sérsic of the lens light (``sersic_<k>``) whose I_e is solved linearly."""

    name: str

    @property
    def prefix(self) -> str:
        return f"{LENS_LIGHT}.{self.name}"

    def component(self, values: Mapping[str, float]) -> Sersic:
        """The unit-intensity Sérsic of ``values``.

        Raises
        ------
        UnphysicalSample
            If R_e ≤ 0 (the edge of its prior) or n lies outside the Sérsic's range.
        """
        centre, ell_comps = _centre_and_ell_comps(values, self.prefix)
        try:
            return Sersic(
                centre,
                ell_comps,
                values[f"{self.prefix}.effective_radius"],
                values[f"{self.prefix}.sersic_index"],
            )
        except ValueError as error:
            raise UnphysicalSample(f"{self.name}: {error}") from error

    def describe(self) -> dict:
        return {"name": self.name, "kind": "sersic"}


LightSpec = LightSetSpec | SersicSpec


def _centre_and_ell_comps(values: Mapping[str, float], prefix: str):
    centre = (values[f"{prefix}.centre_x"], values[f"{prefix}.centre_y"])
    return centre, (values[f"{prefix}.ell_comps_1"], values[f"{prefix}.ell_comps_2"])


def sersic_specs(n_profiles: int) -> tuple[SersicSpec, ...]:
    """``n_profiles`` Sérsics ``sersic_0``, ... (2 in SP, 3 in LIGHT; SPEC §8.1)."""
    return tuple(SersicSpec(f"sersic_{k}") for k in range(n_profiles))


def mge_specs(
    n_sets: int, point_set: bool, pixel_scale: float, mask_radius: float
) -> tuple[LightSetSpec, ...]:
    """``n_sets`` extended sets (30 Gaussians, σ from Δ/5 to the mask radius) + point set."""
    extended = MGESet.extended((0.0, 0.0), (0.0, 0.0), pixel_scale, mask_radius).sigmas
    specs = [LightSetSpec(f"set_{k}", extended) for k in range(n_sets)]
    if point_set:
        specs.append(
            LightSetSpec("point", MGESet.point((0.0, 0.0), (0.0, 0.0), pixel_scale).sigmas)
        )
    return tuple(specs)


def geometry_parameters(
    prefix: str, centre: Sequence[Prior], ell_comps: Sequence[Prior]
) -> list[Parameter]:
    names = ("centre_x", "centre_y", "ell_comps_1", "ell_comps_2")
    priors = (*centre, *ell_comps)
    return [lens_parameter(f"{prefix}.{n}", prior=p) for n, p in zip(names, priors, strict=True)]


def lens_light_parameters(
    specs: Sequence[LightSpec],
    centre: Sequence[Prior],
    ell_comps: Prior,
    point_centre: Sequence[Prior] = (),
    point_ell_comps: Prior = ELL_COMPS_PRIOR,
) -> list[Parameter]:
    """Free lens-light geometry: one shared centre for the extended sets or Sérsics (later
    ones' centres tied to the first), own ell_comps each (Sérsics also R_e and n,
    :data:`SERSIC_PRIORS`); the point set has its own centre and ell_comps.
    """
    parameters: list[Parameter] = []
    first = None
    for spec in specs:
        if spec.name == "point":
            parameters += geometry_parameters(spec.prefix, point_centre, (point_ell_comps,) * 2)
            continue
        geometry = geometry_parameters(spec.prefix, centre, (ell_comps,) * 2)
        if isinstance(spec, SersicSpec):
            geometry += [
                lens_parameter(f"{spec.prefix}.{n}", prior=p) for n, p in SERSIC_PRIORS.items()
            ]
        if first is None:
            first = spec.prefix
        else:
            geometry[:2] = [
                lens_parameter(f"{spec.prefix}.{n}", tied_to=f"{first}.{n}")
                for n in ("centre_x", "centre_y")
            ]
        parameters += geometry
    return parameters


def lens_light_components(values: Mapping[str, float], specs: Sequence[LightSpec]) -> tuple:
    """The linear lens light of ``specs`` (MGE sets, unit Sérsics) with values from ``values``."""
    return tuple(spec.component(values) for spec in specs)


# -- mass -------------------------------------------------------------------------------
def sp_mass_priors(centre: tuple[float, float] = (0.0, 0.0)) -> dict[str, Prior]:
    """Anchor priors of SIE + shear (SPEC §3.1, §3.2): centre N(c, 0.1″), ell_comps
    N(0, 0.3) on [−1, 1], θ_E U(0, 8″), γ₁, γ₂ U(−0.2, 0.2)."""
    return {
        "mass.centre_x": Gaussian(centre[0], 0.1),
        "mass.centre_y": Gaussian(centre[1], 0.1),
        "mass.ell_comps_1": ELL_COMPS_PRIOR,
        "mass.ell_comps_2": ELL_COMPS_PRIOR,
        "mass.einstein_radius": EINSTEIN_RADIUS_PRIOR,
        "shear.gamma_1": SHEAR_PRIOR,
        "shear.gamma_2": SHEAR_PRIOR,
    }


def mass_profiles(values: Mapping[str, float]) -> tuple:
    """(SIE or EPL, ExternalShear) from ``values``; EPL iff ``mass.slope`` is present.

    Raises
    ------
    UnphysicalSample
        If the slope lies outside the EPL's valid range (1.2, 3) (:data:`SLOPE_RANGE`).
    """
    centre = (values["mass.centre_x"], values["mass.centre_y"])
    ell_comps = (values["mass.ell_comps_1"], values["mass.ell_comps_2"])
    einstein_radius = values["mass.einstein_radius"]
    shear = ExternalShear(values["shear.gamma_1"], values["shear.gamma_2"])
    if "mass.slope" not in values:
        return SIE.from_ell_comps(centre, ell_comps, einstein_radius), shear
    slope = values["mass.slope"]
    if not SLOPE_RANGE[0] < slope < SLOPE_RANGE[1]:
        raise UnphysicalSample(f"EPL slope {slope} outside {SLOPE_RANGE}")
    return EPL.from_ell_comps(centre, ell_comps, einstein_radius, slope), shear


# -- multiple-image positions (SPEC §12.21) ---------------------------------------------
POSITIONS_PENALTY_OFFSET = -1e10
"""ln L of a sample whose positions do not re-converge, minus 1e8 per arcsec of excess:
below any fit's ln L, above a rejected sample's −1e99."""
POSITIONS_PENALTY_SLOPE = 1e8


def multiple_image_positions(
    mass: Sequence,
    source_centre: tuple[float, float],
    x: np.ndarray,
    y: np.ndarray,
    tolerance: float = 1e-3,
) -> np.ndarray:
    """Image-plane positions (n, 2) arcsec whose rays land on ``source_centre``.

    Starting points are the local minima of |β(θ) − β_s| on the native grid of points
    (x, y) (2D arrays, unmasked points only, others NaN); each is refined with
    Nelder–Mead and kept if it traces to within ``tolerance`` arcsec of the source centre.
    Positions closer than 0.05″ are merged.
    """
    bx, by = ray_trace(mass, np.nan_to_num(x), np.nan_to_num(y))
    distance = np.hypot(bx - source_centre[0], by - source_centre[1])
    distance[np.isnan(x)] = np.inf
    padded = np.pad(distance, 1, constant_values=np.inf)
    neighbours = [
        padded[1 + dr : padded.shape[0] - 1 + dr, 1 + dc : padded.shape[1] - 1 + dc]
        for dr in (-1, 0, 1)
        for dc in (-1, 0, 1)
        if dr or dc
    ]
    minima = np.isfinite(distance) & np.all([distance <= n for n in neighbours], axis=0)
    positions: list[np.ndarray] = []
    for start in np.column_stack([x[minima], y[minima]]):
        refined = optimize.minimize(
            lambda p: float(np.hypot(*np.subtract(ray_trace(mass, p[0], p[1]), source_centre))),
            start,
            method="Nelder-Mead",
            options={"xatol": 1e-7, "fatol": 1e-9},
        )
        close = [np.hypot(*(refined.x - q)) < 0.05 for q in positions]
        if refined.fun < tolerance and not any(close):
            positions.append(refined.x)
    return np.array(positions).reshape(-1, 2)


@dataclass(frozen=True, eq=False)
class PositionsPenalty:
    """Multiple images of the source centre must re-converge in the source plane
    (optional, SPEC §12.21; anchor ``positions_likelihood_from(factor=3, minimum=0.2″)``).

    A mass model whose traced ``positions`` (n, 2) arcsec spread more than ``threshold``
    (maximum pairwise separation, arcsec) in the source plane is not fitted: it gets
    ln L = −1e10 − 1e8 × excess, which steers the sampler away from unphysical
    (e.g. demagnified) solutions without the cost of an inversion.
    """

    positions: np.ndarray
    threshold: float

    def separation(self, mass: Sequence) -> float:
        """Maximum pairwise source-plane separation (arcsec) of the traced positions."""
        bx, by = ray_trace(mass, self.positions[:, 0], self.positions[:, 1])
        return float(np.max(np.hypot(bx[:, None] - bx, by[:, None] - by)))

    def log_likelihood(self, mass: Sequence) -> float | None:
        """The penalty ln L, or ``None`` if the positions re-converge."""
        excess = self.separation(mass) - self.threshold
        if excess <= 0.0:
            return None
        return POSITIONS_PENALTY_OFFSET - POSITIONS_PENALTY_SLOPE * excess

    def describe(self) -> dict:
        return {"positions": self.positions.tolist(), "threshold": self.threshold}


# -- sources ----------------------------------------------------------------------------
def regularization_from(
    values: Mapping[str, float], scheme: str, offset: str = "anchor", signals: str = "anchor"
):
    """Regularization object of ``scheme`` ("constant", "constant_split", "adaptive_split");
    ``offset`` is the cross offset (SPEC §5.3), ``signals`` the adaptive signal average
    (:func:`mgelens.source.regularization.adaptive_pixel_signals`)."""
    if scheme == "constant":
        return Constant(values["regularization.coefficient"])
    if scheme == "constant_split":
        return ConstantSplit(values["regularization.coefficient"], offset)
    if scheme == "adaptive_split":
        return AdaptiveBrightnessSplit(
            values["regularization.inner_coefficient"],
            values["regularization.outer_coefficient"],
            values["regularization.signal_scale"],
            offset,
            signals,
        )
    raise ValueError(f"unknown regularization scheme {scheme!r}")


@dataclass(frozen=True, eq=False)
class MGESourceModel:
    """SP source: one MGE set in the source plane (:data:`SOURCE_MGE_SIGMAS`)."""

    sigmas: np.ndarray = field(default_factory=SOURCE_MGE_SIGMAS.copy)

    def build(self, values: Mapping[str, float]) -> MGESource:
        p = f"{SOURCE}.set_0"
        centre = (values[f"{p}.centre_x"], values[f"{p}.centre_y"])
        ell_comps = (values[f"{p}.ell_comps_1"], values[f"{p}.ell_comps_2"])
        return MGESource((MGESet(centre, ell_comps, self.sigmas),))

    def describe(self) -> dict:
        return {"kind": "mge", "sigmas": self.sigmas.tolist()}


@dataclass(frozen=True, eq=False)
class MeshSourceModel:
    """Pixelized source on fixed image-plane centres (overlay or a fixed k-means mesh).

    Attributes
    ----------
    x, y : ndarray
        Image-plane mesh centres (arcsec).
    regularization : str
        Scheme for :func:`regularization_from`.
    interpolation, offset : str
        Source interpolation and cross offset (SPEC §4.4, §5.3).
    adapt_image : ndarray or None
        Slim adapt image (needed by adaptive schemes).
    mesh : str
        "overlay" or "kmeans", for the record.
    signals : {"anchor", "weighted"}
        Adaptive signal average (adaptive schemes only).
    arc_threshold : float or None
        Source support: only the source pixels reached by the image pixels where the adapt
        image exceeds this fraction of its peak are solved (:mod:`mgelens.source.support`);
        None: the whole traced mask.
    arc_floor : ndarray or None
        Slim (N_I,) floor the adapt image must also exceed in an arc pixel (data units;
        k times the noise map for ``slam.arc_noise_floor`` k); None: no floor.
    """

    x: np.ndarray
    y: np.ndarray
    regularization: str
    interpolation: str = "natural_neighbour"
    offset: str = "anchor"
    adapt_image: np.ndarray | None = None
    mesh: str = "overlay"
    signals: str = "anchor"
    arc_threshold: float | None = None
    arc_floor: np.ndarray | None = None

    def build(self, values: Mapping[str, float]) -> PixelizedSource:
        arcs = (
            None
            if self.arc_threshold is None
            else support.arc_pixels(self.adapt_image, self.arc_threshold, self.arc_floor)
        )
        return PixelizedSource(
            self.x,
            self.y,
            regularization_from(values, self.regularization, self.offset, self.signals),
            self.interpolation,
            self.adapt_image,
            arcs,
        )

    def describe(self) -> dict:
        return {
            "kind": "pixelized",
            "mesh": self.mesh,
            "n_pixels": int(self.x.size),
            "regularization": self.regularization,
            "interpolation": self.interpolation,
            "cross_offset": self.offset,
            **({"adaptive_signals": self.signals} if "adaptive" in self.regularization else {}),
            **({"arc_threshold": self.arc_threshold} if self.arc_threshold is not None else {}),
        }


@dataclass(frozen=True, eq=False)
class KMeansSourceModel:
    """SPix2 source: k-means mesh recomputed from ``mesh.weight_floor`` and
    ``mesh.weight_power`` for every sample (fixed seed), AdaptiveBrightnessSplit.

    Attributes
    ----------
    pixel_x, pixel_y : ndarray
        Unmasked pixel centres (arcsec), the points k-means clusters.
    adapt_image : ndarray
        Slim adapt image Ξ (SPix1's lensed source model).
    n_pixels, seed : int
        Clusters and k-means seed.
    scheme : {"2023", "2024"}
        Weight formula (SPEC §4.1).
    interpolation, offset, signals : str
        As in :class:`MeshSourceModel`.
    support : {"mask", "arcs"}
        The source's support (``SlamSettings.source_support``): with ``arcs`` the
        hyper-parameter ``mesh.arc_threshold`` sets it.
    seeding : str
        k-means seeding (``SlamSettings.kmeans_seeding``).
    arc_noise_floor : float
        ``SlamSettings.arc_noise_floor`` k: an arc pixel's adapt image must also exceed k
        times its noise (0: no floor; needs ``noise_map``).
    noise_map : ndarray or None
        Slim (N_I,) noise map σ (data units), for the arcs' noise floor.
    signals_mass : {"fitted", "spix2"}
        ``SlamSettings.adaptive_signals_mass``: with ``spix2`` the :meth:`fixed` source
        holds its adaptive signals at the mass it is fixed at.
    """

    pixel_x: np.ndarray
    pixel_y: np.ndarray
    adapt_image: np.ndarray
    n_pixels: int
    seed: int = 0
    scheme: str = "2023"
    interpolation: str = "natural_neighbour"
    offset: str = "anchor"
    signals: str = "anchor"
    support: str = "mask"
    seeding: str = "kmeans++"
    arc_noise_floor: float = 0.0
    noise_map: np.ndarray | None = None
    signals_mass: str = "fitted"

    def __post_init__(self):
        if self.arc_noise_floor > 0.0 and (self.support != "arcs" or self.noise_map is None):
            raise ValueError(
                "an arcs' noise floor needs the arcs' support and the noise map "
                f"(support {self.support!r}, noise map given: {self.noise_map is not None})"
            )

    @classmethod
    def from_settings(
        cls,
        pixel_x: np.ndarray,
        pixel_y: np.ndarray,
        adapt_image: np.ndarray,
        settings,
        n_pixels: int,
        noise_map: np.ndarray | None = None,
    ) -> "KMeansSourceModel":
        """The k-means source of ``n_pixels`` pixels on these pixels and adapt image, with
        the seed, scheme, interpolation, cross offset, adaptive signals, support, seeding,
        arcs' noise floor and adaptive signals' mass of ``settings``
        (:class:`~mgelens.pipeline.settings.SlamSettings`); ``noise_map`` (slim σ) is
        needed for a noise floor."""
        return cls(
            pixel_x,
            pixel_y,
            adapt_image,
            n_pixels,
            settings.kmeans_seed,
            settings.kmeans_scheme,
            settings.interpolation,
            settings.cross_offset,
            settings.adaptive_signals,
            settings.source_support,
            settings.kmeans_seeding,
            settings.arc_noise_floor,
            noise_map,
            settings.adaptive_signals_mass,
        )

    def centres(self, values: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
        """Image-plane k-means centres for the weight hyper-parameters in ``values``
        (duplicated centres make the mesh degenerate, which rejects the sample)."""
        weights = kmeans_weights(
            self.adapt_image, values["mesh.weight_floor"], values["mesh.weight_power"], self.scheme
        )
        if not (np.all(np.isfinite(weights)) and weights.sum() > 0):
            raise UnphysicalSample("k-means weights are not finite and positive")
        return kmeans_centres(
            self.pixel_x,
            self.pixel_y,
            weights,
            self.n_pixels,
            self.seed,
            seeding=self.seeding,
            curve_order=self._curve_order,
        )

    @cached_property
    def _curve_order(self) -> np.ndarray | None:
        """Hilbert order of the pixel centres for the systematic seeding, once per model
        (None for k-means++): the points are the same at every SPix2 call."""
        if self.seeding != "systematic":
            return None
        return hilbert_order(np.column_stack([self.pixel_x, self.pixel_y]))

    @cached_property
    def _arc_floor(self) -> np.ndarray | None:
        """The arcs' noise floor in data units (k σ per slim pixel), once per model; None
        without a floor."""
        return self.arc_noise_floor * self.noise_map if self.arc_noise_floor > 0.0 else None

    def mesh_model(self, values: Mapping[str, float]) -> MeshSourceModel:
        """The k-means mesh of ``values`` with the adaptive split regularization."""
        x, y = self.centres(values)
        return MeshSourceModel(
            x,
            y,
            "adaptive_split",
            self.interpolation,
            self.offset,
            self.adapt_image,
            "kmeans",
            self.signals,
            values[ARC_THRESHOLD] if self.support == "arcs" else None,
            self._arc_floor,
        )

    def fixed(self, values: Mapping[str, float]) -> "FixedSourceModel":
        """Mesh and regularization of ``values`` frozen (LIGHT and MASS keep SPix2's
        source); an arcs' support, and with ``signals_mass`` ``spix2`` the adaptive
        signals, are held at the mass of ``values`` (SPix2's), whatever mass the phase
        samples."""
        source = self.mesh_model(values).build(values)
        if source.arc_pixels is not None:
            source = replace(source, support_mass=mass_profiles(values))
        description = {**self.describe(), "fixed": True}
        if self.signals_mass == "spix2":
            source = replace(source, signals_mass=mass_profiles(values))
            description["adaptive_signals_mass"] = "spix2"
        return FixedSourceModel(source, description)

    def build(self, values: Mapping[str, float]) -> PixelizedSource:
        return self.mesh_model(values).build(values)

    def describe(self) -> dict:
        return {
            "kind": "pixelized",
            "mesh": "kmeans",
            "n_pixels": self.n_pixels,
            "kmeans_seed": self.seed,
            "kmeans_scheme": self.scheme,
            "regularization": "adaptive_split",
            "interpolation": self.interpolation,
            "cross_offset": self.offset,
            "adaptive_signals": self.signals,
            "source_support": self.support,
            "kmeans_seeding": self.seeding,
            **({"arc_noise_floor": self.arc_noise_floor} if self.arc_noise_floor > 0.0 else {}),
        }


@dataclass(frozen=True, eq=False)
class FixedSourceModel:
    """A pixelized source fixed for a whole phase: every sample gets the same object, so a
    fit may reuse whatever it derived from it for an unchanged mass model."""

    source: PixelizedSource
    description: dict

    def build(self, values: Mapping[str, float]) -> PixelizedSource:
        return self.source

    def describe(self) -> dict:
        return dict(self.description)


SourceModel = MGESourceModel | MeshSourceModel | KMeansSourceModel | FixedSourceModel


@dataclass(frozen=True, eq=False)
class PhaseModel:
    """Maps a values dict onto a :class:`~mgelens.fit.LensModel` (picklable).

    ``fixed_light`` holds light profiles with fixed intensities (the SPix phases of the
    3×Sérsic chain keep SP's Sérsics entirely); it is subtracted from the data.
    ``smoothness_prior``: the extended MGE sets' intensities carry the smoothness prior of
    :mod:`mgelens.light_prior` with λ = ``values[SMOOTHNESS]`` (the point set does not).
    """

    lens_light: tuple[LightSpec, ...]
    source: SourceModel
    fixed_light: tuple = ()
    smoothness_prior: bool = False

    def __post_init__(self):
        if self.smoothness_prior and not any(self._penalised):
            raise ValueError("the smoothness prior needs extended MGE sets in the lens light")

    @property
    def _penalised(self) -> tuple[bool, ...]:
        return tuple(isinstance(s, LightSetSpec) and s.name != "point" for s in self.lens_light)

    def build(self, values: Mapping[str, float]) -> LensModel:
        """Lens model of ``values``; raises :class:`UnphysicalSample` for invalid values."""
        prior = (
            MGESmoothnessPrior(values[SMOOTHNESS], self._penalised)
            if self.smoothness_prior
            else None
        )
        return LensModel(
            mass=mass_profiles(values),
            lens_light=lens_light_components(values, self.lens_light),
            fixed_light=self.fixed_light,
            source=self.source.build(values),
            lens_light_prior=prior,
        )

    @property
    def stable_unknowns(self) -> bool:
        """Whether each linear unknown means the same in every sample: false only for
        SPix2's k-means source, whose mesh is recomputed per sample."""
        return not isinstance(self.source, KMeansSourceModel)

    def describe(self) -> dict:
        """Structure of the model for result files."""
        fixed = [{"kind": type(p).__name__.lower(), "fixed": True} for p in self.fixed_light]
        return {
            "lens_light": [s.describe() for s in self.lens_light] + fixed,
            "source": self.source.describe(),
            **({"lens_light_prior": "smoothness"} if self.smoothness_prior else {}),
        }


# -- parameter spaces of the phases -----------------------------------------------------
def frozen_component(
    previous: PhaseResult, component: str, values: Mapping[str, float] | None = None
) -> list[Parameter]:
    """Parameters of ``component`` (e.g. "lens_light") fixed at ``previous``'s max-L values,
    or at ``values`` where given; ties are kept."""
    values = previous.max_likelihood if values is None else values
    return [
        Parameter(p.name, tied_to=p.tied_to, limits=p.limits)
        if p.tied_to is not None
        else Parameter(p.name, value=values[p.name], limits=p.limits)
        for p in previous.space.parameters
        if p.name.startswith(component + ".")
    ]


def free_parameters(priors: Mapping[str, Prior]) -> list[Parameter]:
    return [lens_parameter(name, prior=prior) for name, prior in priors.items()]


def lens_light_centre(values: Mapping[str, float]) -> tuple[float, float]:
    """Centre of the first lens-light component in ``values`` (``{name: value}`` in the
    space's order; the shared centre of the extended MGE sets or of the Sérsics)."""
    first = next(
        n[: -len(".centre_x")]
        for n in values
        if n.startswith(LENS_LIGHT + ".") and n.endswith(".centre_x")
    )
    return values[f"{first}.centre_x"], values[f"{first}.centre_y"]


def light_centre(result: PhaseResult) -> tuple[float, float]:
    """Max-likelihood centre of the first lens-light component of ``result``."""
    return lens_light_centre(result.max_likelihood)

"""SP's start: a maximum-a-posteriori point found from the lensed arcs, whose
neighbourhood becomes SP's prior (``slam.sp_start: search``).

With the anchor priors alone (θ_E U(0, 8″), mass centre N(c, 0.1″), shear U(±0.2)), SP's
nested sampler can settle in a degenerate needle mass on real imaging, where the arcs are
faint against the lens light and the 20-Gaussian source absorbs light residuals wherever
the mass puts it; local optimisers started from round masses fall into the same traps
(docs/slacs.md). The arcs themselves say where the mass is:

1. **Lens light.** The lens-light geometry (shared centre within ±0.3″ of its prior
   mean, ell_comps within ±0.6) maximises ln L + ln prior (Powell, :data:`LIGHT_CALLS`
   evaluations) under a mass of θ_E 0.01″, which lenses nothing: the source Gaussians sit
   on the centre as extra lens light. Every component's ell_comps start at the data's
   second moments within :data:`MOMENTS_RADIUS` (:func:`light_moments`): from round, a
   bright, flattened galaxy's stage can end far from its shape and leave light residuals
   that step 2 takes for arcs (docs/slacs.md, "A bright, flattened lens").
2. **Arcs.** Pixels whose normalised residual of that fit exceeds
   :data:`ARC_SIGNIFICANCE`, between :data:`ARC_INNER_RADIUS` and 0.9 R of the light
   centre (R the mask radius), each weighted by its residual flux. A faint source's arcs
   can be below that in every single pixel (slacs1016+3859: 8 pixels); with fewer than
   :data:`MIN_ARC_PIXELS`, a pixel is an arc pixel if the normalised residuals of the
   :data:`ARC_BOX` × :data:`ARC_BOX` box around it exceed it, summed and divided by √n,
   weighted by the box's mean residual flux (248 pixels there).
3. **Mass from the arcs.** Traced back through a singular isothermal sphere at the light
   centre, the arc pixels of one source land close together only for the right θ_E:
   θ_E is the value of a grid of 40 (0.2″ to 0.9 R, geometric) whose weighted
   source-plane scatter, in units of θ_E², is least. The SIE ellipticity and shear then
   refine that scatter (Powell; θ_E within 0.8–1.25×, |e| ≤ 0.3, |γ| ≤ 0.1), and the
   source centre is the weighted mean of the traced pixels.

   *Sphere scan (3b).* The scatter misleads where one extended image carries most of the
   arc flux: a larger θ_E squeezes that image towards the centre and wins, and on
   slacs1032+5322 (a double) it said 1.58″ for a mass near 1.03″. So the same grid of
   spheres is also scored by ln P itself (the lens light of step 1, the source centred on
   the traced arc pixels' weighted mean), 40 evaluations; it peaked at 0.99–1.06″ there.
   Neither estimate is always the better one (docs/slacs.md), so both start a polish.
4. **Polish.** Powell over every SP parameter, ln L + ln prior, from that point
   (:data:`POLISH_CALLS` evaluations), the mass centre kept within
   :data:`MASS_CENTRE_RANGE` of the light centre, the mass no flatter than
   :data:`MIN_MASS_AXIS_RATIO` and the shear no stronger than :data:`MAX_SHEAR`; twice,
   once with θ_E free and once held within :data:`ARC_EINSTEIN_RANGE` of the starting
   point's θ_E, and the higher ln P is kept.
   Free, Powell's line searches can carry θ_E into a far, worse maximum; held, the
   polish cannot follow arcs that overestimate θ_E (both seen: docs/slacs.md). Both
   polishes run from three points (:data:`STARTING_POINTS`): the arcs' SIE + shear; the
   same θ_E with the mass shaped as the fitted lens light (its first component's
   ell_comps) and no shear; and the light-shaped mass at the scan's θ_E (step 3b). The
   highest ln P of the six wins. Where the lens light dominates SP's likelihood, the
   arcs' point alone led into an elongated mass traded against a strong shear, while
   the light-shaped point reaches a far higher maximum near the true mass
   (docs/paper_mocks.md, M3). Every start's polished point is recorded: SPix1's rescan
   scores the two SP did not choose with its pixelized source, whose preference can
   differ from SP's parametric one (:mod:`mgelens.pipeline.mass_rescan`, step 5).

Every step runs with the non-negative linear solve (:meth:`FitDataset.non_negative`,
called by :func:`mgelens.pipeline.run.started_sp`), also where
SP itself samples the unconstrained one (pn-MGE, ``positive_only: false``): there the
MGE's negative Gaussians can take up the arcs, so a mass that sends the source elsewhere
costs little and SP's likelihood does not single out the lens mass; on M3 its polish
wandered to θ_E 2.26″ for a true 1.1″ (docs/paper_mocks.md). The non-negative lens light
cannot draw the arcs, and its maximum is near the true mass.

Each free SP parameter then gets SLaM's passed prior around the polished point
(:func:`~mgelens.search.priors.passed_prior`, SPEC §8.2: N(value, w) truncated to its
limits, w the width modifier: centres 0.05″, ell_comps 0.2, θ_E 25 %, shear 0.05). With
fewer than :data:`MIN_ARC_PIXELS` arc pixels the anchor priors stay (logged). The search
is deterministic and its record (``start.json`` in SP's folder) is reused when SP reruns
on the same inputs and settings, so a resumed SP samples the same priors.
"""

import json
import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage, optimize

from mgelens.fit import FitDataset, fit
from mgelens.geometry import ell_comps_from
from mgelens.mass import SIE, ExternalShear, ray_trace
from mgelens.pipeline import models
from mgelens.pipeline.fingerprinted import read_or_make
from mgelens.pipeline.parameters import width_of
from mgelens.rejection import REJECTED_LOG_LIKELIHOOD
from mgelens.search.model import ParameterSpace
from mgelens.search.priors import passed_prior

logger = logging.getLogger(__name__)

START_FILE = "start.json"
"""SP's start record in its folder."""

LIGHT_CALLS = 400
"""Evaluations of the lens-light stage (17 parameters of SP: 6 light)."""
POLISH_CALLS = 1500
"""Evaluations of the final all-parameter polish."""
NO_LENSING_EINSTEIN_RADIUS = 0.01
"""θ_E (arcsec) of the lens-light stage's mass."""
LIGHT_CENTRE_RANGE = 0.3
"""Half-width (arcsec) of the lens-light stage's box around the light centre's prior mean."""
MASS_CENTRE_RANGE = 0.3
"""Half-width (arcsec) of the polish's box for the mass centre around the fitted light
centre: unboxed, the polish can carry the mass far from the light into a mass that
lenses nothing, where the source draws the arcs unlensed (docs/slacs.md)."""
MIN_MASS_AXIS_RATIO = 0.3
"""Flattest mass (axis ratio) the polish may reach. Unbounded, one polish on a real lens
ended at q ≈ 0.1 against a shear of 0.26, a maximum no galaxy has, and SP spent 60,000
extra calls climbing out of the priors passed from it (docs/slacs.md, slacs1032+5322).
SP's own prior is not bounded so: its passed ell_comps prior (width 0.2) reaches beyond."""
MAX_SHEAR = 0.15
"""Strongest external shear (magnitude) the polish may reach (see
:data:`MIN_MASS_AXIS_RATIO`)."""
PLAUSIBLE_SHRINK = 0.999
"""A start beyond those limits is shrunk to this fraction of them."""
STARTING_POINTS = ("arcs' SIE + shear", "light-shaped mass", "light-shaped sphere scan")
"""The polishes' starting points of step 4, in order (:func:`search`)."""

ARC_EINSTEIN_RANGE = (0.8, 1.25)
"""θ_E range of the held polish, in units of its starting point's θ_E (the arcs' or the
sphere scan's)."""
LIGHT_ELL_COMPS_RANGE = 0.6
"""Bound of |ell_comps| in the lens-light stage."""
MOMENTS_RADIUS = 1.0
"""Radius (arcsec) of the data's second moments that start the lens-light stage."""
ARC_SIGNIFICANCE = 3.0
"""Normalised residual above which a pixel of the light-only fit is an arc pixel."""
ARC_INNER_RADIUS = 0.25
"""Arc pixels lie at least this far (arcsec) from the light centre."""
ARC_OUTER_FRACTION = 0.9
"""... and within this fraction of the mask radius."""
MIN_ARC_PIXELS = 10
"""Fewer arc pixels and the anchor priors stay."""
ARC_BOX = 3
"""Side (pixels) of the boxes that find a faint source's arcs: where fewer than
:data:`MIN_ARC_PIXELS` single pixels exceed :data:`ARC_SIGNIFICANCE`, a pixel is an arc
pixel if its box's normalised residuals do, summed over the box and divided by √n
(:func:`box_residuals`)."""
OPTIMISER_FLOOR = -1e30
"""ln P the optimiser sees for rejected or non-finite points."""
EINSTEIN_RADIUS_GRID = 40
"""Grid points of the isothermal-sphere scan, 0.2″ to 0.9 R."""


@dataclass(frozen=True)
class ArcMass:
    """The mass and source centre the arc pixels point to (step 3).

    Attributes
    ----------
    n_pixels : int
        Arc pixels used.
    sphere_einstein_radius : float
        θ_E (arcsec) of the best isothermal sphere on the grid.
    einstein_radius, ell_comps_1, ell_comps_2, gamma_1, gamma_2 : float
        The refined SIE + shear (arcsec; dimensionless).
    source_x, source_y : float
        Weighted mean of the traced arc pixels (arcsec).
    scatter : float
        Weighted rms source-plane distance of the traced arc pixels from that mean (arcsec).
    """

    n_pixels: int
    sphere_einstein_radius: float
    einstein_radius: float
    ell_comps_1: float
    ell_comps_2: float
    gamma_1: float
    gamma_2: float
    source_x: float
    source_y: float
    scatter: float


@dataclass(frozen=True)
class SPStart:
    """The start search's record (``start.json``).

    Attributes
    ----------
    values : dict or None
        Polished free-parameter values; ``None`` if too few arc pixels were found.
    log_posterior : float or None
        ln L + ln prior (anchor priors) at ``values``.
    light_log_posterior : float
        ln L + ln prior after the lens-light stage.
    arcs : ArcMass or None
    n_arc_pixels : int
    n_calls : int
        Likelihood evaluations of the whole search.
    seconds : float
        Wall time of the search.
    held_einstein_radius : bool
        Whether the polish that won held θ_E near its starting point's (step 4; false in
        records written before there were two).
    light_shaped_mass : bool
        Whether the polish that won began from a light-shaped mass (step 4; false in
        records written before there were two starting points).
    scanned_einstein_radius : float or None
        θ_E (arcsec) of the isothermal sphere of highest ln P (step 3b; None in records
        written before the scan).
    scanned_mass : bool
        Whether the polish that won began from that sphere's θ_E (step 4).
    polishes : list of dict
        The polished point of each starting point, in the order of
        :data:`STARTING_POINTS`: ``{"values": free values, "log_posterior": ln P}`` (empty
        in records written before they were kept). SPix1's rescan scores the ones SP did
        not choose with its pixelized source (:mod:`mgelens.pipeline.mass_rescan`).
    """

    values: dict | None
    log_posterior: float | None
    light_log_posterior: float
    arcs: ArcMass | None
    n_arc_pixels: int
    n_calls: int
    seconds: float
    held_einstein_radius: bool = False
    light_shaped_mass: bool = False
    scanned_einstein_radius: float | None = None
    scanned_mass: bool = False
    polishes: tuple[dict, ...] = ()

    @property
    def chosen(self) -> int:
        """Index in :data:`STARTING_POINTS` of the starting point whose polish won."""
        return 2 if self.scanned_mass else int(self.light_shaped_mass)

    def unchosen_polishes(self) -> list[dict]:
        """Free values of the polished points that SP did not start from."""
        return [p["values"] for i, p in enumerate(self.polishes) if i != self.chosen]

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, content: dict) -> "SPStart":
        arcs = content["arcs"]
        polishes = tuple(content.get("polishes", ()))
        arcs = None if arcs is None else ArcMass(**arcs)
        return cls(**{**content, "arcs": arcs, "polishes": polishes})


class _Posterior:
    """ln L + ln prior of a free vector, counting evaluations; −1e99 off the prior,
    outside ``box`` (free-vector index → (lower, upper)) and where ``plausible`` (a
    predicate of the free vector) is false, both set by :meth:`boxed`."""

    def __init__(self, likelihood: Callable[[np.ndarray], float], space: ParameterSpace):
        self.likelihood, self.space, self.calls = likelihood, space, 0
        self.box: dict[int, tuple[float, float]] = {}
        self.plausible: Callable[[np.ndarray], bool] | None = None

    def boxed(
        self,
        box: dict[int, tuple[float, float]],
        plausible: Callable[[np.ndarray], bool] | None = None,
    ) -> "_Posterior":
        """This posterior (sharing its call count) restricted to ``box`` and to the points
        where ``plausible`` holds (no restriction when ``None``)."""
        self.box, self.plausible = dict(box), plausible
        return self

    def __call__(self, x: np.ndarray) -> float:
        self.calls += 1
        if any(not lower <= x[i] <= upper for i, (lower, upper) in self.box.items()):
            return REJECTED_LOG_LIKELIHOOD
        if self.plausible is not None and not self.plausible(x):
            return REJECTED_LOG_LIKELIHOOD
        prior = self.space.log_prior(x)
        if not np.isfinite(prior):
            return REJECTED_LOG_LIKELIHOOD
        return self.likelihood(x) + prior


def _maximise(
    posterior: _Posterior,
    x: np.ndarray,
    free: Sequence[int],
    bounds: Sequence[tuple[float, float]] | None,
    max_calls: int,
) -> tuple[np.ndarray, float]:
    """The best point Powell visits maximising ``posterior`` over the entries ``free`` of
    ``x`` (within ``bounds`` if given), and its value.

    Rejected points count as :data:`OPTIMISER_FLOOR` (−1e30): the −1e99 of a rejected
    sample overflows Brent's parabolic steps into NaN. scipy's bounded Powell stops after
    about one sweep of its directions (docs/slacs.md), so the polish passes no bounds and
    leaves the support to the prior (outside it the posterior is the floor).
    """
    free = list(free)
    best = {"value": -np.inf, "x": x.copy()}

    def negative(y: np.ndarray) -> float:
        z = x.copy()
        z[free] = y
        value = posterior(z)
        if not value > OPTIMISER_FLOOR:
            return -OPTIMISER_FLOOR
        if value > best["value"]:
            best["value"], best["x"] = value, z
        return -value

    start = x[free] if bounds is None else np.clip(x[free], *np.transpose(bounds))
    optimize.minimize(
        negative,
        start,
        method="Powell",
        bounds=bounds,
        options={"maxfev": max_calls, "xtol": 1e-3, "ftol": 1e-9},
    )
    return best["x"], float(best["value"])


def _light_bounds(space: ParameterSpace, index: int) -> tuple[float, float]:
    name = space.free_names[index]
    if name.endswith(("centre_x", "centre_y")):
        mean = float(space.priors[index].transform(0.5))
        return mean - LIGHT_CENTRE_RANGE, mean + LIGHT_CENTRE_RANGE
    if name.endswith(("ell_comps_1", "ell_comps_2")):
        return -LIGHT_ELL_COMPS_RANGE, LIGHT_ELL_COMPS_RANGE
    prior = space.priors[index]
    return prior.lower, prior.upper


def light_moments(dataset: FitDataset, centre: tuple[float, float]) -> tuple[float, float]:
    """ell_comps of the data's second moments (step 1's start): the fit pixels within
    :data:`MOMENTS_RADIUS` of ``centre`` (arcsec; the lens-light prior's mean), weighted
    by their positive data, about their weighted centroid; clipped to |ell_comps| ≤
    :data:`LIGHT_ELL_COMPS_RANGE`. Round (0, 0) when fewer than three pixels carry light."""
    px, py = dataset.pixel_centres
    data = dataset.imaging.data[~dataset.mask]
    near = np.hypot(px - centre[0], py - centre[1]) < MOMENTS_RADIUS
    weight = np.where(near, np.clip(data, 0.0, None), 0.0)
    if np.count_nonzero(weight) < 3:
        return 0.0, 0.0
    mx, my = np.average(px, weights=weight), np.average(py, weights=weight)
    dx, dy = px - mx, py - my
    xx, yy, xy = (np.average(v, weights=weight) for v in (dx * dx, dy * dy, dx * dy))
    minor, major = np.linalg.eigvalsh([[xx, xy], [xy, yy]])
    angle = np.degrees(0.5 * np.arctan2(2.0 * xy, xx - yy))
    e1, e2 = ell_comps_from(float(np.sqrt(max(minor, 0.0) / major)), float(angle))
    modulus = np.hypot(e1, e2)
    if modulus > LIGHT_ELL_COMPS_RANGE:
        e1, e2 = e1 * LIGHT_ELL_COMPS_RANGE / modulus, e2 * LIGHT_ELL_COMPS_RANGE / modulus
    return e1, e2


def with_light_ellipticity(
    x: np.ndarray, names: Sequence[str], ell_comps: tuple[float, float]
) -> np.ndarray:
    """``x`` with every free lens-light ell_comps pair among ``names`` set to ``ell_comps``."""
    x = np.array(x, dtype=float)
    for index, name in enumerate(names):
        if name.startswith(f"{models.LENS_LIGHT}.") and name.endswith(".ell_comps_1"):
            x[index] = ell_comps[0]
        elif name.startswith(f"{models.LENS_LIGHT}.") and name.endswith(".ell_comps_2"):
            x[index] = ell_comps[1]
    return x


def arc_pixels(
    dataset: FitDataset, light_fit_values: dict, model: models.PhaseModel, radius: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[float, float]]:
    """Arc pixels of the light-only fit at ``light_fit_values`` (step 2).

    Returns
    -------
    x, y : ndarray
        Arc pixel centres (arcsec).
    weight : ndarray
        Their residual flux (data units).
    centre : (float, float)
        The lens-light centre (arcsec).
    """
    result = fit(dataset, model.build(light_fit_values))
    centre = models.lens_light_centre(light_fit_values)
    px, py = dataset.pixel_centres
    distance = np.hypot(px - centre[0], py - centre[1])
    annulus = (distance > ARC_INNER_RADIUS) & (distance < ARC_OUTER_FRACTION * radius)
    chosen = annulus & (result.normalized_residuals > ARC_SIGNIFICANCE)
    weight = result.residuals
    if np.count_nonzero(chosen) < MIN_ARC_PIXELS:
        significance, weight = box_residuals(
            result.normalized_residuals, result.residuals, dataset.mask, ARC_BOX
        )
        chosen = annulus & (significance > ARC_SIGNIFICANCE)
        logger.info(
            "SP start: fewer than %d pixels above %gσ; %d pixels whose %d×%d box is above it",
            MIN_ARC_PIXELS,
            ARC_SIGNIFICANCE,
            np.count_nonzero(chosen),
            ARC_BOX,
            ARC_BOX,
        )
    return px[chosen], py[chosen], weight[chosen], centre


def box_residuals(
    normalized: np.ndarray, residuals: np.ndarray, mask: np.ndarray, side: int
) -> tuple[np.ndarray, np.ndarray]:
    """Per unmasked pixel (slim order of ``mask``, True = masked), the significance of the
    ``side`` × ``side`` box around it, Σ r / √n over its n unmasked pixels (N(0, 1) for
    white noise), and the box's mean residual (data units)."""

    def box_sum(slim: np.ndarray) -> np.ndarray:
        native = np.zeros(mask.shape)
        native[~mask] = slim
        return ndimage.uniform_filter(native, side, mode="constant")[~mask] * side**2

    count = box_sum(np.ones(normalized.size))
    return box_sum(normalized) / np.sqrt(count), box_sum(residuals) / count


def _traced(parameters: Sequence[float], centre, x, y) -> tuple[np.ndarray, np.ndarray]:
    einstein_radius, e1, e2, g1, g2 = parameters
    sie = SIE.from_ell_comps(centre, (e1, e2), einstein_radius)
    return ray_trace((sie, ExternalShear(g1, g2)), x, y)


def _scatter(parameters, centre, x, y, weight) -> tuple[float, float, float]:
    """(weighted mean source x, y, weighted mean squared distance from it)."""
    bx, by = _traced(parameters, centre, x, y)
    mx, my = np.average(bx, weights=weight), np.average(by, weights=weight)
    return mx, my, float(np.average((bx - mx) ** 2 + (by - my) ** 2, weights=weight))


def _einstein_radius_grid(radius: float) -> np.ndarray:
    """The isothermal spheres' θ_E of steps 3 and 3b (arcsec): 0.2″ to 0.9 R, geometric."""
    return np.geomspace(0.2, ARC_OUTER_FRACTION * radius, EINSTEIN_RADIUS_GRID)


def arc_mass(x, y, weight, centre: tuple[float, float], radius: float) -> ArcMass:
    """The SIE + shear and source centre under which the arc pixels trace to one place
    (step 3; arcsec)."""

    def relative(parameters) -> float:
        return _scatter(parameters, centre, x, y, weight)[2] / parameters[0] ** 2

    grid = _einstein_radius_grid(radius)
    sphere = float(grid[np.argmin([relative((t, 0.0, 0.0, 0.0, 0.0)) for t in grid])])
    with np.errstate(invalid="ignore"):
        refined = optimize.minimize(
            relative,
            [sphere, 0.0, 0.0, 0.0, 0.0],
            method="Powell",
            bounds=[(0.8 * sphere, 1.25 * sphere), (-0.3, 0.3), (-0.3, 0.3), (-0.1, 0.1),
                    (-0.1, 0.1)],
        )  # fmt: skip
    parameters = [float(v) for v in refined.x]
    sx, sy, mean_square = _scatter(parameters, centre, x, y, weight)
    return ArcMass(len(x), sphere, *parameters, float(sx), float(sy), float(np.sqrt(mean_square)))


def _sie_shear(centre: tuple[float, float], parameters: Sequence[float]) -> dict:
    """The free values of an SIE + shear (``parameters``: θ_E, e₁, e₂, γ₁, γ₂) at
    ``centre`` (arcsec)."""
    einstein_radius, e1, e2, g1, g2 = parameters
    return {
        "mass.centre_x": centre[0],
        "mass.centre_y": centre[1],
        "mass.einstein_radius": einstein_radius,
        "mass.ell_comps_1": e1,
        "mass.ell_comps_2": e2,
        "shear.gamma_1": g1,
        "shear.gamma_2": g2,
    }


def _mass_start(
    values: dict, centre: tuple[float, float], parameters: Sequence[float], source: Sequence[float]
) -> dict:
    """``values`` with an SIE + shear (``parameters``: θ_E, e₁, e₂, γ₁, γ₂) at ``centre``
    and the source's centre at ``source`` (arcsec)."""
    return {
        **values,
        **_sie_shear(centre, parameters),
        f"{models.SOURCE}.set_0.centre_x": source[0],
        f"{models.SOURCE}.set_0.centre_y": source[1],
    }


def _arc_start(values: dict, arcs: ArcMass, centre: tuple[float, float]) -> dict:
    parameters = (arcs.einstein_radius, arcs.ell_comps_1, arcs.ell_comps_2, arcs.gamma_1,
                  arcs.gamma_2)  # fmt: skip
    return _mass_start(values, centre, parameters, (arcs.source_x, arcs.source_y))


def scanned_start(
    posterior: _Posterior,
    values: dict,
    x: np.ndarray,
    y: np.ndarray,
    weight: np.ndarray,
    centre: tuple[float, float],
    radius: float,
) -> tuple[dict, float]:
    """Step 3b: of the isothermal spheres at the light ``centre`` on the grid of step 3,
    each with the source centred on the weighted mean of the traced arc pixels
    (``x``, ``y``, ``weight``) and the rest of ``values``, the one of highest ln P.
    Returns that point and its θ_E (arcsec)."""
    best = (-np.inf, None, None)
    for einstein_radius in _einstein_radius_grid(radius):
        sphere = (float(einstein_radius), 0.0, 0.0, 0.0, 0.0)
        source = _scatter(sphere, centre, x, y, weight)[:2]
        point = _mass_start(values, centre, sphere, source)
        value = posterior(posterior.space.vector(point))
        if value > best[0]:
            best = (value, point, sphere[0])
    return best[1], best[2]


def search(
    dataset: FitDataset,
    space: ParameterSpace,
    model: models.PhaseModel,
    likelihood: Callable[[np.ndarray], float],
    radius: float,
) -> SPStart:
    """Run steps 1–4 on SP's problem (its anchor-prior ``space``); see the module."""
    began = time.perf_counter()
    posterior = _Posterior(likelihood, space)
    names = space.free_names
    x = space.prior_transform(np.full(space.n_free, 0.5))
    x[names.index("mass.einstein_radius")] = NO_LENSING_EINSTEIN_RADIUS
    centre = models.lens_light_centre(space.values(x))
    x = with_light_ellipticity(x, names, light_moments(dataset, centre))
    light = [i for i, n in enumerate(names) if n.startswith(models.LENS_LIGHT + ".")]
    x, light_value = _maximise(
        posterior, x, light, [_light_bounds(space, i) for i in light], LIGHT_CALLS
    )
    values = space.values(x)
    ax, ay, weight, centre = arc_pixels(dataset, values, model, radius)
    logger.info(
        "SP start: lens light ln P %.1f after %d calls; %d arc pixels",
        light_value,
        posterior.calls,
        len(ax),
    )
    if len(ax) < MIN_ARC_PIXELS:
        logger.warning(
            "SP start: %d arc pixels (fewer than %d): SP keeps the anchor priors",
            len(ax),
            MIN_ARC_PIXELS,
        )
        return SPStart(None, None, light_value, None, len(ax), posterior.calls,
                       time.perf_counter() - began)  # fmt: skip
    arcs = arc_mass(ax, ay, weight, centre, radius)
    arc_start = _arc_start(values, arcs, centre)
    scanned, scanned_radius = scanned_start(posterior, values, ax, ay, weight, centre, radius)
    logger.info(
        "SP start: arcs θ_E %.3f″ (sphere %.3f″), source (%.3f, %.3f)″; highest ln P of "
        "the spheres at θ_E %.3f″",
        arcs.einstein_radius,
        arcs.sphere_einstein_radius,
        arcs.source_x,
        arcs.source_y,
        scanned_radius,
    )
    starts = [
        (space.vector(arc_start), arcs.einstein_radius),
        (space.vector(light_shaped(arc_start, names)), arcs.einstein_radius),
        (space.vector(light_shaped(scanned, names)), scanned_radius),
    ]
    (x, value, held, chosen), polished = polish_starts(posterior, starts, names, centre)
    found = dict(zip(names, x.tolist(), strict=True))
    logger.info(
        "SP start: polished ln P %.1f (from the %s, θ_E %s), θ_E %.3f″, %d calls",
        value,
        STARTING_POINTS[chosen],
        "held" if held else "free",
        found["mass.einstein_radius"],
        posterior.calls,
    )
    return SPStart(found, value, light_value, arcs, len(ax), posterior.calls,
                   time.perf_counter() - began, held, chosen > 0, scanned_radius,
                   chosen == 2, polished)  # fmt: skip


def light_shaped(start: dict, names: Sequence[str]) -> dict:
    """``start`` with the mass shaped as the lens light: its ell_comps those of the first
    lens-light component among ``names``, and no shear (step 4)."""
    light = next(
        name.removesuffix(".ell_comps_1")
        for name in names
        if name.startswith(f"{models.LENS_LIGHT}.") and name.endswith(".ell_comps_1")
    )
    return {
        **start,
        "mass.ell_comps_1": start[f"{light}.ell_comps_1"],
        "mass.ell_comps_2": start[f"{light}.ell_comps_2"],
        "shear.gamma_1": 0.0,
        "shear.gamma_2": 0.0,
    }


def polish_starts(
    posterior: _Posterior,
    starts: Sequence[tuple[np.ndarray, float]],
    names: Sequence[str],
    centre: tuple[float, float],
) -> tuple[tuple[np.ndarray, float, bool, int], tuple[dict, ...]]:
    """:func:`polish` from each of ``starts`` (a free vector and the θ_E, arcsec, its held
    polish stays near; in the order of :data:`STARTING_POINTS`); the highest ln P wins (a
    tie goes to the earlier start). Returns the point, its ln P, whether the held polish
    won and the index of the winning start; and every start's polished point as
    :attr:`SPStart.polishes` records it."""
    best, polished = None, []
    for index, (start, einstein_radius) in enumerate(starts):
        x, value, held = polish(posterior, start, names, centre, einstein_radius)
        logger.info(
            "SP start: polish from the %s: ln P %.1f (θ_E %.3f″, %s)",
            STARTING_POINTS[index],
            value,
            x[names.index("mass.einstein_radius")],
            "held" if held else "free",
        )
        polished.append({"values": dict(zip(names, x.tolist(), strict=True)),
                         "log_posterior": float(value)})  # fmt: skip
        if best is None or value > best[1]:
            best = (x, value, held, index)
    return best, tuple(polished)


def polish(
    posterior: _Posterior,
    x: np.ndarray,
    names: Sequence[str],
    centre: tuple[float, float],
    einstein_radius: float,
) -> tuple[np.ndarray, float, bool]:
    """Step 4: the better of two Powell polishes of every parameter from ``x`` (made
    plausible, :func:`made_plausible`), both with the mass centre within
    :data:`MASS_CENTRE_RANGE` of the light ``centre`` and a plausible mass and shear
    (:func:`plausible_mass`), the second with θ_E within :data:`ARC_EINSTEIN_RANGE` of
    ``einstein_radius`` (the starting point's, arcsec). Returns the point, its ln P and
    whether the held polish won (a tie goes to the free one). A mass centre tied to the light
    (``slam.sp_mass_centre: light``) is not among ``names`` and needs no box."""
    box = {
        names.index(f"mass.{axis}"): (c - MASS_CENTRE_RANGE, c + MASS_CENTRE_RANGE)
        for axis, c in zip(("centre_x", "centre_y"), centre, strict=True)
        if f"mass.{axis}" in names
    }
    low, high = ARC_EINSTEIN_RANGE
    theta = names.index("mass.einstein_radius")
    held_box = box | {theta: (low * einstein_radius, high * einstein_radius)}
    every = range(len(names))
    plausible = plausible_mass(names)
    x = made_plausible(x, names)
    free_x, free_value = _maximise(posterior.boxed(box, plausible), x, every, None, POLISH_CALLS)
    held_x, held_value = _maximise(
        posterior.boxed(held_box, plausible), x, every, None, POLISH_CALLS
    )
    posterior.boxed({})
    if held_value > free_value:
        return held_x, held_value, True
    return free_x, free_value, False


def _plausible_pairs(names: Sequence[str]) -> list[tuple[int, int, float]]:
    """(index, index, largest modulus) of the mass's ell_comps and the shear's components
    among ``names``; pairs absent from ``names`` (fixed) are left out."""
    limits = (
        (("mass.ell_comps_1", "mass.ell_comps_2"), ell_comps_from(MIN_MASS_AXIS_RATIO, 0.0)[0]),
        (("shear.gamma_1", "shear.gamma_2"), MAX_SHEAR),
    )
    return [
        (names.index(first), names.index(second), limit)
        for (first, second), limit in limits
        if first in names and second in names
    ]


def plausible_mass(names: Sequence[str]) -> Callable[[np.ndarray], bool]:
    """Predicate of a free vector (entries named by ``names``): the mass's axis ratio is at
    least :data:`MIN_MASS_AXIS_RATIO` and the shear's magnitude at most :data:`MAX_SHEAR`.
    Parameters absent from ``names`` (fixed) are not checked."""
    checks = _plausible_pairs(names)

    def plausible(x: np.ndarray) -> bool:
        return all(np.hypot(x[i], x[j]) <= limit for i, j, limit in checks)

    return plausible


def made_plausible(x: np.ndarray, names: Sequence[str]) -> np.ndarray:
    """``x`` with the mass's ell_comps and the shear shrunk, at their angle, to just inside
    the limits of :func:`plausible_mass` where they exceed them (a polish from a point the
    posterior rejects would not move: the light-shaped start of M3 takes a light of
    q < 0.3)."""
    x = np.array(x, dtype=float)
    for i, j, limit in _plausible_pairs(names):
        modulus = np.hypot(x[i], x[j])
        if modulus > limit:
            x[[i, j]] *= PLAUSIBLE_SHRINK * limit / modulus
    return x


def started_space(space: ParameterSpace, start: SPStart) -> ParameterSpace:
    """``space`` with every free parameter's prior passed from the start (SPEC §8.2 width
    modifiers; the anchor space if the search found no arcs)."""
    if start.values is None:
        return space
    for name in space.free_names:
        limits = space.parameter(name).limits
        value = float(np.clip(start.values[name], *limits))
        prior = passed_prior(name, value, 0.0, width_of(name), limits, "2024")
        space = space.with_prior(name, prior)
    return space


def _record(path: Path) -> SPStart | None:
    """The start record at ``path``; ``None`` where SP searched no start (no file). An
    unreadable record stops with its path and the fix."""
    if not path.is_file():
        return None
    try:
        return SPStart.from_dict(json.loads(path.read_text())["start"])
    except (ValueError, KeyError, TypeError) as error:
        raise ValueError(
            f"{path} is not an SP start record ({error}): delete it and rerun phase 'sp'"
        ) from error


def unchosen_polishes(path: Path) -> list[dict]:
    """:meth:`SPStart.unchosen_polishes` of the start record at ``path``; none where SP
    searched no start (no file)."""
    record = _record(path)
    return [] if record is None else record.unchosen_polishes()


def arcs_sphere(path: Path, centre: tuple[float, float]) -> dict | None:
    """The isothermal sphere of step 3 of the start record at ``path``, as SPix1's rescan
    scores it: θ_E the grid's sphere whose traced arc pixels scatter least
    (:attr:`ArcMass.sphere_einstein_radius`, arcsec), centred on ``centre`` (the lens
    light's, arcsec), round and without shear. ``None`` where SP searched no start or found
    too few arc pixels.

    SP's polishes all carry SP's parametric source's preferences; the sphere carries only
    the arcs' radius. On slacs1451−0239 every polish was flattened (q ≈ 0.4) with a strong
    shear, while SPix1's pixelized source polishes this sphere to Bolton's nearly round
    mass (docs/slacs.md)."""
    record = _record(path)
    if record is None or record.arcs is None:
        return None
    return _sie_shear(centre, (record.arcs.sphere_einstein_radius, 0.0, 0.0, 0.0, 0.0))


def read_or_search(folder: Path, fingerprint: dict, run: Callable[[], SPStart]) -> SPStart:
    """The start recorded in ``folder/start.json`` for ``fingerprint`` (the inputs and
    settings it was found for), else ``run()``'s, written there atomically with it."""
    return read_or_make(
        folder / START_FILE, "start", fingerprint, run, SPStart.from_dict, logger, "SP start"
    )

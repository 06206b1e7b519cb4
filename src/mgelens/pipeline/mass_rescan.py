"""SPix1's rescan of θ_E and of SP's start: the pixelized source's view of SP's mass.

SP fits a parametric (MGE) source. A source of several components can give that model a
best mass far from the true one: on the coverage study's P05 (two spiral discs 0.5″
apart) SP's likelihood climbs to θ_E 1.47″ for a true 1.18″ even when polished from the
true mass, while SPix1's pixelized source prefers the truth by 5 × 10⁴ in ln ε
(docs/coverage.md, "P05"). SPix1 samples priors passed around SP's mass, and along θ_E
its ln ε is a row of narrow peaks, so its 24 live points stay in SP's basin and every
later phase with them.

Before SPix1 samples (``slam.spix1_rescan``, the quick profile):

1. The reference point: SPix1's prior medians (SP's mass and shear) with the
   regularization coefficient of highest ln P on :data:`COEFFICIENT_GRID`.
2. A scan of θ_E over :data:`SCAN_RANGE` times the reference's, in relative steps of
   :data:`SCAN_STEP`, every other value held.
3. ``near``: the best scanned point within :data:`NEAR` of the reference's θ_E (the
   reference included); ``far``: the best beyond. If ``far`` does not beat ``near`` by
   :data:`THRESHOLD` in ln P, SPix1 keeps SP's priors: this is what happens when SP found
   the lens's mass, at a cost of about 120 likelihood calls.
4. Otherwise the mass and shear are polished from both (Powell, :data:`POLISH_CALLS`
   each, the centre boxed around the light and the mass kept plausible as in SP's start,
   :mod:`mgelens.pipeline.sp_start`), the coefficient chosen again on the grid after
   each. Each polish holds θ_E within :data:`NEAR` of where it started (``near``'s within
   NEAR of SP's θ_E, ``far``'s of the far point's): the scan has already compared the θ_E
   values, and a polish free in θ_E can run, under a pixelized source that fits almost
   anything, to a barely lensing mass that the images check then refuses, losing the
   far basin with it (P05 on 1,000 source pixels: both free polishes ended at θ_E
   0.44–0.55″, and SPix1 kept SP's 1.43″ for a true 1.18″; docs/coverage.md). If the
   polished far point still lies beyond NEAR of SP's θ_E and beats SP's polished basin by
   :data:`THRESHOLD`, SPix1's mass and shear priors are re-centred on it, their widths as
   passed (SPEC §8.2).
5. Where the scan kept SP's basin, SP's start's other polished points (those SP did not
   start from, :attr:`~mgelens.pipeline.sp_start.SPStart.polishes`) and its arcs' sphere
   (a round mass at the light centre with the θ_E of step 3's sphere, no shear;
   :func:`~mgelens.pipeline.sp_start.arcs_sphere`) are scored (the coefficient chosen on
   the grid, about 17 calls each). SP's parametric source can
   prefer a wrong mass that its pixelized counterpart does not: on the coverage study's
   P18 SP chose the arcs' SIE + shear (shear 0.14 for a true 0.04) at SPix1's ln P
   15,026, where its light-shaped polishes score 22,901 and 23,710 (docs/coverage.md). On
   slacs1451−0239 every polish was flattened by SP's source (q ≈ 0.4, shear 0.15), and
   the arcs' sphere (θ_E 1.061″) scores 145 above SP's basin and polishes to Bolton's
   nearly round mass (docs/slacs.md).
   A point counts if it lies more than :data:`BASIN_WIDTHS` of SPix1's passed prior
   widths from their means (SP's posterior; :func:`widths_from_sp`), since within them
   SPix1 samples it anyway. If the best such point beats ``near`` by :data:`THRESHOLD`,
   it is polished with θ_E free and ``near`` as in 4, and SPix1's priors are re-centred
   on the polished point if it still lies beyond :data:`BASIN_WIDTHS` and beats the
   polished ``near`` by :data:`THRESHOLD`.
6. Where nothing moved yet, SP's mass without its shear: the reference with the shear set
   to zero lies more than :data:`BASIN_WIDTHS` from SP's posterior when SP's shear is
   strong. θ_E is scanned as in 2 at zero shear, and the best point is polished
   (:data:`SHEAR_FREE_CALLS`, mass and shear free). An SIE with a strong shear aligned
   with its ellipticity can mimic a rounder mass of another θ_E for SP's parametric
   source: on the coverage study's P25 (true shear 0.05, θ_E 0.864″) SP chose shear 0.17
   at θ_E 1.00″, and every polish from SP's basin stays there (SPix1's ln P 6,371 after
   1,683 calls), where the polish from SP's mass without its shear climbs to 20,652, at
   θ_E 0.874″ and shear 0.026 (docs/coverage.md, "P25"). If the short polish beats
   ``near`` by :data:`THRESHOLD`, it and ``near`` are polished on as in 4, and SPix1's
   priors are re-centred on it under the same rules as in 5.

ln P is the phase's ln ε (positions penalty included) plus its ln prior. The outcome is
recorded in ``spix1/rescan.json`` and read back for the same inputs and settings.
"""

import dataclasses
import logging
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from mgelens.pipeline import models, sp_start
from mgelens.pipeline.fingerprinted import read_or_make
from mgelens.search.model import ParameterSpace
from mgelens.search.priors import TruncatedGaussian

logger = logging.getLogger(__name__)

RESCAN_FILE = "rescan.json"
SCAN_RANGE = (0.6, 1.6)
"""θ_E range of the scan, in units of the reference's θ_E."""
SCAN_STEP = 0.01
"""Relative step of the scan in θ_E: the peaks of ln ε along θ_E are a few per cent wide
on P05."""
NEAR = 0.05
"""Relative distance in θ_E within which a scanned point belongs to SP's basin (SP's
posterior is narrower than 1 % on every lens fitted)."""
THRESHOLD = 50.0
"""ln P by which a far point must beat SP's basin, in the scan and after the polishes:
above the 1–91 by which two source meshes' evidences differ on the real lenses fitted
(docs/coverage.md, "The source mesh")."""
POLISH_CALLS = 1500
"""Evaluations of each polish."""
COEFFICIENT_GRID = 10.0 ** np.arange(-3.0, 5.01, 0.5)
"""Regularization coefficients tried at each point the rescan compares."""
SHEAR_FREE_CALLS = 300
"""Evaluations of the first polish from SP's mass without its shear (step 6): on P25 it
reached 19,973 of the 20,652 that 2,000 calls reach, after 100."""
STEPS = (
    "theta_scan",
    "start_polishes",
    "arcs_sphere",
    "shear_free",
    "multiply_imaged",
    "held_polishes",
)
"""The rescan's steps and its check of the point moved to (``lensing``: since
2026-12-05 also that most of the lensed signal is multiply imaged; ``held_polishes``:
since 2026-12-07 step 4's polishes and SP's polished basin hold θ_E), part of its record's
fingerprint (a record made without one of them is made again)."""
BASIN_WIDTHS = 1.0
"""Standardised distance (in SPix1's passed prior widths) beyond which one of SP's start's
polished points lies outside SP's basin (step 5). On P17 the best of them lay 0.3 widths
from SP's posterior and scored 121 above it in SPix1 (the same basin, SP's posterior medians
not SPix1's maximum); on P18 and P21 the light-shaped polishes lay several widths away."""


@dataclasses.dataclass(frozen=True)
class Rescan:
    """The rescan's record (``rescan.json``).

    Attributes
    ----------
    reference_einstein_radius : float
        θ_E of SP's mass, the scan's reference (arcsec).
    near_einstein_radius, far_einstein_radius : float
        θ_E of the best scanned point within and beyond :data:`NEAR` of it (arcsec).
    near_log_posterior, far_log_posterior : float
        Their ln P.
    polished_near_einstein_radius, polished_near : float or None
        θ_E (arcsec) and ln P where the polish from ``near`` ended (``None`` when neither
        the scan nor step 5 called for the polishes).
    polished_far_einstein_radius, polished_far : float or None
        The same for the polish from ``far`` (the scan's only).
    values : dict or None
        The free values that SPix1's priors were re-centred on, else ``None``: the better
        of the polished points beyond :data:`NEAR` of SP's θ_E, if it beats SP's basin
        (the best polished point within :data:`NEAR`, else ``near``) by
        :data:`THRESHOLD`; or the polished start point of step 5.
    n_calls : int
        Likelihood evaluations.
    seconds : float
        Wall-clock time.
    start_log_posteriors : list of float
        ln P of SP's start's unchosen polished points (step 5; empty where the scan moved
        or the start kept none).
    start_widths : list of float
        Their distances from SP's posterior in passed prior widths.
    polished_start_einstein_radius, polished_start : float or None
        θ_E (arcsec) and ln P where the polish from the best of them ended (``None`` when
        step 5 did not call for it).
    polished_start_widths : float or None
        That point's distance from SP's posterior in passed prior widths.
    shear_free_einstein_radius, shear_free : float or None
        θ_E (arcsec) and ln P after the short polish from SP's mass without its shear
        (step 6; ``None`` where an earlier step moved or that point lies within
        :data:`BASIN_WIDTHS` of SP's posterior).
    polished_shear_free_einstein_radius, polished_shear_free : float or None
        The same after its full polish (``None`` when step 6 did not call for it).
    polished_shear_free_widths : float or None
        That point's distance from SP's posterior in passed prior widths.
    """

    reference_einstein_radius: float
    near_einstein_radius: float
    near_log_posterior: float
    far_einstein_radius: float
    far_log_posterior: float
    polished_near_einstein_radius: float | None
    polished_near: float | None
    polished_far_einstein_radius: float | None
    polished_far: float | None
    values: dict | None
    n_calls: int
    seconds: float
    start_log_posteriors: tuple[float, ...] = ()
    start_widths: tuple[float, ...] = ()
    polished_start_einstein_radius: float | None = None
    polished_start: float | None = None
    polished_start_widths: float | None = None
    shear_free_einstein_radius: float | None = None
    shear_free: float | None = None
    polished_shear_free_einstein_radius: float | None = None
    polished_shear_free: float | None = None
    polished_shear_free_widths: float | None = None

    @property
    def moved(self) -> bool:
        """Whether SPix1's priors were re-centred."""
        return self.values is not None

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, content: dict) -> "Rescan":
        lists = ("start_log_posteriors", "start_widths")
        return cls(**{**content, **{k: tuple(content.get(k, ())) for k in lists}})


def _with_best_coefficient(posterior: sp_start._Posterior, x: np.ndarray) -> np.ndarray:
    """``x`` with the regularization coefficient of highest ln P on the grid."""
    index = posterior.space.free_names.index("regularization.coefficient")
    trials = []
    for coefficient in COEFFICIENT_GRID:
        trial = x.copy()
        trial[index] = coefficient
        trials.append((posterior(trial), trial))
    return max(trials, key=lambda pair: pair[0])[1]


def _scan(posterior: sp_start._Posterior, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """θ_E on the scan's grid around ``x``'s and ln P there, every other value held."""
    theta = posterior.space.free_names.index("mass.einstein_radius")
    low, high = SCAN_RANGE
    n = int(np.ceil(np.log(high / low) / np.log1p(SCAN_STEP))) + 1
    radii = x[theta] * np.geomspace(low, high, n)
    values = np.empty(n)
    for k, radius in enumerate(radii):
        trial = x.copy()
        trial[theta] = radius
        values[k] = posterior(trial)
    return radii, values


def _polish(
    posterior: sp_start._Posterior,
    x: np.ndarray,
    centre: tuple[float, float],
    calls: int = POLISH_CALLS,
    held_einstein_radius: float | None = None,
) -> tuple[np.ndarray, float]:
    """Powell on the mass and shear from ``x`` (centre boxed around the light centre,
    plausible mass and shear; ``calls`` evaluations), then the coefficient on the grid.
    With ``held_einstein_radius`` (arcsec), θ_E is boxed within :data:`NEAR` of it.

    A start outside the box or the plausible limits is moved just inside them first: from
    a point the boxed posterior rejects Powell does not move (on slacs1250+0523 SP's mass
    centre lay 0.305″ from the light, and both polishes returned their starts)."""
    names = posterior.space.free_names
    mass = [i for i, name in enumerate(names) if name in models.PASSED_MASS_NAMES]
    half = sp_start.MASS_CENTRE_RANGE
    box = {
        names.index(f"mass.{axis}"): (c - half, c + half)
        for axis, c in zip(("centre_x", "centre_y"), centre, strict=True)
    }
    x = sp_start.made_plausible(x, names)
    inner = sp_start.PLAUSIBLE_SHRINK * half
    for i, c in zip(box, centre, strict=True):
        x[i] = np.clip(x[i], c - inner, c + inner)
    if held_einstein_radius is not None:
        theta = names.index("mass.einstein_radius")
        box[theta] = (held_einstein_radius * (1 - NEAR), held_einstein_radius * (1 + NEAR))
        shrink = sp_start.PLAUSIBLE_SHRINK * NEAR
        x[theta] = np.clip(
            x[theta], held_einstein_radius * (1 - shrink), held_einstein_radius * (1 + shrink)
        )
    boxed = posterior.boxed(box, sp_start.plausible_mass(names))
    x, _ = sp_start._maximise(boxed, x, mass, None, calls)
    posterior.boxed({})
    x = _with_best_coefficient(posterior, x)
    return x, posterior(x)


def widths_from_sp(space: ParameterSpace, x: np.ndarray) -> float:
    """Distance of the free vector ``x`` from the means of ``space``'s passed mass and shear
    priors (SP's posterior in SPix1's problem), in their widths: √Σ((x − mean)/sigma)²
    over the passed (truncated-Gaussian) priors of :data:`models.PASSED_MASS_NAMES`."""
    terms = [
        ((x[i] - prior.mean) / prior.sigma) ** 2
        for i, name in enumerate(space.free_names)
        if name in models.PASSED_MASS_NAMES
        and isinstance(prior := space.parameter(name).prior, TruncatedGaussian)
    ]
    return float(np.sqrt(sum(terms)))


def _with_values(space: ParameterSpace, x: np.ndarray, values: dict) -> np.ndarray:
    """``x`` with its passed mass and shear parameters taken from ``values`` (where there)."""
    x = x.copy()
    for i, name in enumerate(space.free_names):
        if name in models.PASSED_MASS_NAMES and name in values:
            x[i] = values[name]
    return x


def _without_shear(space: ParameterSpace, x: np.ndarray) -> np.ndarray:
    """``x`` with its external shear set to zero."""
    x = x.copy()
    for name in ("shear.gamma_1", "shear.gamma_2"):
        x[space.free_names.index(name)] = 0.0
    return x


def _lensed(space: ParameterSpace, x: np.ndarray, lensing) -> dict | None:
    """The free values of ``x`` if ``lensing`` (when given) accepts them, else ``None``."""
    values = dict(zip(space.free_names, x.tolist(), strict=True))
    if lensing is not None and not lensing(values):
        logger.info("SPix1 rescan: the far basin does not multiply image its source")
        return None
    return values


def rescan(
    space: ParameterSpace,
    likelihood: Callable[[np.ndarray], float],
    centre: tuple[float, float],
    lensing: Callable[[dict], bool] | None = None,
    start_points: Sequence[dict] = (),
) -> Rescan:
    """Steps 1–5 on SPix1's problem (its passed-prior ``space``, its ``likelihood``, the
    lens light's ``centre`` in arcsec, SP's start's unchosen polished points and its arcs'
    sphere ``start_points`` as free values); see the module. ``lensing`` (free values → bool),
    if given, must accept the point moved to: SPix1 passes whether that mass forms several
    images of its source's brightest point and images most of its lensed signal more than
    once (:func:`mgelens.pipeline.run.multiply_imaged`), so that an unlensed or barely
    lensed copy of the image, which a pixelized source can fit well, is never taken."""
    began = time.perf_counter()
    posterior = sp_start._Posterior(likelihood, space)
    reference = _with_best_coefficient(posterior, space.prior_transform(np.full(space.n_free, 0.5)))
    theta = space.free_names.index("mass.einstein_radius")
    radii, values = _scan(posterior, reference)

    def in_sp_basin(radius):
        """Whether θ_E ``radius`` (arcsec; scalar or array) lies within NEAR of SP's."""
        return np.abs(radius / reference[theta] - 1.0) <= NEAR

    near = in_sp_basin(radii)
    near_index = int(np.flatnonzero(near)[np.argmax(values[near])])
    far_index = int(np.flatnonzero(~near)[np.argmax(values[~near])])
    near_x, far_x = reference.copy(), reference.copy()
    near_value = posterior(reference)
    if values[near_index] > near_value:
        near_x[theta], near_value = radii[near_index], values[near_index]
    far_x[theta], far_value = radii[far_index], values[far_index]
    scanned = (float(near_x[theta]), float(near_value), float(far_x[theta]), float(far_value))
    polished = [None, None, None, None]
    polished_near = None
    moved = None

    def polish_basin() -> tuple[np.ndarray, float]:
        """SP's basin polished: from ``near``, θ_E held within NEAR of SP's."""
        return _polish(posterior, near_x, centre, held_einstein_radius=reference[theta])

    if far_value >= near_value + THRESHOLD:
        polished_near = polish_basin()
        best, value = _polish(posterior, far_x, centre, held_einstein_radius=far_x[theta])
        polished = [float(polished_near[0][theta]), polished_near[1], float(best[theta]), value]
        if not in_sp_basin(best[theta]) and value >= polished_near[1] + THRESHOLD:
            moved = _lensed(space, best, lensing)

    def contest(x: np.ndarray) -> list:
        """Steps 5 and 6: polish ``x`` and SP's basin (``near``, once) and move to the
        polished ``x`` if it lies beyond :data:`BASIN_WIDTHS` and beats the polished
        basin by :data:`THRESHOLD`; the polished ``x``'s θ_E, ln P and widths."""
        nonlocal polished_near, moved
        if polished_near is None:
            polished_near = polish_basin()
            polished[:2] = float(polished_near[0][theta]), polished_near[1]
        best, value = _polish(posterior, x, centre)
        record = [float(best[theta]), value, widths_from_sp(space, best)]
        if record[2] > BASIN_WIDTHS and value >= polished_near[1] + THRESHOLD:
            moved = _lensed(space, best, lensing)
        return record

    scored, widths, from_start = [], [], [None, None, None]
    if moved is None and start_points:
        starts = [
            _with_best_coefficient(posterior, _with_values(space, reference, point))
            for point in start_points
        ]
        scored = [posterior(x) for x in starts]
        widths = [widths_from_sp(space, x) for x in starts]
        value, best = max(
            ((v, x) for v, x, w in zip(scored, starts, widths, strict=True) if w > BASIN_WIDTHS),
            key=lambda pair: pair[0],
            default=(-np.inf, None),
        )
        if value >= near_value + THRESHOLD:
            from_start = contest(best)
    shear_free, from_shear_free = [None, None], [None, None, None]
    without_shear = _without_shear(space, reference) if moved is None else None
    if without_shear is not None and widths_from_sp(space, without_shear) > BASIN_WIDTHS:
        radii, values = _scan(posterior, without_shear)
        without_shear[theta] = radii[int(np.argmax(values))]
        best, value = _polish(posterior, without_shear, centre, SHEAR_FREE_CALLS)
        shear_free = [float(best[theta]), value]
        if value >= near_value + THRESHOLD:
            from_shear_free = contest(best)
    found = Rescan(float(reference[theta]), *scanned, *polished, moved, posterior.calls,
                   time.perf_counter() - began, tuple(scored), tuple(widths),
                   *from_start, *shear_free, *from_shear_free)  # fmt: skip
    logger.info(
        "SPix1 rescan: ln P %.1f at θ_E %.3f″ (SP's basin), %.1f at %.3f″ beyond it, "
        "%s at SP's start's other polishes, %s without SP's shear; %s (%d calls)",
        found.near_log_posterior, found.near_einstein_radius, found.far_log_posterior,
        found.far_einstein_radius, ", ".join(f"{v:.1f}" for v in scored) or "none",
        "none" if found.shear_free is None else f"{found.shear_free:.1f}",
        "priors re-centred" if found.moved else "SP's priors kept", found.n_calls,
    )  # fmt: skip
    return found


def recentred_space(space: ParameterSpace, found: Rescan) -> ParameterSpace:
    """``space`` with the passed mass and shear priors re-centred on the rescan's point
    (widths and limits kept); ``space`` itself if the rescan kept SP's basin."""
    if not found.moved:
        return space
    for name in space.free_names:
        prior = space.parameter(name).prior
        if name in models.PASSED_MASS_NAMES and isinstance(prior, TruncatedGaussian):
            value = float(np.clip(found.values[name], prior.lower, prior.upper))
            space = space.with_prior(name, dataclasses.replace(prior, mean=value))
    return space


def read_or_rescan(folder: Path, fingerprint: dict, run: Callable[[], Rescan]) -> Rescan:
    """The rescan recorded in ``folder/rescan.json`` for ``fingerprint`` (the inputs and
    settings it was made for), else ``run()``'s, written there atomically with it."""
    return read_or_make(
        folder / RESCAN_FILE, "rescan", fingerprint, run, Rescan.from_dict, logger,
        "SPix1 rescan",
    )  # fmt: skip

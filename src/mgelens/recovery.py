"""How well a phase recovered a mock's truth (SPEC §11 acceptance criteria).

* **Mass**: every true EPL (and shear) parameter of ``truth.json`` against the phase's
  posterior median and 3σ (99.73 %) credible interval; θ_E also as a relative error
  (criterion: within 2 %).
* **Lens light**: (model − true)/true of the PSF-convolved lens light inside the fit mask,
  beyond 0.2″ of the lens centre (criterion: |·| < 5 % everywhere there).
* **Light split** (diagnostic, no criterion): in annuli about the lens centre, the errors of
  the fitted lens light, of the fitted lensed source and of their sum, each as a fraction
  of the true lens light in the annulus. Where the lensed source is bright, the MGE and
  the pixelized source can trade smooth light with little change in the fit; a lens-light
  error matched by an opposite source error, with a small total error, is that trade.
* **True-light refit** (diagnostic, no criterion): the phase's maximum-likelihood model
  refitted with its lens light replaced by the mock's true lens light, only the source
  re-solved. If the refit scores worse (Δ ln ε < 0), the data prefer the fitted lens light:
  its error is a trade the model cannot resolve, not a search that stopped short.
* **Isophotes** (criterion: q within 0.02, PA within 2°, a₄/a within 0.005 over
  0.5–2.5″): see :mod:`mgelens.isophote_recovery`.

Over many mocks, :func:`light_target_table` counts the mocks that meet the lens-light
targets (:data:`LIGHT_TARGETS`): the mean lens-light error beyond 0.2″ within 10 % on
every mock (5 %, the paper's claim, as the stretch) and the isophotes within their
tolerances on ≥ 90 % of them.

Angles are degrees counter-clockwise from +x and defined modulo 180°: a true angle is
inside an interval if any of angle, angle ± 180° is. Mocks without external shear have
true shear components of 0.
"""

import dataclasses
import itertools
from collections.abc import Mapping
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from mgelens.coverage import target_counts
from mgelens.fit import FitDataset, LensModel, fit
from mgelens.grid import pixel_centres
from mgelens.isophote_recovery import IsophoteRecovery
from mgelens.search.results import PhaseResult

EINSTEIN_RADIUS_TOLERANCE = 0.02
"""Relative θ_E error allowed (SPEC §11: θ_E within 2 %)."""
LENS_LIGHT_TOLERANCE = 0.05
"""Relative lens-light error allowed outside the centre (SPEC §11: 5 %)."""
LENS_LIGHT_INNER_RADIUS = 0.2
"""Arcsec around the lens centre left out of the lens-light comparison (SPEC §11)."""

_EPL_NAMES = {
    "einstein_radius": "mass.einstein_radius",
    "axis_ratio": "mass.axis_ratio",
    "angle": "mass.angle",
    "slope": "mass.slope",
}


def true_mass_parameters(truth: Mapping) -> dict[str, float]:
    """The true mass parameters of a mock's ``truth.json`` under the phases' names.

    Raises
    ------
    ValueError
        If the truth has no EPL profile.
    """
    values: dict[str, float] = {}
    shear = {"shear.gamma_1": 0.0, "shear.gamma_2": 0.0}
    for profile in truth["mass"]:
        parameters = profile["parameters"]
        if profile["type"] == "EPL":
            values["mass.centre_x"], values["mass.centre_y"] = map(float, parameters["centre"])
            values.update({name: float(parameters[key]) for key, name in _EPL_NAMES.items()})
        elif profile["type"] == "ExternalShear":
            shear["shear.gamma_1"] = float(parameters["gamma_1"])
            shear["shear.gamma_2"] = float(parameters["gamma_2"])
    if "mass.slope" not in values:
        raise ValueError("the truth has no EPL mass profile to compare with")
    return {**values, **shear}


@dataclass(frozen=True)
class ParameterRecovery:
    """One true parameter against a posterior: median, 3σ and 1σ central credible
    intervals and whether each holds the truth."""

    name: str
    truth: float
    median: float
    lower_3sigma: float
    upper_3sigma: float
    within_3sigma: bool
    error: float
    """median − truth (angles: reduced to [−90°, 90°))."""
    lower_1sigma: float
    upper_1sigma: float
    within_1sigma: bool


def mass_recovery(truth: Mapping, phase: PhaseResult) -> list[ParameterRecovery]:
    """Every true mass parameter the phase fitted, in the order of :func:`true_mass_parameters`."""
    median, wide, narrow = phase.median, phase.interval(3), phase.interval(1)
    rows = []
    for name, value in true_mass_parameters(truth).items():
        if name not in median:
            continue
        error = median[name] - value
        candidates = [value]
        if name.endswith(".angle"):
            error = (error + 90.0) % 180.0 - 90.0
            candidates = [value - 180.0, value, value + 180.0]

        def holds(interval, candidates=candidates) -> bool:
            return any(interval[0] <= v <= interval[1] for v in candidates)

        rows.append(
            ParameterRecovery(
                name=name,
                truth=value,
                median=median[name],
                lower_3sigma=wide[name][0],
                upper_3sigma=wide[name][1],
                within_3sigma=holds(wide[name]),
                error=error,
                lower_1sigma=narrow[name][0],
                upper_1sigma=narrow[name][1],
                within_1sigma=holds(narrow[name]),
            )
        )
    return rows


@dataclass(frozen=True)
class LensLightRecovery:
    """Statistics of r = (model − true)/true over the compared pixels."""

    n_pixels: int
    mean: float
    median: float
    p95_abs: float
    max_abs: float
    fraction_within_tolerance: float
    inner_radius: float


def lens_light_recovery(
    true_light: np.ndarray,
    model_light: np.ndarray,
    mask: np.ndarray,
    pixel_scale: float,
    centre: tuple[float, float],
    inner_radius: float = LENS_LIGHT_INNER_RADIUS,
) -> LensLightRecovery:
    """Compare two native lens-light images (same shape, same units) inside ``mask``
    (True = excluded) beyond ``inner_radius`` arcsec of ``centre``.

    Raises
    ------
    ValueError
        If the shapes differ or no pixel with positive true light is left to compare.
    """
    if true_light.shape != model_light.shape or mask.shape != true_light.shape:
        raise ValueError(
            f"lens-light images and mask differ in shape: {true_light.shape}, "
            f"{model_light.shape}, {mask.shape}"
        )
    x, y = pixel_centres(true_light.shape, pixel_scale)
    keep = ~mask & (np.hypot(x - centre[0], y - centre[1]) > inner_radius) & (true_light > 0)
    if not keep.any():
        raise ValueError("no pixel with positive true lens light to compare")
    ratio = (model_light[keep] - true_light[keep]) / true_light[keep]
    return LensLightRecovery(
        n_pixels=int(keep.sum()),
        mean=float(ratio.mean()),
        median=float(np.median(ratio)),
        p95_abs=float(np.percentile(np.abs(ratio), 95)),
        max_abs=float(np.abs(ratio).max()),
        fraction_within_tolerance=float(np.mean(np.abs(ratio) < LENS_LIGHT_TOLERANCE)),
        inner_radius=inner_radius,
    )


@dataclass(frozen=True)
class LightSplitAnnulus:
    """Light errors in one annulus r_inner ≤ r < r_outer (arcsec) about the lens centre.

    Each error is Σ(model − true) over the annulus's pixels divided by Σ true lens light
    there, for the lens light, the lensed source and their sum (the whole model image).
    """

    inner_radius: float
    outer_radius: float
    n_pixels: int
    lens_light_error: float
    lensed_source_error: float
    total_error: float
    source_to_lens_ratio: float
    """Σ true lensed source / Σ true lens light in the annulus."""


def light_split_profile(
    true_lens: np.ndarray,
    true_source: np.ndarray,
    model_lens: np.ndarray,
    model_source: np.ndarray,
    mask: np.ndarray,
    pixel_scale: float,
    centre: tuple[float, float],
    edges: np.ndarray,
) -> list[LightSplitAnnulus]:
    """Lens-light, lensed-source and total errors in the annuli ``edges[k] ≤ r < edges[k+1]``.

    All images are native PSF-convolved images of one shape and unit (the mock's
    ``lens_light_blurred`` and ``lensed_source_blurred``, the phase's LENS and LENSED);
    ``mask`` is True where excluded. Annuli without unmasked pixels or true lens light are
    left out.

    Raises
    ------
    ValueError
        If the shapes differ or ``edges`` is not increasing.
    """
    images = (true_lens, true_source, model_lens, model_source, mask)
    if len({image.shape for image in images}) != 1:
        raise ValueError(f"light images and mask differ in shape: {[i.shape for i in images]}")
    edges = np.asarray(edges, dtype=float)
    if edges.ndim != 1 or edges.size < 2 or np.any(np.diff(edges) <= 0):
        raise ValueError(f"annulus edges must be increasing, got {edges.tolist()}")
    x, y = pixel_centres(true_lens.shape, pixel_scale)
    radius = np.hypot(x - centre[0], y - centre[1])
    rows = []
    for inner, outer in itertools.pairwise(edges):
        keep = ~mask & (radius >= inner) & (radius < outer)
        lens_total = float(true_lens[keep].sum())
        if not keep.any() or lens_total <= 0.0:
            continue
        lens_error = float((model_lens[keep] - true_lens[keep]).sum()) / lens_total
        source_error = float((model_source[keep] - true_source[keep]).sum()) / lens_total
        rows.append(
            LightSplitAnnulus(
                inner_radius=float(inner),
                outer_radius=float(outer),
                n_pixels=int(keep.sum()),
                lens_light_error=lens_error,
                lensed_source_error=source_error,
                total_error=lens_error + source_error,
                source_to_lens_ratio=float(true_source[keep].sum()) / lens_total,
            )
        )
    return rows


def split_annulus_edges(mask_radius: float, inner_radius: float = LENS_LIGHT_INNER_RADIUS):
    """Annulus edges from ``inner_radius`` to ``mask_radius`` in steps of about 0.3″."""
    n = max(1, round((mask_radius - inner_radius) / 0.3))
    return np.linspace(inner_radius, mask_radius, n + 1)


@dataclass(frozen=True)
class TrueLightRefit:
    """A phase's maximum-likelihood fit against the same model with the lens light replaced
    by the true (PSF-convolved) lens light, only the source re-solved (same mass, mesh and
    regularization). ``delta_*`` = refit − phase fit; ln ε is the log evidence of a
    pixelized source, the log likelihood otherwise.

    Without a prior the lens light's linear intensities carry no Occam factor in ln ε
    (SPEC §7), so on pure noise alone freeing them lowers χ² by about their number:
    compare ``delta_chi_squared`` with ``n_lens_light_intensities``, the phase fit's
    non-zero ones. ``lens_light_prior_coefficient`` is λ of the phase's smoothness prior
    on those intensities (:mod:`mgelens.light_prior`; None without one), whose Occam terms
    the fitted light's ln ε then pays.
    """

    n_lens_light_intensities: int
    chi_squared: float
    log_evidence: float
    true_light_chi_squared: float
    true_light_log_evidence: float
    delta_chi_squared: float
    delta_log_evidence: float
    lens_light_prior_coefficient: float | None = None


def true_light_refit(
    dataset: FitDataset,
    model: LensModel,
    true_light: np.ndarray,
    passive_start: np.ndarray | None = None,
) -> TrueLightRefit:
    """Score ``model`` on ``dataset`` with its own lens light and with ``true_light``.

    Parameters
    ----------
    dataset : FitDataset
    model : LensModel
        A model with a source (e.g. a phase's maximum-likelihood model); its lens light,
        free and fixed, is replaced (and a prior on its intensities dropped: the true
        light has none to marginalise, so ln ε compares the fitted light, with its prior's
        Occam terms, against the truth held exactly).
    true_light : ndarray
        Native image of the true PSF-convolved lens light (shape of ``dataset.imaging``,
        units of the data). It is subtracted from the data and the source alone is solved,
        which equals fitting the data with the lens light fixed to the truth.
    passive_start : ndarray, optional
        Warm start of ``model``'s own fit (:func:`mgelens.fit.fit`), the one its phase's
        sampler used (:func:`mgelens.pipeline.run.reference_passive_set`): the same
        minimum, without the default start's factorisation of the whole system, which
        fails on some ill-conditioned lens-light blocks.
    """
    if model.source is None:
        raise ValueError("the true-light refit needs a model with a source")
    imaging = dataset.imaging
    if true_light.shape != imaging.shape:
        raise ValueError(f"true lens light has shape {true_light.shape}, data {imaging.shape}")
    own = fit(dataset, model, passive_start)
    without_light = FitDataset.from_imaging(
        dataclasses.replace(imaging, data=imaging.data - true_light),
        dataset.mask,
        dataset.settings,
    )
    truth = fit(
        without_light,
        dataclasses.replace(model, lens_light=(), fixed_light=(), lens_light_prior=None),
    )
    return TrueLightRefit(
        n_lens_light_intensities=int(np.count_nonzero(own.lens_light_intensities)),
        chi_squared=own.chi_squared,
        log_evidence=own.log_evidence,
        true_light_chi_squared=truth.chi_squared,
        true_light_log_evidence=truth.log_evidence,
        delta_chi_squared=truth.chi_squared - own.chi_squared,
        delta_log_evidence=truth.log_evidence - own.log_evidence,
        lens_light_prior_coefficient=None
        if model.lens_light_prior is None
        else float(model.lens_light_prior.coefficient),
    )


def recovery_summary(
    lens: str,
    mass: list[ParameterRecovery],
    light: LensLightRecovery | None,
    split: list[LightSplitAnnulus] | None = None,
    refit: TrueLightRefit | None = None,
    isophotes: IsophoteRecovery | None = None,
) -> dict:
    """JSON-ready record with the three SPEC §11 criteria as booleans (and, if given, the
    light split per annulus under ``light_split``, the true-light refit under
    ``true_light_refit`` and the isophote recovery under ``isophotes``, whose
    ``within_tolerance`` joins the criteria as ``isophotes_within_tolerance``)."""
    by_name = {row.name: row for row in mass}
    theta_e = by_name.get("mass.einstein_radius")
    theta_e_error = None if theta_e is None else theta_e.error / theta_e.truth
    epl = [row for row in mass if row.name.startswith("mass.")]
    return {
        "lens": lens,
        "mass": [asdict(row) for row in mass],
        "einstein_radius_relative_error": theta_e_error,
        "lens_light": None if light is None else asdict(light),
        "light_split": None if split is None else [asdict(row) for row in split],
        "true_light_refit": None if refit is None else asdict(refit),
        "isophotes": None if isophotes is None else isophotes.to_dict(),
        "criteria": {
            "einstein_radius_within_2_percent": None
            if theta_e_error is None
            else bool(abs(theta_e_error) < EINSTEIN_RADIUS_TOLERANCE),
            "epl_within_3sigma": bool(epl) and all(row.within_3sigma for row in epl),
            "lens_light_within_5_percent": None
            if light is None
            else bool(light.max_abs < LENS_LIGHT_TOLERANCE),
            "isophotes_within_tolerance": None if isophotes is None else isophotes.within_tolerance,
        },
    }


@dataclass(frozen=True)
class LightTarget:
    """A fraction of mocks (``goal`` ≤ fraction) whose :func:`recovery_table` column meets
    a condition: |value| < ``limit``, or, without a limit, a criterion that is True."""

    name: str
    column: str
    goal: float
    limit: float | None = None


LIGHT_TARGETS = (
    LightTarget("lens light within 10 % (mean beyond 0.2″)", "lens_light.mean", 1.0, 0.10),
    LightTarget("lens light within 5 % (mean beyond 0.2″)", "lens_light.mean", 1.0, 0.05),
    LightTarget("isophotes within q 0.02, PA 2°, a₄/a 0.005", "isophotes_within_tolerance", 0.90),
)
"""The lens-light targets over the mocks (the 5 % row is the paper's claim)."""


def light_target_table(
    table: pd.DataFrame, targets: tuple[LightTarget, ...] = LIGHT_TARGETS
) -> pd.DataFrame:
    """Each target's count and fraction of the mocks of a :func:`recovery_table` that meet
    it, its goal and whether it is met. Mocks where the column is empty (no lens-light
    record, no isophote comparison) are not counted; ``met`` is False with none left.
    Columns ``target, column, n, passed, fraction, goal, met``."""
    rows = []
    for target in targets:
        values = table[target.column].dropna()
        if target.limit is None:
            passed = values.astype(bool)
        else:
            passed = values.astype(float).abs() < target.limit
        rows.append(
            {"target": target.name, "column": target.column} | target_counts(passed, target.goal)
        )
    return pd.DataFrame(rows)


_ISOPHOTE_ERRORS = ("max_abs_axis_ratio_error", "max_abs_angle_error", "max_abs_a4_error")
_ISOPHOTE_STATISTICS = ("delta_q_max", "delta_pa_max", "a4_a_extreme")


def _number(value) -> float:
    return np.nan if value is None else float(value)


def recovery_table(records: list[Mapping]) -> pd.DataFrame:
    """One row per lens from :func:`recovery_summary` records: per parameter the truth,
    median and whether the 3σ interval holds it, the θ_E relative error, lens-light
    statistics, the largest lens-light and total errors of the light split (by modulus,
    with sign), the true-light refit's Δχ² and Δ ln ε (and the lens-light prior's λ, NaN
    without one), the isophotes' largest errors and fitted and true Δq_max, ΔPA_max and
    extreme a₄/a, and the criteria."""
    rows = []
    for record in records:
        row: dict = {"lens": record["lens"]}
        for entry in record["mass"]:
            name = entry["name"]
            row[f"{name}.truth"] = entry["truth"]
            row[f"{name}.median"] = entry["median"]
            row[f"{name}.within_3sigma"] = entry["within_3sigma"]
        row["einstein_radius_relative_error"] = record["einstein_radius_relative_error"]
        light = record["lens_light"] or {}
        for key in ("mean", "p95_abs", "max_abs"):
            row[f"lens_light.{key}"] = light.get(key, np.nan)
        split = record.get("light_split") or []
        for key in ("lens_light_error", "total_error"):
            values = [annulus[key] for annulus in split]
            row[f"light_split.{key}"] = max(values, key=abs) if values else np.nan
        refit = record.get("true_light_refit") or {}
        for key in ("delta_chi_squared", "delta_log_evidence", "lens_light_prior_coefficient"):
            row[f"true_light_refit.{key}"] = _number(refit.get(key))
        isophotes = record.get("isophotes") or {}
        for key in _ISOPHOTE_ERRORS:
            row[f"isophotes.{key}"] = _number(isophotes.get(key))
        for side in ("fitted", "true"):
            statistics = isophotes.get(f"{side}_statistics") or {}
            for key in _ISOPHOTE_STATISTICS:
                row[f"isophotes.{side}.{key}"] = _number(statistics.get(key))
        row.update(record["criteria"])
        rows.append(row)
    return pd.DataFrame(rows)

"""How well a fit recovered a mock's isophotes: q, PA and a₄/a of the fitted lens light
against the truth's over the statistics range 0.5–2.5″ (SPEC §9.1).

Both sides are measured the same way. The fitted side is the isophote table of the fit's
PSF-convolved lens light (``mgelens isophotes --phase``); the true side is the same
analysis (:func:`mgelens.isophotes.isophote_table`) of the mock's PSF-convolved true lens
light (``lens_light_blurred.fits``), about the true light centre. Measuring the truth
instead of reading an analytic table makes the comparison fair to the measurement: the
PSF's rounding of the inner isophotes and the contour tracer's small biases act on both
sides alike, and M1–M3, whose true light is a sum of Gaussians of different q, have no
analytic isophote table at all. For the population mocks, whose light is defined by its
isophotes (``truth.json``'s ``lens_light.isophotes``), the tests check that the measured
truth agrees with that table.

The two tables have isophotes at different semi-major axes (their levels differ), so each
is interpolated linearly in ln a onto :data:`COMPARISON_RADII`; PA is unwrapped along a
before interpolation, and PA differences are taken modulo 180° into [−90°, 90°). Where
the true isophote is round (q > :data:`~mgelens.isophotes.ROUND_AXIS_RATIO`) its PA is
undefined and is not compared. A radius outside either table's range is not compared;
the recovery then does not hold (it asks for the whole range).

Angles are degrees counter-clockwise from +x; lengths are arcsec.
"""

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from mgelens.isophotes import (
    ROUND_AXIS_RATIO,
    STATISTICS_SMA_RANGE,
    isophote_statistics,
    unwrap_position_angles,
)


@dataclass(frozen=True)
class IsophoteTolerances:
    """Largest allowed |fitted − true| of an isophote's shape at any compared radius."""

    axis_ratio: float = 0.02
    angle: float = 2.0
    """Degrees."""
    a4_over_a: float = 0.005


ISOPHOTE_TOLERANCES = IsophoteTolerances()
"""The targets for a fitted lens light: q within 0.02, PA within 2° and a₄/a within 0.005
of the truth at every radius over 0.5–2.5″ (docs/recovery.md)."""

COMPARISON_RADII = np.geomspace(*STATISTICS_SMA_RANGE, 21)
"""Semi-major axes (arcsec) at which fitted and true isophotes are compared: 21 log-spaced
over the statistics range 0.5–2.5″ (SPEC §9.1), about 0.035 in log₁₀ a apart."""

PROFILE_COLUMNS = (
    "sma",
    "q_fit",
    "q_true",
    "q_error",
    "pa_fit",
    "pa_true",
    "pa_error",
    "a4_a_fit",
    "a4_a_true",
    "a4_a_error",
)
"""Columns of :func:`compare_isophotes` (``_error`` = fitted − true)."""


def true_light_centre(truth: Mapping) -> tuple[float, float]:
    """(x, y) arcsec of a mock's true lens-light centre from its ``truth.json``.

    Raises
    ------
    ValueError
        If the truth's lens light is of a kind without a single centre.
    """
    light = truth["lens_light"]
    if light["model"] == "mge":
        centre = light["gaussians"][0]["centre"]
    elif "centre" in light:  # isophote light, independent (lenstronomy) mocks
        centre = light["centre"]
    else:
        raise ValueError(f"no centre for a true lens light of model {light['model']!r}")
    return float(centre[0]), float(centre[1])


def profile_on_radii(table: pd.DataFrame, radii: np.ndarray) -> pd.DataFrame:
    """q, PA and a₄/a of an isophote table interpolated linearly in ln a onto ``radii``.

    PA is unwrapped along increasing a first and returned in [0, 180). Radii outside the
    table's range of ``sma`` get NaN; a table with fewer than two isophotes gives NaN
    everywhere. Columns ``sma, q, pa, a4_a``.
    """
    radii = np.asarray(radii, dtype=float)
    ordered = table.sort_values("sma")
    sma = ordered["sma"].to_numpy(dtype=float)
    out = {"sma": radii}
    if sma.size < 2:
        return pd.DataFrame({**out, "q": np.nan, "pa": np.nan, "a4_a": np.nan})
    log_a = np.log(sma)
    inside = (radii >= sma[0]) & (radii <= sma[-1])
    columns = {
        "q": ordered["q"].to_numpy(dtype=float),
        "pa": unwrap_position_angles(ordered["pa"].to_numpy(dtype=float)),
        "a4_a": ordered["a4_a"].to_numpy(dtype=float),
    }
    for name, values in columns.items():
        interpolated = np.full(radii.shape, np.nan)
        interpolated[inside] = np.interp(np.log(radii[inside]), log_a, values)
        out[name] = np.mod(interpolated, 180.0) if name == "pa" else interpolated
    return pd.DataFrame(out)


def angle_difference(fitted: np.ndarray, true: np.ndarray) -> np.ndarray:
    """fitted − true for axis angles defined modulo 180°, in [−90°, 90°) degrees."""
    return np.mod(np.asarray(fitted) - np.asarray(true) + 90.0, 180.0) - 90.0


def compare_isophotes(
    fitted: pd.DataFrame,
    true: pd.DataFrame,
    radii: np.ndarray = COMPARISON_RADII,
    round_axis_ratio: float = ROUND_AXIS_RATIO,
) -> pd.DataFrame:
    """Fitted and true isophote shape side by side at ``radii`` (columns
    :data:`PROFILE_COLUMNS`). PA and its error are NaN where the true isophote is round."""
    fit = profile_on_radii(fitted, radii)
    truth = profile_on_radii(true, radii)
    round_true = truth["q"].to_numpy() > round_axis_ratio
    pa_fit = np.where(round_true, np.nan, fit["pa"])
    pa_true = np.where(round_true, np.nan, truth["pa"])
    return pd.DataFrame(
        {
            "sma": fit["sma"],
            "q_fit": fit["q"],
            "q_true": truth["q"],
            "q_error": fit["q"] - truth["q"],
            "pa_fit": pa_fit,
            "pa_true": pa_true,
            "pa_error": angle_difference(pa_fit, pa_true),
            "a4_a_fit": fit["a4_a"],
            "a4_a_true": truth["a4_a"],
            "a4_a_error": fit["a4_a"] - truth["a4_a"],
        },
        columns=list(PROFILE_COLUMNS),
    )


def _max_abs(values: pd.Series) -> float | None:
    finite = np.abs(values.to_numpy(dtype=float))
    finite = finite[np.isfinite(finite)]
    return float(finite.max()) if finite.size else None


@dataclass(frozen=True)
class IsophoteRecovery:
    """The fitted lens light's isophotes against the truth's over 0.5–2.5″.

    Attributes
    ----------
    n_radii, n_compared : int
        Comparison radii, and those where both tables give q and a₄/a.
    max_abs_axis_ratio_error, max_abs_angle_error, max_abs_a4_error : float or None
        Largest |fitted − true| of q, PA (degrees; non-round true isophotes only) and
        a₄/a over the compared radii (None if none were compared).
    within_tolerance : bool
        Every radius compared and every error within :data:`ISOPHOTE_TOLERANCES`.
    fitted_statistics, true_statistics : dict
        :func:`~mgelens.isophotes.isophote_statistics` of each table (Δq_max, ΔPA_max,
        extreme a₄/a): the per-lens numbers of the sample histograms (SPEC §9.1).
    profile : list of dict
        The rows of :func:`compare_isophotes` (NaN written as None).
    tolerances : dict
        The tolerances applied.
    """

    n_radii: int
    n_compared: int
    max_abs_axis_ratio_error: float | None
    max_abs_angle_error: float | None
    max_abs_a4_error: float | None
    within_tolerance: bool
    fitted_statistics: dict
    true_statistics: dict
    profile: list[dict]
    tolerances: dict

    def to_dict(self) -> dict:
        return asdict(self)


def isophote_recovery(
    fitted: pd.DataFrame,
    true: pd.DataFrame,
    tolerances: IsophoteTolerances = ISOPHOTE_TOLERANCES,
    radii: np.ndarray = COMPARISON_RADII,
) -> IsophoteRecovery:
    """Score a fit's isophote table against the true one (see the module docstring)."""
    profile = compare_isophotes(fitted, true, radii)
    compared = profile[["q_error", "a4_a_error"]].notna().all(axis=1)
    errors = {
        "axis_ratio": _max_abs(profile["q_error"]),
        "angle": _max_abs(profile["pa_error"]),
        "a4_over_a": _max_abs(profile["a4_a_error"]),
    }
    limits = asdict(tolerances)
    within = bool(compared.all()) and all(
        value is None or value <= limits[name] for name, value in errors.items()
    )
    rows = [
        {
            key: None if isinstance(value, float) and math.isnan(value) else value
            for key, value in row.items()
        }
        for row in profile.to_dict(orient="records")
    ]
    return IsophoteRecovery(
        n_radii=len(profile),
        n_compared=int(compared.sum()),
        max_abs_axis_ratio_error=errors["axis_ratio"],
        max_abs_angle_error=errors["angle"],
        max_abs_a4_error=errors["a4_over_a"],
        within_tolerance=within,
        fitted_statistics=isophote_statistics(fitted).to_dict(),
        true_statistics=isophote_statistics(true).to_dict(),
        profile=rows,
        tolerances=limits,
    )

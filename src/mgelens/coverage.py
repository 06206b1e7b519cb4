"""Coverage of the mass posteriors over a set of truth-known mocks: how often the credible
intervals hold the truth, the bias and scatter of the medians, and the project's targets.

The input is one recovery record per mock (:func:`mgelens.recovery.recovery_summary`,
``results/<lens>/recovery.json``). Per parameter:

* ``within_1sigma``, ``within_3sigma``: fraction of mocks whose central 68.27 % and
  99.73 % credible intervals hold the truth (angles modulo 180°);
* ``bias``: mean of median − truth; ``scatter``: its standard deviation (ddof 1);
* ``median_abs_pull``: median of |pull|, the pull being (median − truth) over the 1σ
  half-width on the side of the truth (median − lower if the median lies above the
  truth, upper − median otherwise). For calibrated Gaussian posteriors the pulls are
  N(0, 1) and the median |pull| is 0.674.

Targets (:data:`TARGETS`): ≥ 95 % of the true γ, θ_E and shear components inside their
3σ intervals; |median γ − truth| < 0.05 for ≥ 90 % of the mocks; θ_E within 1 % for
≥ 95 %. :func:`targets_by_fits` counts them over every fit and, where the rows carry
each mock's quality checks (column ``flags``, :func:`mgelens.quality.flagged_checks`),
over the fits that no check flags: the ones a user would read as lens models.
"""

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from mgelens.quality import NO_FLAG

PARAMETERS = (
    "mass.centre_x",
    "mass.centre_y",
    "mass.einstein_radius",
    "mass.axis_ratio",
    "mass.angle",
    "mass.slope",
    "shear.gamma_1",
    "shear.gamma_2",
)
"""Parameters in the order of the tables and the figure."""

ROW_COLUMNS = (
    "lens",
    "parameter",
    "truth",
    "median",
    "error",
    "lower_1sigma",
    "upper_1sigma",
    "lower_3sigma",
    "upper_3sigma",
    "within_1sigma",
    "within_3sigma",
    "pull",
)
"""Columns of :func:`coverage_rows`, one row per mock and parameter."""

TABLE_COLUMNS = (
    "parameter",
    "n",
    "within_1sigma",
    "within_3sigma",
    "bias",
    "scatter",
    "median_abs_pull",
)
"""Columns of :func:`coverage_table`, one row per parameter."""


@dataclass(frozen=True)
class Target:
    """A fraction of mocks that must meet a condition: ``goal`` ≤ fraction."""

    name: str
    parameter: str
    condition: str
    """``within_3sigma``, ``abs_error`` (|median − truth| < ``limit``) or
    ``relative_error`` (|median − truth|/truth < ``limit``)."""
    goal: float
    limit: float | None = None


TARGETS = (
    Target("γ inside 3σ", "mass.slope", "within_3sigma", 0.95),
    Target("θ_E inside 3σ", "mass.einstein_radius", "within_3sigma", 0.95),
    Target("γ₁ inside 3σ", "shear.gamma_1", "within_3sigma", 0.95),
    Target("γ₂ inside 3σ", "shear.gamma_2", "within_3sigma", 0.95),
    Target("|median γ − truth| < 0.05", "mass.slope", "abs_error", 0.90, 0.05),
    Target("θ_E within 1 %", "mass.einstein_radius", "relative_error", 0.95, 0.01),
)


def _toward_truth(error, median, lower, upper):
    """Distance from the median to the interval limit on the truth's side: the lower limit
    where the median lies above the truth (``error`` > 0), else the upper (scalars or
    arrays)."""
    return np.where(np.asarray(error) > 0, median - lower, upper - median)


def _pull(error: float, median: float, lower: float, upper: float) -> float:
    width = float(_toward_truth(error, median, lower, upper))
    return error / width if width > 0 else np.nan


def interval_pulls(rows: pd.DataFrame) -> np.ndarray:
    """``error`` (median − truth, angles wrapped) of each row of :func:`coverage_rows` on
    the scale of its own intervals, toward the truth: |d| / s₁ up to the 1σ limit (s₁ its
    distance from the median), then linear from 1 to 3 between the 1σ and 3σ limits, and
    3 + 3 (|d| − s₃) / s₃ beyond the 3σ limit, with the sign of ``error``. So |value| > 3
    exactly where the truth lies outside the 3σ interval, and < 1 where it lies inside
    the 1σ interval, however skewed the posterior; for a Gaussian posterior it is the
    usual pull. Rows without 1σ limits (older records) take 3 |d| / s₃."""
    error, median, lower_1, upper_1, lower_3, upper_3 = (
        rows[name].to_numpy(dtype=float)
        for name in ("error", "median", "lower_1sigma", "upper_1sigma", "lower_3sigma",
                     "upper_3sigma")
    )  # fmt: skip
    one = _toward_truth(error, median, lower_1, upper_1)
    three = _toward_truth(error, median, lower_3, upper_3)
    size = np.abs(error)
    with np.errstate(divide="ignore", invalid="ignore"):
        scaled = np.where(
            size <= three,
            np.where(size <= one, size / one, 1.0 + 2.0 * (size - one) / (three - one)),
            3.0 + 3.0 * (size - three) / three,
        )
        scaled = np.where(np.isfinite(one) & (one > 0), scaled, 3.0 * size / three)
    return np.sign(error) * scaled


def coverage_rows(records: Sequence[Mapping]) -> pd.DataFrame:
    """One row per mock and mass parameter of the records (columns :data:`ROW_COLUMNS`).

    Records written before the 1σ intervals were recorded give NaN there (and in the
    pull) and ``within_1sigma`` None.
    """
    rows = []
    for record in records:
        for entry in record["mass"]:
            if entry["name"] not in PARAMETERS:
                continue
            lower_1 = entry.get("lower_1sigma", np.nan)
            upper_1 = entry.get("upper_1sigma", np.nan)
            rows.append(
                {
                    "lens": record["lens"],
                    "parameter": entry["name"],
                    "truth": entry["truth"],
                    "median": entry["median"],
                    "error": entry["error"],
                    "lower_1sigma": lower_1,
                    "upper_1sigma": upper_1,
                    "lower_3sigma": entry["lower_3sigma"],
                    "upper_3sigma": entry["upper_3sigma"],
                    "within_1sigma": entry.get("within_1sigma"),
                    "within_3sigma": entry["within_3sigma"],
                    "pull": _pull(entry["error"], entry["median"], lower_1, upper_1),
                }
            )
    return pd.DataFrame(rows, columns=list(ROW_COLUMNS))


def _fraction(values: pd.Series) -> float:
    known = values.dropna()
    return float(known.astype(bool).mean()) if len(known) else np.nan


def coverage_table(rows: pd.DataFrame) -> pd.DataFrame:
    """Per parameter (columns :data:`TABLE_COLUMNS`) over the rows of :func:`coverage_rows`;
    parameters without rows are left out."""
    table = []
    for name in PARAMETERS:
        part = rows[rows["parameter"] == name]
        if part.empty:
            continue
        errors = part["error"].to_numpy(dtype=float)
        pulls = np.abs(part["pull"].to_numpy(dtype=float))
        table.append(
            {
                "parameter": name,
                "n": len(part),
                "within_1sigma": _fraction(part["within_1sigma"]),
                "within_3sigma": _fraction(part["within_3sigma"]),
                "bias": float(errors.mean()),
                "scatter": float(errors.std(ddof=1)) if errors.size > 1 else np.nan,
                "median_abs_pull": float(np.nanmedian(pulls))
                if np.isfinite(pulls).any()
                else np.nan,
            }
        )
    return pd.DataFrame(table, columns=list(TABLE_COLUMNS))


def target_table(rows: pd.DataFrame, targets: Sequence[Target] = TARGETS) -> pd.DataFrame:
    """Each target's count and fraction of mocks that meet it, its goal and whether it is
    met (``met`` is False with no mocks). Columns ``target, parameter, n, passed,
    fraction, goal, met``."""
    out = []
    for target in targets:
        part = rows[rows["parameter"] == target.parameter]
        if target.condition == "within_3sigma":
            passed = part["within_3sigma"].astype(bool)
        elif target.condition == "abs_error":
            passed = part["error"].abs() < target.limit
        elif target.condition == "relative_error":
            passed = (part["error"] / part["truth"]).abs() < target.limit
        else:
            raise ValueError(f"unknown target condition {target.condition!r}")
        out.append(
            {"target": target.name, "parameter": target.parameter}
            | target_counts(passed, target.goal)
        )
    return pd.DataFrame(out)


def target_counts(passed: pd.Series, goal: float) -> dict:
    """``n`` (mocks counted), ``passed``, ``fraction`` (NaN with none), ``goal`` and ``met``
    (fraction ≥ goal; False with no mocks) of one target, from a boolean per mock."""
    fraction = float(passed.mean()) if len(passed) else np.nan
    return {
        "n": len(passed),
        "passed": int(passed.sum()),
        "fraction": fraction,
        "goal": goal,
        "met": bool(len(passed)) and fraction >= goal,
    }


FITS_ALL = "all"
"""``fits`` of :func:`targets_by_fits`'s rows over every mock."""
FITS_UNFLAGGED = "unflagged"
"""``fits`` of :func:`targets_by_fits`'s rows over the mocks that no quality check flags."""


def known_flags(rows: pd.DataFrame) -> pd.Series:
    """The ``flags`` column of ``rows`` (:func:`mgelens.quality.flagged_checks`), missing
    (NA) where a mock has no quality record: an absent column, a NaN or an empty text
    (a CSV read with ``keep_default_na=False``) all count as unknown."""
    flags = rows["flags"] if "flags" in rows else pd.Series(pd.NA, index=rows.index)
    return flags.astype("string").replace("", pd.NA)


def targets_by_fits(rows: pd.DataFrame, targets: Sequence[Target] = TARGETS) -> pd.DataFrame:
    """:func:`target_table` over every row (``fits`` :data:`FITS_ALL`) and, when at least
    one mock's flags are known (:func:`known_flags`), again over the mocks whose flags are
    :data:`mgelens.quality.NO_FLAG` (``fits`` :data:`FITS_UNFLAGGED`). Mocks without a
    quality record count in the first only; a fit whose residual statistic could not be
    measured is unflagged if the other checks pass, as ``mgelens quality`` reports it."""
    tables = [target_table(rows, targets).assign(fits=FITS_ALL)]
    flags = known_flags(rows)
    if flags.notna().any():
        unflagged = rows[(flags == NO_FLAG).fillna(False).to_numpy(dtype=bool)]
        tables.append(target_table(unflagged, targets).assign(fits=FITS_UNFLAGGED))
    table = pd.concat(tables, ignore_index=True)
    return table[["fits", *[name for name in table.columns if name != "fits"]]]

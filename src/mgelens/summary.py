"""Sample summary: per-lens isophote summaries (JSON) gathered into one table.

A per-lens summary is the JSON written by ``mgelens isophotes --summary`` (built by
:func:`lens_summary`)::

    {
      "lens": "J0252+0039",
      "mgelens_version": "...", "conventions": "...",
      "statistics": {"delta_q_max": ..., "delta_pa_max": ..., "a4_a_extreme": ...,
                     "n_isophotes": ..., "n_isophotes_pa": ..., "sma_min": 0.5,
                     "sma_max": 2.5, "round_axis_ratio": 0.95},
      "mass": null or {"axis_ratio": ..., "angle": ..., "critical_curve_axis_ratio": ...,
                       "critical_curve_angle": ..., "critical_curve_einstein_radius": ...,
                       ...},
      "inputs": {...}
    }

Statistics are those of :class:`mgelens.isophotes.IsophoteStatistics` (Δq_max, ΔPA_max in
degrees, the extreme a₄/a with its sign; JSON ``null`` = undefined). A lens is
"complex" (paper, SPEC §11) when Δq_max > 0.1 or ΔPA_max > 10°.
"""

import json
import math
import os
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pandas as pd

from mgelens import CONVENTIONS_VERSION, __version__
from mgelens.isophotes import IsophoteStatistics, MassShape

DELTA_Q_THRESHOLD = 0.1
DELTA_PA_THRESHOLD = 10.0
"""Degrees."""

STATISTICS_COLUMNS = ("delta_q_max", "delta_pa_max", "a4_a_extreme")
COUNT_COLUMNS = ("n_isophotes", "n_isophotes_pa")
MASS_COLUMNS = (
    "axis_ratio",
    "angle",
    "critical_curve_axis_ratio",
    "critical_curve_angle",
    "critical_curve_einstein_radius",
)
_DERIVED_COLUMNS = ("abs_a4_a_max", "complex")
TABLE_COLUMNS = (
    "lens",
    *STATISTICS_COLUMNS,
    *COUNT_COLUMNS,
    *_DERIVED_COLUMNS,
    *(f"mass_{name}" for name in MASS_COLUMNS),
    "source",
)
"""Columns of :func:`sample_table` (mass columns NaN when a summary has no mass model)."""


def lens_summary(
    lens: str,
    statistics: IsophoteStatistics,
    mass: MassShape | None = None,
    inputs: dict | None = None,
) -> dict:
    """The per-lens summary dictionary (write it with :func:`mgelens.atomic.write_json`)."""
    return {
        "lens": lens,
        "mgelens_version": __version__,
        "conventions": CONVENTIONS_VERSION,
        "statistics": statistics.to_dict(),
        "mass": None if mass is None else mass.to_dict(),
        "inputs": inputs or {},
    }


def _number(value) -> float:
    return math.nan if value is None else float(value)


def _summary_row(path: Path) -> dict:
    try:
        content = json.loads(path.read_text())
        statistics = content["statistics"]
        row = {"lens": str(content["lens"])}
        row.update({name: _number(statistics[name]) for name in STATISTICS_COLUMNS})
        row.update({name: int(statistics[name]) for name in COUNT_COLUMNS})
    except FileNotFoundError as exc:
        raise ValueError(f"{path}: lens summary not found") from exc
    except (json.JSONDecodeError, KeyError, TypeError) as exc:
        raise ValueError(
            f"{path}: not a lens summary written by 'mgelens isophotes --summary' ({exc})"
        ) from exc
    mass = content.get("mass") or {}
    row.update({f"mass_{name}": _number(mass.get(name)) for name in MASS_COLUMNS})
    row["source"] = str(path)
    return row


def complex_lenses(
    table: pd.DataFrame,
    delta_q_threshold: float = DELTA_Q_THRESHOLD,
    delta_pa_threshold: float = DELTA_PA_THRESHOLD,
) -> pd.Series:
    """Boolean per lens: Δq_max > ``delta_q_threshold`` or ΔPA_max > ``delta_pa_threshold``
    (undefined statistics count as not exceeding)."""
    return (table["delta_q_max"] > delta_q_threshold) | (table["delta_pa_max"] > delta_pa_threshold)


def complex_fraction(
    table: pd.DataFrame,
    delta_q_threshold: float = DELTA_Q_THRESHOLD,
    delta_pa_threshold: float = DELTA_PA_THRESHOLD,
) -> float:
    """Fraction of the lenses with isophotes (``n_isophotes`` > 0) that are complex.

    NaN when no lens has isophotes.
    """
    measured = table[table["n_isophotes"] > 0]
    if measured.empty:
        return math.nan
    flags = complex_lenses(measured, delta_q_threshold, delta_pa_threshold)
    return float(np.mean(flags))


def sample_table(
    paths: Iterable[str | os.PathLike],
    delta_q_threshold: float = DELTA_Q_THRESHOLD,
    delta_pa_threshold: float = DELTA_PA_THRESHOLD,
) -> pd.DataFrame:
    """One row per lens from per-lens summary JSON files, sorted by lens name.

    Columns :data:`TABLE_COLUMNS`: the statistics, ``abs_a4_a_max`` = |a₄/a| extreme,
    ``complex`` (:func:`complex_lenses`), the mass-model shape and the source file.

    Raises
    ------
    ValueError
        A file is missing or not a lens summary, or two files describe the same lens.
    """
    rows = [_summary_row(Path(path)) for path in paths]
    table = pd.DataFrame(rows, columns=[c for c in TABLE_COLUMNS if c not in _DERIVED_COLUMNS])
    duplicated = table["lens"][table["lens"].duplicated()]
    if not duplicated.empty:
        lens = duplicated.iloc[0]
        files = ", ".join(table.loc[table["lens"] == lens, "source"])
        raise ValueError(f"lens {lens!r} appears in several summaries: {files}")
    table["abs_a4_a_max"] = table["a4_a_extreme"].abs()
    table["complex"] = complex_lenses(table, delta_q_threshold, delta_pa_threshold)
    return table[list(TABLE_COLUMNS)].sort_values("lens", ignore_index=True)

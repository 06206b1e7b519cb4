"""Published SLACS lens models to compare with, and the Einstein-radius conversion (SPEC §3.3).

Reference tables (folder ``shared/data/reference``, described by its README):

* Bolton et al. 2008, Table 5 (``bolton2008_table5_sie.csv``): SIE Einstein radius
  ``bSIE`` in arcsec, intermediate-axis normalisation (= the lenstronomy convention of an
  SIE), axis ratio ``qSIE``.
* Shajib et al. 2021 power-law fits as compiled for TDCOSMO 2020
  (``shajib2021_slacs_powerlaw_tdcosmo2020.csv``): only rows with ``flag_imaging == 1``
  (imaging-only fits) are used; ``theta_E`` (arcsec, lenstronomy convention) and slope
  ``gamma`` with their ``_lo``/``_hi`` 1σ errors.

Lens ids: our sheets use folder names ``slacs0008-0004``, Bolton ``J0008-0004``, Shajib
``SDSSJ0008-0004``; :func:`lens_key` maps each to ``J0008-0004``. Mock ids have no key.

Einstein radii: mgelens (as PyAutoGalaxy) stores θ_E^AG; lenstronomy's EPL and Bolton's
intermediate-axis radius are θ_E^LT = θ_E^AG · √q · (2/(1 + q))^{1/(γ−1)} (SPEC §3.3),
with q the mass axis ratio and γ the 3D slope (γ = 2: the SIE, factor 2√q/(1 + q)).

Slopes: :func:`slope_differences` sets our γ against Shajib's, in units of the two
errors combined.
"""

import logging
import math
import os
import re
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pandas as pd

from mgelens.search.posterior import SIGMA_PROBABILITY, weighted_quantile

logger = logging.getLogger(__name__)

BOLTON_FILE = "bolton2008_table5_sie.csv"
SHAJIB_FILE = "shajib2021_slacs_powerlaw_tdcosmo2020.csv"
PUBLISHED_COLUMNS = (
    "bolton_b_sie",
    "bolton_q_sie",
    "shajib_theta_e",
    "shajib_theta_e_lo",
    "shajib_theta_e_hi",
    "shajib_gamma",
    "shajib_gamma_lo",
    "shajib_gamma_hi",
)
"""Columns of :func:`published_values`: Bolton b_SIE (arcsec) and q_SIE; Shajib imaging-only
θ_E^LT (arcsec) and γ with their 1σ lower/upper errors (positive numbers)."""

_KEY = re.compile(r"(\d{4}[+-]\d{4})$")


def lens_key(lens: str) -> str | None:
    """``J<hhmm>±<ddmm>`` of a SLACS id in any of the three schemes, else ``None``."""
    match = _KEY.search(str(lens).strip())
    return None if match is None else f"J{match.group(1)}"


def einstein_radius_lt(theta_ag, axis_ratio, slope):
    """θ_E^LT (lenstronomy / intermediate axis) from θ_E^AG (SPEC §3.3); arrays broadcast."""
    q = np.asarray(axis_ratio, dtype=float)
    return (
        np.asarray(theta_ag, dtype=float)
        * np.sqrt(q)
        * (2.0 / (1.0 + q)) ** (1.0 / (np.asarray(slope, dtype=float) - 1.0))
    )


def einstein_radius_ag(theta_lt, axis_ratio, slope):
    """θ_E^AG from θ_E^LT: the inverse of :func:`einstein_radius_lt`."""
    return np.asarray(theta_lt, dtype=float) / einstein_radius_lt(1.0, axis_ratio, slope)


def read_bolton(folder: str | os.PathLike) -> pd.DataFrame:
    """Bolton 2008 Table 5 indexed by :func:`lens_key`: ``bolton_b_sie``, ``bolton_q_sie``."""
    table = pd.read_csv(Path(folder) / BOLTON_FILE)
    table.index = table["Name"].map(lens_key)
    return table.rename(columns={"bSIE": "bolton_b_sie", "qSIE": "bolton_q_sie"})[
        ["bolton_b_sie", "bolton_q_sie"]
    ]


def read_shajib(folder: str | os.PathLike) -> pd.DataFrame:
    """Shajib 2021 imaging-only rows (``flag_imaging == 1``) indexed by :func:`lens_key`."""
    table = pd.read_csv(Path(folder) / SHAJIB_FILE)
    table = table[table["flag_imaging"] == 1]
    table.index = table["name"].map(lens_key)
    names = {
        "theta_E": "shajib_theta_e",
        "theta_E_lo": "shajib_theta_e_lo",
        "theta_E_hi": "shajib_theta_e_hi",
        "gamma": "shajib_gamma",
        "gamma_lo": "shajib_gamma_lo",
        "gamma_hi": "shajib_gamma_hi",
    }
    return table.rename(columns=names)[list(names.values())].astype(float)


def published_values(lenses: Iterable[str], folder: str | os.PathLike | None) -> pd.DataFrame:
    """:data:`PUBLISHED_COLUMNS` for each lens id (index = the ids as given).

    NaN where a table has no row for a lens; all NaN, with a logged warning naming the
    folder, when ``folder`` is ``None`` or lacks the tables.
    """
    lenses = list(lenses)
    table = pd.DataFrame(math.nan, index=pd.Index(lenses, name="lens"), columns=PUBLISHED_COLUMNS)
    missing = (
        [BOLTON_FILE, SHAJIB_FILE]
        if folder is None
        else [f for f in (BOLTON_FILE, SHAJIB_FILE) if not (Path(folder) / f).is_file()]
    )
    if missing:
        logger.warning(
            "published lens models not found (%s in %s): their columns are NaN",
            ", ".join(missing),
            folder,
        )
        return table
    keys = [lens_key(lens) for lens in lenses]
    for reference in (read_bolton(folder), read_shajib(folder)):
        for lens, key in zip(lenses, keys, strict=True):
            if key in reference.index:
                table.loc[lens, reference.columns] = reference.loc[key].to_numpy(dtype=float)
    return table


def posterior_einstein_radius(samples: pd.DataFrame) -> dict[str, float]:
    """Median and 1σ (68.27 %) interval of θ_E^AG, θ_E^LT and γ from a phase's samples.

    θ_E^LT is converted sample by sample with each sample's q and γ, so its interval is the
    posterior's, not a propagated one.

    Parameters
    ----------
    samples : pandas.DataFrame
        ``samples.csv`` of an EPL phase: ``weight``, ``mass.einstein_radius``,
        ``mass.axis_ratio``, ``mass.slope`` (:mod:`mgelens.search.results`).

    Returns
    -------
    dict
        ``theta_e``, ``theta_e_lower``, ``theta_e_upper``, ``theta_e_lt``,
        ``theta_e_lt_lower``, ``theta_e_lt_upper``, ``slope``, ``slope_lower``,
        ``slope_upper`` (interval bounds, not errors).

    Raises
    ------
    KeyError
        If a column is missing (not an EPL phase).
    """
    p = SIGMA_PROBABILITY[1]
    quantiles = [0.5, (1.0 - p) / 2.0, (1.0 + p) / 2.0]
    weights = samples["weight"].to_numpy(dtype=float)
    theta = samples["mass.einstein_radius"].to_numpy(dtype=float)
    slope = samples["mass.slope"].to_numpy(dtype=float)
    columns = {
        "theta_e": theta,
        "theta_e_lt": einstein_radius_lt(theta, samples["mass.axis_ratio"], slope),
        "slope": slope,
    }
    values = {}
    for name, column in columns.items():
        median, lower, upper = weighted_quantile(column, weights, quantiles)
        values.update({name: median, f"{name}_lower": lower, f"{name}_upper": upper})
    return {k: float(v) for k, v in values.items()}


def slope_through_origin(x, y) -> tuple[float, float, int]:
    """Least-squares slope a of y = a·x over the finite pairs, its standard error from the
    scatter about the line, and the number of pairs (NaN slope with no pair, NaN error
    with one)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    finite = np.isfinite(x) & np.isfinite(y)
    x, y = x[finite], y[finite]
    n = int(x.size)
    if n == 0 or not np.any(x != 0):
        return math.nan, math.nan, n
    slope = float(np.sum(x * y) / np.sum(x * x))
    if n < 2:
        return slope, math.nan, n
    scatter = np.sum((y - slope * x) ** 2) / (n - 1)
    return slope, float(np.sqrt(scatter / np.sum(x * x))), n


def slope_text(slope: float, error: float, n: int) -> str:
    """``"a = 0.875 ± 0.080 (5 lenses)"``; without ``±`` when the error is undefined
    (one lens), ``"1 lens"`` in the singular."""
    spread = f" ± {error:.3f}" if math.isfinite(error) else ""
    return f"a = {slope:.3f}{spread} ({n} {'lens' if n == 1 else 'lenses'})"


SLOPE_TENSION = 3.0
"""Combined 1σ errors beyond which our γ and Shajib's are named as differing."""


def slope_differences(table: pd.DataFrame) -> pd.DataFrame:
    """Our MASS γ against Shajib et al. 2021's imaging-only γ, per lens of a sample table
    with both (columns ``slope``, ``slope_err_lo``/``_err_hi``, ``shajib_gamma``,
    ``shajib_gamma_err_lo``/``_err_hi``).

    Returns ``lens``, ``difference`` (ours − Shajib's), ``sigma`` (the errors that face
    each other, added in quadrature: our upper and their lower error when ours is below,
    our lower and their upper one when above) and ``tension`` (|difference| / sigma >
    :data:`SLOPE_TENSION`), indexed as those lenses' rows of ``table``.
    """
    rows = table[np.isfinite(table["slope"]) & np.isfinite(table["shajib_gamma"])]
    difference = (rows["slope"] - rows["shajib_gamma"]).to_numpy(float)
    below = difference < 0
    ours = np.where(below, rows["slope_err_hi"], rows["slope_err_lo"]).astype(float)
    theirs = np.where(below, rows["shajib_gamma_err_lo"], rows["shajib_gamma_err_hi"]).astype(float)
    sigma = np.hypot(ours, theirs)
    return pd.DataFrame(
        {
            "lens": rows["lens"].to_numpy(),
            "difference": difference,
            "sigma": sigma,
            "tension": np.abs(difference) > SLOPE_TENSION * sigma,
        },
        index=rows.index,
    )

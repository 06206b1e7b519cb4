"""The paper's mock comparison (its Section 4, Table 3 and Figures 5–7; SPEC §11).

Fits of the mocks M1–M3 with three lens-light models, each a lens row of one sample:

* ``nn_mge``: the MGE with every linear unknown non-negative (the paper's method);
* ``pn_mge``: the same MGE solved without that constraint;
* ``sersic``: 3 Sérsics (2 in SP), unconstrained.

From each fit's recovery record (``mgelens recovery``: the MASS posterior against
``truth.json``, the light split per annulus) this module builds Table 3, one row per fit
and EPL parameter, next to the paper's values, and the per-annulus table of the lens-light
and total-light errors.
"""

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

PAPER_MOCKS = ("M1", "M2", "M3")
"""The paper's mocks (SPEC §10)."""
MODELS = ("nn_mge", "pn_mge", "sersic")
"""Lens-light models of the comparison, in the paper's order."""
MODEL_LABELS = {"nn_mge": "nn-MGE", "pn_mge": "pn-MGE", "sersic": "3×Sérsic"}
PARAMETERS = {
    "centre_x": "mass.centre_x",
    "centre_y": "mass.centre_y",
    "einstein_radius": "mass.einstein_radius",
    "axis_ratio": "mass.axis_ratio",
    "angle": "mass.angle",
    "slope": "mass.slope",
}
"""Table 3's parameters (arcsec, arcsec, arcsec in the AG convention, –, degrees, –) and
their names in the phases' posteriors."""
COLUMNS = (
    "lens",
    "mock",
    "model",
    "parameter",
    "truth",
    "median",
    "lower_3sigma",
    "upper_3sigma",
    "within_3sigma",
)
"""Columns of :func:`mock_table` (``lens`` tells apart two fits of one mock and model)."""

_PAPER_ROWS = {
    ("M1", "nn_mge"): ((0.014, 0.010, 0.018), (-0.068, -0.072, -0.065), (1.198, 1.178, 1.218),
                       (0.80, 0.77, 0.83), (45.6, 43.1, 47.9), (2.08, 1.92, 2.23)),
    ("M2", "nn_mge"): ((0.047, 0.044, 0.051), (0.017, 0.014, 0.019), (1.006, 0.990, 1.023),
                       (0.77, 0.74, 0.80), (59.6, 58.0, 61.1), (1.94, 1.83, 2.05)),
    ("M3", "nn_mge"): ((-0.003, -0.005, 0.000), (-0.033, -0.035, -0.031), (1.101, 1.088, 1.124),
                       (0.75, 0.72, 0.77), (31.2, 30.2, 32.5), (2.01, 1.94, 2.15)),
    ("M1", "pn_mge"): ((0.015, 0.010, 0.018), (-0.068, -0.072, -0.065), (1.199, 1.178, 1.222),
                       (0.80, 0.76, 0.82), (46.1, 43.4, 47.6), (2.08, 1.91, 2.25)),
    ("M2", "pn_mge"): ((0.047, 0.044, 0.051), (0.015, 0.012, 0.018), (1.013, 0.995, 1.032),
                       (0.76, 0.73, 0.79), (59.2, 57.3, 60.6), (1.99, 1.86, 2.13)),
    ("M3", "pn_mge"): ((-0.000, -0.004, 0.003), (-0.030, -0.032, -0.027), (1.108, 1.089, 1.136),
                       (0.74, 0.70, 0.77), (32.6, 29.1, 33.7), (2.04, 1.92, 2.20)),
    ("M1", "sersic"): ((0.013, 0.009, 0.017), (-0.067, -0.072, -0.064), (1.184, 1.177, 1.193),
                       (0.80, 0.78, 0.82), (46.0, 43.6, 47.5), (1.96, 1.91, 2.02)),
    ("M2", "sersic"): ((0.026, 0.022, 0.035), (0.010, 0.006, 0.023), (1.05, 0.99, 1.09),
                       (0.71, 0.68, 0.98), (-4.2, -17.7, 9.5), (2.72, 2.61, 2.82)),
    ("M3", "sersic"): ((-0.006, -0.009, -0.003), (-0.032, -0.034, -0.030), (1.14, 1.12, 1.15),
                       (0.73, 0.69, 0.74), (32.1, 30.1, 33.4), (2.27, 2.18, 2.36)),
}  # fmt: skip
PAPER_TABLE_3: Mapping[tuple[str, str], Mapping[str, tuple[float, float, float]]] = {
    key: dict(zip(PARAMETERS, values, strict=True)) for key, values in _PAPER_ROWS.items()
}
"""The paper's Table 3 (SPEC §11): (mock, model) → parameter → (median, lower, upper 3σ)."""


def mock_table(fits: Sequence[Mapping]) -> pd.DataFrame:
    """Table 3 of the fits: one row per fit and parameter of :data:`PARAMETERS` that the
    fit's MASS phase sampled, with the columns of :data:`COLUMNS`.

    Parameters
    ----------
    fits : sequence of mapping
        Each with ``lens``, ``mock`` (M1, M2, M3), ``model`` (a key of :data:`MODELS`) and
        ``recovery``, the fit's recovery record (``mgelens recovery``).

    Raises
    ------
    ValueError
        For an unknown model.
    """
    rows = []
    for entry in fits:
        if entry["model"] not in MODELS:
            raise ValueError(f"{entry['lens']}: unknown model {entry['model']!r}, one of {MODELS}")
        by_name = {row["name"]: row for row in entry["recovery"]["mass"]}
        for parameter, name in PARAMETERS.items():
            if name not in by_name:
                continue
            row = by_name[name]
            rows.append(
                {
                    "lens": entry["lens"],
                    "mock": entry["mock"],
                    "model": entry["model"],
                    "parameter": parameter,
                    "truth": row["truth"],
                    "median": row["median"],
                    "lower_3sigma": row["lower_3sigma"],
                    "upper_3sigma": row["upper_3sigma"],
                    "within_3sigma": bool(row["within_3sigma"]),
                }
            )
    return pd.DataFrame(rows, columns=list(COLUMNS))


def _cell(median: float, lower: float, upper: float, digits: int, missed: bool) -> str:
    text = f"{median:.{digits}f} ({lower:.{digits}f}, {upper:.{digits}f})"
    return f"**{text}** ✗" if missed else text


_DIGITS = {
    "centre_x": 3,
    "centre_y": 3,
    "einstein_radius": 3,
    "axis_ratio": 2,
    "angle": 1,
    "slope": 2,
}


def markdown_table(table: pd.DataFrame) -> str:
    """Table 3 as markdown: per mock, model and lens, the truth row once per mock, our
    median (3σ interval) with values whose truth lies outside marked ✗ in bold, and the
    paper's row beneath ours (SPEC §11)."""
    header = "| mock | fit | " + " | ".join(PARAMETERS) + " |"
    lines = [header, "|" + "---|" * (len(PARAMETERS) + 2)]
    order = {model: k for k, model in enumerate(MODELS)}
    fits = table.drop_duplicates(["mock", "model", "lens"])[["mock", "model", "lens"]]
    fits = fits.assign(rank=fits["model"].map(order)).sort_values(["mock", "rank", "lens"])
    for mock, group in fits.groupby("mock", sort=True):
        truth = table[table["mock"] == mock].drop_duplicates("parameter").set_index("parameter")
        cells = [
            f"{truth.loc[p, 'truth']:.{_DIGITS[p]}f}" if p in truth.index else ""
            for p in PARAMETERS
        ]
        lines.append(f"| {mock} | truth | " + " | ".join(cells) + " |")
        for _, fit in group.iterrows():
            rows = table[table["lens"] == fit["lens"]].set_index("parameter")
            cells = [
                _cell(
                    rows.loc[p, "median"],
                    rows.loc[p, "lower_3sigma"],
                    rows.loc[p, "upper_3sigma"],
                    _DIGITS[p],
                    not rows.loc[p, "within_3sigma"],
                )
                if p in rows.index
                else ""
                for p in PARAMETERS
            ]
            label = f"{MODEL_LABELS[fit['model']]} ({fit['lens']})"
            lines.append(f"| {mock} | {label} | " + " | ".join(cells) + " |")
            paper = PAPER_TABLE_3.get((mock, fit["model"]))
            if paper is not None:
                cells = [_cell(*paper[p], _DIGITS[p], False) for p in PARAMETERS]
                lines.append(
                    f"| {mock} | paper {MODEL_LABELS[fit['model']]} | " + " | ".join(cells) + " |"
                )
    return "\n".join(lines) + "\n"


def annulus_table(fits: Sequence[Mapping]) -> pd.DataFrame:
    """The light split of every fit per annulus (``mgelens recovery``'s ``light_split``):
    ``lens, mock, model, inner_radius, outer_radius`` (arcsec), ``lens_light_error``,
    ``lensed_source_error`` and ``total_error`` (Σ(model − true) over the annulus's pixels
    as a fraction of the Σ of the true lens light there)."""
    rows = []
    for entry in fits:
        for annulus in entry["recovery"].get("light_split") or []:
            rows.append(
                {
                    "lens": entry["lens"],
                    "mock": entry["mock"],
                    "model": entry["model"],
                    **{
                        key: annulus[key]
                        for key in (
                            "inner_radius",
                            "outer_radius",
                            "lens_light_error",
                            "lensed_source_error",
                            "total_error",
                        )
                    },
                }
            )
    return pd.DataFrame(rows)


def relative_difference(model: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(model − truth)/truth inside the fit (``mask`` True where excluded; NaN there and
    where the truth is not positive)."""
    out = np.full(truth.shape, np.nan)
    used = ~mask & (truth > 0)
    out[used] = (model[used] - truth[used]) / truth[used]
    return out

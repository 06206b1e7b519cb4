"""Sample summary: per-lens isophote summaries, fits and quality flags in one table.

A per-lens summary is the JSON written by ``mgelens isophotes --summary`` (built by
:func:`lens_summary`)::

    {
      "lens": "J0252+0039",
      "mgelens_version": "...", "conventions": "...",
      "statistics": {"delta_q_max": ..., "delta_pa_max": ..., "a4_a_extreme": ...,
                     "n_isophotes": ..., "n_isophotes_pa": ...,
                     "a4_a_source_share": ... or null, "sma_min": 0.5,
                     "sma_max": 2.5, "round_axis_ratio": 0.95},
      "mass": null or {"axis_ratio": ..., "angle": ..., "critical_curve_axis_ratio": ...,
                       "critical_curve_angle": ..., "critical_curve_einstein_radius": ...,
                       ...},
      "inputs": {...}
    }

Statistics are those of :class:`mgelens.isophotes.IsophoteStatistics` (Δq_max, ΔPA_max in
degrees, the extreme a₄/a with its sign; JSON ``null`` = undefined). A lens is
"complex" (paper, SPEC §11) when Δq_max > 0.1 or ΔPA_max > 10°.

:func:`lens_table` adds, from the files next to each summary (``<lens folder>/mass/``
``result.json`` and ``samples.csv``, and ``<lens folder>/quality.json`` of
``mgelens quality``), the lens model and its comparison with published models
(:mod:`mgelens.published`). Columns of the sample table (``results/summary/lenses.csv``):

==============================  ==============================================================
column                          meaning
==============================  ==============================================================
lens                            lens id (folder name)
delta_q_max                     largest minus smallest isophote q over 0.5″–2.5″
delta_pa_max                    ΔPA_max, degrees (NaN if all isophotes are round)
a4_a_extreme                    a₄/a of largest modulus, signed (> 0 disky)
a4_a_source_share               lensed-source / lens-light model around the isophote of
                                a4_a_extreme (:mod:`mgelens.source_share`; NaN for a
                                summary of an image, not of a phase)
n_isophotes, n_isophotes_pa     isophotes measured; of them, not round (used for ΔPA)
abs_a4_a_max                    |a4_a_extreme|
complex                         Δq_max > 0.1 or ΔPA_max > 10°
mass_axis_ratio, mass_angle     MASS EPL q and φ (degrees CCW from +x)
mass_critical_curve_*           tangential critical curve: q, angle (deg), θ_eff (arcsec)
source                          the isophote summary file
light_model                     MASS lens light: "X<n>" n MGE sets, "+point" with the point
                                set; "<n>xSersic" for Sérsics
light_chosen_by                 ``evidence`` (LIGHT candidates compared, ``model_choice.json``
                                next to the summary) or ``sheet`` (the sheet pins the model)
light_evidence_margin           ln Z of the chosen candidate minus the highest ln Z of the
                                others (NaN when pinned; negative when a simpler model
                                within the threshold was taken; a lower bound where the
                                others' ln Z are upper bounds, ``light_models.csv``)
source_pixels                   k-means source pixels of MASS's meshes
source_pixels_chosen_by         ``evidence`` (SPix2 fitted per count of a
                                ``slam.source_pixels`` list,
                                ``source_pixels_choice.json`` next to the summary) or
                                ``config`` (one count set)
theta_e                         θ_E^AG (arcsec), MASS posterior median
theta_e_err_lo, theta_e_err_hi  its 1σ (68.27 %) errors: median − lower, upper − median
theta_e_lt                      θ_E^LT = θ_E^AG √q (2/(1+q))^{1/(γ−1)}, arcsec (SPEC §3.3),
                                median of the per-sample conversion
theta_e_lt_err_lo, _err_hi      its 1σ errors
slope, slope_err_lo, _err_hi    EPL γ, median and 1σ errors
bolton_b_sie                    Bolton et al. 2008 SIE b (arcsec, intermediate axis)
theta_e_over_bolton             theta_e_lt / bolton_b_sie
shajib_theta_e                  Shajib et al. 2021 imaging-only power-law θ_E (arcsec, LT)
shajib_theta_e_err_lo, _err_hi  its 1σ errors
shajib_gamma                    its slope γ
shajib_gamma_err_lo, _err_hi    its 1σ errors
theta_e_over_shajib             theta_e_lt / shajib_theta_e
quality_statistic               coherence significance K of :mod:`mgelens.quality`
quality_peak                    largest block |z| / τ
quality_flag                    K or the peak above its threshold (empty: not measured)
quality_noise_scale_from        where its noise scale τ came from: ``residuals`` (the
                                judged blocks), ``sky`` (beyond the fit circle, when the
                                lensed source leaves too few blocks) or empty
lensing_flag                    the MASS model has no closed, galaxy-like tangential critical
                                curve around the lens light in the fit circle
                                (:func:`mgelens.quality.lensing_check`), or its centre lies
                                more than 0.1″ from the lens light's
mass_light_offset               distance of the MASS model's mass centre from the lens-light
                                centre (arcsec)
multiply_imaged_fraction        share of the lensed source's signal, Σ (LENSED/σ)², that is
                                multiply imaged under the MASS model
                                (:func:`mgelens.image_multiplicity.multiplicity_check`; NaN
                                in quality records written before it)
singly_imaged_flag              that share is below one half: θ_E rests mostly on the shape
                                of single arcs (empty where not measured)
mass_converged                  MASS's ``result.json`` says ``converged``: every source mesh's
                                run met its stopping rule and held its peak after the
                                restarts (a run the peak check still beats is recorded as not
                                converged; ``allow_unconverged`` let the chain go on)
mass_peak_gain                  the largest gain in ln L + ln prior that the peak check's
                                local search found above the best sample of a MASS mesh's
                                final run (:mod:`mgelens.search.peak_check`; NaN where the
                                sampler has no check)
prior_edge                      the MASS parameters whose 3σ interval the prior cuts
                                (:func:`mgelens.search.results.prior_edges`, e.g.
                                ``mass.slope at its lower bound 1.5``; ``none``; empty in
                                records without their parameter space)
==============================  ==============================================================

Published columns are NaN for lenses absent from a table, and all NaN (with a logged
warning) when the reference folder is absent.

:func:`light_model_table` lists every LIGHT candidate of the lenses whose model was
chosen by evidence (``results/summary/light_models.csv``), one row per lens and
candidate: :data:`LIGHT_MODEL_COLUMNS`, with ``log_evidence`` the sampler's ln Z (where
``bounded``, an upper bound of it: the candidate could not win and was not sampled,
:mod:`mgelens.pipeline.light_bound`) and ``chi_squared``, ``n_linear`` (lens-light
amplitudes + source pixels) and ``n_free`` those of the candidate's fit
(:class:`mgelens.pipeline.model_choice.Candidate`).
"""

import json
import logging
import math
import os
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pandas as pd

from mgelens import CONVENTIONS_VERSION, __version__
from mgelens.isophotes import IsophoteStatistics, MassShape
from mgelens.pipeline import pixel_choice
from mgelens.pipeline.model_choice import CHOICE_FILE, holds_choice
from mgelens.pipeline.records import (
    PhaseInputError,
    fit_record_of,
    light_components,
    read_result_record,
)
from mgelens.published import posterior_einstein_radius, published_values
from mgelens.search.results import NO_PRIOR_EDGE, RESULT_FILE, SAMPLES_FILE, prior_edges

logger = logging.getLogger(__name__)

DELTA_Q_THRESHOLD = 0.1
DELTA_PA_THRESHOLD = 10.0
"""Degrees."""

STATISTICS_COLUMNS = ("delta_q_max", "delta_pa_max", "a4_a_extreme")
OPTIONAL_STATISTICS_COLUMNS = ("a4_a_source_share",)
"""Statistics a summary may lack (NaN then): written only for a phase's lens light."""
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
    *OPTIONAL_STATISTICS_COLUMNS,
    *COUNT_COLUMNS,
    *_DERIVED_COLUMNS,
    *(f"mass_{name}" for name in MASS_COLUMNS),
    "source",
)
"""Columns of :func:`sample_table` (mass columns NaN when a summary has no mass model)."""
FIT_COLUMNS = (
    "light_model",
    "light_chosen_by",
    "light_evidence_margin",
    "source_pixels",
    "source_pixels_chosen_by",
    *(f"{name}{suffix}" for name in ("theta_e", "theta_e_lt", "slope")
      for suffix in ("", "_err_lo", "_err_hi")),
    "bolton_b_sie",
    "theta_e_over_bolton",
    "shajib_theta_e",
    "shajib_theta_e_err_lo",
    "shajib_theta_e_err_hi",
    "shajib_gamma",
    "shajib_gamma_err_lo",
    "shajib_gamma_err_hi",
    "theta_e_over_shajib",
    "quality_statistic",
    "quality_peak",
    "quality_flag",
    "quality_noise_scale_from",
    "lensing_flag",
    "mass_light_offset",
    "multiply_imaged_fraction",
    "singly_imaged_flag",
    "mass_converged",
    "mass_peak_gain",
    "prior_edge",
)  # fmt: skip
"""Columns :func:`lens_table` adds to :data:`TABLE_COLUMNS`."""
QUALITY_FILE = "quality.json"
MASS_PHASE = "mass"
LIGHT_MODEL_COLUMNS = (
    "lens",
    "candidate",
    "log_evidence",
    "log_evidence_error",
    "chi_squared",
    "n_linear",
    "n_free",
    "converged",
    "bounded",
    "chosen",
)
"""Columns of :func:`light_model_table`."""


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
        row.update({name: _number(statistics.get(name)) for name in OPTIONAL_STATISTICS_COLUMNS})
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


def light_model_label(record: dict) -> str:
    """ "X<n>" (+ "+point") for n MGE sets (and the point set), "<n>xSersic" for Sérsics,
    from a phase's ``max_likelihood_fit`` record."""
    components = light_components(record)
    sersics = [c for c in components if c["kind"] == "sersic"]
    if sersics:
        return f"{len(sersics)}xSersic"
    point = any(c.get("name") == "point" for c in components)
    extended = len(components) - point
    return f"X{extended}" + ("+point" if point else "")


def read_model_choice(lens_folder: Path) -> dict | None:
    """The lens folder's ``model_choice.json``; None if its LIGHT model is pinned: no such
    file, or one that ``light/`` no longer follows (:func:`holds_choice`; a warning is
    logged).

    Raises
    ------
    ValueError
        If the record is not JSON or lacks ``chosen`` or ``candidates``.
    """
    path = lens_folder / CHOICE_FILE
    if not path.is_file():
        return None
    try:
        record = json.loads(path.read_text())
        chosen = record["chosen"]
        labels = [c["label"] for c in record["candidates"]]
    except (json.JSONDecodeError, KeyError, TypeError) as exc:
        raise ValueError(
            f"{path}: not a model-choice record ({exc!r}); rerun choose_light"
        ) from exc
    if chosen not in labels:
        raise ValueError(f"{path}: chosen {chosen!r} is not one of its candidates {labels}")
    if not holds_choice(lens_folder, chosen):
        logger.warning(
            "%s: ignored, light/ does not hold its chosen candidate %s (the sheet pins the "
            "model since); delete it",
            path,
            chosen,
        )
        return None
    return record


def _choice_columns(lens_folder: Path, mass_record: dict) -> dict:
    """``light_chosen_by`` and ``light_evidence_margin`` of one lens; checks that MASS ran
    on the chosen candidate's light."""
    choice = read_model_choice(lens_folder)
    if choice is None:
        return {"light_chosen_by": "sheet", "light_evidence_margin": math.nan}
    fitted = light_model_label(mass_record)
    if fitted != choice["chosen"]:
        raise ValueError(
            f"{lens_folder}: MASS fitted {fitted} but {CHOICE_FILE} chose {choice['chosen']}; "
            "rerun choose_light and MASS"
        )
    evidence = {c["label"]: float(c["log_evidence"]) for c in choice["candidates"]}
    chosen = evidence.pop(choice["chosen"])
    margin = chosen - max(evidence.values()) if evidence else math.nan
    return {"light_chosen_by": "evidence", "light_evidence_margin": margin}


def light_model_table(lens_folders: Iterable[tuple[str, str | os.PathLike]]) -> pd.DataFrame:
    """Every LIGHT candidate of the ``(lens, results folder)`` pairs whose model was chosen
    by evidence, one row each (:data:`LIGHT_MODEL_COLUMNS`; module docstring).

    Raises
    ------
    ValueError
        As :func:`read_model_choice`.
    """
    rows = []
    for lens, folder in lens_folders:
        choice = read_model_choice(Path(folder))
        if choice is None:
            continue
        for candidate in choice["candidates"]:
            rows.append(
                {
                    "lens": lens,
                    "candidate": candidate["label"],
                    **{name: candidate[name] for name in LIGHT_MODEL_COLUMNS[2:-2]},
                    "bounded": candidate.get("bounded", False),
                    "chosen": candidate["label"] == choice["chosen"],
                }
            )
    return pd.DataFrame(rows, columns=list(LIGHT_MODEL_COLUMNS))


def _fit_row(lens_folder: Path) -> dict:
    """The fit columns of one lens (not the published ones)."""
    mass = lens_folder / MASS_PHASE
    try:
        result = read_result_record(mass)
        record = fit_record_of(result, mass / RESULT_FILE)
        posterior = posterior_einstein_radius(pd.read_csv(mass / SAMPLES_FILE))
        quality = json.loads((lens_folder / QUALITY_FILE).read_text())
        row = {"light_model": light_model_label(record), **_choice_columns(lens_folder, record)}
        row["source_pixels"] = int(record["source"]["n_pixels"])
        held = pixel_choice.holds_choice(lens_folder) is not None
        row["source_pixels_chosen_by"] = "evidence" if held else "config"
        for name in ("theta_e", "theta_e_lt", "slope"):
            median = posterior[name]
            row[name] = median
            row[f"{name}_err_lo"] = median - posterior[f"{name}_lower"]
            row[f"{name}_err_hi"] = posterior[f"{name}_upper"] - median
        row["quality_statistic"] = _number(quality["significance"])
        row["quality_peak"] = _number(quality["peak"])
        row["quality_flag"] = bool(quality["flag"]) if quality["measured"] else pd.NA
        # records written before the sky's τ existed took τ from the residuals
        measured_from = "residuals" if quality["measured"] else ""
        row["quality_noise_scale_from"] = quality.get("noise_scale_from", measured_from)
        row["lensing_flag"] = bool(quality["lensing"]["flag"])
        row["mass_light_offset"] = _number(quality["lensing"]["centre_offset"])
        row.update(_multiplicity_columns(quality))
        row["mass_converged"] = bool(result["converged"])
        row["mass_peak_gain"] = _number(result.get("sampler", {}).get("peak_gain"))
        row["prior_edge"] = (
            ("; ".join(prior_edges(result)) or NO_PRIOR_EDGE)
            if "parameter_space" in result
            else pd.NA
        )
    except FileNotFoundError as exc:
        raise ValueError(f"{lens_folder}: {exc.filename} not found") from exc
    except PhaseInputError as exc:
        raise ValueError(f"{lens_folder}: {exc}") from exc
    except (json.JSONDecodeError, KeyError, TypeError) as exc:
        raise ValueError(
            f"{lens_folder}: incomplete MASS result or quality record ({exc!r})"
        ) from exc
    return row


def _multiplicity_columns(quality: dict) -> dict:
    """``multiply_imaged_fraction`` and ``singly_imaged_flag`` of a quality record (NaN
    and NA for records written before the check, or without lensed pixels above the
    noise)."""
    check = quality.get("multiplicity") or {}
    fraction = check.get("multiply_imaged_fraction")
    return {
        "multiply_imaged_fraction": _number(fraction),
        "singly_imaged_flag": pd.NA if fraction is None else bool(check["flag"]),
    }


def lens_table(
    paths: Iterable[str | os.PathLike],
    reference_dir: str | os.PathLike | None,
    delta_q_threshold: float = DELTA_Q_THRESHOLD,
    delta_pa_threshold: float = DELTA_PA_THRESHOLD,
) -> pd.DataFrame:
    """:func:`sample_table` plus :data:`FIT_COLUMNS` (module docstring).

    Each summary's folder (``results/<lens>/``) must hold ``mass/result.json``,
    ``mass/samples.csv`` and ``quality.json``; published values come from
    ``reference_dir`` (:func:`mgelens.published.published_values`).

    Raises
    ------
    ValueError
        As :func:`sample_table`, or naming a lens folder whose fit files are missing.
    """
    table = sample_table(paths, delta_q_threshold, delta_pa_threshold)
    fits = pd.DataFrame(
        [_fit_row(Path(source).parent) for source in table["source"]], index=table.index
    )
    published = published_values(table["lens"], reference_dir).reset_index(drop=True)
    fits["bolton_b_sie"] = published["bolton_b_sie"]
    fits["theta_e_over_bolton"] = fits["theta_e_lt"] / published["bolton_b_sie"]
    fits["shajib_theta_e"] = published["shajib_theta_e"]
    fits["shajib_theta_e_err_lo"] = published["shajib_theta_e_lo"]
    fits["shajib_theta_e_err_hi"] = published["shajib_theta_e_hi"]
    fits["shajib_gamma"] = published["shajib_gamma"]
    fits["shajib_gamma_err_lo"] = published["shajib_gamma_lo"]
    fits["shajib_gamma_err_hi"] = published["shajib_gamma_hi"]
    fits["theta_e_over_shajib"] = fits["theta_e_lt"] / published["shajib_theta_e"]
    fits["quality_flag"] = fits["quality_flag"].astype("boolean")
    fits["singly_imaged_flag"] = fits["singly_imaged_flag"].astype("boolean")
    fits["mass_converged"] = fits["mass_converged"].astype("boolean")
    return pd.concat([table, fits[list(FIT_COLUMNS)]], axis=1)

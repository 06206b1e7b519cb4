"""The record of a phase's maximum-likelihood model in ``result.json``: its one writer
(:func:`fit_record`) and its readers, used by the next phases and by every analysis
(isophotes, recovery, fit quality, the sample summary).

``result.json`` holds the sampler's summary (:class:`~mgelens.search.results.PhaseResult`)
and the block ``max_likelihood_fit``:

* ``lens_light.components``: each component with its name, ``kind`` ("mge" or "sersic"),
  centre (arcsec), ell_comps, axis ratio, angle (degrees CCW from +x) and, for an MGE set,
  σ (minor-axis, arcsec) and solved intensities I₀ (data units per pixel), for a Sérsic
  R_e (arcsec), n and I_e (data units per pixel; ``fixed`` if an earlier phase set it);
* ``mass``: each profile's record (``to_dict`` of :mod:`mgelens.mass`);
* ``source``: the source description with its hyper-parameters (and, for SP's source
  MGE, its solved intensities);
* figures of merit: ln L, ln ε, χ², image pixels, the solve and its active bounds.
"""

import dataclasses
import json
from pathlib import Path

import numpy as np

from mgelens.fit import FitResult
from mgelens.light import Sersic, light_from_dict
from mgelens.mass import mass_from_dict
from mgelens.pipeline import models
from mgelens.pipeline.settings import (
    FIT_KEYS,
    LENS_KEYS,
    LensSpec,
    SlamSettings,
    settings_from_mapping,
)
from mgelens.search.results import RESULT_FILE

MODEL_FILE = "model.fits"
"""A phase folder's images of its maximum-likelihood model (:mod:`mgelens.pipeline.products`)."""
ADAPT_IMAGE_FILE = "adapt_image.fits"
"""SPix1's adapt image, read by the adaptive regularization of later phases."""


class PhaseInputError(ValueError):
    """A phase's inputs are missing or inconsistent; the message names the file and fix."""


def _light_record(component, intensities: np.ndarray) -> dict:
    """A lens-light component's record with its solved intensities."""
    if isinstance(component, Sersic):
        return dataclasses.replace(component, intensity=float(intensities[0])).to_dict()
    return component.to_dict(intensities)


def fit_record(result: FitResult, model: models.PhaseModel, values: dict) -> dict:
    """The ``max_likelihood_fit`` block of ``result.json``.

    Lens-light components, each with its name, ``kind`` ("mge" or "sersic"), centre
    (arcsec), ell_comps, axis ratio, angle (degrees CCW from +x) and, for an MGE set, σ
    (minor-axis, arcsec) and solved intensities I₀ (data units per pixel), for a Sérsic
    R_e (arcsec), n and I_e (data units per pixel; ``fixed`` if an earlier phase set it);
    mass profiles; source description with its hyper-parameters (and, for the SP source
    MGE, its solved intensities); figures of merit; with a lens-light prior
    (:mod:`mgelens.light_prior`) its λ and evidence terms under ``lens_light_prior``.
    """
    components, start = [], 0
    intensities = result.lens_light_intensities
    for spec, component in zip(model.lens_light, result.model.lens_light, strict=True):
        solved = intensities[start : start + component.n_columns]
        components.append({"name": spec.name, **_light_record(component, solved)})
        start += component.n_columns
    for k, profile in enumerate(result.model.fixed_light):
        record = _light_record(profile, np.array([profile.intensity]))
        components.append({"name": f"{record['kind']}_{k}", **record, "fixed": True})
    source = model.source.describe()
    source["parameters"] = {
        k: v for k, v in values.items() if k.split(".")[0] in ("source", "mesh", "regularization")
    }
    if result.n_source_light:
        source["intensities"] = result.source_light_intensities.tolist()
    prior = {}
    if result.lens_light_prior is not None:
        terms = result.lens_light_prior
        prior["lens_light_prior"] = {
            "kind": "smoothness",
            "coefficient": result.model.lens_light_prior.coefficient,
            "penalty": terms.penalty,
            "log_det_curvature": terms.log_det_curvature,
            "log_det_prior": terms.log_det_prior,
        }
    return {
        "log_likelihood": result.log_likelihood,
        "log_evidence": result.log_evidence,
        "chi_squared": result.chi_squared,
        "n_image_pixels": int(result.dataset.data.size),
        "positive_only": result.solution.positive_only,
        "n_active_zero": int(result.solution.active_zero.sum()),
        "lens_light": {"components": components},
        "mass": [profile.to_dict() for profile in result.model.mass],
        "source": source,
        **prior,
    }


def read_result_record(result_folder: str | Path) -> dict:
    """A phase folder's whole ``result.json`` (settings, fit record, sampler summary),
    without its samples."""
    path = Path(result_folder) / RESULT_FILE
    if not path.is_file():
        raise PhaseInputError(f"{path} not found: run the phase first")
    return json.loads(path.read_text())


def read_fit_record(result_folder: str | Path) -> dict:
    """The ``max_likelihood_fit`` block of a phase folder's ``result.json``."""
    return fit_record_of(read_result_record(result_folder), Path(result_folder) / RESULT_FILE)


def fit_record_of(result: dict, path: Path) -> dict:
    """The ``max_likelihood_fit`` block of a ``result.json`` read from ``path``."""
    record = result.get("max_likelihood_fit")
    if record is None:
        raise PhaseInputError(f"{path} has no max_likelihood_fit block")
    return record


def light_components(record: dict) -> list[dict]:
    """The lens-light component entries of a ``max_likelihood_fit`` record.

    Records written before the 3×Sérsic option list MGE sets under ``sets``; they are
    read as components of kind "mge".
    """
    light = record["lens_light"]
    if "components" in light:
        return light["components"]
    return [{"kind": "mge", **entry} for entry in light["sets"]]


def profiles_from_record(record: dict) -> tuple:
    """Lens-light profiles with their intensities from a ``max_likelihood_fit`` record
    (see :func:`lens_light_profiles`)."""
    return tuple(profile for c in light_components(record) for profile in light_from_dict(c))


def lens_light_profiles(result_folder: str | Path) -> tuple:
    """The maximum-likelihood lens light of a phase folder, from its ``result.json``.

    Returns
    -------
    tuple of Gaussian and Sersic
        Every Gaussian of every MGE set and every Sérsic (fixed ones included) with its
        solved intensity, first component first; the light before the PSF is the sum of
        their ``image(x, y)`` (data units per pixel).
    """
    return profiles_from_record(read_fit_record(result_folder))


def mass_model(result_folder: str | Path) -> tuple:
    """The maximum-likelihood mass profiles (SIE or EPL, ExternalShear) of a phase folder."""
    return masses_from_record(read_fit_record(result_folder))


def masses_from_record(record: dict) -> tuple:
    """The mass profiles of a ``max_likelihood_fit`` record."""
    return tuple(mass_from_dict(entry) for entry in record["mass"])


def recorded_settings(settings: dict) -> tuple[SlamSettings, LensSpec]:
    """The chain's settings and the lens spec a phase ran with, from the ``settings``
    record of its ``result.json`` (:attr:`~mgelens.search.results.PhaseResult.settings`).

    Results written before the fit settings nested under ``slam.fit`` and the per-lens
    values moved to ``lens`` (their ``slam`` record is flat, with ``mask_radius``,
    ``mask_centre``, ``pixel_scale``, ``mge_sets`` and ``point_set``, and no ``lens``)
    are read too: their keys are sorted into the same two records.
    """
    slam, lens = _sorted_record(settings)
    chain = settings_from_mapping(slam, slam.pop("profile"), origin=RESULT_FILE)
    return chain, lens


def recorded_lens(settings: dict) -> LensSpec:
    """The lens spec of a phase's ``settings`` record (see :func:`recorded_settings`)."""
    return _sorted_record(settings)[1]


def _sorted_record(settings: dict) -> tuple[dict, LensSpec]:
    """The ``slam`` mapping (fit settings nested) and the lens spec of a settings record."""
    slam = dict(settings["slam"])
    lens = settings.get("lens")
    if lens is None:
        lens = {key: slam.pop(key) for key in LENS_KEYS if key in slam}
        slam["fit"] = {key: slam.pop(key) for key in FIT_KEYS if key in slam}
    return slam, LensSpec(**lens)

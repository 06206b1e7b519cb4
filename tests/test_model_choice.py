"""LIGHT model choice by evidence (mgelens.pipeline.model_choice, rule choose_light) and
the sample sheet's per-lens pixel scale."""

import dataclasses
import json
import shutil

import numpy as np
import pytest
from astropy.io import fits
from test_pipeline import LENS, mock_dir  # noqa: F401  (fixture)

from mgelens.cli import main
from mgelens.imaging_input import ImagingError
from mgelens.pipeline import light_bound, problem, run
from mgelens.pipeline.model_choice import (
    Candidate,
    LightModel,
    adopt,
    candidates,
    choose,
    holds_choice,
)
from mgelens.pipeline.phases import mass as mass_phase
from mgelens.pipeline.settings import LensSpec, SettingsError, settings_from_mapping


# -- candidates and labels ---------------------------------------------------------------
@pytest.mark.parametrize(
    ("mge_sets", "point_set", "labels"),
    [
        ("auto", "auto", ["X2+point", "X6+point", "X2"]),
        ("auto", "yes", ["X2+point", "X6+point"]),
        ("auto", "no", ["X2", "X6"]),
        (2, "auto", ["X2+point", "X2"]),
        (6, "auto", ["X6+point", "X6"]),
        (4, "yes", ["X4+point"]),
        (np.int64(2), "no", ["X2"]),
    ],
)
def test_candidates_of_a_sheet_row(mge_sets, point_set, labels):
    assert [m.label for m in candidates(mge_sets, point_set)] == labels


def test_labels_and_folders_round_trip():
    for model in (LightModel(2, True), LightModel(6, False), LightModel(12, True)):
        assert LightModel.from_label(model.label) == model
    assert LightModel(6, True).folder == "light_x6_point"
    assert LightModel(2, False).folder == "light_x2"
    for bad in ("X0", "2+point", "X2+points", "x2", "X6 + point"):
        with pytest.raises(ValueError, match="X<n> or X<n>\\+point"):
            LightModel.from_label(bad)


# -- the rule ----------------------------------------------------------------------------
def _candidate(label, log_evidence, n_linear, n_free=10):
    return Candidate(
        label, log_evidence, 0.3, log_evidence + 5, log_evidence + 9, 1e4, n_linear, n_free, True
    )


X2 = ("X2", 60 + 500)
X2P = ("X2+point", 70 + 500)
X6P = ("X6+point", 190 + 500)


@pytest.mark.parametrize(
    ("evidences", "chosen"),
    [
        ((100.0, 100.0, 100.0), "X2"),  # a tie: the simplest
        ((100.0, 104.9, 104.0), "X2"),  # gains below the threshold
        ((100.0, 105.1, 104.0), "X2+point"),  # the point set pays
        ((100.0, 105.1, 110.0), "X2+point"),  # X6 leads X2+point by less than 5
        ((100.0, 105.1, 110.2), "X6+point"),  # X6 beats both by more than 5
        ((100.0, 90.0, 106.0), "X6+point"),
        ((120.0, 90.0, 124.0), "X2"),  # the best is within 5 of the simplest
    ],
)
def test_the_simplest_model_within_the_threshold_of_the_best_is_chosen(evidences, chosen):
    found = [
        _candidate(label, z, n) for (label, n), z in zip((X2, X2P, X6P), evidences, strict=True)
    ]
    assert choose(found, threshold=5.0).label == chosen


def test_a_zero_threshold_takes_the_highest_evidence_and_bad_thresholds_stop():
    found = [_candidate("X2", 100.0, 560), _candidate("X6+point", 100.01, 690)]
    assert choose(found, threshold=0.0).label == "X6+point"
    for bad in (-1.0, float("nan")):
        with pytest.raises(ValueError, match="threshold"):
            choose(found, bad)
    with pytest.raises(ValueError, match="no LIGHT candidate"):
        choose([], 5.0)


def test_equal_linear_unknowns_fall_back_to_fewer_free_parameters():
    found = [_candidate("X2+point", 100.0, 570, n_free=14), _candidate("X2", 101.0, 570, n_free=8)]
    assert choose(found, 5.0).label == "X2"


# -- candidates fitted on a small mock ---------------------------------------------------
def capped_settings(**changes):
    """Quick plumbing settings: capped samplers, a coarse source, the MGE lens light."""
    capped = {"progress_every": 1e9, "n_live": 12, "method": "dynesty_static"}
    iterations = {"sp": 40, "spix1": 15, "spix2": 10, "light": 15, "mass": 10}
    return settings_from_mapping(
        {
            "fit": {"lp_sub_size_centre": 4},
            "source_pixels": 60,
            "overlay_shape": [8, 8],
            "allow_unconverged": True,
            "samplers": {p: {**capped, "max_iterations": n} for p, n in iterations.items()},
            **changes,
        }
    )


@pytest.fixture(scope="module")
def candidate_run(mock_dir, tmp_path_factory):  # noqa: F811
    """SP, SPix1, SPix2 and two LIGHT candidates (X2+point, X2) in their own folders."""
    results = tmp_path_factory.mktemp("choice")
    settings = capped_settings()
    for phase in ("sp", "spix1", "spix2"):
        run.run_phase(phase, mock_dir, results, settings, LENS, seed=1, threads=1)
    models = [LightModel(2, True), LightModel(2, False)]
    for model in models:
        run.run_phase(
            "light",
            mock_dir,
            results,
            settings,
            dataclasses.replace(LENS, mge_sets=model.mge_sets, point_set=model.point_set),
            seed=1,
            threads=1,
            folder_name=model.folder,
        )
    return results, models


def test_candidates_are_written_to_their_own_folders_and_read_back(candidate_run):
    results, models = candidate_run
    assert not (results / "light").exists()
    for model in models:
        result = json.loads((results / model.folder / "result.json").read_text())
        candidate = Candidate.read(results / model.folder, model)
        assert candidate.log_evidence == result["log_evidence"]
        record = result["max_likelihood_fit"]
        assert candidate.max_log_evidence == record["log_evidence"]
        assert candidate.chi_squared == record["chi_squared"]
        # 2 × 30 Gaussians (+ 10 of the point set) and the source pixels
        n_source = record["source"]["n_pixels"]
        assert n_source == 60
        assert candidate.n_linear == 60 + 10 * model.point_set + n_source
        names = {c["name"] for c in record["lens_light"]["components"]}
        assert ("point" in names) == model.point_set


def test_adopt_copies_the_chosen_candidate_and_mass_reads_it(candidate_run, mock_dir, tmp_path):  # noqa: F811
    results, models = candidate_run
    record_path = tmp_path / "model_choice.json"
    chosen = adopt(results, models, threshold=5.0, record_path=record_path)
    record = json.loads(record_path.read_text())
    assert record["chosen"] == chosen.label
    assert record["threshold"] == 5.0
    found = {c["label"]: c for c in record["candidates"]}
    assert set(found) == {"X2+point", "X2"}
    best = max(c["log_evidence"] for c in found.values())
    simplest_within = min(
        (c for c in found.values() if c["log_evidence"] >= best - 5.0), key=lambda c: c["n_linear"]
    )
    assert chosen.label == simplest_within["label"]
    folder = results / LightModel.from_label(chosen.label).folder
    for name in ("result.json", "samples.csv", "model.fits", "phase.log"):
        assert (results / "light" / name).read_bytes() == (folder / name).read_bytes()
    other = next(m.label for m in models if m.label != chosen.label)
    assert holds_choice(results, chosen.label)
    assert not holds_choice(results, other)
    # MASS fixes the lens light of light/, the chosen candidate's
    problem = mass_phase.problem(mock_dir, results, capped_settings(), LENS)
    names = {spec.name for spec in problem.model.lens_light}
    assert ("point" in names) == LightModel.from_label(chosen.label).point_set
    assert str(results / "light" / "result.json") in map(str, problem.inputs)


def test_choose_command_names_a_missing_candidate(candidate_run, tmp_path, caplog):
    results, _ = candidate_run
    code = main(
        ["choose", "--results", str(results), "--candidates", "X2", "X6+point",
         "--record", str(tmp_path / "choice.json")]
    )  # fmt: skip
    assert code == 1
    assert "light_x6_point/result.json not found" in caplog.text
    assert "mgelens phase light --folder light_x6_point" in caplog.text
    assert not (tmp_path / "choice.json").exists()


def _reference_with_evidence(results, folder, log_evidence):
    """A copy of the X2+point candidate in ``folder`` whose ln Z reads ``log_evidence``, as
    a converged run's (the capped samplers stop early; only a converged ln Z bounds)."""
    shutil.copytree(results / "light_x2_point", results / folder, dirs_exist_ok=True)
    path = results / folder / "result.json"
    result = json.loads(path.read_text())
    result["log_evidence"] = result["sampler"]["log_evidence"] = log_evidence
    result["converged"] = result["sampler"]["converged"] = True
    path.write_text(json.dumps(result))


def _bounded_x2(results, mock_dir, folder, reference, log_evidence):  # noqa: F811
    """LIGHT X2 into ``folder``, bounded by a reference candidate of ln Z ``log_evidence``."""
    _reference_with_evidence(results, reference, log_evidence)
    x2 = dataclasses.replace(LENS, mge_sets=2, point_set=False)
    run.run_phase(
        "light", mock_dir, results, capped_settings(), x2, seed=1, threads=1,
        folder_name=folder, bound_by=(reference, 5.0),
    )  # fmt: skip


def test_a_candidate_that_cannot_win_is_bounded_not_sampled(candidate_run, mock_dir):  # noqa: F811
    """X2 against a reference whose ln Z lies far above anything X2 reaches: the phase
    writes the local search's maximum, which the choice reads as an upper bound."""
    results, _ = candidate_run
    _bounded_x2(results, mock_dir, "light_bounded", "light_far", 1e7)
    result = json.loads((results / "light_bounded" / "result.json").read_text())
    assert result["sampler"]["method"] == light_bound.METHOD
    assert result["sampler"]["n_calls"] <= light_bound.SEARCH_CALLS + 20
    assert "not sampled" in result["stop_reason"]
    bounded = Candidate.read(results / "light_bounded", LightModel(2, False))
    assert bounded.bounded
    # the bound is the highest ln ε found, at least the sampled X2's highest
    sampled = Candidate.read(results / "light_x2", LightModel(2, False))
    assert bounded.log_evidence >= bounded.max_log_evidence
    assert bounded.log_evidence >= sampled.max_log_evidence - 1e-6
    far = dataclasses.replace(sampled, label="X6+point", log_evidence=1e7, n_linear=10**4)
    assert choose([bounded, far], 5.0).label == "X6+point"
    within = dataclasses.replace(far, log_evidence=bounded.log_evidence + 1.0)
    with pytest.raises(ValueError, match="were not sampled"):
        choose([bounded, within], 5.0)


def test_a_candidate_that_could_win_is_sampled(candidate_run, mock_dir):  # noqa: F811
    results, _ = candidate_run
    _bounded_x2(results, mock_dir, "light_sampled", "light_near", -1e7)
    sampled = json.loads((results / "light_sampled" / "result.json").read_text())
    again = json.loads((results / "light_x2" / "result.json").read_text())
    assert sampled["sampler"]["method"] == again["sampler"]["method"] != light_bound.METHOD
    assert sampled["log_evidence"] == again["log_evidence"]
    with pytest.raises(ValueError, match="only a LIGHT candidate"):
        run.run_phase("mass", mock_dir, results, capped_settings(), LENS, bound_by=("x", 5.0))
    with pytest.raises(FileNotFoundError, match=r"light_x6_point/result\.json not found"):
        run.run_phase(
            "light", mock_dir, results, capped_settings(), LENS, bound_by=("light_x6_point", 5.0)
        )


def test_a_phase_folder_must_be_one_name(mock_dir, tmp_path):  # noqa: F811
    for bad in ("../light", "a/b", ".."):
        with pytest.raises(ValueError, match="one folder name"):
            run.run_phase("sp", mock_dir, tmp_path, capped_settings(), LENS, folder_name=bad)


# -- pixel scale from the sheet ----------------------------------------------------------
def _headerless_folder(mock_dir, folder):  # noqa: F811
    """The mock's images without any header keyword and without info.json."""
    folder.mkdir()
    for name in ("data", "noise_map", "psf"):
        fits.PrimaryHDU(fits.getdata(mock_dir / f"{name}.fits")).writeto(folder / f"{name}.fits")
    return folder


def test_a_folder_without_pixel_scale_needs_the_settings_value(mock_dir, tmp_path):  # noqa: F811
    folder = _headerless_folder(mock_dir, tmp_path / "bare")
    with pytest.raises(ImagingError, match=r"`pixel_scale` column"):
        problem.load_dataset(folder, capped_settings(), LENS, (0.0, 0.0))
    scale = fits.getheader(mock_dir / "data.fits")["PIXSCALE"]
    with_scale = dataclasses.replace(LENS, pixel_scale=scale)
    dataset, _ = problem.load_dataset(folder, capped_settings(), with_scale, (0.0, 0.0))
    reference, _ = problem.load_dataset(mock_dir, capped_settings(), LENS, (0.0, 0.0))
    assert dataset.imaging.pixel_scale == scale
    np.testing.assert_array_equal(dataset.mask, reference.mask)
    np.testing.assert_array_equal(dataset.data, reference.data)


@pytest.mark.parametrize("value", [0.0, -0.05, "x"])
def test_a_bad_pixel_scale_setting_is_named(value):
    with pytest.raises(SettingsError, match=r"pixel_scale must be a number > 0.*--pixel-scale"):
        LensSpec(pixel_scale=value)
    with pytest.raises(SettingsError, match=r"slam\.pixel_scale is set per lens"):
        capped_settings(pixel_scale=value)

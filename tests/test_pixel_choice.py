"""The source pixel count chosen by SPix2's evidence (mgelens.pipeline.pixel_choice, rule
choose_source_pixels): the rule, the candidates' files, and LIGHT and MASS keeping the
chosen count."""

import json

import pytest
from test_model_choice import capped_settings
from test_pipeline import LENS, mock_dir  # noqa: F401  (fixture)

from mgelens.cli import main
from mgelens.pipeline import run
from mgelens.pipeline.phases import light as light_phase
from mgelens.pipeline.phases import mass as mass_phase
from mgelens.pipeline.phases import spix2 as spix2_phase
from mgelens.pipeline.pixel_choice import PixelCandidate, adopt, choose, folder
from mgelens.pipeline.problem import PhaseInputError
from mgelens.pipeline.settings import SettingsError, settings_from_mapping

COUNTS = (40, 70)
"""Two counts of the toy mock; LIGHT on the 40-pixel SPix2 is the case whose best sample the
phase once refitted from the NNLS's default start and failed to factorise (the sampler's
warm start scores it)."""


# -- settings ----------------------------------------------------------------------------
def test_source_pixels_take_one_count_or_increasing_candidates():
    assert settings_from_mapping({"source_pixels": 700}).source_pixel_candidates == (700,)
    listed = settings_from_mapping({"source_pixels": [1000, 500]})
    assert listed.source_pixels == (500, 1000)
    assert listed.source_pixel_candidates == (500, 1000)
    assert listed.to_dict()["source_pixels"] == (500, 1000)
    for bad, what in (
        ([500], "two or more distinct"),
        ([500, 500], "two or more distinct"),
        ([500, 2], ">= 3"),
    ):
        with pytest.raises(SettingsError, match=f"slam.source_pixels must be an integer .*{what}"):
            settings_from_mapping({"source_pixels": bad})
    assert settings_from_mapping({"mass_source_pixels": 90}).mass_pixels(500) == 90
    assert settings_from_mapping({}).mass_pixels(500) == 500


# -- the rule ----------------------------------------------------------------------------
def _candidate(n_pixels, log_evidence):
    return PixelCandidate(n_pixels, log_evidence, 1.0, log_evidence + 15.0, True)


def test_the_fewest_pixels_within_the_threshold_of_the_best_win():
    # a finer mesh must beat every coarser one by the threshold
    assert choose([_candidate(500, 100.0), _candidate(1000, 104.9)]).n_pixels == 500
    assert choose([_candidate(500, 100.0), _candidate(1000, 105.1)]).n_pixels == 1000
    assert choose([_candidate(500, 120.0), _candidate(1000, 100.0)]).n_pixels == 500
    three = [_candidate(500, 100.0), _candidate(1000, 150.0), _candidate(1500, 153.0)]
    assert choose(three).n_pixels == 1000
    assert choose(three, threshold=2.0).n_pixels == 1500
    assert choose(three, threshold=0.0).n_pixels == 1500
    with pytest.raises(ValueError, match="no SPix2 candidate"):
        choose([])
    with pytest.raises(ValueError, match="threshold must be a number >= 0"):
        choose(three, threshold=-1.0)


def test_a_missing_or_mismatched_candidate_names_the_fix(tmp_path):
    with pytest.raises(FileNotFoundError, match="mgelens phase spix2 --folder spix2_n500"):
        PixelCandidate.read(tmp_path / folder(500), 500)
    (tmp_path / folder(500)).mkdir()
    (tmp_path / folder(500) / "result.json").write_text("{not json")
    with pytest.raises(ValueError, match=r"not a finished SPix2 result.*rerun the SPix2 candidate"):
        PixelCandidate.read(tmp_path / folder(500), 500)
    record = {"source": {"n_pixels": 1000}, "log_evidence": 1.0}
    content = {"log_evidence": 1.0, "log_evidence_error": 0.1, "converged": True}
    (tmp_path / folder(500) / "result.json").write_text(
        json.dumps({**content, "max_likelihood_fit": record})
    )
    with pytest.raises(ValueError, match="fitted with 1000 source pixels, not 500"):
        PixelCandidate.read(tmp_path / folder(500), 500)


# -- candidates fitted by the chain ------------------------------------------------------
def choose_pixels(results, record_path, *arguments):
    """``mgelens choose --source-pixels`` on ``results``: counts, then options."""
    counts = [str(a) for a in arguments if isinstance(a, int)]
    options = [a for a in arguments if isinstance(a, str)]
    return main(
        ["choose", "--results", str(results), "--source-pixels", *counts,
         "--record", str(record_path), *options]
    )  # fmt: skip


@pytest.fixture(scope="module")
def pixel_run(mock_dir, tmp_path_factory):  # noqa: F811
    """SP, SPix1, and SPix2 once per count of :data:`COUNTS` in its own folder."""
    results = tmp_path_factory.mktemp("pixels")
    settings = capped_settings()
    for phase in ("sp", "spix1"):
        run.run_phase(phase, mock_dir, results, settings, LENS, seed=1, threads=1)
    for n in COUNTS:
        counted = capped_settings(source_pixels=n)
        run.run_phase(
            "spix2", mock_dir, results, counted, LENS, seed=1, threads=1, folder_name=folder(n)
        )
    return results


def test_spix2_fits_one_count(pixel_run, mock_dir):  # noqa: F811
    listed = capped_settings(source_pixels=list(COUNTS))
    with pytest.raises(PhaseInputError, match="SPix2 fits one source pixel count"):
        spix2_phase.problem(mock_dir, pixel_run, listed, LENS)


def test_choose_adopts_the_evidence_s_count_and_light_and_mass_keep_it(
    pixel_run,
    mock_dir,  # noqa: F811
    tmp_path,
):
    """`mgelens choose --source-pixels` copies the chosen SPix2 into spix2/ by the rule, and
    LIGHT and MASS build SPix2's count whatever candidate list the settings give; a count
    the settings do not allow is refused."""
    record_path = tmp_path / "choice.json"
    assert choose_pixels(pixel_run, record_path, *COUNTS, "--threshold", "0") == 0
    record = json.loads(record_path.read_text())
    found = {c["n_pixels"]: c["log_evidence"] for c in record["candidates"]}
    assert found == {
        n: json.loads((pixel_run / folder(n) / "result.json").read_text())["log_evidence"]
        for n in COUNTS
    }
    assert record["chosen"] == max(found, key=found.get)
    chosen = record["chosen"]
    for name in ("result.json", "samples.csv", "model.fits", "phase.log"):
        assert (pixel_run / "spix2" / name).read_bytes() == (
            pixel_run / folder(chosen) / name
        ).read_bytes()
    # a threshold no gain reaches keeps the coarser count
    assert adopt(
        pixel_run, COUNTS, threshold=1e9, record_path=tmp_path / "coarse.json"
    ).n_pixels == min(COUNTS)
    listed = capped_settings(source_pixels=list(COUNTS))
    light = light_phase.problem(mock_dir, pixel_run, listed, LENS)
    assert light.model.source.describe()["n_pixels"] == min(COUNTS)
    other = capped_settings(source_pixels=max(COUNTS) + 1)
    with pytest.raises(PhaseInputError, match=f"fitted with {min(COUNTS)} source pixels"):
        light_phase.problem(mock_dir, pixel_run, other, LENS)
    run.run_phase("light", mock_dir, pixel_run, listed, LENS, seed=1, threads=1)
    mass = mass_phase.problem(mock_dir, pixel_run, listed, LENS)
    assert mass.model.source.describe()["n_pixels"] == min(COUNTS)
    finer = mass_phase.problem(
        mock_dir,
        pixel_run,
        capped_settings(source_pixels=list(COUNTS), mass_source_pixels=90),
        LENS,
    )
    assert finer.model.source.describe()["n_pixels"] == 90


def test_choose_refuses_a_candidate_not_fitted(pixel_run, tmp_path):
    assert choose_pixels(pixel_run, tmp_path / "c.json", 40, 55) == 1
    assert not (tmp_path / "c.json").exists()

"""The Appendix A scan as a command (`mgelens smoothness`, :mod:`mgelens.smoothness`)."""

import json

import numpy as np
import pandas as pd
import pytest

from mgelens.cli import main
from mgelens.mask import circular
from mgelens.mock_lenses import paper_mock
from mgelens.simulate import Observation, simulate, write_mock
from mgelens.smoothness import (
    EDGE_RULES,
    SCHEMES,
    evidence_scan,
    jump_summary,
    jumps,
    mock_dataset,
    scan_model,
    scan_slopes,
)

MASK_RADIUS = 1.4


def test_the_papers_scan_is_101_slopes_centred_on_the_truth():
    slopes = scan_slopes(2.1)
    assert slopes.size == 101
    assert slopes[50] == pytest.approx(2.1, abs=1e-15)
    np.testing.assert_allclose(np.diff(slopes), 0.0004, rtol=1e-9)
    assert slopes[0] == pytest.approx(2.08)
    assert slopes[-1] == pytest.approx(2.12)


def test_a_jump_is_the_step_change_less_the_local_trend():
    k = np.arange(40, dtype=float)
    smooth = 0.5 * k**2  # changes k + 0.5: a linear trend that the running median follows
    assert jumps(smooth)[5:-5].max() == pytest.approx(0.0, abs=1e-12)
    stepped = 2.0 * k + 3.0 * (k >= 20)  # constant trend 2 per step, one step of +3
    found = jumps(stepped)
    assert int(np.argmax(found)) == 19
    assert found[19] == pytest.approx(3.0)
    assert np.delete(found, 19).max() == pytest.approx(0.0, abs=1e-12)


def test_jump_summary_gives_each_curves_largest_95th_percentile_and_median():
    rng = np.random.default_rng(0)
    values = rng.exponential(size=30)
    table = pd.DataFrame(
        {
            "scheme": "nearest",
            "edge_rule": "anchor",
            "slope": np.arange(31.0),
            "log_evidence": 0.0,
            "jump": np.concatenate([[np.nan], values]),
        }
    )
    row = jump_summary(table).iloc[0]
    assert row["max_jump"] == values.max()
    assert row["p95_jump"] == pytest.approx(np.percentile(values, 95))
    assert row["median_jump"] == pytest.approx(np.median(values))


@pytest.fixture(scope="module")
def small_m1(tmp_path_factory):
    """M1 on a 71 × 71 grid (4 × 4 sub-pixels) written as a mock folder."""
    folder = tmp_path_factory.mktemp("smoothness") / "mock"
    lens = paper_mock("M1")
    mock = simulate(lens, Observation(image_size=71, sub_size=4))
    write_mock(mock, folder)
    return folder, lens, mock


def test_the_command_writes_every_scheme_and_edge_rules_scan(small_m1, tmp_path):
    folder, lens, mock = small_m1
    out, table_path = tmp_path / "smoothness.png", tmp_path / "smoothness.csv"
    arguments = ["smoothness", "--lens-dir", str(folder), "--mask-radius", str(MASK_RADIUS)]
    arguments += ["--out", str(out), "--table", str(table_path), "--source-pixels", "120"]
    arguments += ["--half-range", "0.002"]
    assert main(arguments) == 0
    assert out.stat().st_size > 20_000
    table = pd.read_csv(table_path)
    assert list(table.columns) == ["scheme", "edge_rule", "slope", "log_evidence", "jump"]
    assert len(table) == len(SCHEMES) * len(EDGE_RULES) * 11
    truth = lens.mass[0].slope
    # every curve equals an independent evaluation of its scheme at the same slopes
    imaging = mock.imaging
    mask = circular(imaging.shape, imaging.pixel_scale, MASK_RADIUS)
    centre = tuple(lens.mass[0].centre)
    for edge_rule in EDGE_RULES:
        dataset = mock_dataset(imaging, mask, centre, edge_rule)
        model = scan_model(
            dataset, lens.mass[0], mock.lensed_source_blurred[~mask], MASK_RADIUS, 120, 1
        )
        for scheme in SCHEMES:
            rows = table[(table["scheme"] == scheme) & (table["edge_rule"] == edge_rule)]
            np.testing.assert_allclose(rows["slope"], scan_slopes(truth, 0.0004, 0.002))
            expected = evidence_scan(dataset, model, scheme, rows["slope"].to_numpy()[[0, 5]])
            np.testing.assert_allclose(
                rows["log_evidence"].to_numpy()[[0, 5]], expected, rtol=1e-12
            )
            np.testing.assert_allclose(
                rows["jump"].to_numpy()[1:], jumps(rows["log_evidence"].to_numpy())
            )
    # the schemes differ: nearest-cell mapping is a different likelihood
    by_scheme = table[table["edge_rule"] == "anchor"].groupby("scheme")["log_evidence"].mean()
    assert abs(by_scheme["nearest"] - by_scheme["natural_neighbour"]) > 1.0


def test_the_command_names_a_missing_mock_and_bad_options(tmp_path, caplog):
    out = ["--out", str(tmp_path / "s.png"), "--table", str(tmp_path / "s.csv")]
    assert main(["smoothness", "--lens-dir", str(tmp_path / "absent"), *out]) == 1
    assert "truth.json" in caplog.text
    assert main(["smoothness", "--lens-dir", str(tmp_path), "--step", "0", *out]) == 2
    assert "give a positive step" in caplog.text
    assert main(["smoothness", "--lens-dir", str(tmp_path), "--mask-radius", "-1", *out]) == 2
    assert not (tmp_path / "s.png").exists()


def test_a_mock_without_an_epl_is_refused(small_m1, tmp_path, caplog):
    folder, _, _ = small_m1
    truth = json.loads((folder / "truth.json").read_text())
    copy = tmp_path / "mock"
    copy.mkdir()
    for path in folder.iterdir():
        (copy / path.name).write_bytes(path.read_bytes())
    truth["mass"] = [entry for entry in truth["mass"] if entry["type"] != "EPL"]
    (copy / "truth.json").write_text(json.dumps(truth))
    out = ["--out", str(tmp_path / "s.png"), "--table", str(tmp_path / "s.csv")]
    assert main(["smoothness", "--lens-dir", str(copy), *out]) == 1
    assert "holds no EPL mass" in caplog.text

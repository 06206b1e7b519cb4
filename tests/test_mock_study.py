"""The paper's mock comparison: Table 3, the light errors per annulus and Figures 5–7
(:mod:`mgelens.mock_study`, ``mgelens mockstudy``)."""

import numpy as np
import pytest

from mgelens.cli import main
from mgelens.mock_study import (
    COLUMNS,
    PAPER_TABLE_3,
    PARAMETERS,
    annulus_table,
    markdown_table,
    mock_table,
    relative_difference,
)
from mgelens.plot.mock_study import LightPanel, lens_light_figure

TRUTH = {
    "mass.centre_x": 0.0, "mass.centre_y": 0.0, "mass.einstein_radius": 1.2,
    "mass.axis_ratio": 0.8, "mass.angle": 45.0, "mass.slope": 2.1,
    "shear.gamma_1": 0.0, "shear.gamma_2": 0.0,
}  # fmt: skip


def record(slope_median: float) -> dict:
    """A recovery record whose slope posterior is slope_median ± 0.05 (3σ)."""
    rows = []
    for name, truth in TRUTH.items():
        median = slope_median if name == "mass.slope" else truth + 0.001
        lower, upper = median - 0.05, median + 0.05
        rows.append(
            {
                "name": name, "truth": truth, "median": median, "lower_3sigma": lower,
                "upper_3sigma": upper, "within_3sigma": lower <= truth <= upper,
                "error": median - truth,
            }
        )  # fmt: skip
    split = [
        {"inner_radius": 0.2, "outer_radius": 0.5, "n_pixels": 100, "lens_light_error": 0.3,
         "lensed_source_error": -0.29, "total_error": 0.01, "source_to_lens_ratio": 0.2},
    ]  # fmt: skip
    return {"lens": "x", "mass": rows, "light_split": split}


FITS = [
    {"lens": "M1", "mock": "M1", "model": "nn_mge", "recovery": record(2.11)},
    {"lens": "M1_sersic", "mock": "M1", "model": "sersic", "recovery": record(1.96)},
]


def test_table_3_has_one_row_per_fit_and_epl_parameter_with_the_recovery_values():
    table = mock_table(FITS)
    assert list(table.columns) == list(COLUMNS)
    assert len(table) == 2 * len(PARAMETERS)  # the shear is not a Table 3 parameter
    assert set(table["parameter"]) == set(PARAMETERS)
    slope = table[table["parameter"] == "slope"].set_index("lens")
    assert slope.loc["M1", "within_3sigma"]
    assert not slope.loc["M1_sersic", "within_3sigma"]
    assert slope.loc["M1_sersic", "median"] == 1.96
    assert slope.loc["M1_sersic", "lower_3sigma"] == pytest.approx(1.91)
    with pytest.raises(ValueError, match="unknown model"):
        mock_table([{**FITS[0], "model": "sersic4"}])


def test_the_markdown_table_marks_misses_and_shows_the_papers_rows():
    text = markdown_table(mock_table(FITS))
    lines = text.splitlines()
    assert lines[0].startswith("| mock | fit | centre_x")
    assert sum(line.startswith("| M1 | truth |") for line in lines) == 1
    sersic = next(line for line in lines if line.startswith("| M1 | 3×Sérsic (M1_sersic)"))
    assert "**1.96 (1.91, 2.01)** ✗" in sersic
    nn = next(line for line in lines if line.startswith("| M1 | nn-MGE (M1)"))
    assert "✗" not in nn
    paper = next(line for line in lines if line.startswith("| M1 | paper 3×Sérsic"))
    assert "1.96 (1.91, 2.02)" in paper  # SPEC §11
    assert PAPER_TABLE_3[("M2", "sersic")]["slope"] == (2.72, 2.61, 2.82)
    # nn-MGE before 3×Sérsic, each followed by the paper's row
    order = [line.split("|")[2].strip() for line in lines[2:]]
    assert order == ["truth", "nn-MGE (M1)", "paper nn-MGE", "3×Sérsic (M1_sersic)",
                     "paper 3×Sérsic"]  # fmt: skip


def test_the_annulus_table_lists_each_fits_light_split():
    table = annulus_table(FITS)
    assert list(table["lens"]) == ["M1", "M1_sersic"]
    assert table["lens_light_error"].tolist() == [0.3, 0.3]
    assert table["total_error"].tolist() == [0.01, 0.01]


def test_relative_difference_is_nan_outside_the_fit_and_where_the_truth_is_zero():
    truth = np.array([[1.0, 2.0], [0.0, 4.0]])
    model = np.array([[1.1, 1.0], [5.0, 4.0]])
    mask = np.array([[False, False], [False, True]])
    out = relative_difference(model, truth, mask)
    np.testing.assert_allclose(out[0], [0.1, -0.5])
    assert np.isnan(out[1]).all()


def test_the_lens_light_figure_has_one_column_per_fit_with_colour_bars():
    shape = (41, 41)
    rng = np.random.default_rng(1)
    panels = [
        LightPanel(f"M{k} (M{k})", rng.normal(0, 0.05, shape), rng.normal(0, 1, shape),
                   np.exp(-np.hypot(*np.indices(shape) - 20.0) / 5.0), 0.05, 0.9)
        for k in (1, 2, 3)
    ]  # fmt: skip
    figure = lens_light_figure("pn_mge", panels)
    images = [ax for ax in figure.axes if ax.images]
    assert len(images) == 6
    labels = {ax.get_ylabel() for ax in figure.axes if not ax.images}
    assert labels == {"lens light (model − true)/true", "(data − model)/σ"}
    top = images[0].images[0]
    assert top.get_clim() == (-0.2, 0.2)
    assert images[0].get_xlabel() == "x [arcsec]"
    assert images[0].get_xlim() == pytest.approx((-0.99, 0.99))
    assert any(ax.collections for ax in images[3:])  # contours of data − lens light
    assert figure.get_suptitle().startswith("pn-MGE: lens-light error (top),\nnormalised")


def test_the_command_names_a_bad_fit_or_a_missing_record(tmp_path, caplog):
    out = ["--out-table", str(tmp_path / "t.csv"), "--out-markdown", str(tmp_path / "t.md"),
           "--out-annuli", str(tmp_path / "a.csv"), "--figures-dir", str(tmp_path)]  # fmt: skip
    assert main(["mockstudy", "--fit", "M1", "M4", "nn_mge", *out]) == 1
    assert "the mock must be one of" in caplog.text
    assert main(["mockstudy", "--fit", "M1", "M1", "sersic3", *out]) == 1
    assert "the model must be one of" in caplog.text
    assert main(["mockstudy", "--fit", "M1", "M1", "nn_mge", "--results", str(tmp_path), *out]) == 1
    assert "recovery.json" in caplog.text
    assert not (tmp_path / "t.csv").exists()

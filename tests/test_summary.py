"""Tests of mgelens.summary, mgelens.plot.summary and ``mgelens summary``."""

import dataclasses
import json
import math

import numpy as np
import pandas as pd
import pytest
from astropy.io import fits

from mgelens.atomic import write_json
from mgelens.cli import main
from mgelens.isophotes import IsophoteStatistics, MassShape
from mgelens.pipeline.model_choice import Candidate, LightModel, choice_record, choose
from mgelens.plot import save_png
from mgelens.plot.comparison import einstein_radius_figure, slope_figure
from mgelens.plot.mosaic import read_panel, residual_mosaic
from mgelens.plot.summary import histogram_figure
from mgelens.published import SLOPE_TENSION, slope_differences
from mgelens.summary import (
    FIT_COLUMNS,
    LIGHT_MODEL_COLUMNS,
    TABLE_COLUMNS,
    complex_fraction,
    complex_lenses,
    lens_summary,
    lens_table,
    light_model_label,
    light_model_table,
    sample_table,
)

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

LENSES = {
    # lens: (Δq_max, ΔPA_max, extreme a4/a, n_isophotes); complex iff Δq > 0.1 or ΔPA > 10°
    "J0003": (0.12, 3.0, -0.037, 30),  # complex by Δq
    "J0001": (0.05, 12.0, 0.026, 30),  # complex by ΔPA
    "J0002": (0.05, 3.0, 0.011, 30),  # simple
    "J0004": (0.1, 10.0, -0.004, 30),  # thresholds are strict: simple
    "J0005": (0.02, math.nan, 0.015, 30),  # all isophotes round: ΔPA undefined, simple
    "J0006": (math.nan, math.nan, math.nan, 0),  # no isophotes: excluded from the fraction
}


def statistics(delta_q, delta_pa, a4, n):
    return IsophoteStatistics(delta_q, delta_pa, a4, n, n if math.isfinite(delta_pa) else 0)


@pytest.fixture
def summaries(tmp_path):
    paths = []
    for lens, values in LENSES.items():
        mass = MassShape(0.8, 45.0, critical_curve_einstein_radius=1.2) if lens == "J0001" else None
        path = tmp_path / lens / "isophotes.json"
        shape = statistics(*values)
        if lens == "J0001":  # a phase's lens light: the source share is measured
            shape = dataclasses.replace(shape, a4_a_source_share=0.25)
        write_json(path, lens_summary(lens, shape, mass, {"image": "x.fits"}))
        paths.append(path)
    return paths


def test_lens_summary_is_plain_json(summaries):
    content = json.loads(summaries[-1].read_text())
    assert content["lens"] == "J0006"
    assert content["statistics"]["delta_q_max"] is None
    assert content["statistics"]["n_isophotes"] == 0
    assert content["mass"] is None
    assert "conventions" in content


def test_sample_table_has_one_row_per_lens(summaries):
    table = sample_table(summaries)
    assert list(table.columns) == list(TABLE_COLUMNS)
    assert list(table["lens"]) == sorted(LENSES)
    row = table.set_index("lens").loc["J0003"]
    assert row["delta_q_max"] == pytest.approx(0.12)
    assert row["a4_a_extreme"] == pytest.approx(-0.037)
    assert row["abs_a4_a_max"] == pytest.approx(0.037)
    assert math.isnan(row["mass_axis_ratio"])
    assert math.isnan(row["a4_a_source_share"])  # an image's summary: no source share
    with_mass = table.set_index("lens").loc["J0001"]
    assert with_mass["mass_axis_ratio"] == pytest.approx(0.8)
    assert with_mass["a4_a_source_share"] == pytest.approx(0.25)
    assert with_mass["mass_critical_curve_einstein_radius"] == pytest.approx(1.2)
    expected = {"J0001": True, "J0002": False, "J0003": True, "J0004": False, "J0005": False,
                "J0006": False}  # fmt: skip
    assert dict(zip(table["lens"], table["complex"], strict=True)) == expected


def test_complex_fraction_counts_only_lenses_with_isophotes(summaries):
    table = sample_table(summaries)
    assert complex_fraction(table) == pytest.approx(2.0 / 5.0)
    assert complex_fraction(table, delta_q_threshold=0.06) == pytest.approx(3.0 / 5.0)
    assert complex_fraction(table, delta_pa_threshold=2.0) == pytest.approx(4.0 / 5.0)
    assert math.isnan(complex_fraction(table[table["n_isophotes"] == 0]))
    flags = complex_lenses(pd.DataFrame({"delta_q_max": [0.2, np.nan], "delta_pa_max": [0, 20]}))
    assert list(flags) == [True, True]


def test_sample_table_errors_name_the_file(tmp_path, summaries):
    with pytest.raises(ValueError, match="appears in several summaries"):
        sample_table([*summaries, summaries[0]])
    bad = tmp_path / "bad.json"
    bad.write_text('{"lens": "J9"}')
    with pytest.raises(ValueError, match=r"bad\.json: not a lens summary"):
        sample_table([bad])
    with pytest.raises(ValueError, match="not found"):
        sample_table([tmp_path / "missing.json"])


def test_histogram_figure_is_written_atomically(tmp_path, summaries):
    table = sample_table(summaries)
    figure = histogram_figure(table)
    assert len(figure.axes) == 3
    assert "2/5" in figure.get_suptitle()
    assert "paper ≈ 40 % of 35" in figure.get_suptitle()
    # |a₄/a| 0.037, 0.026, 0.011, 0.004, 0.015 (and one lens without isophotes)
    assert figure.axes[2].get_title() == "max |a₄/a| < 0.02: 3/5 (paper 32/35)"
    for ax in figure.axes:  # counts of lenses: whole-number ticks
        ticks = [tick for tick in ax.get_yticks() if ax.get_ylim()[0] <= tick <= ax.get_ylim()[1]]
        assert ticks == [round(tick) for tick in ticks]
    path = tmp_path / "plots" / "histograms.png"
    save_png(figure, path)
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    assert path.stat().st_size > 10_000
    assert sorted(p.name for p in path.parent.iterdir()) == ["histograms.png"]
    empty = histogram_figure(table[table["n_isophotes"] == 0])
    assert empty.get_suptitle() == "no lens with isophotes"


# -- fits, published values, quality flags and their figures ---------------------------
FITS = {
    # lens: (θ_E^AG, q, γ, light components, quality measured, flag)
    "slacs0029-0055": (1.0, 0.8, 2.0, ("set_0", "set_1", "point"), True, False),
    "slacs0037-0942": (1.5, 0.7, 2.2, ("set_0", "set_1", "set_2", "set_3"), True, True),
    "M1": (1.2, 0.9, 2.1, ("sersic_0", "sersic_1", "sersic_2"), False, False),
}
SHAPE, PIXEL, RADIUS = (41, 41), 0.1, 1.8


def light_record(names, n_pixels=500):
    kind = "sersic" if names[0].startswith("sersic") else "mge"
    return {
        "lens_light": {"components": [{"name": n, "kind": kind} for n in names]},
        "source": {"kind": "pixelized", "mesh": "kmeans", "n_pixels": n_pixels},
    }


def write_lens_folder(root, lens, theta, q, slope, names, measured, flag):
    """results/<lens>/{isophotes.json, quality.json, mass/{result.json, samples.csv,
    model.fits}} with a posterior of three weighted samples about (θ_E, q, γ)."""
    folder = root / lens
    write_json(folder / "isophotes.json", lens_summary(lens, statistics(0.05, 3.0, 0.01, 30)))
    # the quality-flagged lens's MASS also missed its peak after the restarts; M1's
    # record predates the peak check
    sampler = {"peak_gain": 5.1 if flag else 0.4} if measured else {}
    result = {"converged": not flag, "sampler": sampler, "max_likelihood_fit": light_record(names)}
    if measured:  # the flagged lens's slope also runs into its prior's bound 1.5
        low_3 = 1.5 if flag else slope - 0.15
        uniform = {"type": "Uniform", "lower": 1.5, "upper": 3.0}
        result["parameter_space"] = {"parameters": [
            {"name": "mass.slope", "status": "free", "prior": uniform},
            {"name": "mass.centre_y", "status": "fixed", "prior": None},
        ]}  # fmt: skip
        result["interval_1sigma"] = {"mass.slope": [slope - 0.05, slope + 0.05]}
        result["interval_3sigma"] = {"mass.slope": [low_3, slope + 0.15]}
    write_json(folder / "mass" / "result.json", result)
    pd.DataFrame(
        {
            "weight": [1.0, 2.0, 1.0],
            "mass.einstein_radius": [0.98 * theta, theta, 1.02 * theta],
            "mass.axis_ratio": [q, q, q],
            "mass.slope": [slope - 0.05, slope, slope + 0.05],
        }
    ).to_csv(folder / "mass" / "samples.csv", index=False)
    quality = {"measured": measured, "flag": flag, "significance": 2.0 if measured else None,
               "peak": 7.0 if flag else 3.0, "worst_x": 1.0, "worst_y": -0.5,
               "lensing": {"critical_curve_einstein_radius": 1.0 if measured else None,
                           "flag": not measured, "reason": "",
                           "centre_offset": 0.02 if measured else None}}  # fmt: skip
    if flag:  # a record of the sky's τ and of the image multiplicity; the others predate them
        quality["noise_scale_from"] = "sky"
        quality["multiplicity"] = {"multiply_imaged_fraction": 0.3, "n_pixels": 40,
                                   "flag": True, "reason": "singly imaged"}  # fmt: skip
    write_json(folder / "quality.json", quality)
    y, x = (np.indices(SHAPE) - 20) * PIXEL
    mask = np.hypot(x, y) > RADIUS
    nresid = np.where(mask, 0.0, x)  # rises to +x: the orientation check
    header = fits.Header({"PIXSCALE": PIXEL})
    images = {
        "NRESID": nresid,
        "RESID": 0.01 * nresid,
        "LENSED": np.where(mask, 0.0, 0.5 * np.exp(-((np.hypot(x, y) - 1.0) ** 2) / 0.02)),
    }
    hdus = [fits.PrimaryHDU()] + [fits.ImageHDU(a, header, name=n) for n, a in images.items()]
    fits.HDUList(hdus).writeto(folder / "mass" / "model.fits")
    return folder / "isophotes.json"


@pytest.fixture
def lens_folders(tmp_path):
    return [write_lens_folder(tmp_path / "results", lens, *v) for lens, v in FITS.items()]


@pytest.fixture
def reference(tmp_path):
    """Published tables in the real files' formats, with hand-picked values."""
    folder = tmp_path / "reference"
    folder.mkdir()
    (folder / "bolton2008_table5_sie.csv").write_text(
        "Name,bSIE,qSIE,PASIE\nJ0029-0055,0.96,0.89,25.4\nJ0037-0942,1.53,0.84,15.9\n"
    )
    (folder / "shajib2021_slacs_powerlaw_tdcosmo2020.csv").write_text(
        "name,flag_imaging,theta_E,gamma,theta_E_lo,theta_E_hi,gamma_lo,gamma_hi\n"
        "SDSSJ0029-0055,0,0.95,,,,,\n"
        "SDSSJ0037-0942,1,1.50,2.19,0.03,0.01,0.03,0.05\n"
    )
    return folder


def test_light_model_labels():
    assert light_model_label(light_record(("set_0", "set_1", "point"))) == "X2+point"
    assert light_model_label(light_record(("set_0",) * 6)) == "X6"
    assert light_model_label(light_record(("sersic_0", "sersic_1", "sersic_2"))) == "3xSersic"
    legacy = {"lens_light": {"sets": [{"name": "set_0"}, {"name": "point"}]}}
    assert light_model_label(legacy) == "X1+point"


def test_lens_table_converts_and_compares(lens_folders, reference):
    table = lens_table(lens_folders, reference).set_index("lens")
    assert list(table.columns) == [c for c in (*TABLE_COLUMNS, *FIT_COLUMNS) if c != "lens"]
    sie = table.loc["slacs0029-0055"]
    assert sie["light_model"] == "X2+point"
    assert (sie["source_pixels"], sie["source_pixels_chosen_by"]) == (500, "config")
    assert sie["theta_e"] == 1.0
    assert sie["theta_e_err_lo"] == pytest.approx(0.02)
    assert sie["theta_e_err_hi"] == pytest.approx(0.02)
    factor = 2 * math.sqrt(0.8) / 1.8  # γ = 2: SIE factor of SPEC §3.3
    assert sie["theta_e_lt"] == pytest.approx(factor, rel=1e-12)
    assert sie["bolton_b_sie"] == 0.96
    assert sie["theta_e_over_bolton"] == pytest.approx(factor / 0.96, rel=1e-12)
    assert math.isnan(sie["shajib_theta_e"])  # flag_imaging = 0
    assert sie["quality_flag"] == False  # noqa: E712 (pandas nullable boolean)
    epl = table.loc["slacs0037-0942"]
    # median sample (θ 1.5, γ 2.2); slopes 2.15/2.25 of the other samples move θ_LT less
    expected = 1.5 * math.sqrt(0.7) * (2 / 1.7) ** (1 / 1.2)
    assert epl["theta_e_lt"] == pytest.approx(expected, rel=1e-12)
    low = 0.98 * 1.5 * math.sqrt(0.7) * (2 / 1.7) ** (1 / 1.15)
    assert epl["theta_e_lt_err_lo"] == pytest.approx(expected - low, rel=1e-9)
    assert epl["slope"] == 2.2
    assert epl["shajib_theta_e"] == 1.5
    assert epl["shajib_theta_e_err_lo"] == 0.03
    assert (epl["shajib_gamma"], epl["shajib_gamma_err_lo"], epl["shajib_gamma_err_hi"]) == (
        2.19,
        0.03,
        0.05,
    )
    assert epl["theta_e_over_shajib"] == pytest.approx(expected / 1.5, rel=1e-12)
    assert epl["quality_flag"] == True  # noqa: E712
    mock = table.loc["M1"]
    assert mock["light_model"] == "3xSersic"
    assert pd.isna(mock["quality_flag"])
    assert (sie["lensing_flag"], epl["lensing_flag"], mock["lensing_flag"]) == (False, False, True)
    sources = [t["quality_noise_scale_from"] for t in (sie, epl, mock)]
    assert [s if isinstance(s, str) else "" for s in sources] == ["residuals", "sky", ""]
    assert sie["mass_light_offset"] == 0.02
    assert epl["multiply_imaged_fraction"] == 0.3
    assert epl["singly_imaged_flag"] == True  # noqa: E712
    assert math.isnan(sie["multiply_imaged_fraction"])
    assert pd.isna(sie["singly_imaged_flag"])
    assert math.isnan(mock["mass_light_offset"])
    converged = [t["mass_converged"] for t in (sie, epl, mock)]
    assert converged == [True, False, True]
    assert (sie["mass_peak_gain"], epl["mass_peak_gain"]) == (0.4, 5.1)
    assert math.isnan(mock["mass_peak_gain"])
    assert (sie["prior_edge"], epl["prior_edge"]) == ("none", "mass.slope at its lower bound 1.5")
    assert pd.isna(mock["prior_edge"])
    assert mock[["bolton_b_sie", "shajib_theta_e", "quality_statistic"]].isna().all()


CANDIDATES = (
    # label, ln Z, χ², linear unknowns, free parameters
    ("X2+point", 100.0, 950.0, 570, 10),
    ("X6+point", 103.0, 940.0, 690, 18),  # higher ln Z, but by less than the threshold 5
    ("X2", 90.0, 990.0, 560, 6),
)


def write_choice(folder, chosen_label=None):
    """folder/model_choice.json as rule choose_light writes it, over :data:`CANDIDATES`
    (the choice by :func:`choose` unless ``chosen_label`` overrides it), with each
    candidate's result.json and the chosen one's adopted as light/result.json."""
    found = [Candidate(label, ln_z, 0.3, ln_z + 1, ln_z + 50, chi2, n_linear, n_free, True)
             for label, ln_z, chi2, n_linear, n_free in CANDIDATES]  # fmt: skip
    chosen = choose(found, 5.0)
    if chosen_label is not None:
        chosen = next(c for c in found if c.label == chosen_label)
    for candidate in found:
        folder_name = LightModel.from_label(candidate.label).folder
        write_json(folder / folder_name / "result.json", {"candidate": candidate.label})
    write_json(folder / "light" / "result.json", {"candidate": chosen.label})
    write_json(folder / "model_choice.json", choice_record(found, chosen, 5.0))


def test_lens_table_reads_the_evidence_choice(lens_folders, reference):
    write_choice(lens_folders[0].parent)  # slacs0029-0055, whose MASS fitted X2+point
    table = lens_table(lens_folders, reference).set_index("lens")
    assert list(table["light_chosen_by"]) == ["sheet", "evidence", "sheet"]  # M1 sorts first
    chosen = table.loc["slacs0029-0055"]
    assert chosen["light_model"] == "X2+point"
    assert chosen["light_evidence_margin"] == pytest.approx(100.0 - 103.0)
    assert table.loc[["M1", "slacs0037-0942"], "light_evidence_margin"].isna().all()
    candidates = light_model_table(
        (path.parent.name, path.parent) for path in lens_folders
    ).set_index("candidate")
    assert list(candidates.columns) == [c for c in LIGHT_MODEL_COLUMNS if c != "candidate"]
    assert set(candidates["lens"]) == {"slacs0029-0055"}
    for label, ln_z, chi2, n_linear, n_free in CANDIDATES:
        row = candidates.loc[label]
        assert (row["log_evidence"], row["chi_squared"]) == (ln_z, chi2)
        assert (row["n_linear"], row["n_free"], row["converged"]) == (n_linear, n_free, True)
        assert row["chosen"] == (label == "X2+point")


def test_a_choice_that_light_no_longer_holds_is_ignored(lens_folders, reference, caplog):
    """After the sheet pins the model, LIGHT's own fit replaces the adopted candidate."""
    folder = lens_folders[0].parent
    write_choice(folder, chosen_label="X6+point")  # MASS fitted X2+point, pinned since
    write_json(folder / "light" / "result.json", {"pinned": "X2+point"})
    table = lens_table(lens_folders, reference).set_index("lens")
    assert table.loc["slacs0029-0055", "light_chosen_by"] == "sheet"
    assert math.isnan(table.loc["slacs0029-0055", "light_evidence_margin"])
    assert "does not hold its chosen candidate X6+point" in caplog.text
    assert light_model_table([("slacs0029-0055", folder)]).empty


def test_lens_table_refuses_a_choice_that_mass_did_not_fit(lens_folders, reference):
    folder = lens_folders[0].parent
    write_choice(folder, chosen_label="X6+point")
    with pytest.raises(ValueError, match=r"MASS fitted X2\+point but model_choice.json chose "
                                         r"X6\+point; rerun choose_light and MASS"):  # fmt: skip
        lens_table(lens_folders, reference)
    (folder / "model_choice.json").write_text('{"chosen": "X2+point"}')
    with pytest.raises(ValueError, match=r"model_choice.json: not a model-choice record"):
        lens_table(lens_folders, reference)


def test_lens_table_names_missing_fit_files(lens_folders, reference):
    (lens_folders[0].parent / "quality.json").unlink()
    with pytest.raises(ValueError, match=r"slacs0029-0055: .*quality.json not found"):
        lens_table(lens_folders, reference)


def test_einstein_radius_figure(lens_folders, reference, tmp_path):
    table = lens_table(lens_folders, reference)
    figure = einstein_radius_figure(table)
    bolton, shajib = figure.axes
    texts = [t.get_text() for t in bolton.texts]
    assert any(t.startswith("y = a·x: a = ") and "(2 lenses)" in t for t in texts)
    shajib_texts = [t.get_text() for t in shajib.texts]
    assert any(t.endswith("(1 lens)") and "±" not in t for t in shajib_texts)
    assert "slacs0029-0055" not in texts  # 1.6 % off Bolton: not named
    legend = [t.get_text() for t in bolton.get_legend().get_texts()]
    assert "residuals flagged" in legend
    assert "lensing flagged" not in legend
    crossed = [line for line in bolton.lines if line.get_label() == "MASS not converged"]
    epl = table.set_index("lens").loc["slacs0037-0942"]  # its MASS missed its peak
    np.testing.assert_allclose(crossed[0].get_xydata(), [[epl["bolton_b_sie"], epl["theta_e_lt"]]])
    edged = [line for line in bolton.lines if line.get_label() == "MASS at a prior bound"]
    assert len(edged) == 1  # its slope at the bound; the other's "none", the mock's empty
    assert edged[0].get_marker() == "^"
    np.testing.assert_allclose(edged[0].get_xydata(), [[epl["bolton_b_sie"], epl["theta_e_lt"]]])
    table.loc[table["lens"] == "slacs0029-0055", "lensing_flag"] = True
    bolton = einstein_radius_figure(table).axes[0]
    boxed = [line for line in bolton.lines if line.get_label() == "lensing flagged"]
    assert len(boxed) == 1
    assert boxed[0].get_marker() == "s"
    sie = table.set_index("lens").loc["slacs0029-0055"]
    np.testing.assert_allclose(boxed[0].get_xydata(), [[sie["bolton_b_sie"], sie["theta_e_lt"]]])
    save_png(figure, tmp_path / "einstein.png")
    empty = einstein_radius_figure(table[table["lens"] == "M1"])
    for ax in empty.axes:
        assert [t.get_text() for t in ax.texts] == ["no published values"]


SLOPES = pd.DataFrame(
    {
        "lens": ["above", "below", "close", "unpublished"],
        "slope": [2.40, 1.95, 2.10, 2.0],
        "slope_err_lo": [0.02, 0.01, 0.02, 0.02],
        "slope_err_hi": [0.03, 0.04, 0.02, 0.02],
        "shajib_gamma": [2.10, 2.30, 2.15, math.nan],
        "shajib_gamma_err_lo": [0.05, 0.10, 0.05, math.nan],
        "shajib_gamma_err_hi": [0.06, 0.02, 0.05, math.nan],
        "quality_flag": [False, True, False, False],
    }
)


def test_slope_differences_use_the_errors_that_face_each_other():
    differences = slope_differences(SLOPES).set_index("lens")
    assert list(differences.index) == ["above", "below", "close"]  # no published slope
    # above: our lower and their upper error; below: our upper and their lower one
    np.testing.assert_allclose(differences["difference"], [0.30, -0.35, -0.05], atol=1e-12)
    facing = [math.hypot(0.02, 0.06), math.hypot(0.04, 0.10), math.hypot(0.02, 0.05)]
    np.testing.assert_allclose(differences["sigma"], facing)
    # 4.7σ and 3.25σ apart; "close" is 0.9σ apart
    assert list(differences["tension"]) == [True, True, False]
    assert SLOPE_TENSION == 3.0


def test_slope_figure_names_the_lenses_in_tension(tmp_path):
    figure = slope_figure(SLOPES)
    ax = figure.axes[0]
    assert ax.get_xlabel().startswith("Shajib et al. 2021")
    assert ax.get_ylabel() == r"mgelens $\gamma$ (MASS)"
    texts = [t.get_text() for t in ax.texts]
    assert any(t.startswith("mean γ − γ_Shajib = -0.033 (3 lenses)") for t in texts)
    names = sorted(t for t in texts if not t.startswith("mean"))
    assert names == ["above (+4.7σ)", "below (-3.2σ)"]
    circled = [line for line in ax.lines if line.get_label() == "residuals flagged"]
    np.testing.assert_allclose(circled[0].get_xydata(), [[2.30, 1.95]])  # x Shajib's, y ours
    low, high = ax.get_xlim()
    assert low <= 1.5  # the default range holds every point
    assert high >= 2.7
    save_png(figure, tmp_path / "slopes.png")
    assert (tmp_path / "slopes.png").read_bytes()[:8] == PNG_SIGNATURE
    empty = slope_figure(SLOPES[SLOPES["lens"] == "unpublished"])
    assert [t.get_text() for t in empty.axes[0].texts] == ["no published slopes"]


def test_residual_mosaic_has_one_panel_per_lens_in_arcsec(lens_folders, tmp_path):
    panels = [
        read_panel(
            path.parent / "mass" / "model.fits",
            path.parent.name,
            "X2",
            json.loads((path.parent / "quality.json").read_text()),
        )
        for path in lens_folders
    ]
    assert [p.state for p in panels] == ["ok", "FLAG", "n/a"]
    assert [p.lensing_flag for p in panels] == [False, False, True]
    figure = residual_mosaic(panels)
    images = [ax for ax in figure.axes if ax.images and ax.get_title()]
    assert [ax.get_title() for ax in images] == [p.lens for p in panels]
    for ax, panel in zip(images, panels, strict=True):
        image = ax.images[0]
        assert image.origin == "lower"  # row index = +y
        np.testing.assert_array_equal(image.get_array(), panel.nresid)
        assert image.get_extent() == pytest.approx([-2.05, 2.05, -2.05, 2.05])
        assert image.get_clim() == (-3.5, 3.5)
        assert ax.get_xlim() == pytest.approx((-1.9, 1.9))  # mask radius + one pixel
        assert ax.get_ylim() == pytest.approx((-1.9, 1.9))
        lensing = {"LENSING"} if panel.lensing_flag else set()
        assert {t.get_text() for t in ax.texts} == {"X2", panel.state} | lensing
    colour_bars = [ax for ax in figure.axes if ax.get_ylabel() == "(data − model)/σ [σ]"]
    assert len(colour_bars) == 1
    flagged = images[1].lines[0].get_xydata()[0]
    assert tuple(flagged) == (1.0, -0.5)
    save_png(figure, tmp_path / "mosaic.png")
    assert residual_mosaic([]).axes[0].texts[0].get_text() == "no lens"


def test_summary_command(tmp_path, lens_folders, reference, capsys):
    out = tmp_path / "out"
    names = ("out-figure", "out-einstein", "out-mosaic", "out-slopes")
    figures = {name: out / f"{name}.png" for name in names}
    arguments = ["summary", *map(str, lens_folders), "--out-table", str(out / "lenses.csv")]
    arguments += [f"--{name}={path}" for name, path in figures.items()]
    write_choice(lens_folders[0].parent)
    arguments += ["--out-light-models", str(out / "light_models.csv")]
    assert main([*arguments, "--reference-dir", str(reference)]) == 0
    candidates = pd.read_csv(out / "light_models.csv")
    assert list(candidates["candidate"]) == [c[0] for c in CANDIDATES]
    assert list(candidates["chosen"]) == [True, False, False]
    table = pd.read_csv(out / "lenses.csv")
    assert list(table["lens"]) == sorted(FITS)
    assert list(table["quality_flag"].astype("boolean")) == [pd.NA, False, True]
    for path in figures.values():
        assert path.read_bytes()[:8] == PNG_SIGNATURE
    printed = capsys.readouterr().out
    assert "lenses: 3 (3 with isophotes)" in printed
    assert "complex_fraction: 0.000" in printed
    assert "quality_flagged: 1 of 2 measured" in printed
    assert "singly_imaged_flagged: 1 of 1 measured" in printed
    assert "lensing_flagged: 1 of 3" in printed
    assert "mass_unconverged: 1 of 3 ['slacs0037-0942']" in printed
    assert "prior_edge: 1 of 2 ['slacs0037-0942']" in printed
    assert "light_models_chosen: {'X2+point': 1} (1 by evidence)" in printed
    assert "theta_e_lt_vs_bolton: a = " in printed
    assert "theta_e_lt_vs_shajib: a = 0.958 (1 lens)" in printed
    assert "slope_vs_shajib: 1 lens, mean difference +0.010, beyond 3 sigma: none" in printed
    assert "(2 lenses)" in printed
    assert main([*arguments, "--reference-dir", str(tmp_path / "absent")]) == 0
    assert pd.read_csv(out / "lenses.csv")["bolton_b_sie"].isna().all()
    assert "slope_vs_shajib: 0 lenses\n" in capsys.readouterr().out


def test_summary_command_refuses_lenses_without_fits(tmp_path, summaries, caplog):
    out = tmp_path / "out"
    arguments = ["summary", *map(str, summaries), "--out-table", str(out / "lenses.csv")]
    arguments += [
        f"--{name}={out / name}.png" for name in ("out-figure", "out-einstein", "out-mosaic")
    ]
    assert main(arguments) == 1
    assert "J0001: " in caplog.text
    assert "result.json not found" in caplog.text
    assert not out.exists()
    arguments[1 : 1 + len(summaries)] = [str(tmp_path / "nope.json")]
    assert main(arguments) == 1


def test_a_summary_written_before_the_source_share_reads_as_undefined(summaries):
    content = json.loads(summaries[0].read_text())
    del content["statistics"]["a4_a_source_share"]
    summaries[0].write_text(json.dumps(content))
    row = sample_table(summaries).set_index("lens").loc[content["lens"]]
    assert math.isnan(row["a4_a_source_share"])
    assert row["delta_q_max"] == pytest.approx(LENSES[content["lens"]][0])


def test_lens_table_says_where_the_source_pixel_count_came_from(lens_folders, reference):
    """``source_pixels_chosen_by`` is ``evidence`` while spix2/ holds the candidate that
    ``source_pixels_choice.json`` chose, ``config`` once SPix2 is fitted with one count."""
    lens = lens_folders[0].parent
    result = lens / "mass" / "result.json"
    write_json(
        result,
        {
            **json.loads(result.read_text()),
            "max_likelihood_fit": light_record(("set_0", "set_1"), 1000),
        },
    )
    for name in ("spix2", "spix2_n1000"):
        write_json(lens / name / "result.json", {"log_evidence": 2.0})
    write_json(lens / "source_pixels_choice.json", {"chosen": 1000, "candidates": []})
    row = lens_table(lens_folders, reference).set_index("lens").loc[lens.name]
    assert (row["source_pixels"], row["source_pixels_chosen_by"]) == (1000, "evidence")
    write_json(lens / "spix2" / "result.json", {"log_evidence": 3.0})
    row = lens_table(lens_folders, reference).set_index("lens").loc[lens.name]
    assert row["source_pixels_chosen_by"] == "config"

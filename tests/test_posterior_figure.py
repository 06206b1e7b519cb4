"""The posterior corner figure: its contour levels hold the stated weight, its lines are
result.json's numbers, and angles and truths land on the samples' side of 180°."""

import json
from pathlib import Path

import numpy as np
import pytest
from matplotlib import colors
from matplotlib.lines import Line2D
from sampler_outputs import equal_weight_run

from mgelens.cli import main
from mgelens.coverage import PARAMETERS
from mgelens.geometry import ell_comps_from
from mgelens.plot.posterior import (
    CONTOUR_FRACTIONS,
    LABELS,
    PUBLISHED_COLOUR,
    TRUTH_COLOUR,
    credible_levels,
    posterior_figure,
    published_references,
)
from mgelens.search.model import ParameterSpace
from mgelens.search.priors import Uniform
from mgelens.search.results import PhaseResult

MASS_NAMES = (
    "mass.centre_x",
    "mass.centre_y",
    "mass.ell_comps_1",
    "mass.ell_comps_2",
    "mass.einstein_radius",
    "mass.slope",
    "shear.gamma_1",
    "shear.gamma_2",
)


def mass_result(angle: float = 3.0, n: int = 3000, seed: int = 1) -> PhaseResult:
    """Equal-weight MASS-like samples: q 0.8 at ``angle`` degrees (near 0°, so the
    samples straddle the 180° wrap), θ_E 1.2″ and γ 2.05 anti-correlated (ρ −0.8)."""
    rng = np.random.default_rng(seed)
    e1, e2 = ell_comps_from(0.8, angle)
    centre = np.array([0.01, -0.02, e1, e2, 1.2, 2.05, 0.03, -0.01])
    scale = np.array([0.002, 0.002, 0.01, 0.01, 0.003, 0.03, 0.004, 0.004])
    draws = rng.standard_normal((n, centre.size))
    draws[:, 5] = -0.8 * draws[:, 4] + 0.6 * draws[:, 5]
    samples = centre + scale * draws
    space = ParameterSpace.from_priors({name: Uniform(-5.0, 5.0) for name in MASS_NAMES})
    output = equal_weight_run(MASS_NAMES, samples, -0.5 * np.sum(draws**2, axis=1))
    return PhaseResult("mass", space, output)


def test_credible_levels_hold_their_fraction_of_a_gaussian():
    """For a finely binned 2D Gaussian the 39.3 % and 86.5 % regions are the 1σ and 2σ
    ellipses: their thresholds are exp(−r²/2) at r = 1 and 2 (relative to the peak)."""
    x = np.linspace(-6, 6, 601)
    density = np.exp(-0.5 * (x[:, None] ** 2 + x[None, :] ** 2))
    levels = credible_levels(density, CONTOUR_FRACTIONS)
    assert levels / density.max() == pytest.approx(np.exp(-0.5 * np.array([1.0, 4.0])), rel=0.01)
    for level, fraction in zip(levels, CONTOUR_FRACTIONS, strict=True):
        held = density[density >= level].sum() / density.sum()
        assert fraction <= held < fraction + 0.002


def test_credible_levels_reject_an_empty_density_and_bad_fractions():
    with pytest.raises(ValueError, match="no positive weight"):
        credible_levels(np.zeros((3, 3)), [0.5])
    with pytest.raises(ValueError, match="fractions"):
        credible_levels(np.ones((3, 3)), [1.5])


def _diagonal_lines(figure, n):
    axes = figure.axes
    return [
        [line.get_xdata()[0] for line in axes[i * n + i].get_lines() if isinstance(line, Line2D)]
        for i in range(n)
    ]


def test_corner_lines_are_the_results_median_and_interval_and_the_truth():
    phase = mass_result()
    truth = {
        "mass.centre_x": 0.011,
        "mass.centre_y": -0.021,
        "mass.einstein_radius": 1.201,
        "mass.axis_ratio": 0.8,
        "mass.angle": 183.0,  # the same axis as 3°: drawn on the samples' side
        "mass.slope": 2.0,
        "shear.gamma_1": 0.03,
        "shear.gamma_2": -0.01,
    }
    figure = posterior_figure(phase, truth, title="mock")
    names = list(PARAMETERS)  # every one sampled, in the coverage tables' order
    n = len(names)
    assert len(figure.axes) == n * n
    assert [figure.axes[(n - 1) * n + i].get_xlabel() for i in range(n)] == [
        LABELS[name] for name in names
    ]
    interval = phase.interval(1)
    for name, lines in zip(names, _diagonal_lines(figure, n), strict=True):
        median, lower, upper, true = lines
        if name == "mass.angle":
            # result.json reduces the angle to [0°, 180°); samples near 0° may draw it at
            # −3° or 177°: the drawn lines are the reported ones up to one turn of 180°
            turn = median - phase.median[name]
            assert turn in (0.0, -180.0)
            assert (lower - turn, upper - turn) == pytest.approx(interval[name])
            assert abs(true - median) < 5.0  # 183° drawn beside the samples
        else:
            assert median == pytest.approx(phase.median[name])
            assert (lower, upper) == pytest.approx(interval[name])
            assert true == pytest.approx(truth[name])
    slope_vs_radius = figure.axes[5 * n + 2]
    truth_lines = [
        line
        for line in slope_vs_radius.get_lines()
        if colors.same_color(line.get_color(), TRUTH_COLOUR)
    ]
    assert {tuple(np.ravel(line.get_xydata())[:2]) for line in truth_lines} >= {
        (truth["mass.einstein_radius"], truth["mass.slope"])
    }
    assert slope_vs_radius.collections  # filled credible regions drawn


def test_the_filled_region_of_a_degenerate_pair_follows_its_correlation():
    """θ_E and γ are drawn anti-correlated: the 1σ region's vertices run from upper left
    to lower right."""
    figure = posterior_figure(mass_result())
    n = 8
    axis = figure.axes[5 * n + 2]  # γ (row 5) against θ_E (column 2)
    vertices = np.concatenate(
        [path.vertices for c in axis.collections for path in c.get_paths() if len(path.vertices)]
    )
    assert np.corrcoef(vertices[:, 0], vertices[:, 1])[0, 1] < -0.5


def test_a_phase_without_mass_parameters_is_refused():
    space = ParameterSpace.from_priors({"regularization.coefficient": Uniform(0.0, 1.0)})
    output = equal_weight_run(
        ["regularization.coefficient"], np.random.default_rng(0).random((50, 1)), np.zeros(50)
    )
    with pytest.raises(ValueError, match="sampled none of the mass"):
        posterior_figure(PhaseResult("spix1", space, output))


def test_command_draws_a_written_phase_with_a_mocks_truth(tmp_path):
    """End to end: result.json and samples.csv written by the phase, truth.json of a
    population mock's recipe (EPL + shear), one PNG out."""
    mass_result().write(tmp_path / "L" / "mass")
    truth = {
        "mass": [
            {
                "type": "EPL",
                "parameters": {
                    "centre": [0.01, -0.02],
                    "einstein_radius": 1.2,
                    "axis_ratio": 0.8,
                    "angle": 3.0,
                    "slope": 2.05,
                },
            },
            {"type": "ExternalShear", "parameters": {"gamma_1": 0.03, "gamma_2": -0.01}},
        ]
    }
    (tmp_path / "truth.json").write_text(json.dumps(truth))
    out = tmp_path / "figures" / "posterior.png"
    arguments = ["posterior", "--phase", str(tmp_path / "L" / "mass"), "--out", str(out)]
    assert main([*arguments, "--truth", str(tmp_path / "truth.json")]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_command_names_a_missing_phase_and_a_bad_truth(tmp_path, caplog):
    out = tmp_path / "posterior.png"
    assert main(["posterior", "--phase", str(tmp_path / "none"), "--out", str(out)]) == 1
    assert "result.json not found" in caplog.text
    mass_result().write(tmp_path / "mass")
    (tmp_path / "truth.json").write_text('{"mass": [{"type": "SIE", "parameters": {}}]}')
    arguments = ["posterior", "--phase", str(tmp_path / "mass"), "--out", str(out)]
    assert main([*arguments, "--truth", str(tmp_path / "truth.json")]) == 1
    assert "cannot read the true mass" in caplog.text
    assert not out.exists()


def test_published_references_convert_bolton_to_our_convention_and_keep_shajibs_errors():
    """b_SIE is an SIE's intermediate-axis radius: θ_E^AG = b_SIE (1 + q) / (2 √q) (SPEC
    §3.3 at γ = 2); Shajib's slope keeps its asymmetric errors; missing values are left out."""
    row = {"bolton_b_sie": 1.2, "bolton_q_sie": 0.64, "shajib_gamma": 1.92}
    row |= {"shajib_gamma_lo": 0.045, "shajib_gamma_hi": 0.079}
    references = published_references(row)
    assert references["mass.einstein_radius"] == pytest.approx((1.2 * 1.64 / 1.6, 0.0, 0.0))
    assert references["mass.slope"] == (1.92, 0.045, 0.079)
    assert published_references({"bolton_b_sie": float("nan"), "shajib_gamma": float("nan")}) == {}


def test_published_values_are_drawn_beside_the_posterior():
    """A published value inside the posterior's range is a line (and its 1σ band on the
    diagonal); one beyond it is written at that edge and leaves the range alone."""
    phase = mass_result()
    inside = posterior_figure(phase, published={"mass.slope": (2.06, 0.04, 0.06)})
    n = 8
    slope = inside.axes[5 * n + 5]
    published_lines = [
        line.get_xdata()[0]
        for line in slope.get_lines()
        if colors.same_color(line.get_color(), PUBLISHED_COLOUR)
    ]
    assert published_lines == [2.06]
    assert slope.patches  # the 1σ band
    joint = inside.axes[5 * n + 2]  # γ against θ_E: a horizontal line at 2.06
    drawn = [
        tuple(line.get_ydata())
        for line in joint.get_lines()
        if colors.same_color(line.get_color(), PUBLISHED_COLOUR)
    ]
    assert drawn == [(2.06, 2.06)]
    far = posterior_figure(phase, published={"mass.slope": (1.80, 0.04, 0.06)})
    slope_far = far.axes[5 * n + 5]
    assert slope_far.get_xlim() == slope.get_xlim()
    assert [t.get_text() for t in slope_far.texts] == ["← 1.8"]


def test_command_marks_a_real_lenses_published_values(tmp_path):
    reference_dir = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "reference"
    if not (reference_dir / "bolton2008_table5_sie.csv").is_file():
        pytest.skip(f"published reference tables absent: expected them in {reference_dir}")
    mass_result().write(tmp_path / "mass")
    out = tmp_path / "posterior.png"
    arguments = ["posterior", "--phase", str(tmp_path / "mass"), "--out", str(out)]
    arguments += ["--lens", "slacs1250+0523", "--reference-dir", str(reference_dir)]
    assert main(arguments) == 0
    assert out.stat().st_size > 20_000


def test_a_pooled_phase_shows_each_meshs_share_of_the_marginal():
    """MASS pools its meshes' runs (samples in turn, counts in settings' meshes): each
    run's share is drawn on the diagonal, and the shares add up to the pooled marginal."""
    phase = mass_result(n=3000)
    meshes = [{"kmeans_seed": 0, "n_samples": 1200}, {"kmeans_seed": 1, "n_samples": 1800}]
    pooled = PhaseResult("mass", phase.space, phase.output, settings={"meshes": meshes})
    figure = posterior_figure(pooled)
    slope = figure.axes[5 * 8 + 5]
    heights = [patch.get_path().vertices[:, 1] for patch in slope.patches]
    assert len(heights) == 3  # the pool and its two meshes
    assert np.allclose(heights[0], heights[1] + heights[2])
    assert "k-means seed 0 blue, 1 orange" in figure.get_suptitle()
    unaccounted = [{"kmeans_seed": 0, "n_samples": 1000}, {"kmeans_seed": 1, "n_samples": 1000}]
    other = PhaseResult("mass", phase.space, phase.output, settings={"meshes": unaccounted})
    assert len(posterior_figure(other).axes[5 * 8 + 5].patches) == 1

"""Likelihood smoothness in the mass slope (the paper's Appendix A; SPEC §11).

On an M1-like mock, with everything but the EPL slope fixed and NNLS on, the log evidence
of natural-neighbour interpolation + cross regularization varies smoothly with γ, while
nearest-cell mapping + neighbour regularization jumps between adjacent steps.

A "jump" is the change between adjacent steps minus the local trend (the running median
of the changes over ±5 steps): the evidence itself slopes by several units per step away
from its peak. Edge pixels are not forced to zero here: that anchor rule (SPEC §6.3) makes
the evidence jump whenever a source pixel joins or leaves the convex hull of the mesh.

The largest jump depends on the mesh: over k-means seeds 1–7 the natural-neighbour + cross
scheme had 95th-percentile jumps of 0.25–0.50 but maxima of 1.0–4.7, against 95th
percentiles of 7.5–8.9 and maxima of 12–23 for nearest-cell + neighbour. The test
therefore scans three meshes, and asserts what held on every mesh measured (meshes of
scikit-learn's Lloyd iterations and of the compiled ones, which break equal-distance
ties differently; docs/slam.md, "Smoothness of the evidence on other meshes"). The rare
large steps were traced to three anchor rules that
are discontinuous by construction, each seen directly in the weights of single steps:

* a traced mesh centre joins the convex hull (SPEC §4.3): on seed 1 the two largest jumps
  (1.8, 2.1) are the two steps where the hull grows (34 → 35 → 36 points), ln det H
  jumping by 0.4–0.5; neighbour regularization jumps at the same steps;
* border relocation moves a point to the radius of its *nearest* border point (SPEC §4.2);
  when that nearest point switches, the demagnified central sub-pixels and relocated mesh
  centres jump by 0.02–0.04″ in one step (7 sub-pixels per step on seed 2). Without the
  border the 95th percentiles fall to 0.11–0.29;
* sub-pixels outside the hull take their nearest mesh point's flux (SPEC §4.4), and the
  area cap of the cross offsets counts hull cells as −1 (§4.3).

``FitSettings(edge_rule="continuous")`` replaces these three rules by continuous ones
(border polygon, Sibson weights over a ringed mesh, ringed cell areas). With it the
evidence is a continuous function of γ: the step-to-step roughness vanishes (median jump
< 0.001 against 0.03–0.06) and halving the step halves even the largest remaining jumps,
whereas the anchor's largest jumps (2.4 on seed 1, 1.5 on seed 3) keep their size at any
step. Those remaining jumps of the continuous rule are steep but continuous features:
seed 2's (4.7, the same with the anchor's rules) is where two traced mesh centres, k-means
centres on two images of the same source spot, pass within 6e−5″ of each other and their
shared Voronoi boundary turns round; seed 1's largest (0.65) is a pair of kinks in ln det H
a quarter of a step apart. With the paper's 1500 source pixels the continuous rule meets
the paper's criterion, no jump above 0.5, on meshes 1–3 (largest 0.41, 0.46, 0.23; mesh 4:
0.88), where the anchor's rules jump by 1.69 and 1.48 (meshes 1–2).
"""

import numpy as np
import pytest

from mgelens.mask import circular
from mgelens.mock_lenses import paper_mock
from mgelens.simulate import simulate
from mgelens.smoothness import evidence_scan as scheme_scan
from mgelens.smoothness import jumps, mock_dataset, scan_model
from mgelens.source.regularization import AdaptiveBrightnessSplit, Constant, ConstantSplit

STEP = 0.0004
N_STEPS = 200
N_SOURCE_PIXELS = 500
MESH_SEEDS = (1, 2, 3)


def scan_setup(dataset, lens, adapt, n_pixels, seed):
    """(dataset, scan model) of a scan: the true EPL, two MGE sets, k-means mesh centres."""
    model = scan_model(dataset, lens.mass[0], adapt, lens.mask_radius, n_pixels, seed)
    return dataset, model


@pytest.fixture(scope="module", params=MESH_SEEDS)
def m1_setup(request, m1_dataset):
    dataset, lens, adapt = m1_dataset
    return scan_setup(dataset, lens, adapt, N_SOURCE_PIXELS, request.param)


@pytest.fixture(scope="module")
def continuous_dataset(m1_dataset):
    """The same mock, mask and settings with the continuous edge rule."""
    dataset, lens, _ = m1_dataset
    centre = tuple(lens.mass[0].centre)
    return mock_dataset(dataset.imaging, dataset.mask, centre, edge_rule="continuous")


@pytest.fixture(scope="module")
def cross_scan(m1_setup):
    """The evidence scan of natural-neighbour + constant cross regularization."""
    return evidence_scan(m1_setup, "natural_neighbour", ConstantSplit(1.0))


@pytest.fixture(scope="module")
def m1_dataset():
    lens = paper_mock("M1")
    mock = simulate(lens)
    imaging = mock.imaging
    mask = circular(imaging.shape, imaging.pixel_scale, lens.mask_radius)
    dataset = mock_dataset(imaging, mask, tuple(lens.mass[0].centre))
    return dataset, lens, mock.lensed_source_blurred[~mask]


def evidence_scan(
    m1_setup, interpolation, regularization, adapt_image=None, dataset=None, steps=None
):
    """ln ε at the slopes truth − STEP·N_STEPS/2 + STEP·k, k = ``steps`` (default
    0 … N_STEPS − 1), on ``dataset`` (default the setup's)."""
    setup_dataset, model = m1_setup
    dataset = setup_dataset if dataset is None else dataset
    steps = np.arange(N_STEPS) if steps is None else steps
    slopes = model.mass.slope - STEP * N_STEPS / 2 + STEP * steps
    return scheme_scan(dataset, model, interpolation, slopes, regularization, adapt_image)


def refined_jump(m1_setup, step, n_sub, dataset=None):
    """The largest jump within step ``step`` … ``step + 1`` cut into ``n_sub`` sub-steps
    (|sub-step change − their median|): a discontinuity keeps its size as ``n_sub``
    grows, a continuous feature shrinks in proportion."""
    values = evidence_scan(
        m1_setup, "natural_neighbour", ConstantSplit(1.0), dataset=dataset,
        steps=np.linspace(step, step + 1, n_sub + 1),
    )  # fmt: skip
    changes = np.diff(values)
    return np.abs(changes - np.median(changes)).max()


@pytest.mark.slow
def test_natural_neighbour_cross_scheme_is_smooth_and_nearest_cell_is_not(m1_setup, cross_scan):
    rough = evidence_scan(m1_setup, "nearest", Constant(1.0))
    smooth_jumps, rough_jumps = jumps(cross_scan), jumps(rough)
    assert np.percentile(smooth_jumps, 95) < 0.6
    assert np.percentile(rough_jumps, 95) > 3.0
    assert smooth_jumps.max() < 5.0
    assert rough_jumps.max() > 10.0
    assert smooth_jumps.max() < 0.5 * rough_jumps.max()


@pytest.mark.slow
def test_the_continuous_edge_rule_makes_the_evidence_continuous(
    m1_setup, cross_scan, continuous_dataset
):
    """The continuous rule's median jump is < 0.001 on every mesh, the anchor's 0.017 to
    0.059 (docs/slam.md, "Smoothness of the evidence on other meshes"); the continuous
    rule's largest jump shrinks when its step is refined, and one of the anchor's two
    largest does not."""
    anchor = jumps(cross_scan)
    continuous = jumps(
        evidence_scan(m1_setup, "natural_neighbour", ConstantSplit(1.0), dataset=continuous_dataset)
    )
    assert np.median(continuous) < 0.005
    assert np.median(anchor) > 0.01
    assert np.percentile(continuous, 95) < 0.4
    largest = int(np.argmax(continuous))
    coarse, fine = (refined_jump(m1_setup, largest, n, continuous_dataset) for n in (10, 20))
    assert fine < 0.65 * coarse
    # a discontinuity among the anchor's two largest jumps (seed 2's largest is the
    # continuous site-crossing feature, the same under both rules)
    refined = [
        (refined_jump(m1_setup, int(i), 10), refined_jump(m1_setup, int(i), 20))
        for i in np.argsort(anchor)[-2:]
    ]
    assert any(fine > 0.85 * coarse and fine > 0.5 for coarse, fine in refined)


@pytest.mark.slow
def test_with_the_papers_1500_pixels_the_continuous_rule_leaves_rare_jumps_below_one(
    m1_dataset, continuous_dataset
):
    """At the paper's source resolution (1500 k-means pixels, mesh seed 1) with
    natural-neighbour interpolation, cross regularization and the continuous edge rule,
    the median jump is below 0.02, the 95th percentile below 0.3 and the largest below
    1.0, where the anchor's edge rules jump by 1.5–1.7 (95th percentiles 0.44–0.57) and
    nearest-cell mapping by 12–23. The paper's criterion, no jump above 0.5, holds on some
    meshes and not on others (largest jumps over seven meshes 0.23–0.88; docs/slam.md,
    "Smoothness of the evidence on other meshes"), so it is not asserted."""
    _, lens, adapt = m1_dataset
    setup = scan_setup(continuous_dataset, lens, adapt, 1500, 1)
    scan_jumps = jumps(evidence_scan(setup, "natural_neighbour", ConstantSplit(1.0)))
    assert scan_jumps.max() < 1.0
    assert np.percentile(scan_jumps, 95) < 0.3
    assert np.median(scan_jumps) < 0.02


@pytest.mark.slow
@pytest.mark.parametrize("m1_setup", [1], indirect=True)
def test_weighted_adaptive_signals_remove_the_small_steps(m1_setup, m1_dataset, continuous_dataset):
    """Adaptive cross regularization with M2's SPix2 hyper-parameters (λ_in ≈ 0,
    λ_out = 12.7, κ_s = 0.127) under the continuous edge rule, as the quick profile runs
    it: the anchor's per-count signal average moves at most steps (median jump > 0.03),
    the interpolation-weighted average leaves rare steps only (median < 0.01). Those rare
    steps can be larger than the anchor average's (docs/slam.md, "Smoothness of the
    evidence"), so only the medians are compared."""
    adapt = m1_dataset[2]
    scans = {
        signals: jumps(
            evidence_scan(
                m1_setup,
                "natural_neighbour",
                AdaptiveBrightnessSplit(3e-5, 12.7, 0.127, signals=signals),
                adapt,
                dataset=continuous_dataset,
            )
        )
        for signals in ("anchor", "weighted")
    }
    assert np.median(scans["anchor"]) > 0.03
    assert np.median(scans["weighted"]) < 0.01

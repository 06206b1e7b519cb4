"""Result files: write/read round trip, samples.csv, weighted quantiles, prior passing."""

import hashlib
import json
import math

import numpy as np
import pandas as pd
import pytest
from sampler_outputs import equal_weight_run

from mgelens.geometry import axis_ratio_and_angle_from, ell_comps_from
from mgelens.search.model import Parameter, ParameterSpace
from mgelens.search.posterior import SamplerOutput, credible_interval, weighted_quantile
from mgelens.search.priors import Gaussian, LogUniform, TruncatedGaussian, Uniform, WidthModifier
from mgelens.search.results import (
    PhaseResult,
    collect_versions,
    file_sha256,
    input_checksums,
    passed_priors,
    prior_edges,
)
from mgelens.search.sampler_settings import SamplerSettings

N = 2000
E1, E2 = ell_comps_from(0.7, 178.0)  # the angle posterior straddles 0°/180°
LIMITS = {
    "mass.ell_comps_1": (-1.0, 1.0),
    "mass.ell_comps_2": (-1.0, 1.0),
    "mass.einstein_radius": (0.0, math.inf),
    "regularization.coefficient": (0.0, math.inf),
}
"""The limits the model declares (as mgelens.pipeline.parameters would)."""
WIDTHS = {
    "mass.centre_x": WidthModifier("absolute", 0.05),
    "mass.centre_y": WidthModifier("absolute", 0.05),
    "mass.ell_comps_1": WidthModifier("absolute", 0.2),
    "mass.einstein_radius": WidthModifier("relative", 0.25),
    "regularization.coefficient": WidthModifier("relative", 0.5),
}


@pytest.fixture(scope="module")
def result() -> PhaseResult:
    priors = {
        "mass.centre_x": Gaussian(0.0, 0.1),
        "mass.ell_comps_1": TruncatedGaussian(0.0, 0.3, -1.0, 1.0),
        "mass.ell_comps_2": TruncatedGaussian(0.0, 0.3, -1.0, 1.0),
        "mass.einstein_radius": Uniform(0.0, 8.0),
        "shear.gamma_1": Uniform(-0.2, 0.2),
        "shear.gamma_2": Uniform(-0.2, 0.2),
        "regularization.coefficient": LogUniform(1e-6, 1e6),
    }
    space = (
        ParameterSpace(
            tuple(Parameter(n, prior=p, limits=LIMITS.get(n)) for n, p in priors.items())
        )
        .with_parameter(Parameter("mass.centre_y", value=0.02))
        .with_parameter(Parameter("lens_light.centre_x", tied_to="mass.centre_x"))
    )
    rng = np.random.default_rng(7)
    centre = [0.01, E1, E2, 1.2, 0.03, -0.02, 30.0]
    scale = [0.01, 0.01, 0.01, 0.02, 0.005, 0.005, 5.0]
    samples = rng.normal(centre, scale, size=(N, 7))
    log_likelihoods = -0.5 * np.sum(((samples - centre) / scale) ** 2, axis=1)
    log_likelihoods[:3] = -1e99  # rejected samples carry no weight
    raw = log_likelihoods + rng.normal(0.0, 0.5, N)
    output = SamplerOutput(
        names=space.free_names,
        samples=samples,
        log_weights=raw - np.logaddexp.reduce(raw),
        log_likelihoods=log_likelihoods,
        log_evidence=-12.5,
        log_evidence_error=0.2,
        n_calls=12345,
        n_rejected=17,
        runtime=3.5,
        n_resumes=1,
        method="dynesty_static",
        settings=SamplerSettings().to_dict(),
        seed=3,
    )
    return PhaseResult(
        phase="source_lp",
        space=space,
        output=output,
        settings={"mask_radius": 3.0, "sets": (2, 30)},
        input_checksums={"data.fits": "0" * 64},
    )


def test_write_read_round_trip(result, tmp_path):
    result.write(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.json", "samples.csv"]
    again = PhaseResult.read(tmp_path)
    assert again == result
    assert again.median == result.median
    assert again.interval(3) == result.interval(3)
    assert again.settings["sets"] == [2, 30]  # settings are stored as JSON


def test_result_json_content(result, tmp_path):
    result.write(tmp_path)

    def refuse(constant):
        raise ValueError(f"non-standard JSON constant {constant}")

    content = json.loads((tmp_path / "result.json").read_text(), parse_constant=refuse)
    assert content["phase"] == "source_lp"
    assert content["log_evidence"] == -12.5
    assert content["sampler"]["n_rejected"] == 17
    assert content["sampler"]["seed"] == 3
    assert set(content["versions"]) >= {"python", "mgelens", "numpy", "scipy", "dynesty"}
    expected = [
        "mass.centre_x",
        "mass.ell_comps_1",
        "mass.ell_comps_2",
        "mass.axis_ratio",
        "mass.angle",
        "mass.einstein_radius",
        "shear.gamma_1",
        "shear.gamma_2",
        "shear.magnitude",
        "shear.angle",
        "regularization.coefficient",
        "mass.centre_y",
        "lens_light.centre_x",
    ]
    for key in ("max_likelihood", "median", "interval_1sigma", "interval_3sigma"):
        assert list(content[key]) == expected
    assert content["median"]["mass.centre_y"] == 0.02
    assert content["interval_3sigma"]["mass.centre_y"] == [0.02, 0.02]
    assert content["median"]["lens_light.centre_x"] == content["median"]["mass.centre_x"]


def test_samples_csv_columns(result, tmp_path):
    result.write(tmp_path)
    table = pd.read_csv(tmp_path / "samples.csv")
    assert list(table.columns[:3]) == ["weight", "log_weight", "log_likelihood"]
    assert "mass.axis_ratio" in table.columns
    assert len(table) == N
    assert table["weight"].sum() == pytest.approx(1.0)
    np.testing.assert_array_equal(table["mass.einstein_radius"], result.output.samples[:, 3])
    np.testing.assert_array_equal(table["log_likelihood"], result.output.log_likelihoods)


def test_max_likelihood_with_derived_values(result):
    best = result.max_likelihood
    row = result.output.samples[np.argmax(result.output.log_likelihoods)]
    assert best["mass.einstein_radius"] == row[3]
    q, angle = axis_ratio_and_angle_from((row[1], row[2]))
    assert (best["mass.axis_ratio"], best["mass.angle"]) == (q, angle)
    assert best["shear.magnitude"] == pytest.approx(math.hypot(row[4], row[5]))


def test_weighted_quantile_matches_numpy():
    rng = np.random.default_rng(1)
    values = rng.normal(size=(500, 3))
    weights = rng.exponential(size=500)
    weights[:50] = 0.0
    q = np.array([0.00135, 0.1587, 0.5, 0.8413, 0.99865])
    ours = weighted_quantile(values, weights, q)
    for j in range(3):
        reference = np.quantile(values[:, j], q, weights=weights, method="inverted_cdf")
        np.testing.assert_array_equal(ours[:, j], reference)
    lower, upper = credible_interval(values, weights, sigma=1)
    np.testing.assert_array_equal(lower, ours[1])
    np.testing.assert_array_equal(upper, ours[3])
    with pytest.raises(ValueError, match="weights"):
        weighted_quantile(values, -weights, 0.5)


def test_median_and_intervals_are_weighted_quantiles(result):
    weights = result.output.weights
    radius = result.output.samples[:, 3]
    p1, p3 = math.erf(1 / math.sqrt(2)), math.erf(3 / math.sqrt(2))
    q = [0.5, (1 - p1) / 2, (1 + p1) / 2, (1 - p3) / 2, (1 + p3) / 2]
    expected = np.quantile(radius, q, weights=weights, method="inverted_cdf")
    assert result.median["mass.einstein_radius"] == expected[0]
    assert result.interval(1)["mass.einstein_radius"] == tuple(expected[1:3])
    assert result.interval(3)["mass.einstein_radius"] == tuple(expected[3:5])
    assert result.median["mass.einstein_radius"] == pytest.approx(1.2, abs=0.005)


def test_derived_angle_interval_stays_contiguous(result):
    median = result.median["mass.angle"]
    lower, upper = result.interval(1)["mass.angle"]
    assert 0.0 <= median < 180.0
    assert median == pytest.approx(178.0, abs=0.5)
    assert lower < median < upper
    assert upper - lower < 5.0  # not ~180°, although samples wrap around 0°/180°
    assert result.median["mass.axis_ratio"] == pytest.approx(0.7, abs=0.01)


def test_passed_priors_from_a_result(result):
    priors = passed_priors(
        result,
        ["mass.centre_x", "mass.einstein_radius", "mass.ell_comps_1", "mass.centre_y"],
        widths=WIDTHS,
    )
    median, interval = result.median, result.interval(3)

    def half_width(name):
        return max(interval[name][1] - median[name], median[name] - interval[name][0])

    centre = priors["mass.centre_x"]
    assert centre.mean == median["mass.centre_x"]
    assert centre.sigma == max(half_width("mass.centre_x"), 0.05)
    assert (centre.lower, centre.upper) == (-math.inf, math.inf)
    radius = priors["mass.einstein_radius"]
    assert radius.sigma == pytest.approx(0.25 * median["mass.einstein_radius"])
    assert (radius.lower, radius.upper) == (0.0, math.inf)
    assert (priors["mass.ell_comps_1"].lower, priors["mass.ell_comps_1"].upper) == (-1.0, 1.0)
    # a parameter fixed before gets the width alone (SPEC §8.2: freed centre → N(c, 0.05″))
    assert (priors["mass.centre_y"].mean, priors["mass.centre_y"].sigma) == (0.02, 0.05)

    wide = passed_priors(
        result, ["regularization.coefficient"], rule="2024", limits={}, widths=WIDTHS
    )
    coefficient = wide["regularization.coefficient"]
    assert coefficient.sigma == pytest.approx(0.5 * median["regularization.coefficient"])
    assert coefficient.lower == 0.0
    clipped = passed_priors(
        result, ["mass.centre_x"], limits={"mass.centre_x": (-0.5, 0.5)}, widths=WIDTHS
    )
    assert clipped["mass.centre_x"].upper == 0.5
    with pytest.raises(KeyError, match="not a parameter"):
        passed_priors(result, ["mass.slope"], widths=WIDTHS)


def test_checksums_and_versions(tmp_path):
    path = tmp_path / "data.fits"
    path.write_bytes(b"lens" * 100_000)
    assert file_sha256(path) == hashlib.sha256(b"lens" * 100_000).hexdigest()
    assert input_checksums([path]) == {str(path): file_sha256(path)}
    versions = collect_versions()
    assert versions["numpy"] == np.__version__


def test_mismatched_output_is_refused(result):
    space = ParameterSpace.from_priors({"mass.centre_x": Gaussian(0.0, 0.1)})
    with pytest.raises(ValueError, match="do not match"):
        PhaseResult(phase="x", space=space, output=result.output)


def _written_record(space, samples, tmp_path) -> dict:
    """The result.json record of equally weighted ``samples`` of ``space``'s free
    parameters, as a phase writes it."""
    output = equal_weight_run(space.free_names, samples, np.zeros(len(samples)))
    PhaseResult(phase="mass", space=space, output=output, settings={}).write(tmp_path)
    return json.loads((tmp_path / "result.json").read_text())


def test_prior_edges_names_a_posterior_cut_by_its_prior(result, tmp_path):
    """A slope piled at the EPL prior's lower bound 1.5 and a shear piled at its upper
    bound are named; a shear whose 3σ interval ends 1σ from its bound is not, nor are the
    fixture's parameters under Gaussian and wide priors."""
    space = ParameterSpace(
        (
            Parameter("mass.slope", prior=Uniform(1.5, 3.0)),
            Parameter("shear.gamma_1", prior=Uniform(-0.2, 0.2)),
            Parameter("shear.gamma_2", prior=Uniform(-0.2, 0.2)),
        )
    )
    rng = np.random.default_rng(3)
    n = 4000
    slope = 1.5 + np.abs(rng.normal(0.0, 0.01, n))  # half a Gaussian against the bound
    inside = rng.normal(0.1, 0.01, n)  # its 3σ end 7σ from the upper bound
    near = rng.normal(-0.16, 0.01, n)  # its 3σ end 1σ from the lower bound
    record = _written_record(space, np.column_stack([slope, inside, near]), tmp_path / "a")
    assert prior_edges(record) == ["mass.slope at its lower bound 1.5"]
    piled = 0.2 - np.abs(rng.normal(0.0, 0.01, n))
    record = _written_record(space, np.column_stack([slope, piled, near]), tmp_path / "b")
    assert prior_edges(record) == [
        "mass.slope at its lower bound 1.5",
        "shear.gamma_1 at its upper bound 0.2",
    ]
    result.write(tmp_path / "fixture")
    assert prior_edges(json.loads((tmp_path / "fixture" / "result.json").read_text())) == []

"""The peak check of a nested-sampling run (mgelens.search.peak_check) and the restarts
it drives in run_nested (SamplerSettings.peak_restarts)."""

import dataclasses

import numpy as np
import pytest
from sampler_outputs import equal_weight_run

from mgelens.search import peak_check
from mgelens.search.model import ParameterSpace
from mgelens.search.posterior import SamplerOutput, pool_runs
from mgelens.search.priors import TruncatedGaussian, Uniform
from mgelens.search.sampler import run_nested
from mgelens.search.sampler_settings import SamplerSettings

SPACE = ParameterSpace.from_priors({"toy.a": Uniform(-5.0, 5.0), "toy.b": Uniform(-5.0, 5.0)})
PEAK = np.array([0.4, -0.2])
COVARIANCE = np.array([[0.04, 0.0396], [0.0396, 0.04]])
"""A narrow ridge: σ 0.2 on each axis, correlation 0.99 (σ 0.028 across the ridge)."""
PEAK_LOG_L = 100.0


def ridge(x: np.ndarray) -> float:
    offset = np.asarray(x) - PEAK
    return float(PEAK_LOG_L - 0.5 * offset @ np.linalg.solve(COVARIANCE, offset))


def run_around(
    centre: np.ndarray, n: int = 2000, seed: int = 1, scale: float = 1.0
) -> SamplerOutput:
    """Equal-weight samples of the ridge's shape, ``scale`` times its variance, centred on
    ``centre``: a narrow cloud away from the peak is what a run whose live points stayed
    on one part of the ridge returns."""
    samples = np.random.default_rng(seed).multivariate_normal(centre, scale * COVARIANCE, n)
    log_likelihoods = np.array([ridge(x) for x in samples])
    return equal_weight_run(SPACE.free_names, samples, log_likelihoods, {"n_live": 10})


def test_the_search_climbs_a_ridge_to_a_peak_the_posterior_misses():
    """A narrow cloud 4σ up the ridge from its peak: the search reaches the analytic peak,
    and its gain is the peak's ln L minus the best sample's."""
    along = np.array([0.2, 0.2])  # one σ along the ridge on each axis
    missed = run_around(PEAK + 4 * along, scale=0.05)
    gain, calls = peak_check.peak_gain(ridge, SPACE, missed, 400)
    assert gain == pytest.approx(PEAK_LOG_L - missed.log_likelihoods.max(), abs=0.02)
    assert gain > 5.0
    assert 0 < calls <= 420
    found = run_around(PEAK)
    gain, _ = peak_check.peak_gain(ridge, SPACE, found, 400)
    assert gain == pytest.approx(PEAK_LOG_L - found.log_likelihoods.max(), abs=0.02)
    assert gain < 0.05  # 2,000 samples of a 2-D Gaussian come within ~0.003 of its peak


def test_the_search_stays_inside_the_priors():
    """A peak beyond the prior's edge: the search stops at the edge (the gain is what is
    reachable inside the support) and never calls the likelihood outside it."""
    space = ParameterSpace.from_priors({"toy.a": Uniform(-5.0, 0.3), "toy.b": Uniform(-5.0, 5.0)})
    outside = []

    def guarded(x):
        if x[0] > 0.3:
            outside.append(x)
        return ridge(x)

    missed = run_around(PEAK - 3 * np.array([0.2, 0.2]), scale=0.05)
    gain, _ = peak_check.peak_gain(guarded, space, missed, 400)
    assert not outside
    assert 0.0 < gain < PEAK_LOG_L - missed.log_likelihoods.max()


def test_the_search_climbs_the_posterior_not_the_likelihood():
    """A Gaussian likelihood (σ 0.1 at 0) under a passed prior N(1, 0.1) in tension with it:
    the posterior is N(0.5, 0.071), whose samples come no closer than about 0.25 to the
    likelihood's peak, 3 below it in ln L. The check climbs ln L + ln prior, whose maximum
    the samples do reach, so it gains almost nothing; climbing ln L alone would gain 3
    and restart a posterior that is right."""
    space = ParameterSpace.from_priors(
        {"toy.a": TruncatedGaussian(1.0, 0.1, -np.inf, np.inf), "toy.b": Uniform(-5.0, 5.0)}
    )

    def likelihood(x):
        return float(-0.5 * ((x[0] / 0.1) ** 2 + (x[1] / 0.1) ** 2))

    rng = np.random.default_rng(2)
    samples = np.column_stack([rng.normal(0.5, 0.1 / np.sqrt(2), 2000), rng.normal(0.0, 0.1, 2000)])
    log_likelihoods = np.array([likelihood(x) for x in samples])
    output = equal_weight_run(space.free_names, samples, log_likelihoods, {"n_live": 10})
    assert -log_likelihoods.max() > 2.0  # ln L's own peak is 0
    gain, _ = peak_check.peak_gain(likelihood, space, output, 400)
    assert gain < 0.05
    # the posterior's maximum, at (0.5, 0): the best sample's ln L + ln prior is within
    # the gain of it
    log_posteriors = log_likelihoods + np.array([space.log_prior(x) for x in samples])
    peak = likelihood(np.array([0.5, 0.0])) + space.log_prior(np.array([0.5, 0.0]))
    assert peak - log_posteriors.max() == pytest.approx(gain, abs=0.01)


class Gains:
    """Stands for peak_check.peak_gain: the given gains in turn, 7 calls each."""

    def __init__(self, *gains):
        self.gains, self.runs = list(gains), []

    def __call__(self, log_likelihood, space, output, max_evaluations):
        self.runs.append(output)
        return self.gains.pop(0), 7


def gaussian(x):
    return float(-0.5 * np.sum(((np.asarray(x) - PEAK) / 0.3) ** 2))


FAST = SamplerSettings(n_live=20, sample="rwalk", dlogz=0.5, progress_every=1e9)


def test_a_run_that_misses_the_peak_restarts_with_twice_the_live_points(monkeypatch):
    gains = Gains(4.5, 0.3)
    monkeypatch.setattr(peak_check, "peak_gain", gains)
    settings = dataclasses.replace(FAST, peak_restarts=2)
    lines: list[str] = []
    output = run_nested(gaussian, SPACE, settings, seed=3, log=lines.append)
    assert any("restart 1 of 2 with 40 live points and seed 4" in line for line in lines)
    fresh = run_nested(gaussian, SPACE, dataclasses.replace(FAST, n_live=40), seed=4)
    np.testing.assert_array_equal(output.samples, fresh.samples)
    assert (output.settings["n_live"], output.seed) == (40, 4)
    assert output.converged
    assert output.peak_gain == 0.3
    first = gains.runs[0]
    assert output.n_calls == first.n_calls + fresh.n_calls + 2 * 7
    assert "attempt 2, live points 20, 40" in output.stop_reason


def test_a_run_that_keeps_missing_the_peak_is_not_converged(monkeypatch):
    monkeypatch.setattr(peak_check, "peak_gain", Gains(4.5, 3.0))
    settings = dataclasses.replace(FAST, peak_restarts=1, peak_tolerance=2.5)
    output = run_nested(gaussian, SPACE, settings, seed=3, log=lambda _: None)
    assert not output.converged
    assert output.peak_gain == 3.0
    assert "gained 3.00 over its best sample (more than 2.5)" in output.stop_reason
    assert output.statistics()["peak_gain"] == 3.0


def test_a_run_that_holds_its_peak_is_kept_as_it_is():
    """The real check on a converged toy run: it gains almost nothing, so no restart;
    the run is the one without the check, its calls plus the search's."""
    settings = dataclasses.replace(FAST, peak_restarts=2)
    checked = run_nested(gaussian, SPACE, settings, seed=3, log=lambda _: None)
    plain = run_nested(gaussian, SPACE, FAST, seed=3, log=lambda _: None)
    np.testing.assert_array_equal(checked.samples, plain.samples)
    assert checked.converged
    assert checked.settings["n_live"] == 20
    assert 0.0 <= checked.peak_gain < 0.5
    assert plain.peak_gain is None
    assert checked.n_calls > plain.n_calls


REFERENCE = np.array([-3.0, 3.0])
"""A point 10σ from the Gaussian's peak (ln L −100 there), where a spike can hide."""


def spiked(x):
    """The Gaussian, with ln L 10 at exactly :data:`REFERENCE`: a peak no run can find."""
    return 10.0 if np.array_equal(x, REFERENCE) else gaussian(x)


def no_search(*_):
    raise AssertionError("peak_evaluations = 0 runs no local search")


def test_a_run_below_its_reference_point_samples_again(monkeypatch):
    """The reference's ln L (10) is far above every sample's (≤ 0): the run misses it, is
    sampled again with twice the live points, misses again and is not converged; the
    reference costs one call, and no local search runs."""
    monkeypatch.setattr(peak_check, "peak_gain", no_search)
    settings = dataclasses.replace(FAST, peak_restarts=1, peak_evaluations=0)
    lines: list[str] = []
    output = run_nested(spiked, SPACE, settings, seed=3, log=lines.append, reference=REFERENCE)
    first = run_nested(spiked, SPACE, FAST, seed=3, log=lambda _: None)
    second = run_nested(spiked, SPACE, dataclasses.replace(FAST, n_live=40), seed=4)
    np.testing.assert_array_equal(output.samples, second.samples)
    assert any("restart 1 of 1 with 40 live points and seed 4" in line for line in lines)
    assert any("the reference point has ln L 10.00" in line for line in lines)
    assert output.n_calls == first.n_calls + second.n_calls + 1
    assert output.peak_gain == pytest.approx(10.0 - second.log_likelihoods.max())
    assert not output.converged
    assert f"gained {output.peak_gain:.2f} over its best sample" in output.stop_reason


def test_a_run_above_its_reference_point_is_kept_as_it_is(monkeypatch):
    """A reference in the far tail (ln L −100) says nothing against the run: no restart,
    the run without the check plus one call, a peak gain of 0."""
    monkeypatch.setattr(peak_check, "peak_gain", no_search)
    settings = dataclasses.replace(FAST, peak_restarts=1, peak_evaluations=0)
    checked = run_nested(gaussian, SPACE, settings, seed=3, log=lambda _: None, reference=REFERENCE)
    plain = run_nested(gaussian, SPACE, FAST, seed=3, log=lambda _: None)
    np.testing.assert_array_equal(checked.samples, plain.samples)
    assert checked.converged
    assert checked.peak_gain == 0.0
    assert checked.n_calls == plain.n_calls + 1


def test_the_larger_of_the_search_and_the_reference_is_the_gain(monkeypatch):
    """With both checks, the gain is the larger: a search gaining 0.5 and a reference
    10 above the run's best (as a spike) restart the run; one that gains 4.5 and a
    reference in the far tail restart it too, with the search's gain."""
    monkeypatch.setattr(peak_check, "peak_gain", Gains(0.5, 0.4))
    settings = dataclasses.replace(FAST, peak_restarts=1)
    output = run_nested(spiked, SPACE, settings, seed=3, log=lambda _: None, reference=REFERENCE)
    assert output.settings["n_live"] == 40
    assert output.peak_gain > 9.0
    monkeypatch.setattr(peak_check, "peak_gain", Gains(4.5, 0.4))
    output = run_nested(gaussian, SPACE, settings, seed=3, log=lambda _: None, reference=REFERENCE)
    assert output.settings["n_live"] == 40
    assert output.peak_gain == 0.4
    assert output.converged


def test_without_a_search_or_a_reference_nothing_is_checked(monkeypatch):
    """peak_evaluations 0 and no usable reference (none, or outside the priors): the run
    as it is, peak_gain None (not a passed check), no extra call."""
    monkeypatch.setattr(peak_check, "peak_gain", no_search)
    settings = dataclasses.replace(FAST, peak_restarts=1, peak_evaluations=0)
    plain = run_nested(spiked, SPACE, FAST, seed=3, log=lambda _: None)
    outside = np.array([9.0, 0.0])  # beyond Uniform(-5, 5)
    for reference in (None, outside):
        lines: list[str] = []
        output = run_nested(spiked, SPACE, settings, seed=3, log=lines.append, reference=reference)
        np.testing.assert_array_equal(output.samples, plain.samples)
        assert output.peak_gain is None
        assert output.n_calls == plain.n_calls
        assert any("no peak check" in line for line in lines)


def test_pooled_runs_keep_the_largest_peak_gain():
    runs = [
        dataclasses.replace(run_around(PEAK, 50, seed), peak_gain=g)
        for seed, g in ((1, 0.2), (2, 1.1))
    ]
    assert pool_runs(runs).peak_gain == 1.1
    assert pool_runs([run_around(PEAK, 50)] * 2).peak_gain is None


@pytest.mark.parametrize(
    ("field", "value"), [("peak_restarts", -1), ("peak_tolerance", 0.0), ("peak_evaluations", -1)]
)
def test_peak_settings_are_validated(field, value):
    with pytest.raises(ValueError, match=field):
        SamplerSettings(**{field: value})


def test_a_run_that_did_not_converge_is_not_checked(monkeypatch):
    """A capped run is reported as unconverged; more live points would not lift the cap."""
    gains = Gains(9.0)
    monkeypatch.setattr(peak_check, "peak_gain", gains)
    capped = dataclasses.replace(FAST, peak_restarts=2, max_iterations=5)
    output = run_nested(gaussian, SPACE, capped, seed=3, log=lambda _: None)
    assert not output.converged
    assert output.peak_gain is None
    assert not gains.runs


def clouds_around(*centres):
    """Stands for sampler._sample_with_plateau_restarts: each attempt returns 500
    equal-weight samples (σ 0.05) of the Gaussian around the next of ``centres``."""
    runs = iter(centres)

    def clouds(evaluation, settings, checkpoint, seed, log, live_reference=None):
        samples = np.random.default_rng(seed).normal(next(runs), 0.05, (500, 2))
        log_likelihoods = np.array([gaussian(x) for x in samples])
        return equal_weight_run(
            SPACE.free_names, samples, log_likelihoods, {"n_live": settings.n_live}, seed
        )

    return clouds


LOW = PEAK + np.array([3.0, 0.0])
"""(3.0 / 0.3)² / 2 = 50 below the Gaussian's peak in ln L."""


def test_a_restart_that_settles_below_the_run_it_replaces_still_misses(monkeypatch):
    """The first run (around the Gaussian's peak, ln L ≤ 0) fails its local search; every
    restart returns a cloud around a lower point (ln L ≈ −50) whose own neighbourhood is
    flat to the search. Each restart's best sample lies about 50 below the first run's, so
    it misses the peak too: both restarts run, and the phase is not converged, its gain
    the shortfall (as on slacs1451−0239's MASS, a 60-point restart 22.6 below the 30-point
    run it replaced)."""
    from mgelens.search import sampler

    monkeypatch.setattr(peak_check, "peak_gain", Gains(4.5, 0.3, 0.3))
    monkeypatch.setattr(sampler, "_sample_with_plateau_restarts", clouds_around(PEAK, LOW, LOW))
    settings = dataclasses.replace(FAST, peak_restarts=2)
    lines: list[str] = []
    output = run_nested(gaussian, SPACE, settings, seed=3, log=lines.append)
    assert sum("restart" in line and "live points and seed" in line for line in lines) == 2
    assert output.settings["n_live"] == 80
    assert not output.converged
    assert 40.0 < output.peak_gain < 55.0  # the clouds reach within ~0.2 of their centres
    assert any("the earlier attempts' highest ln L + ln prior is" in line for line in lines)


def test_a_restart_that_climbs_above_the_run_it_replaces_is_kept(monkeypatch):
    """The mirror case: the first run sits in the lower cloud and the restart around the
    peak; the restart is 50 above, its own search flat, so it is kept, converged."""
    from mgelens.search import sampler

    monkeypatch.setattr(peak_check, "peak_gain", Gains(4.5, 0.3))
    monkeypatch.setattr(sampler, "_sample_with_plateau_restarts", clouds_around(LOW, PEAK))
    output = run_nested(gaussian, SPACE, dataclasses.replace(FAST, peak_restarts=2), seed=3)
    assert output.converged
    assert output.settings["n_live"] == 40
    assert output.peak_gain == 0.3

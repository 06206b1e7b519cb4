"""A reference point among a static dynesty run's first live points
(SamplerSettings.reference_live_point, an option for SP and its start)."""

import dataclasses
import json

import numpy as np
import pytest

from mgelens.search.model import ParameterSpace
from mgelens.search.priors import TruncatedGaussian, Uniform
from mgelens.search.sampler import CheckpointMismatchError, run_nested
from mgelens.search.sampler_settings import SamplerSettings

SPACE = ParameterSpace.from_priors(
    {
        "toy.a": Uniform(-5.0, 5.0),
        "toy.b": TruncatedGaussian(0.0, 2.0, -5.0, 5.0),
        "toy.c": Uniform(-5.0, 5.0),
    }
)
BROAD = np.zeros(3)
NARROW = np.array([3.2, -2.9, 3.1])
NARROW_SIGMA, NARROW_LOG_L = 0.2, 8.0
"""A narrow peak in a corner far from a broad one (σ 1, ln L 0): its evidence,
(2π)^1.5 0.2³ e⁸ ≈ 376 against (2π)^1.5 ≈ 16 of the broad peak, makes it the posterior
(0.96 of it), but it fills about 10⁻⁴ of the prior, and 20 live points drawn from the
prior often settle in the broad peak (seed 2 does, below)."""


def two_peaks(x) -> float:
    x = np.asarray(x)
    broad = -0.5 * np.sum((x - BROAD) ** 2)
    narrow = NARROW_LOG_L - 0.5 * np.sum(((x - NARROW) / NARROW_SIGMA) ** 2)
    return float(np.logaddexp(broad, narrow))


FAST = SamplerSettings(n_live=20, sample="rwalk", dlogz=0.5, progress_every=1e9)
SEEDED = dataclasses.replace(FAST, reference_live_point=True)


def test_unit_cube_inverts_the_prior_transform():
    u = np.random.default_rng(0).random((50, 3))
    for row in u:
        np.testing.assert_allclose(SPACE.unit_cube(SPACE.prior_transform(row)), row, atol=1e-12)
    with pytest.raises(ValueError, match="length 3"):
        SPACE.unit_cube(np.zeros(2))


def test_prior_draws_alone_miss_the_narrow_peak():
    """The control of the next test: the same run without the reference settles in the
    broad peak."""
    plain = run_nested(two_peaks, SPACE, FAST, seed=2, log=lambda _: None, reference=NARROW)
    assert plain.log_likelihoods.max() < 1.0


def test_a_reference_live_point_holds_a_peak_the_prior_draws_miss():
    """Seeded with the narrow peak's centre, the run's best sample is at least the
    reference's ln L and its posterior sits on the narrow peak."""
    lines: list[str] = []
    seeded = run_nested(two_peaks, SPACE, SEEDED, seed=2, log=lines.append, reference=NARROW)
    assert seeded.converged
    assert seeded.log_likelihoods.max() >= two_peaks(NARROW)
    weights = np.exp(seeded.log_weights)
    mean = weights @ seeded.samples
    np.testing.assert_allclose(mean, NARROW, atol=0.3)
    near = np.linalg.norm(seeded.samples - NARROW, axis=1) < 3 * NARROW_SIGMA
    assert weights[near].sum() > 0.9
    assert any("the reference point (ln L 8.00) replaces the lowest" in line for line in lines)


def test_without_the_setting_the_reference_is_not_a_live_point():
    """reference_live_point off (both profiles' default): the reference changes nothing in
    the run."""
    with_reference = run_nested(
        two_peaks, SPACE, FAST, seed=2, log=lambda _: None, reference=NARROW
    )
    without = run_nested(two_peaks, SPACE, FAST, seed=2, log=lambda _: None)
    np.testing.assert_array_equal(with_reference.samples, without.samples)


def test_a_reference_outside_the_priors_is_not_used():
    lines: list[str] = []
    outside = np.array([6.0, 0.0, 0.0])
    seeded = run_nested(two_peaks, SPACE, SEEDED, seed=2, log=lines.append, reference=outside)
    plain = run_nested(two_peaks, SPACE, FAST, seed=2, log=lambda _: None)
    np.testing.assert_array_equal(seeded.samples, plain.samples)
    assert any("lies outside the priors: not used" in line for line in lines)


def test_a_checkpoint_of_another_reference_is_refused(tmp_path):
    checkpoint = tmp_path / "sampler.pickle"
    run_nested(two_peaks, SPACE, SEEDED, checkpoint, seed=2, log=lambda _: None, reference=NARROW)
    stored = json.loads(checkpoint.with_suffix(".fingerprint.json").read_text())
    assert stored["live_reference"] == pytest.approx(NARROW.tolist())
    with pytest.raises(CheckpointMismatchError):
        run_nested(
            two_peaks, SPACE, SEEDED, checkpoint, seed=2, log=lambda _: None, reference=BROAD
        )


def test_the_setting_is_dynesty_static_only():
    with pytest.raises(ValueError, match="reference_live_point applies to method dynesty_static"):
        SamplerSettings(method="nautilus", reference_live_point=True)
    with pytest.raises(ValueError, match="reference_live_point must be true or false"):
        SamplerSettings(reference_live_point=1)

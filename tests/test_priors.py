"""Priors: unit-cube transforms against scipy.stats, validation, JSON, prior passing."""

import json
import math

import numpy as np
import pytest
from scipy import stats

from mgelens.mass import SLOPE_RANGE
from mgelens.pipeline.parameters import lens_parameter, limits_of, width_of
from mgelens.search.priors import (
    Gaussian,
    LogUniform,
    PriorTransform,
    TruncatedGaussian,
    Uniform,
    WidthModifier,
    passed_prior,
    prior_from_dict,
)

ABSOLUTE = WidthModifier("absolute", 0.2)
RELATIVE_QUARTER = WidthModifier("relative", 0.25)

U = np.concatenate([[1e-6, 1e-4], np.linspace(0.001, 0.999, 999), [1 - 1e-4, 1 - 1e-6]])


def test_uniform_matches_scipy():
    prior = Uniform(-2.0, 3.0)
    reference = stats.uniform(loc=-2.0, scale=5.0)
    np.testing.assert_allclose(prior.transform(U), reference.ppf(U), rtol=1e-10, atol=1e-10)
    x = np.array([-2.5, -1.0, 2.9, 3.5])
    np.testing.assert_allclose(prior.log_prob(x), reference.logpdf(x), rtol=1e-10)


def test_log_uniform_matches_scipy():
    prior = LogUniform(1e-6, 1e6)
    reference = stats.loguniform(1e-6, 1e6)
    np.testing.assert_allclose(prior.transform(U), reference.ppf(U), rtol=1e-10)
    x = np.array([1e-7, 1e-3, 10.0, 1e5, 1e7])
    np.testing.assert_allclose(prior.log_prob(x), reference.logpdf(x), rtol=1e-10)


def test_gaussian_matches_scipy():
    prior = Gaussian(0.3, 0.1)
    reference = stats.norm(0.3, 0.1)
    np.testing.assert_allclose(prior.transform(U), reference.ppf(U), rtol=1e-10, atol=1e-12)
    x = np.linspace(-1.0, 1.0, 11)
    np.testing.assert_allclose(prior.log_prob(x), reference.logpdf(x), rtol=1e-10)
    assert (prior.lower, prior.upper) == (-math.inf, math.inf)


@pytest.mark.parametrize(
    ("mean", "sigma", "lower", "upper"),
    [
        (0.0, 0.3, -1.0, 1.0),
        (0.8, 0.2, -1.0, 1.0),
        (1.2, 0.3, 0.0, math.inf),
        (0.0, 1.0, -math.inf, 0.5),
        (0.0, 1.0, 5.0, 10.0),
        (0.0, 1.0, -10.0, -5.0),
        (0.0, 1.0, 30.0, math.inf),
        (0.0, 1.0, -40.0, -38.0),
        (0.0, 1.0, -3.0, 12.0),
    ],
)
def test_truncated_gaussian_matches_scipy(mean, sigma, lower, upper):
    prior = TruncatedGaussian(mean, sigma, lower, upper)
    a, b = (lower - mean) / sigma, (upper - mean) / sigma
    reference = stats.truncnorm(a, b, loc=mean, scale=sigma)
    np.testing.assert_allclose(prior.transform(U), reference.ppf(U), rtol=1e-10, atol=1e-10)
    x = reference.ppf(np.array([0.01, 0.3, 0.5, 0.9, 0.99]))
    np.testing.assert_allclose(prior.log_prob(x), reference.logpdf(x), rtol=1e-9)


CDF_CASES = [
    (Uniform(-2.0, 3.0), stats.uniform(loc=-2.0, scale=5.0)),
    (LogUniform(1e-6, 1e6), stats.loguniform(1e-6, 1e6)),
    (Gaussian(0.3, 0.1), stats.norm(0.3, 0.1)),
    (TruncatedGaussian(0.8, 0.2, -1.0, 1.0), stats.truncnorm(-9.0, 1.0, loc=0.8, scale=0.2)),
    (TruncatedGaussian(0.0, 1.0, 5.0, 10.0), stats.truncnorm(5.0, 10.0)),
    (TruncatedGaussian(0.0, 1.0, -10.0, -5.0), stats.truncnorm(-10.0, -5.0)),
    (TruncatedGaussian(0.0, 1.0, -3.0, 12.0), stats.truncnorm(-3.0, 12.0)),
]


@pytest.mark.parametrize(("prior", "reference"), CDF_CASES)
def test_cdf_matches_scipy_and_inverts_the_transform(prior, reference):
    """cdf is scipy's CDF (inside the support) and maps transform(u) back to u, deep
    into both tails of the truncated Gaussians too."""
    x = reference.ppf(np.array([1e-6, 0.01, 0.3, 0.5, 0.9, 0.99, 1 - 1e-6]))
    np.testing.assert_allclose(prior.cdf(x), reference.cdf(x), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(prior.cdf(prior.transform(U)), U, rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize(("prior", "reference"), CDF_CASES)
def test_cdf_outside_the_support_is_clipped(prior, reference):
    below, above = reference.ppf(0.0) - 1.0, reference.ppf(1.0) + 1.0
    assert prior.cdf(below) == 0.0 or not math.isfinite(below)
    assert prior.cdf(above) == 1.0 or not math.isfinite(above)
    assert prior.cdf(-1e300) == 0.0
    assert prior.cdf(1e300) == 1.0


@pytest.mark.parametrize(("lower", "upper"), [(-1.0, 1.0), (5.0, 10.0), (-math.inf, 0.5)])
def test_truncated_gaussian_ends_stay_in_support(lower, upper):
    prior = TruncatedGaussian(0.0, 1.0, lower, upper)
    u = np.array([0.0, 1e-300, 1e-16, 0.5, 1 - 1e-16, 1.0])
    x = prior.transform(u)
    assert x[0] == lower
    assert x[-1] == upper
    assert np.all(np.diff(x) >= 0)
    assert np.all((x >= lower) & (x <= upper))
    assert np.all(np.isinf(prior.log_prob(np.array([lower - 1.0, upper + 1.0]))))


@pytest.mark.parametrize(
    "prior",
    [
        Uniform(0.0, 8.0),
        LogUniform(1e-3, 1e3),
        Gaussian(0.0, 0.3),
        TruncatedGaussian(0, 0.3, -1, 1),
    ],
)
def test_transform_keeps_array_shape(prior):
    u = np.random.default_rng(1).random((3, 4))
    x = prior.transform(u)
    assert x.shape == (3, 4)
    np.testing.assert_array_equal(x[1], prior.transform(u[1]))


@pytest.mark.parametrize(
    "build",
    [
        lambda: Uniform(1.0, 1.0),
        lambda: Uniform(2.0, 1.0),
        lambda: Uniform(0.0, math.inf),
        lambda: Uniform(math.nan, 1.0),
        lambda: LogUniform(0.0, 1.0),
        lambda: LogUniform(-1.0, 1.0),
        lambda: LogUniform(1.0, 0.5),
        lambda: Gaussian(0.0, 0.0),
        lambda: Gaussian(0.0, -1.0),
        lambda: Gaussian(math.nan, 1.0),
        lambda: TruncatedGaussian(0.0, 1.0, 1.0, -1.0),
        lambda: TruncatedGaussian(0.0, 1.0, 1.0, 1.0),
        lambda: TruncatedGaussian(0.0, 0.0, -1.0, 1.0),
        lambda: TruncatedGaussian(0.0, 1.0, math.nan, 1.0),
    ],
)
def test_invalid_parameters_raise(build):
    with pytest.raises(ValueError, match=r"lower|sigma|finite"):
        build()


@pytest.mark.parametrize(
    "prior",
    [
        Uniform(-0.2, 0.2),
        LogUniform(1e-6, 1e6),
        Gaussian(0.1, 0.05),
        TruncatedGaussian(1.2, 0.3, 0.0, math.inf),
        TruncatedGaussian(0.0, 1.0, -math.inf, math.inf),
    ],
)
def test_json_round_trip(prior):
    text = json.dumps(prior.to_dict(), allow_nan=False)
    assert prior_from_dict(json.loads(text)) == prior


def test_unknown_prior_type_raises():
    with pytest.raises(ValueError, match="unknown prior type"):
        prior_from_dict({"type": "Cauchy", "mean": 0.0})


# -- prior passing (SPEC §8.2) --------------------------------------------------------------
@pytest.mark.parametrize(
    ("name", "median", "half_width", "paper_sigma", "sigma_2024"),
    [
        ("mass.centre_x", 0.01, 0.02, 0.05, 0.05),
        ("lens_light.centre_y", 0.01, 0.3, 0.3, 0.05),
        ("mass.ell_comps_1", 0.1, 0.05, 0.2, 0.2),
        ("lens_light.set_1.ell_comps_2", -0.1, 0.25, 0.25, 0.2),
        ("mass.einstein_radius", 1.2, 0.1, 0.3, 0.3),
        ("mass.einstein_radius", 1.2, 0.5, 0.5, 0.3),
        ("mass.slope", 2.1, 0.05, 0.2, 0.2),
        ("shear.gamma_1", 0.02, 0.01, 0.05, 0.05),
        ("shear.gamma_2", -0.02, 0.08, 0.08, 0.05),
        ("regularization.inner_coefficient", 4.0, 1.0, 2.0, 2.0),
        ("regularization.coefficient", 4.0, 3.0, 3.0, 2.0),
        ("source.set_0.something_else", -2.0, 0.1, 1.0, 1.0),
    ],
)
def test_passed_prior_widths(name, median, half_width, paper_sigma, sigma_2024):
    paper = passed_prior(name, median, half_width, width_of(name))
    modern = passed_prior(name, median, half_width, width_of(name), rule="2024")
    assert paper.mean == modern.mean == median
    assert paper.sigma == pytest.approx(paper_sigma, rel=1e-12)
    assert modern.sigma == pytest.approx(sigma_2024, rel=1e-12)


def test_width_modifier_matches_last_component():
    assert width_of("mass.einstein_radius").kind == "relative"
    assert width_of("lens_light.set_3.centre_x").value == 0.05
    assert width_of("einstein_radius_extra").value == 0.5


def test_lens_model_limits_by_last_component():
    assert limits_of("lens_light.set_2.ell_comps_1") == (-1.0, 1.0)
    assert limits_of("mass.einstein_radius") == (0.0, math.inf)
    assert limits_of("mass.slope") == SLOPE_RANGE  # one source of truth for the slope
    assert limits_of("regularization.inner_coefficient") == (0.0, math.inf)
    assert limits_of("shear.gamma_1") == (-math.inf, math.inf)
    assert lens_parameter("mass.slope", prior=Uniform(1.5, 3.0)).limits == SLOPE_RANGE


def test_passed_prior_is_truncated_to_limits():
    prior = passed_prior("mass.ell_comps_1", 0.95, 0.1, width_of("mass.ell_comps_1"), (-1.0, 1.0))
    assert (prior.lower, prior.upper, prior.sigma) == (-1.0, 1.0, 0.2)
    x = prior.transform(np.linspace(0.0, 1.0, 101))
    assert x.min() == -1.0
    assert x.max() == 1.0
    # the mass above the upper limit is cut off: the median moves below μ
    assert prior.transform(0.5) < 0.95
    theta_e = passed_prior("mass.einstein_radius", 0.1, 0.01, RELATIVE_QUARTER, (0.0, math.inf))
    assert theta_e.sigma == pytest.approx(0.025)
    assert theta_e.transform(0.0) == 0.0


def test_passed_prior_rejects_bad_input():
    with pytest.raises(ValueError, match="rule"):
        passed_prior("mass.slope", 2.0, 0.1, ABSOLUTE, rule="2023")
    with pytest.raises(ValueError, match="zero width"):
        passed_prior("mass.einstein_radius", 0.0, 0.0, RELATIVE_QUARTER, rule="2024")
    with pytest.raises(ValueError, match="outside its limits"):
        passed_prior("mass.ell_comps_1", 1.5, 0.1, ABSOLUTE, (-1.0, 1.0))
    with pytest.raises(ValueError, match="previous_sigma"):
        passed_prior("mass.slope", 2.0, -0.1, ABSOLUTE)


def test_the_batched_transform_gives_each_priors_own_numbers_to_the_bit():
    """:class:`PriorTransform` evaluates the truncated Gaussians together; every value,
    at the ends of the cube and far in the tails included, must be what each prior's own
    transform gives, bit for bit (a sampler's path depends on them), for one vector and
    for a batch."""
    priors = (
        TruncatedGaussian(1.2, 0.3, 0.0, math.inf),
        Uniform(-1.0, 2.0),
        TruncatedGaussian(0.0, 0.05, -1.0, 1.0),
        LogUniform(1e-3, 10.0),
        TruncatedGaussian(2.0, 0.1, 1.2, 2.8),
        Gaussian(0.5, 2.0),
        TruncatedGaussian(-3.0, 1e-3, -math.inf, math.inf),
        TruncatedGaussian(5.0, 0.2, 0.0, 4.0),  # mean beyond the upper limit
    )
    batch = PriorTransform(priors)
    rng = np.random.default_rng(7)
    u = rng.uniform(size=(500, len(priors)))
    u[0], u[1], u[2] = 0.0, 1.0, 1e-300
    u[3], u[4] = 1.0 - 1e-16, 0.5
    expected = np.column_stack([prior.transform(u[:, i]) for i, prior in enumerate(priors)])
    np.testing.assert_array_equal(batch.transform(u), expected)
    for row in u[:20]:
        single = np.array([float(prior.transform(v)) for prior, v in zip(priors, row, strict=True)])
        np.testing.assert_array_equal(batch.transform(row), single)
    assert PriorTransform(()).transform(np.empty(0)).shape == (0,)

"""ParameterSpace: free / fixed / tied parameters, prior transform, JSON, derived values."""

import json
import math

import numpy as np
import pytest

from mgelens.geometry import axis_ratio_and_angle_from, ell_comps_from
from mgelens.mass import ExternalShear
from mgelens.search.model import (
    Parameter,
    ParameterSpace,
    axis_ratio_and_angle,
    derived_values,
    names_with_derived,
    shear_magnitude_and_angle,
)
from mgelens.search.priors import Gaussian, LogUniform, TruncatedGaussian, Uniform


@pytest.fixture
def space() -> ParameterSpace:
    return ParameterSpace.from_priors(
        {
            "mass.centre_x": Gaussian(0.0, 0.1),
            "mass.centre_y": Gaussian(0.0, 0.1),
            "mass.ell_comps_1": TruncatedGaussian(0.0, 0.3, -1.0, 1.0),
            "mass.ell_comps_2": TruncatedGaussian(0.0, 0.3, -1.0, 1.0),
            "mass.einstein_radius": Uniform(0.0, 8.0),
            "shear.gamma_1": Uniform(-0.2, 0.2),
            "shear.gamma_2": Uniform(-0.2, 0.2),
            "lens_light.centre_x": Gaussian(0.0, 0.3),
            "regularization.coefficient": LogUniform(1e-6, 1e6),
        }
    )


def test_free_fixed_and_tied(space):
    space = space.with_fixed("mass.einstein_radius", 1.5).tie(
        "lens_light.centre_x", "mass.centre_x"
    )
    assert space.free_names == (
        "mass.centre_x",
        "mass.centre_y",
        "mass.ell_comps_1",
        "mass.ell_comps_2",
        "shear.gamma_1",
        "shear.gamma_2",
        "regularization.coefficient",
    )
    assert space.n_free == 7
    assert space.names[4] == "mass.einstein_radius"  # declaration order is kept
    x = np.arange(1.0, 8.0) / 10
    values = space.values(x)
    assert list(values) == list(space.names)
    assert values["mass.einstein_radius"] == 1.5
    assert values["lens_light.centre_x"] == values["mass.centre_x"] == 0.1
    assert values["regularization.coefficient"] == 0.7
    assert [space.parameter(n).status for n in ("mass.centre_x", "mass.einstein_radius")] == [
        "free",
        "fixed",
    ]
    assert space.parameter("lens_light.centre_x").status == "tied"
    np.testing.assert_array_equal(space.vector(values), x)


def test_ties_follow_their_root(space):
    space = space.tie("lens_light.centre_x", "mass.centre_x")
    # tying to a tied parameter resolves to its root
    space = space.with_parameter(Parameter("source.set_0.centre_x", value=0.0))
    space = space.tie("source.set_0.centre_x", "lens_light.centre_x")
    assert space.parameter("source.set_0.centre_x").tied_to == "mass.centre_x"
    # fixing the root fixes everything tied to it
    fixed = space.with_fixed("mass.centre_x", 0.02)
    values = fixed.values(np.zeros(fixed.n_free))
    assert values["lens_light.centre_x"] == values["source.set_0.centre_x"] == 0.02
    # re-tying the root carries its dependents along
    moved = space.tie("mass.centre_x", "mass.centre_y")
    assert {moved.parameter(n).tied_to for n in ("mass.centre_x", "lens_light.centre_x")} == {
        "mass.centre_y"
    }
    # a tied parameter becomes free again with a prior
    freed = space.with_prior("lens_light.centre_x", Uniform(-0.1, 0.1))
    assert "lens_light.centre_x" in freed.free_names
    with pytest.raises(ValueError, match="itself"):
        space.tie("mass.centre_x", "lens_light.centre_x")


def test_prior_transform_shape_and_order(space):
    rng = np.random.default_rng(3)
    u = rng.random((5, space.n_free))
    x = space.prior_transform(u)
    assert x.shape == (5, space.n_free)
    for i, prior in enumerate(space.priors):
        np.testing.assert_array_equal(x[:, i], prior.transform(u[:, i]))
    np.testing.assert_array_equal(space.prior_transform(u[2]), x[2])
    with pytest.raises(ValueError, match="length"):
        space.prior_transform(np.full(space.n_free + 1, 0.5))
    assert np.isfinite(space.log_prior(x[0]))


def test_columns_match_values(space):
    space = space.with_fixed("mass.einstein_radius", 1.5).tie(
        "lens_light.centre_x", "mass.centre_x"
    )
    x = space.prior_transform(np.random.default_rng(4).random((6, space.n_free)))
    columns = space.columns(x)
    for row in range(6):
        assert {k: v[row] for k, v in columns.items()} == space.values(x[row])


def test_json_round_trip(space):
    space = (
        space.with_fixed("mass.einstein_radius", 1.5)
        .tie("lens_light.centre_x", "mass.centre_x")
        .with_parameter(Parameter("mass.slope", prior=Uniform(1.5, 3.0), limits=(1.2, 2.8)))
    )
    text = json.dumps(space.to_dict(), allow_nan=False)
    again = ParameterSpace.from_dict(json.loads(text))
    assert again == space
    assert again.parameter("mass.slope").limits == (1.2, 2.8)
    assert again.parameter("mass.centre_x").limits == (-math.inf, math.inf)


def test_limits_are_the_declarers_and_unbounded_by_default():
    """The search layer knows no lens names: a parameter is unbounded unless the model
    that declares it gives limits."""
    assert Parameter("mass.slope", prior=Uniform(1.5, 3.0)).limits == (-math.inf, math.inf)
    assert Parameter("mass.slope", value=2.0, limits=(1.2, 3.0)).limits == (1.2, 3.0)


@pytest.mark.parametrize(
    "build",
    [
        lambda: ParameterSpace((Parameter("a.b", value=1.0), Parameter("a.b", value=2.0))),
        lambda: ParameterSpace((Parameter("a.b", tied_to="a.c"),)),
        lambda: Parameter("a.b", prior=Uniform(0, 1), value=0.5),
        lambda: Parameter("a.b"),
        lambda: Parameter("a..b", value=1.0),
        lambda: Parameter("a.b", value=math.inf),
        lambda: Parameter("a.b", value=1.0, limits=(1.0, 0.0)),
    ],
)
def test_invalid_spaces_raise(build):
    with pytest.raises(ValueError, match=r"duplicate|unknown|exactly one|invalid|finite|limits"):
        build()


def test_unknown_name_lookup_raises(space):
    with pytest.raises(KeyError, match="known"):
        space.parameter("mass.nope")


def test_axis_ratio_and_angle_inverts_ell_comps():
    q = np.array([[0.5, 0.7], [0.9, 0.99]])
    angle = np.array([[10.0, 95.0], [170.0, 45.0]])
    e1, e2 = np.vectorize(ell_comps_from)(q, angle)
    q_back, angle_back = axis_ratio_and_angle(e1, e2)
    assert q_back.shape == (2, 2)
    np.testing.assert_allclose(q_back, q, rtol=1e-12)
    np.testing.assert_allclose(angle_back, angle, rtol=1e-12)
    assert axis_ratio_and_angle(0.1, -0.2) == tuple(
        np.asarray(v) for v in axis_ratio_and_angle_from((0.1, -0.2))
    )


def test_shear_magnitude_and_angle():
    magnitude, angle = shear_magnitude_and_angle(np.array([0.03, 0.0]), np.array([0.04, -0.05]))
    np.testing.assert_allclose(magnitude, [0.05, 0.05])
    np.testing.assert_allclose(angle, [0.5 * np.rad2deg(np.arctan2(0.04, 0.03)), 135.0])
    gammas = np.random.default_rng(2).uniform(-0.2, 0.2, size=(50, 2))
    magnitude, angle = shear_magnitude_and_angle(gammas[:, 0], gammas[:, 1])
    shears = [ExternalShear(g1, g2) for g1, g2 in gammas]
    np.testing.assert_array_equal(magnitude, [s.magnitude for s in shears])
    np.testing.assert_array_equal(angle, [s.angle for s in shears])


def test_derived_names_sit_next_to_their_pair(space):
    names = names_with_derived(space.names)
    assert names[2:6] == [
        "mass.ell_comps_1",
        "mass.ell_comps_2",
        "mass.axis_ratio",
        "mass.angle",
    ]
    assert names[7:11] == ["shear.gamma_1", "shear.gamma_2", "shear.magnitude", "shear.angle"]
    values = space.values(space.prior_transform(np.full(space.n_free, 0.6)))
    derived = derived_values(values)
    assert set(derived) == {"mass.axis_ratio", "mass.angle", "shear.magnitude", "shear.angle"}
    assert set(names) == set(space.names) | set(derived)

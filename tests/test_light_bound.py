"""A LIGHT candidate bounded by its maximum (mgelens.pipeline.light_bound): the local
search finds an analytic maximum, and the skip rule keeps its slack."""

import numpy as np
import pytest

from mgelens.pipeline import light_bound
from mgelens.pipeline.models import free_parameters
from mgelens.search.model import ParameterSpace
from mgelens.search.priors import Uniform

SPACE = ParameterSpace(
    tuple(
        free_parameters({"a": Uniform(-1.0, 1.0), "b": Uniform(0.0, 4.0), "c": Uniform(2.0, 3.0)})
    )
)
PEAK = np.array([0.3, 1.7, 2.45])
WIDTHS = np.array([0.05, 0.2, 0.01])
TOP = 1234.5


def correlated_gaussian(x: np.ndarray) -> float:
    """ln ε with its maximum TOP at PEAK, a and b correlated (ρ 0.9)."""
    z = (np.asarray(x) - PEAK) / WIDTHS
    return TOP - 0.5 * (z @ np.linalg.solve([[1, 0.9, 0], [0.9, 1, 0], [0, 0, 1]], z))


def test_the_search_finds_an_analytic_maximum_within_its_calls():
    found = light_bound.search_maximum(correlated_gaussian, SPACE)
    assert found.value == pytest.approx(TOP, abs=1e-4)
    assert np.allclose(found.x, PEAK, atol=1e-3 * WIDTHS.max())
    assert found.n_calls <= light_bound.SEARCH_CALLS + 2 * SPACE.n_free + 1


def test_a_candidate_is_skipped_only_beyond_threshold_and_slack():
    maximum = light_bound.Maximum(np.zeros(3), 100.0, 10, 0.1)
    edge = 100.0 + 5.0 + light_bound.SLACK
    assert light_bound.cannot_win(maximum, edge + 0.01, threshold=5.0)
    assert not light_bound.cannot_win(maximum, edge - 0.01, threshold=5.0)


def test_the_bounded_output_is_one_sample_at_the_maximum():
    maximum = light_bound.search_maximum(correlated_gaussian, SPACE)
    output = light_bound.bounded_output(maximum, SPACE, "light_x6_point", TOP + 100.0)
    assert output.method == light_bound.METHOD
    assert output.log_evidence == maximum.value
    assert output.samples.shape == (1, 3)
    assert output.max_likelihood() == pytest.approx(maximum.x)
    assert "light_x6_point" in output.stop_reason

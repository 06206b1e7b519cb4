"""What the lens model's parameters are, beyond their priors: physical limits and the
widths of passed priors (SPEC §8.2), by the last component of a dotted name. The phases
attach them to every :class:`~mgelens.search.model.Parameter` they declare
(:func:`lens_parameter`) and to every prior they pass (:func:`passed`); the search layer
itself knows no lens names.
"""

import math
from collections.abc import Sequence

from mgelens.mass import SLOPE_RANGE
from mgelens.search.model import Parameter
from mgelens.search.priors import Prior, TruncatedGaussian, WidthModifier
from mgelens.search.results import PhaseResult, passed_priors

PHYSICAL_LIMITS: dict[str, tuple[float, float]] = {
    "ell_comps_1": (-1.0, 1.0),
    "ell_comps_2": (-1.0, 1.0),
    "einstein_radius": (0.0, math.inf),
    "slope": SLOPE_RANGE,
    "effective_radius": (0.0, math.inf),
    "sersic_index": (0.8, 5.0),
    "smoothness": (0.0, math.inf),
}
"""Limits by the last component of a dotted name: |e| < 1 keeps q > 0, θ_E > 0, the EPL's
valid slopes (:data:`mgelens.mass.SLOPE_RANGE`); a Sérsic has R_e > 0 and the anchor's
0.8 ≤ n ≤ 5; the lens light's smoothness λ > 0. Names ending in ``coefficient``
(regularization) get (0, inf); everything else is unbounded. Passed priors are
truncated to these limits (SPEC §8.2)."""

_CENTRE = WidthModifier("absolute", 0.05)
_ELL_COMPS = WidthModifier("absolute", 0.2)
_SHEAR = WidthModifier("absolute", 0.05)
DEFAULT_WIDTH = WidthModifier("relative", 0.5)
"""Width of a passed prior for names without their own (the anchor's default)."""
WIDTH_MODIFIERS: dict[str, WidthModifier] = {
    "centre_x": _CENTRE,
    "centre_y": _CENTRE,
    "ell_comps_1": _ELL_COMPS,
    "ell_comps_2": _ELL_COMPS,
    "einstein_radius": WidthModifier("relative", 0.25),
    "slope": WidthModifier("absolute", 0.2),
    "gamma_1": _SHEAR,
    "gamma_2": _SHEAR,
    "effective_radius": WidthModifier("relative", 1.0),
    "sersic_index": WidthModifier("absolute", 1.5),
}
"""Width modifiers of passed priors by the last component of a dotted name (SPEC §8.2;
Sérsic R_e and n from the anchor's ``priors/light/linear/sersic.yaml``). Regularization
coefficients and every other parameter use :data:`DEFAULT_WIDTH`."""


def _kind(name: str) -> str:
    return name.rsplit(".", 1)[-1]


def limits_of(name: str) -> tuple[float, float]:
    """Physical limits of the parameter with dotted ``name`` (:data:`PHYSICAL_LIMITS`)."""
    if _kind(name).endswith("coefficient"):
        return 0.0, math.inf
    return PHYSICAL_LIMITS.get(_kind(name), (-math.inf, math.inf))


def width_of(name: str) -> WidthModifier:
    """Width modifier of a prior passed to the parameter with dotted ``name``."""
    return WIDTH_MODIFIERS.get(_kind(name), DEFAULT_WIDTH)


def lens_parameter(
    name: str, *, prior: Prior | None = None, value: float | None = None, tied_to: str | None = None
) -> Parameter:
    """A parameter of the lens model with its physical limits (:func:`limits_of`)."""
    return Parameter(name, prior=prior, value=value, tied_to=tied_to, limits=limits_of(name))


def passed(
    previous: PhaseResult, names: Sequence[str], rule: str = "paper"
) -> dict[str, TruncatedGaussian]:
    """Priors for ``names`` passed from ``previous`` (SPEC §8.2) with the lens model's
    widths (:func:`width_of`), truncated to the limits ``previous`` declared."""
    return passed_priors(previous, names, rule, widths={name: width_of(name) for name in names})

"""Named parameters of a phase: free (with a prior), fixed, or tied to another (SPEC §8).

A :class:`ParameterSpace` knows nothing about profiles. Parameters have stable dotted
names, ``<component>[.<sub-component>].<parameter>``, for example ``mass.centre_x``,
``mass.ell_comps_1``, ``mass.einstein_radius``, ``mass.slope``, ``shear.gamma_1``,
``lens_light.centre_x``, ``lens_light.set_0.ell_comps_1``, ``source.set_0.centre_x``,
``regularization.inner_coefficient``. The phases map the value dictionary onto
``mgelens.mass`` / ``mgelens.light`` objects.

The sampler sees only the free parameters, in declaration order: ``prior_transform``
maps the unit cube onto that vector and ``values`` expands it into the full dictionary.

Derived quantities for result files (:func:`derived_values`): for every pair
``<prefix>.ell_comps_1/2`` the axis ratio ``<prefix>.axis_ratio`` (minor/major) and
position angle ``<prefix>.angle`` (degrees counter-clockwise from +x, in [0, 180)); for
every pair ``<prefix>.gamma_1/2`` the shear ``<prefix>.magnitude`` and ``<prefix>.angle``.
"""

import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from mgelens.geometry import axis_ratio_and_angle_from
from mgelens.search.priors import Prior, PriorTransform, prior_from_dict

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")


@dataclass(frozen=True)
class Parameter:
    """One named parameter; exactly one of ``prior``, ``value``, ``tied_to`` is set.

    Attributes
    ----------
    name : str
        Dotted name (``component.parameter``).
    prior : Prior or None
        Set for a free parameter.
    value : float or None
        Set for a fixed parameter (parameter units).
    tied_to : str or None
        Name of the free or fixed parameter whose value this one takes.
    limits : (float, float) or None
        Limits used to truncate priors passed to this parameter; ``None`` means
        unbounded. The model that declares the parameter sets them.
    """

    name: str
    prior: Prior | None = None
    value: float | None = None
    tied_to: str | None = None
    limits: tuple[float, float] | None = None

    def __post_init__(self):
        if not _NAME.match(self.name):
            raise ValueError(f"invalid parameter name {self.name!r}: use dotted identifiers")
        roles = [self.prior is not None, self.value is not None, self.tied_to is not None]
        if sum(roles) != 1:
            raise ValueError(f"{self.name}: give exactly one of prior, value or tied_to")
        if self.value is not None:
            if not math.isfinite(self.value):
                raise ValueError(f"{self.name}: fixed value must be finite, got {self.value}")
            object.__setattr__(self, "value", float(self.value))
        limits = (-math.inf, math.inf) if self.limits is None else self.limits
        lower, upper = float(limits[0]), float(limits[1])
        if not lower < upper:
            raise ValueError(f"{self.name}: limits must satisfy lower < upper, got {limits}")
        object.__setattr__(self, "limits", (lower, upper))

    @property
    def status(self) -> str:
        """``"free"``, ``"fixed"`` or ``"tied"``."""
        if self.prior is not None:
            return "free"
        return "fixed" if self.value is not None else "tied"

    def to_dict(self) -> dict:
        content: dict = {"name": self.name, "status": self.status}
        if self.prior is not None:
            content["prior"] = self.prior.to_dict()
        elif self.value is not None:
            content["value"] = self.value
        else:
            content["tied_to"] = self.tied_to
        content["limits"] = [v if math.isfinite(v) else None for v in self.limits]
        return content

    @classmethod
    def from_dict(cls, content: dict) -> "Parameter":
        lower, upper = content["limits"]
        return cls(
            name=content["name"],
            prior=prior_from_dict(content["prior"]) if "prior" in content else None,
            value=content.get("value"),
            tied_to=content.get("tied_to"),
            limits=(-math.inf if lower is None else lower, math.inf if upper is None else upper),
        )


@dataclass(frozen=True)
class ParameterSpace:
    """An ordered collection of :class:`Parameter` objects with unique names.

    Ties always point to a free or fixed parameter (chains are resolved when tying).
    """

    parameters: tuple[Parameter, ...] = ()
    _index: dict[str, int] = field(init=False, repr=False, compare=False)
    _transform: PriorTransform = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        parameters = tuple(self.parameters)
        object.__setattr__(self, "parameters", parameters)
        index = {p.name: i for i, p in enumerate(parameters)}
        if len(index) != len(parameters):
            names = [p.name for p in parameters]
            duplicates = sorted({n for n in names if names.count(n) > 1})
            raise ValueError(f"duplicate parameter names: {duplicates}")
        object.__setattr__(self, "_index", index)
        free = tuple(p.prior for p in parameters if p.prior is not None)
        object.__setattr__(self, "_transform", PriorTransform(free))
        for p in parameters:
            if p.tied_to is None:
                continue
            if p.tied_to not in index:
                raise ValueError(f"{p.name} is tied to unknown parameter {p.tied_to!r}")
            if parameters[index[p.tied_to]].tied_to is not None:
                raise ValueError(f"{p.name} is tied to {p.tied_to}, which is itself tied")

    @classmethod
    def from_priors(cls, priors: Mapping[str, Prior]) -> "ParameterSpace":
        """Space of free parameters, in the order of ``priors``."""
        return cls(tuple(Parameter(name, prior=prior) for name, prior in priors.items()))

    # -- lookup ------------------------------------------------------------------------
    def __contains__(self, name: str) -> bool:
        return name in self._index

    def parameter(self, name: str) -> Parameter:
        """The parameter called ``name`` (KeyError naming the known parameters otherwise)."""
        try:
            return self.parameters[self._index[name]]
        except KeyError:
            raise KeyError(f"no parameter {name!r}; known: {list(self._index)}") from None

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def free_names(self) -> tuple[str, ...]:
        """Names of the free parameters, in the order of the sampler's vector."""
        return tuple(p.name for p in self.parameters if p.prior is not None)

    @property
    def n_free(self) -> int:
        return len(self.priors)

    @property
    def priors(self) -> tuple[Prior, ...]:
        """Priors of the free parameters, in vector order."""
        return self._transform.priors

    # -- sampling ----------------------------------------------------------------------
    def prior_transform(self, u: np.ndarray) -> np.ndarray:
        """Free-parameter vector(s) from unit-cube coordinates.

        Parameters
        ----------
        u : ndarray, shape (..., n_free)
            Unit-cube coordinates in [0, 1].

        Returns
        -------
        ndarray, shape (..., n_free)
            Parameter values in the order of :attr:`free_names`.
        """
        u = np.asarray(u, dtype=float)
        if u.shape[-1:] != (self.n_free,):
            raise ValueError(f"expected unit-cube vectors of length {self.n_free}, got {u.shape}")
        return self._transform.transform(u)

    def unit_cube(self, x: np.ndarray) -> np.ndarray:
        """Unit-cube coordinates of the free-parameter vector ``x``, the inverse of
        :meth:`prior_transform` (each prior's ``cdf``; values outside a prior's support go to
        0 or 1)."""
        x = np.asarray(x, dtype=float)
        if x.shape != (self.n_free,):
            raise ValueError(f"expected a vector of length {self.n_free}, got {x.shape}")
        return np.array([prior.cdf(x[i]) for i, prior in enumerate(self.priors)], dtype=float)

    def log_prior(self, x: np.ndarray) -> float:
        """Sum of the free parameters' log prior densities at the vector ``x``."""
        x = np.asarray(x, dtype=float)
        return float(sum(prior.log_prob(x[i]) for i, prior in enumerate(self.priors)))

    def values(self, x: np.ndarray) -> dict[str, float]:
        """Full ``{name: value}`` dictionary (free, fixed and tied) from a free vector ``x``."""
        x = np.asarray(x, dtype=float)
        if x.shape != (self.n_free,):
            raise ValueError(f"expected a vector of length {self.n_free}, got shape {x.shape}")
        own = dict(zip(self.free_names, x.tolist(), strict=True))
        own.update({p.name: p.value for p in self.parameters if p.value is not None})
        return {p.name: own[p.tied_to or p.name] for p in self.parameters}

    def columns(self, samples: np.ndarray) -> dict[str, np.ndarray]:
        """Like :meth:`values` for many vectors: ``{name: array (n,)}`` from (n, n_free)."""
        samples = np.asarray(samples, dtype=float).reshape(-1, self.n_free)
        own = {name: samples[:, i] for i, name in enumerate(self.free_names)}
        n = samples.shape[0]
        own.update({p.name: np.full(n, p.value) for p in self.parameters if p.value is not None})
        return {p.name: own[p.tied_to or p.name] for p in self.parameters}

    def vector(self, values: Mapping[str, float]) -> np.ndarray:
        """Free-parameter vector from a dictionary holding (at least) every free name."""
        return np.array([float(values[name]) for name in self.free_names])

    # -- editing (each returns a new space) ----------------------------------------------
    def _replaced(self, name: str, **changes) -> "ParameterSpace":
        old = self.parameter(name)
        new = replace(old, **{"prior": None, "value": None, "tied_to": None, **changes})
        return ParameterSpace(tuple(new if p is old else p for p in self.parameters))

    def with_parameter(self, parameter: Parameter) -> "ParameterSpace":
        """Append ``parameter`` (its name must be new)."""
        return ParameterSpace((*self.parameters, parameter))

    def with_fixed(self, name: str, value: float) -> "ParameterSpace":
        """Fix ``name`` to ``value``; parameters tied to it follow."""
        return self._replaced(name, value=value)

    def with_prior(self, name: str, prior: Prior) -> "ParameterSpace":
        """Make ``name`` free with ``prior``; parameters tied to it follow."""
        return self._replaced(name, prior=prior)

    def tie(self, name: str, to: str) -> "ParameterSpace":
        """Give ``name`` the value of ``to``; parameters tied to ``name`` follow ``to``."""
        root = self.parameter(to).tied_to or to
        if root == name:
            raise ValueError(f"cannot tie {name} to itself (via {to})")
        self.parameter(name)
        parameters = tuple(
            replace(p, prior=None, value=None, tied_to=root)
            if p.name == name or p.tied_to == name
            else p
            for p in self.parameters
        )
        return ParameterSpace(parameters)

    # -- JSON --------------------------------------------------------------------------
    def to_dict(self) -> dict:
        return {"parameters": [p.to_dict() for p in self.parameters]}

    @classmethod
    def from_dict(cls, content: dict) -> "ParameterSpace":
        return cls(tuple(Parameter.from_dict(p) for p in content["parameters"]))


def _pairwise(function, first, second) -> tuple[np.ndarray, np.ndarray]:
    """Apply the scalar ``function(a, b) -> (c, d)`` element-wise over broadcast arrays."""
    first, second = np.broadcast_arrays(np.asarray(first, float), np.asarray(second, float))
    pairs = [function(a, b) for a, b in zip(first.ravel(), second.ravel(), strict=True)]
    table = np.array(pairs, dtype=float).reshape(*first.shape, 2)
    return table[..., 0], table[..., 1]


def axis_ratio_and_angle(
    e1: np.ndarray | float, e2: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """Axis ratio q and angle φ (degrees, [0, 180)) from ell_comps, element-wise (SPEC §2.1)."""
    return _pairwise(lambda a, b: axis_ratio_and_angle_from((a, b)), e1, e2)


def shear_magnitude_and_angle(
    gamma_1: np.ndarray | float, gamma_2: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """Shear γ_ext = sqrt(γ₁² + γ₂²) and angle ½ atan2(γ₂, γ₁) in degrees, in [0, 180)
    (SPEC §3.2, as ``mgelens.mass.ExternalShear``), element-wise."""
    gamma_1, gamma_2 = np.asarray(gamma_1, dtype=float), np.asarray(gamma_2, dtype=float)
    angle = 0.5 * np.rad2deg(np.arctan2(gamma_2, gamma_1))
    return np.hypot(gamma_1, gamma_2), np.where(angle < 0.0, angle + 180.0, angle)


def _pair_prefixes(names: Iterable[str], first: str, second: str) -> list[str]:
    names = list(names)
    return [
        name[: -len(first)]
        for name in names
        if name.endswith(first) and name[: -len(first)] + second in names
    ]


def derived_values(values: Mapping[str, np.ndarray | float]) -> dict[str, np.ndarray]:
    """Derived quantities of ell_comps and shear pairs in ``values`` (scalars or arrays).

    Returns
    -------
    dict
        ``<prefix>.axis_ratio`` and ``<prefix>.angle`` for each ``<prefix>.ell_comps_1/2``
        pair; ``<prefix>.magnitude`` and ``<prefix>.angle`` for each ``<prefix>.gamma_1/2``
        pair. Angles in degrees counter-clockwise from +x, in [0, 180).
    """
    derived: dict[str, np.ndarray] = {}
    for prefix in _pair_prefixes(values, "ell_comps_1", "ell_comps_2"):
        q, angle = axis_ratio_and_angle(
            values[prefix + "ell_comps_1"], values[prefix + "ell_comps_2"]
        )
        derived[prefix + "axis_ratio"], derived[prefix + "angle"] = q, angle
    for prefix in _pair_prefixes(values, "gamma_1", "gamma_2"):
        magnitude, angle = shear_magnitude_and_angle(
            values[prefix + "gamma_1"], values[prefix + "gamma_2"]
        )
        derived[prefix + "magnitude"], derived[prefix + "angle"] = magnitude, angle
    return derived


_DERIVED_AFTER = {
    "ell_comps_2": ("ell_comps_1", ("axis_ratio", "angle")),
    "gamma_2": ("gamma_1", ("magnitude", "angle")),
}


def names_with_derived(names: Iterable[str]) -> list[str]:
    """``names`` with the names of :func:`derived_values` inserted right after their pair."""
    names = list(names)
    out = []
    for name in names:
        out.append(name)
        for second, (first, derived) in _DERIVED_AFTER.items():
            prefix = name[: -len(second)]
            if name.endswith(second) and prefix + first in names:
                out.extend(prefix + d for d in derived)
    return out

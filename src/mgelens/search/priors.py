"""Priors of the non-linear search and prior passing between phases (SPEC §2.4, §3, §8.2).

A prior maps the unit cube onto a parameter: ``transform(u)`` is its inverse cumulative
distribution function, vectorised over numpy arrays, which is what nested samplers need;
``cdf(x)`` maps a value back to its unit-cube coordinate (values outside the support are
clipped to 0 or 1).
Every prior has ``lower`` and ``upper`` support limits (±inf where unbounded), a
``log_prob`` and a JSON form (``to_dict`` / :func:`prior_from_dict`) for result files.

Prior passing (:func:`passed_prior`) replaces a prior by a Gaussian centred on the previous
phase's posterior median and truncated to the parameter's physical limits.
"""

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy import special

PassingRule = Literal["paper", "2024"]

_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


def _check_finite(**values: float) -> None:
    for name, value in values.items():
        if not math.isfinite(value):
            raise ValueError(f"{name} must be finite, got {value}")


def _check_ordered(lower: float, upper: float) -> None:
    if math.isnan(lower) or math.isnan(upper) or not lower < upper:
        raise ValueError(f"prior bounds must satisfy lower < upper, got ({lower}, {upper})")


def _check_width(sigma: float) -> None:
    if not (math.isfinite(sigma) and sigma > 0.0):
        raise ValueError(f"sigma must be finite and positive, got {sigma}")


def _log_difference(log_p, log_q):
    """ln(e^log_p − e^log_q) for log_p ≥ log_q (−inf where they are equal)."""
    return log_p + np.log(-np.expm1(log_q - log_p))


def _bound_to_json(value: float) -> float | None:
    """JSON has no infinity: an unbounded side is written as ``null``."""
    return value if math.isfinite(value) else None


def _bound_from_json(value: float | None, infinity: float) -> float:
    return infinity if value is None else float(value)


@dataclass(frozen=True)
class Uniform:
    """Uniform prior on [lower, upper] (both finite)."""

    lower: float
    upper: float

    def __post_init__(self):
        _check_finite(lower=self.lower, upper=self.upper)
        _check_ordered(self.lower, self.upper)

    def transform(self, u: np.ndarray | float) -> np.ndarray:
        """Value at unit-cube coordinate ``u``: lower + u (upper − lower)."""
        return self.lower + np.asarray(u, dtype=float) * (self.upper - self.lower)

    def cdf(self, x: np.ndarray | float) -> np.ndarray:
        """Unit-cube coordinate of ``x``: (x − lower)/(upper − lower), clipped to [0, 1]."""
        u = (np.asarray(x, dtype=float) - self.lower) / (self.upper - self.lower)
        return np.clip(u, 0.0, 1.0)

    def log_prob(self, x: np.ndarray | float) -> np.ndarray:
        """Log density: −ln(upper − lower) inside the support, −inf outside."""
        x = np.asarray(x, dtype=float)
        inside = (x >= self.lower) & (x <= self.upper)
        return np.where(inside, -math.log(self.upper - self.lower), -np.inf)

    def to_dict(self) -> dict:
        return {"type": "Uniform", "lower": self.lower, "upper": self.upper}


@dataclass(frozen=True)
class LogUniform:
    """Prior uniform in ln x on [lower, upper], 0 < lower < upper < inf (density ∝ 1/x)."""

    lower: float
    upper: float

    def __post_init__(self):
        _check_finite(lower=self.lower, upper=self.upper)
        _check_ordered(self.lower, self.upper)
        if self.lower <= 0.0:
            raise ValueError(f"LogUniform needs lower > 0, got {self.lower}")

    def transform(self, u: np.ndarray | float) -> np.ndarray:
        """Value at unit-cube coordinate ``u``: lower · (upper/lower)^u."""
        log_lower = math.log(self.lower)
        log_range = math.log(self.upper) - log_lower
        return np.exp(log_lower + np.asarray(u, dtype=float) * log_range)

    def cdf(self, x: np.ndarray | float) -> np.ndarray:
        """Unit-cube coordinate of ``x``: ln(x/lower)/ln(upper/lower), clipped to [0, 1]."""
        x = np.clip(np.asarray(x, dtype=float), self.lower, self.upper)
        return np.log(x / self.lower) / math.log(self.upper / self.lower)

    def log_prob(self, x: np.ndarray | float) -> np.ndarray:
        """Log density −ln x − ln ln(upper/lower) inside the support, −inf outside."""
        x = np.asarray(x, dtype=float)
        inside = (x >= self.lower) & (x <= self.upper)
        norm = math.log(math.log(self.upper / self.lower))
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(inside, -np.log(x) - norm, -np.inf)

    def to_dict(self) -> dict:
        return {"type": "LogUniform", "lower": self.lower, "upper": self.upper}


@dataclass(frozen=True)
class Gaussian:
    """Normal prior N(mean, sigma²) on the whole real line."""

    mean: float
    sigma: float

    def __post_init__(self):
        _check_finite(mean=self.mean)
        _check_width(self.sigma)

    @property
    def lower(self) -> float:
        return -math.inf

    @property
    def upper(self) -> float:
        return math.inf

    def transform(self, u: np.ndarray | float) -> np.ndarray:
        """Value at unit-cube coordinate ``u``: mean + sigma Φ⁻¹(u)."""
        return self.mean + self.sigma * special.ndtri(np.asarray(u, dtype=float))

    def cdf(self, x: np.ndarray | float) -> np.ndarray:
        """Unit-cube coordinate of ``x``: Φ((x − mean)/sigma)."""
        return special.ndtr((np.asarray(x, dtype=float) - self.mean) / self.sigma)

    def log_prob(self, x: np.ndarray | float) -> np.ndarray:
        z = (np.asarray(x, dtype=float) - self.mean) / self.sigma
        return -0.5 * z**2 - _LOG_SQRT_2PI - math.log(self.sigma)

    def to_dict(self) -> dict:
        return {"type": "Gaussian", "mean": self.mean, "sigma": self.sigma}


@dataclass(frozen=True)
class TruncatedGaussian:
    """Normal prior N(mean, sigma²) truncated to [lower, upper] (either side may be ±inf).

    The inverse CDF stays accurate far in the tails: with the standardised limits
    a = (lower − mean)/sigma, b = (upper − mean)/sigma, the quantile z of u satisfies both
    Φ(z) = (1 − u) Φ(a) + u Φ(b) and Φ(−z) = (1 − u) Φ(−a) + u Φ(−b). Both right-hand sides
    are sums of positive terms, evaluated in log space (``scipy.special.log_ndtr``); z comes
    from the first where Φ(z) < ½ and from the second otherwise (``ndtri_exp``).
    """

    mean: float
    sigma: float
    lower: float
    upper: float

    def __post_init__(self):
        _check_finite(mean=self.mean)
        _check_width(self.sigma)
        _check_ordered(self.lower, self.upper)

    @property
    def _standard_limits(self) -> tuple[float, float]:
        return (self.lower - self.mean) / self.sigma, (self.upper - self.mean) / self.sigma

    def transform(self, u: np.ndarray | float) -> np.ndarray:
        """Value at unit-cube coordinate ``u`` (u = 0 → lower, u = 1 → upper)."""
        return _truncated_gaussian_quantile(np.asarray(u, dtype=float), *self._quantile_constants())

    def _quantile_constants(self) -> tuple[float, ...]:
        """What :func:`_truncated_gaussian_quantile` needs besides u: mean, sigma, lower,
        upper, ln Φ(a), ln Φ(b), ln Φ(−a), ln Φ(−b)."""
        a, b = self._standard_limits
        logs = special.log_ndtr(np.array([a, b, -a, -b]))
        return (self.mean, self.sigma, self.lower, self.upper, *(float(v) for v in logs))

    def cdf(self, x: np.ndarray | float) -> np.ndarray:
        """Unit-cube coordinate of ``x``: [Φ(z) − Φ(a)] / [Φ(b) − Φ(a)] for z = (x − mean)/sigma,
        from the lower tail where z < 0 and as 1 − [Φ(−z) − Φ(−b)] / [Φ(−a) − Φ(−b)] from
        the upper tail otherwise (log space, as :meth:`transform`); 0 below the support, 1
        above it."""
        x = np.clip(np.asarray(x, dtype=float), self.lower, self.upper)
        z = (x - self.mean) / self.sigma
        a, b = self._standard_limits
        log_mass = self.log_normalisation()  # ln[Φ(b) − Φ(a)] = ln[Φ(−a) − Φ(−b)]
        with np.errstate(divide="ignore", invalid="ignore"):
            lower_tail = _log_difference(special.log_ndtr(z), special.log_ndtr(a))
            upper_tail = _log_difference(special.log_ndtr(-z), special.log_ndtr(-b))
        u = np.where(z < 0.0, np.exp(lower_tail - log_mass), -np.expm1(upper_tail - log_mass))
        return np.clip(u, 0.0, 1.0)

    def log_normalisation(self) -> float:
        """ln[Φ(b) − Φ(a)], the log prior mass of the untruncated Gaussian inside the limits."""
        a, b = self._standard_limits
        if a > 0.0:
            log_hi, log_lo = special.log_ndtr(-a), special.log_ndtr(-b)
        else:
            log_hi, log_lo = special.log_ndtr(b), special.log_ndtr(a)
        return float(_log_difference(log_hi, log_lo))

    def log_prob(self, x: np.ndarray | float) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        z = (x - self.mean) / self.sigma
        density = -0.5 * z**2 - _LOG_SQRT_2PI - math.log(self.sigma) - self.log_normalisation()
        inside = (x >= self.lower) & (x <= self.upper)
        return np.where(inside, density, -np.inf)

    def to_dict(self) -> dict:
        return {
            "type": "TruncatedGaussian",
            "mean": self.mean,
            "sigma": self.sigma,
            "lower": _bound_to_json(self.lower),
            "upper": _bound_to_json(self.upper),
        }


Prior = Uniform | LogUniform | Gaussian | TruncatedGaussian


def _truncated_gaussian_quantile(
    u, mean, sigma, lower, upper, log_cdf_a, log_cdf_b, log_sf_a, log_sf_b
) -> np.ndarray:
    """:meth:`TruncatedGaussian.transform` of ``u`` elementwise, every other argument a
    scalar or an array broadcasting with ``u`` (the constants of
    :meth:`TruncatedGaussian._quantile_constants`)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        log_u, log_complement = np.log(u), np.log1p(-u)
        log_cdf = np.logaddexp(log_complement + log_cdf_a, log_u + log_cdf_b)
        log_sf = np.logaddexp(log_complement + log_sf_a, log_u + log_sf_b)
        z = np.where(
            log_cdf < math.log(0.5), special.ndtri_exp(log_cdf), -special.ndtri_exp(log_sf)
        )
    x = np.clip(mean + sigma * z, lower, upper)
    return np.where(u <= 0.0, lower, np.where(u >= 1.0, upper, x))


class PriorTransform:
    """The unit-cube map of several priors at once: ``transform(u)`` with u of shape
    (..., n) gives each prior's :meth:`transform` of its column, the same numbers (the
    same elementwise operations), but the truncated Gaussians, which passed priors make
    the most common, in one vectorised evaluation instead of one per prior (a sampler
    calls this once per likelihood call; docs/benchmarks.md, "The samplers' own
    overheads").
    """

    def __init__(self, priors: tuple[Prior, ...]):
        self.priors = tuple(priors)
        self._truncated = np.array(
            [i for i, prior in enumerate(self.priors) if isinstance(prior, TruncatedGaussian)],
            dtype=int,
        )
        self._others = [
            (i, prior)
            for i, prior in enumerate(self.priors)
            if not isinstance(prior, TruncatedGaussian)
        ]
        constants = [self.priors[i]._quantile_constants() for i in self._truncated]
        self._constants = tuple(
            np.array(column, dtype=float) for column in zip(*constants, strict=True)
        )

    def transform(self, u: np.ndarray) -> np.ndarray:
        """Parameter values of unit-cube coordinates ``u`` (shape (..., n), n priors)."""
        x = np.empty_like(u)
        if self._truncated.size:
            x[..., self._truncated] = _truncated_gaussian_quantile(
                u[..., self._truncated], *self._constants
            )
        for i, prior in self._others:
            x[..., i] = prior.transform(u[..., i])
        return x


def prior_from_dict(content: dict) -> Prior:
    """Inverse of ``prior.to_dict()``."""
    kind = content.get("type")
    if kind == "Uniform":
        return Uniform(float(content["lower"]), float(content["upper"]))
    if kind == "LogUniform":
        return LogUniform(float(content["lower"]), float(content["upper"]))
    if kind == "Gaussian":
        return Gaussian(float(content["mean"]), float(content["sigma"]))
    if kind == "TruncatedGaussian":
        return TruncatedGaussian(
            float(content["mean"]),
            float(content["sigma"]),
            _bound_from_json(content["lower"], -math.inf),
            _bound_from_json(content["upper"], math.inf),
        )
    raise ValueError(f"unknown prior type {kind!r} in {content}")


@dataclass(frozen=True)
class WidthModifier:
    """Minimum width of a passed prior (SPEC §8.2).

    ``kind == "absolute"``: width = value (parameter units);
    ``kind == "relative"``: width = value × |posterior median|.
    """

    kind: Literal["absolute", "relative"]
    value: float

    def width(self, median: float) -> float:
        return self.value if self.kind == "absolute" else self.value * abs(median)


def passed_prior(
    name: str,
    previous_median: float,
    previous_sigma: float,
    width: WidthModifier,
    limits: tuple[float, float] = (-math.inf, math.inf),
    rule: PassingRule = "paper",
) -> TruncatedGaussian:
    """Prior for ``name`` passed from a previous phase's posterior (SPEC §8.2).

    Parameters
    ----------
    name : str
        Dotted parameter name (for messages).
    previous_median : float
        Posterior median μ of the previous phase (parameter units).
    previous_sigma : float
        Half-width of the previous 3σ (99.73 %) credible interval,
        max(upper − μ, μ − lower) (parameter units); 0 for a parameter that was fixed.
    width : WidthModifier
        The width modifier w of the parameter, set by the model that declares it.
    limits : (float, float)
        Physical limits of the parameter; the Gaussian is truncated to them.
    rule : {"paper", "2024"}
        ``"paper"`` (anchor 2023, default): σ_p = max(previous_sigma, w);
        ``"2024"``: σ_p = w.

    Returns
    -------
    TruncatedGaussian
        N(μ, σ_p²) truncated to ``limits``.
    """
    if rule not in ("paper", "2024"):
        raise ValueError(f"rule must be 'paper' or '2024', got {rule!r}")
    if not previous_sigma >= 0.0:
        raise ValueError(f"previous_sigma must be >= 0, got {previous_sigma} for {name}")
    modifier = width.width(previous_median)
    sigma = max(previous_sigma, modifier) if rule == "paper" else modifier
    if not sigma > 0.0:
        raise ValueError(
            f"passed prior of {name} has zero width (median {previous_median}, "
            f"3σ half-width {previous_sigma}, rule {rule!r}): give it an explicit prior"
        )
    lower, upper = limits
    if not lower <= previous_median <= upper:
        raise ValueError(f"median {previous_median} of {name} lies outside its limits {limits}")
    return TruncatedGaussian(previous_median, sigma, lower, upper)

"""Result files of one phase and prior passing from them (ARCHITECTURE "Data that flows").

A phase folder holds

* ``result.json``: phase name; whether the sampler converged (``converged``) and why it
  stopped (``stop_reason``); max-likelihood and median values with 1σ (68.27 %) and
  3σ (99.73 %) central credible intervals of every parameter under its dotted name, with
  the derived axis ratio / angle next to each ell_comps pair and the shear magnitude /
  angle next to each (gamma_1, gamma_2) pair; log evidence; sampler statistics and
  settings; seed; phase settings; package versions; sha256 checksums of the input files;
  the parameter space (priors, fixed and tied parameters);
* ``samples.csv``: one row per sample with ``weight``, ``log_weight``, ``log_likelihood``
  and one column per parameter (free, fixed, tied and derived).

Both are written atomically. :meth:`PhaseResult.read` returns an object equal to the one
written. Medians and intervals are weighted quantiles of the samples
(:func:`~mgelens.search.posterior.weighted_quantile`). Derived angles are unwrapped around
the max-likelihood angle before taking quantiles, so their intervals stay contiguous and
may extend below 0° or above 180°; the reported median is brought back into [0°, 180°)
with the interval shifted by the same multiple of 180°.
"""

import hashlib
import json
import platform
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, fields
from functools import cached_property
from importlib import metadata
from pathlib import Path

import numpy as np
import pandas as pd

import mgelens
from mgelens.atomic import atomic_path, write_json
from mgelens.provenance import code_version
from mgelens.search.model import ParameterSpace, derived_values, names_with_derived
from mgelens.search.posterior import SIGMA_PROBABILITY, SamplerOutput, weighted_quantile
from mgelens.search.priors import PassingRule, TruncatedGaussian, WidthModifier, passed_prior

RESULT_FILE = "result.json"
SAMPLES_FILE = "samples.csv"
_SAMPLE_COLUMNS = ("weight", "log_weight", "log_likelihood")


def file_sha256(path: str | Path) -> str:
    """Hex sha256 of a file's bytes."""
    digest = hashlib.sha256()
    with Path(path).open("rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def input_checksums(paths: Iterable[str | Path]) -> dict[str, str]:
    """``{path as given: sha256}`` of the input files of a phase."""
    return {str(path): file_sha256(path) for path in paths}


def _distribution_version(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def collect_versions() -> dict[str, str]:
    """Versions of Python, mgelens (number and :func:`~mgelens.provenance.code_version`) and
    the numerical packages a result depends on."""
    versions = {
        "python": platform.python_version(),
        "mgelens": mgelens.__version__,
        "mgelens_code": code_version(),
    }
    for name in ("numpy", "scipy", "dynesty", "nautilus-sampler"):
        version = _distribution_version(name)
        if version is not None:
            versions[name] = version
    return versions


def _json_normalised(content: dict) -> dict:
    """``content`` as it reads back from JSON (tuples become lists, keys strings)."""
    return json.loads(json.dumps(content))


def unwrapped_angles(angles, reference: float):
    """Angles (degrees, period 180°; an array or a number) moved to within ±90° of
    ``reference``."""
    return reference + np.mod(angles - reference + 90.0, 180.0) - 90.0


@dataclass(frozen=True, eq=False)
class PhaseResult:
    """Outcome of one phase: its parameter space, sampler output and provenance.

    Attributes
    ----------
    phase : str
        Phase name (e.g. ``"source_lp"``, ``"source_pix_1"``).
    space : ParameterSpace
    output : SamplerOutput
    settings : dict
        Phase settings given by the caller (JSON-serialisable).
    input_checksums : dict
        ``{path: sha256}`` of the phase's input files (:func:`input_checksums`).
    versions : dict
        Package versions (:func:`collect_versions`, filled in when omitted).
    """

    phase: str
    space: ParameterSpace
    output: SamplerOutput
    settings: dict = field(default_factory=dict)
    input_checksums: dict = field(default_factory=dict)
    versions: dict = field(default_factory=collect_versions)

    def __post_init__(self):
        if self.output.names != self.space.free_names:
            raise ValueError(
                f"sampler output columns {self.output.names} do not match the free "
                f"parameters {self.space.free_names}"
            )
        for name in ("settings", "input_checksums", "versions"):
            object.__setattr__(self, name, _json_normalised(getattr(self, name)))

    def __eq__(self, other) -> bool:
        if not isinstance(other, PhaseResult):
            return NotImplemented
        return all(getattr(self, f.name) == getattr(other, f.name) for f in fields(self))

    __hash__ = None

    # -- summaries -------------------------------------------------------------------------
    @cached_property
    def _columns(self) -> dict[str, np.ndarray]:
        columns = self.space.columns(self.output.samples)
        columns.update(derived_values(columns))
        return {name: columns[name] for name in names_with_derived(self.space.names)}

    @cached_property
    def max_likelihood(self) -> dict[str, float]:
        """Parameter values (incl. fixed, tied, derived) of the highest-likelihood sample."""
        index = self.output.max_likelihood_index
        return {name: float(column[index]) for name, column in self._columns.items()}

    @cached_property
    def _quantiles(self) -> dict[str, np.ndarray]:
        """Per name: median, 1σ lower/upper, 3σ lower/upper."""
        p1, p3 = SIGMA_PROBABILITY[1], SIGMA_PROBABILITY[3]
        q = [0.5, (1 - p1) / 2, (1 + p1) / 2, (1 - p3) / 2, (1 + p3) / 2]
        weights = self.output.weights
        derived = set(derived_values(self.max_likelihood))
        quantiles = {}
        for name, column in self._columns.items():
            if name in derived and name.endswith(".angle"):
                column = unwrapped_angles(column, self.max_likelihood[name])
                values = weighted_quantile(column, weights, q)
                values -= 180.0 * np.floor(values[0] / 180.0)
            else:
                values = weighted_quantile(column, weights, q)
            quantiles[name] = values
        return quantiles

    @property
    def median(self) -> dict[str, float]:
        """Weighted posterior median of every parameter (incl. fixed, tied, derived)."""
        return {name: float(v[0]) for name, v in self._quantiles.items()}

    def interval(self, sigma: int = 1) -> dict[str, tuple[float, float]]:
        """Central credible interval at 1σ (68.27 %) or 3σ (99.73 %) of every parameter."""
        if sigma not in (1, 3):
            raise ValueError(f"sigma must be 1 or 3, got {sigma}")
        lower, upper = (1, 2) if sigma == 1 else (3, 4)
        return {n: (float(v[lower]), float(v[upper])) for n, v in self._quantiles.items()}

    def summary(self) -> dict:
        """The content of ``result.json``."""
        return {
            "phase": self.phase,
            "converged": self.output.converged,
            "stop_reason": self.output.stop_reason,
            "log_evidence": self.output.log_evidence,
            "log_evidence_error": self.output.log_evidence_error,
            "max_log_likelihood": float(self.output.log_likelihoods.max()),
            "max_likelihood": self.max_likelihood,
            "median": self.median,
            "interval_1sigma": self.interval(1),
            "interval_3sigma": self.interval(3),
            "sampler": self.output.statistics(),
            "settings": self.settings,
            "input_checksums": self.input_checksums,
            "versions": self.versions,
            "parameter_space": self.space.to_dict(),
        }

    def samples_table(self) -> pd.DataFrame:
        """The content of ``samples.csv``."""
        table = {
            "weight": self.output.weights,
            "log_weight": self.output.log_weights,
            "log_likelihood": self.output.log_likelihoods,
        }
        table.update(self._columns)
        return pd.DataFrame(table)

    # -- files -----------------------------------------------------------------------------
    def write(self, folder: str | Path) -> None:
        """Write ``result.json`` and ``samples.csv`` into ``folder`` (created if needed)."""
        folder = Path(folder)
        with atomic_path(folder / SAMPLES_FILE) as temporary:
            self.samples_table().to_csv(temporary, index=False, float_format="%.17g")
        write_json(folder / RESULT_FILE, self.summary())

    @classmethod
    def read(cls, folder: str | Path) -> "PhaseResult":
        """Read the result written by :meth:`write` into ``folder`` (a file written before
        convergence was recorded reads as converged, with an empty stop reason)."""
        folder = Path(folder)
        summary = json.loads((folder / RESULT_FILE).read_text())
        table = pd.read_csv(folder / SAMPLES_FILE)
        space = ParameterSpace.from_dict(summary["parameter_space"])
        sampler = summary["sampler"]
        output = SamplerOutput(
            names=space.free_names,
            samples=table[list(space.free_names)].to_numpy(dtype=float),
            log_weights=table["log_weight"].to_numpy(dtype=float),
            log_likelihoods=table["log_likelihood"].to_numpy(dtype=float),
            log_evidence=sampler["log_evidence"],
            log_evidence_error=sampler["log_evidence_error"],
            n_calls=sampler["n_calls"],
            n_rejected=sampler["n_rejected"],
            runtime=sampler["runtime_s"],
            n_resumes=sampler["n_resumes"],
            method=sampler["method"],
            settings=sampler["settings"],
            seed=sampler["seed"],
            converged=sampler.get("converged", True),
            stop_reason=sampler.get("stop_reason", ""),
            peak_gain=sampler.get("peak_gain"),
        )
        return cls(
            phase=summary["phase"],
            space=space,
            output=output,
            settings=summary["settings"],
            input_checksums=summary["input_checksums"],
            versions=summary["versions"],
        )


def passed_priors(
    previous: PhaseResult,
    names: Sequence[str],
    rule: PassingRule = "paper",
    limits: Mapping[str, tuple[float, float]] | None = None,
    *,
    widths: Mapping[str, WidthModifier],
) -> dict[str, TruncatedGaussian]:
    """Priors for ``names`` passed from a previous phase's result (SPEC §8.2).

    Each becomes N(μ, σ_p) truncated to the parameter's limits, with μ the previous
    posterior median and σ_p from :func:`~mgelens.search.priors.passed_prior` fed with the
    3σ half-width max(upper − μ, μ − lower). A parameter that was fixed (or tied) in the
    previous phase has half-width 0, so it gets the width modifier alone.

    Parameters
    ----------
    previous : PhaseResult
        Result of the earlier phase (e.g. ``PhaseResult.read(folder)``).
    names : sequence of str
        Dotted names present in ``previous.space``.
    rule : {"paper", "2024"}
    limits : mapping, optional
        Per-name limits overriding those stored in ``previous.space``.
    widths : mapping
        Width modifier of every name (the model's, e.g.
        :func:`mgelens.pipeline.parameters.width_of`).

    Returns
    -------
    dict
        ``{name: TruncatedGaussian}`` in the order of ``names``.
    """
    limits = {} if limits is None else limits
    median, interval = previous.median, previous.interval(3)
    priors = {}
    for name in names:
        if name not in previous.space:
            raise KeyError(
                f"{name!r} is not a parameter of phase {previous.phase!r}; "
                f"it has {list(previous.space.names)}"
            )
        mu = median[name]
        lower, upper = interval[name]
        half_width = max(upper - mu, mu - lower, 0.0)
        bounds = limits.get(name, previous.space.parameter(name).limits)
        priors[name] = passed_prior(name, mu, half_width, widths[name], bounds, rule)
    return priors


PRIOR_EDGE_FRACTION = 0.1
"""A posterior is at its prior's edge when its 3σ interval ends within this fraction of
its 1σ half-width of a finite bound of the prior (:func:`prior_edges`)."""


def prior_edges(result: Mapping) -> list[str]:
    """The free parameters of a ``result.json`` record (:meth:`PhaseResult.write`) whose
    posterior runs into a finite bound of their prior, each as ``"name at its lower
    bound 1.5"``: the 3σ interval ends within :data:`PRIOR_EDGE_FRACTION` of the 1σ
    half-width of the bound. Such an interval is cut by the prior, not by the data (a
    slope piled at the EPL prior's 1.5, on a bright lens whose arcs are faint), and its
    width says nothing about how well the data measure the parameter."""
    edges = []
    for entry in result["parameter_space"]["parameters"]:
        if entry["status"] != "free":
            continue
        name, prior = entry["name"], entry.get("prior") or {}
        low_3, high_3 = result["interval_3sigma"][name]
        low_1, high_1 = result["interval_1sigma"][name]
        reach = PRIOR_EDGE_FRACTION * (high_1 - low_1) / 2.0
        lower, upper = prior.get("lower"), prior.get("upper")
        if lower is not None and low_3 - lower <= reach:
            edges.append(f"{name} at its lower bound {lower:g}")
        if upper is not None and upper - high_3 <= reach:
            edges.append(f"{name} at its upper bound {upper:g}")
    return edges


NO_PRIOR_EDGE = "none"
"""The sample table's ``prior_edge`` entry of a MASS result that :func:`prior_edges` checked
and found no parameter at a bound (an empty entry: a record without its parameter space)."""


def names_a_prior_edge(column: pd.Series) -> pd.Series:
    """Per entry of a ``prior_edge`` column: whether it names a parameter at a bound."""
    return column.notna() & column.ne(NO_PRIOR_EDGE)

"""Choice of the LIGHT phase's lens-light model by Bayesian evidence (paper §5).

A lens whose sample sheet says ``auto`` for ``mge_sets`` or ``point_set`` has its LIGHT
phase fitted once per candidate model, from the same SP, SPix1 and SPix2, each into
``<results>/light_<model>/`` (:attr:`LightModel.folder`). :func:`choose` picks one by the
sampler's Bayesian log evidence ln Z (SPEC §7: ln ε marginalised over the phase's
non-linear parameters), and :func:`adopt` copies the chosen candidate's files into
``<results>/light/``, which MASS reads as for a lens with a pinned model.

The rule: take the simplest candidate whose ln Z is within ``threshold`` of the highest
ln Z, "simplest" meaning fewest linear unknowns (then fewest free parameters). A more
complex model is taken only if it beats every simpler one by at least ``threshold``
(default :data:`DEFAULT_THRESHOLD` = 5, odds of e⁵ ≈ 150 : 1, "strong" on Jeffreys'
scale). The MGE amplitudes carry no prior (SPEC §7), so extra Gaussians pay no Occam
penalty of their own in ln ε; the threshold is what keeps a model with three times the
linear unknowns from winning on noise.

A candidate that cannot win need not be sampled: its ln Z is at most its highest ln ε,
and the workflow fits the most complex candidate first and bounds the others by it
(:mod:`mgelens.pipeline.light_bound`; ``model_choice_bound`` in the config).

``model_choice.json`` records every candidate (label, ln Z and its error, the ln ε, ln L
and χ² of its maximum-likelihood fit, linear unknowns, free parameters, convergence,
whether its ln Z is an upper bound), the threshold, the rule and ``chosen``.
"""

import json
import re
import shutil
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

from mgelens.atomic import atomic_path, write_json
from mgelens.pipeline import light_bound
from mgelens.search.results import RESULT_FILE, SAMPLES_FILE

DEFAULT_THRESHOLD = 5.0
"""ln Z by which a more complex LIGHT model must beat every simpler candidate."""

AUTO = "auto"
"""Sample-sheet value of ``mge_sets`` / ``point_set`` that asks for a choice."""

AUTO_MGE_SETS = (2, 6)
"""Extended-set counts tried when ``mge_sets`` is ``auto`` (the paper's X2 and X6)."""

CHOICE_FILE = "model_choice.json"
PHASE_FILES = (RESULT_FILE, SAMPLES_FILE, "model.fits", "phase.log")
"""Files of a LIGHT candidate's folder copied into ``light/`` (the log if present)."""

_LABEL = re.compile(r"^X([1-9][0-9]*)(\+point)?$")


@dataclass(frozen=True)
class LightModel:
    """A lens-light model of the LIGHT phase: ``mge_sets`` extended 30-Gaussian sets, with
    or without the 10-Gaussian central point set (SPEC §2.4)."""

    mge_sets: int
    point_set: bool

    @property
    def label(self) -> str:
        """``X<n>+point`` or ``X<n>`` (the paper's names, e.g. ``X6+point``)."""
        return f"X{self.mge_sets}" + ("+point" if self.point_set else "")

    @property
    def folder(self) -> str:
        """Phase folder of this candidate: ``light_x<n>_point`` or ``light_x<n>``."""
        return f"light_x{self.mge_sets}" + ("_point" if self.point_set else "")

    @classmethod
    def from_label(cls, label: str) -> "LightModel":
        """Parse :attr:`label`; ValueError naming the accepted form otherwise."""
        match = _LABEL.match(label)
        if match is None:
            raise ValueError(f"light model {label!r} is not of the form X<n> or X<n>+point")
        return cls(int(match.group(1)), match.group(2) is not None)


def candidates(mge_sets: int | str, point_set: str) -> tuple[LightModel, ...]:
    """The LIGHT models to compare for a sheet row's ``mge_sets`` and ``point_set``.

    ``auto`` in both gives the paper's three, X2+point, X6+point and X2; ``auto`` in one
    varies that one only (e.g. ``mge_sets`` 2 and ``point_set`` auto: X2+point, X2). With
    neither ``auto`` the one pinned model is returned.
    """
    if mge_sets == AUTO and point_set == AUTO:
        return (LightModel(2, True), LightModel(6, True), LightModel(2, False))
    sets = AUTO_MGE_SETS if mge_sets == AUTO else (int(mge_sets),)
    points = (True, False) if point_set == AUTO else (point_set == "yes",)
    return tuple(LightModel(n, p) for p in points for n in sets)


@dataclass(frozen=True)
class Candidate:
    """A finished LIGHT candidate as read from its folder's ``result.json``.

    ``log_evidence`` (ln Z) and its error are the sampler's; ``max_log_evidence``,
    ``max_log_likelihood`` and ``chi_squared`` are those of the maximum-likelihood fit
    (ln ε, ln L and χ² of SPEC §7); ``n_linear`` counts the solved lens-light amplitudes
    and source pixels. ``bounded``: the candidate was not sampled because it could not win
    (:mod:`mgelens.pipeline.light_bound`); its ``log_evidence`` is then an upper bound of
    ln Z, the highest ln ε a local search found, with error 0.
    """

    label: str
    log_evidence: float
    log_evidence_error: float
    max_log_evidence: float
    max_log_likelihood: float
    chi_squared: float
    n_linear: int
    n_free: int
    converged: bool
    bounded: bool = False

    @classmethod
    def read(cls, folder: str | Path, model: LightModel) -> "Candidate":
        """The candidate ``model`` whose LIGHT phase is in ``folder``."""
        path = Path(folder) / RESULT_FILE
        if not path.is_file():
            raise FileNotFoundError(
                f"{path} not found: run the LIGHT candidate {model.label} first "
                f"(mgelens phase light --folder {model.folder} ...)"
            )
        try:
            result = json.loads(path.read_text())
            record = result["max_likelihood_fit"]
            amplitudes = sum(
                len(c.get("intensities", ()))
                for c in record["lens_light"]["components"]
                if not c.get("fixed", False)
            )
            return cls(
                label=model.label,
                log_evidence=float(result["log_evidence"]),
                log_evidence_error=float(result["log_evidence_error"]),
                max_log_evidence=float(record["log_evidence"]),
                max_log_likelihood=float(record["log_likelihood"]),
                chi_squared=float(record["chi_squared"]),
                n_linear=amplitudes + int(record["source"].get("n_pixels", 0)),
                n_free=sum(p["status"] == "free" for p in result["parameter_space"]["parameters"]),
                converged=bool(result["converged"]),
                bounded=result["sampler"]["method"] == light_bound.METHOD,
            )
        except (json.JSONDecodeError, KeyError, TypeError) as error:
            raise ValueError(
                f"{path} is not a finished phase's result ({type(error).__name__}: {error}); "
                f"delete {path.parent} and rerun the LIGHT candidate {model.label}"
            ) from None


def choose(found: Sequence[Candidate], threshold: float = DEFAULT_THRESHOLD) -> Candidate:
    """The simplest candidate whose ln Z is within ``threshold`` of the highest.

    Simplest = fewest linear unknowns, then fewest free parameters (module docstring). A
    bounded candidate's upper bound stands for its ln Z: it is never the highest and never
    within the threshold of it, since it was bounded for lying below both.

    Raises
    ------
    ValueError
        If a bounded candidate's bound comes within ``threshold`` of the highest sampled
        ln Z (a bound made against another candidate or threshold).
    """
    eligible = within_threshold(found, threshold, "LIGHT candidate to choose from")
    best = max(c.log_evidence for c in found)
    reached = [c.label for c in eligible if c.bounded]
    if reached:
        raise ValueError(
            f"the LIGHT candidates {reached} were not sampled, but their upper bounds of ln Z "
            f"come within {threshold} of the highest ln Z {best:.2f}: delete their folders "
            "and fit them again (mgelens phase light without --bound-by)"
        )
    return min(eligible, key=lambda c: (c.n_linear, c.n_free))


def within_threshold(found: Sequence, threshold: float, what: str) -> list:
    """The candidates of ``found`` (each with a ``log_evidence``) whose ln Z is within
    ``threshold`` of the highest.

    Raises
    ------
    ValueError
        With no candidate ("no ``what``"), or a threshold that is not a number >= 0.
    """
    if not found:
        raise ValueError(f"no {what}")
    if not threshold >= 0.0:
        raise ValueError(f"model-choice threshold must be a number >= 0, got {threshold!r}")
    best = max(c.log_evidence for c in found)
    return [c for c in found if c.log_evidence >= best - threshold]


def adopt(
    results_dir: str | Path,
    models: Sequence[LightModel],
    threshold: float = DEFAULT_THRESHOLD,
    record_path: str | Path | None = None,
) -> Candidate:
    """Choose among the LIGHT candidates ``models`` of ``results_dir`` and adopt the
    winner: its folder's files (:data:`PHASE_FILES`) are copied, each atomically, into
    ``results_dir/light/``; the choice is written to ``record_path`` (default
    ``results_dir/model_choice.json``). Returns the chosen candidate."""
    results_dir = Path(results_dir)
    found = [Candidate.read(results_dir / m.folder, m) for m in models]
    chosen = choose(found, threshold)
    copy_phase_files(
        results_dir / LightModel.from_label(chosen.label).folder, results_dir / "light"
    )
    write_json(
        results_dir / CHOICE_FILE if record_path is None else record_path,
        choice_record(found, chosen, threshold),
    )
    return chosen


def copy_phase_files(source: Path, target: Path) -> None:
    """Copy the phase files (:data:`PHASE_FILES`) that ``source`` holds into ``target``,
    each atomically: a chosen candidate's folder into the folder the next phase reads."""
    for name in PHASE_FILES:
        if (source / name).is_file():
            with atomic_path(target / name) as temporary:
                shutil.copyfile(source / name, temporary)


def holds_choice(results_dir: str | Path, chosen_label: str) -> bool:
    """Whether ``results_dir/light/`` still holds the candidate ``chosen_label`` that
    :func:`adopt` copied there (its ``result.json`` byte-identical to the candidate's).

    False when LIGHT has since been fitted with a model the sheet pins (the earlier
    ``model_choice.json`` then describes a choice MASS no longer reads), or when either
    file is missing.
    """
    results_dir = Path(results_dir)
    return same_result(
        results_dir / "light", results_dir / LightModel.from_label(chosen_label).folder
    )


def same_result(adopted: Path, candidate: Path) -> bool:
    """Whether the phase folder ``adopted`` holds the ``result.json`` of ``candidate``
    byte for byte (False if either is missing): a choice's copy still in place."""
    adopted, candidate = adopted / RESULT_FILE, candidate / RESULT_FILE
    if not (adopted.is_file() and candidate.is_file()):
        return False
    return adopted.read_bytes() == candidate.read_bytes()


def choice_record(found: Sequence[Candidate], chosen: Candidate, threshold: float) -> dict:
    """The ``model_choice.json`` record (module docstring) of ``chosen`` among ``found``."""
    return {
        "chosen": chosen.label,
        "criterion": "log_evidence",
        "threshold": threshold,
        "rule": "the candidate with the fewest linear unknowns (then free parameters) "
        "whose ln Z is within `threshold` of the highest ln Z",
        "candidates": [asdict(c) for c in found],
    }

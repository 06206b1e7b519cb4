"""Choice of the pixelized source's k-means pixel count by SPix2's Bayesian evidence.

With ``slam: source_pixels`` a list of counts (e.g. ``[500, 1000]``), the workflow fits
SPix2 once per count, from the same SP and SPix1, each into ``<results>/spix2_n<count>/``
(:func:`folder`). :func:`choose` picks one by the sampler's ln Z (SPEC §7: ln ε
marginalised over SPix2's mesh and regularization hyper-parameters), and :func:`adopt`
copies the chosen candidate's files into ``<results>/spix2/``, which LIGHT and MASS read
(they keep its count, :meth:`mgelens.pipeline.problem.EarlierPhase.source_pixels`).

The counts compare like any two models of the same data: the same lens light geometry
and mass, a source prior of more or fewer pixels, and each candidate's evidence carries
its regularization's Occam factor (the ln det terms of SPEC §7). The rule is LIGHT's
(:mod:`mgelens.pipeline.model_choice`): the fewest pixels whose ln Z is within
``threshold`` (default 5) of the highest, so that a finer mesh, dearer in every later
call, must win by odds of e⁵ ≈ 150 : 1.

``source_pixels_choice.json`` records every candidate (count, ln Z and its error, the
ln ε of its maximum-likelihood fit, convergence), the threshold, the rule and ``chosen``.
"""

import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

from mgelens.atomic import write_json
from mgelens.pipeline.model_choice import (
    DEFAULT_THRESHOLD,
    copy_phase_files,
    same_result,
    within_threshold,
)
from mgelens.search.results import RESULT_FILE

CHOICE_FILE = "source_pixels_choice.json"
FOLDER_PREFIX = "spix2_n"


def folder(n_pixels: int) -> str:
    """Phase folder of the SPix2 candidate with ``n_pixels`` k-means pixels."""
    return f"{FOLDER_PREFIX}{n_pixels}"


@dataclass(frozen=True)
class PixelCandidate:
    """A finished SPix2 candidate as read from its folder's ``result.json``: its k-means
    pixel count, the sampler's ln Z and its error, the ln ε of its maximum-likelihood fit
    and whether its sampler converged."""

    n_pixels: int
    log_evidence: float
    log_evidence_error: float
    max_log_evidence: float
    converged: bool

    @classmethod
    def read(cls, phase_folder: str | Path, n_pixels: int) -> "PixelCandidate":
        """The candidate of ``n_pixels`` pixels whose SPix2 phase is in ``phase_folder``.

        Raises
        ------
        FileNotFoundError
            If the folder has no ``result.json`` (naming the command that makes it).
        ValueError
            If the file is not a finished SPix2 result, or its k-means source has another
            pixel count.
        """
        path = Path(phase_folder) / RESULT_FILE
        if not path.is_file():
            raise FileNotFoundError(
                f"{path} not found: run the SPix2 candidate of {n_pixels} source pixels first "
                f"(mgelens phase spix2 --folder {folder(n_pixels)} with source_pixels "
                f"{n_pixels} in --slam)"
            )
        try:
            result = json.loads(path.read_text())
            record = result["max_likelihood_fit"]
            fitted = int(record["source"]["n_pixels"])
            candidate = cls(
                n_pixels=fitted,
                log_evidence=float(result["log_evidence"]),
                log_evidence_error=float(result["log_evidence_error"]),
                max_log_evidence=float(record["log_evidence"]),
                converged=bool(result["converged"]),
            )
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as error:
            raise ValueError(
                f"{path} is not a finished SPix2 result ({type(error).__name__}: {error}); "
                f"delete {path.parent} and rerun the SPix2 candidate of {n_pixels} pixels"
            ) from None
        if fitted != n_pixels:
            raise ValueError(
                f"{path} was fitted with {fitted} source pixels, not {n_pixels}: delete "
                f"{path.parent} and rerun the SPix2 candidate of {n_pixels} pixels"
            )
        return candidate


def choose(found: Sequence[PixelCandidate], threshold: float = DEFAULT_THRESHOLD) -> PixelCandidate:
    """The candidate with the fewest pixels whose ln Z is within ``threshold`` of the
    highest.

    Raises
    ------
    ValueError
        With no candidate, or a threshold that is not a number >= 0.
    """
    eligible = within_threshold(
        found, threshold, "SPix2 candidate to choose a source pixel count from"
    )
    return min(eligible, key=lambda c: c.n_pixels)


def adopt(
    results_dir: str | Path,
    counts: Sequence[int],
    threshold: float = DEFAULT_THRESHOLD,
    record_path: str | Path | None = None,
) -> PixelCandidate:
    """Choose among the SPix2 candidates of ``counts`` pixels in ``results_dir`` and adopt
    the winner: its folder's phase files are copied, each atomically, into
    ``results_dir/spix2/``; the choice is written to ``record_path`` (default
    ``results_dir/source_pixels_choice.json``). Returns the chosen candidate."""
    results_dir = Path(results_dir)
    found = [PixelCandidate.read(results_dir / folder(n), n) for n in counts]
    chosen = choose(found, threshold)
    copy_phase_files(results_dir / folder(chosen.n_pixels), results_dir / "spix2")
    write_json(
        results_dir / CHOICE_FILE if record_path is None else record_path,
        {
            "chosen": chosen.n_pixels,
            "criterion": "log_evidence",
            "threshold": threshold,
            "rule": "the candidate with the fewest source pixels whose ln Z is within "
            "`threshold` of the highest ln Z",
            "candidates": [asdict(c) for c in found],
        },
    )
    return chosen


def holds_choice(results_dir: str | Path) -> int | None:
    """The count of ``results_dir``'s ``source_pixels_choice.json`` if ``spix2/`` still
    holds that candidate (its ``result.json`` byte-identical to the candidate's); None
    without the record, or where SPix2 has since been fitted with one count set in the
    settings (the record then describes a choice LIGHT and MASS no longer read).

    Raises
    ------
    ValueError
        If the record is not JSON or lacks ``chosen``.
    """
    results_dir = Path(results_dir)
    path = results_dir / CHOICE_FILE
    if not path.is_file():
        return None
    try:
        chosen = int(json.loads(path.read_text())["chosen"])
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as error:
        raise ValueError(
            f"{path}: not a source-pixel choice record ({error!r}); rerun choose_source_pixels"
        ) from None
    return chosen if same_result(results_dir / "spix2", results_dir / folder(chosen)) else None

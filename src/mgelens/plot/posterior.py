"""Corner figure of a phase's posterior: the mass and shear parameters' one- and
two-dimensional marginals, with the truth of a mock marked.

A lens modeller reads the degeneracies of a fit here (the slope against the shear and
θ_E, the mass ellipticity against the shear: docs/coverage.md) and sees at a glance
whether a mock's truth lies inside them. Parameters are those of
:data:`mgelens.coverage.PARAMETERS` that the phase sampled (a parameter with no spread,
fixed or tied, is left out). Units: centres and θ_E in arcsec (θ_E in the phase's own
convention, SPEC §3.3), the mass angle φ in degrees counter-clockwise from +x (unwrapped
around the highest-likelihood sample, SPEC §1.1), the shear components dimensionless.

* Diagonal: the weighted marginal (histogram of the samples' weights), the weighted
  median (solid) and central 68.27 % interval (dashed), the same numbers as
  ``result.json``'s ``median`` and ``interval_1sigma`` (:class:`PhaseResult`), written
  above each column. Where MASS pooled the runs of several source meshes (``settings``'
  ``meshes``, their samples stored in turn), each run's share of the marginal is drawn
  too, in :data:`MESH_COLOURS`: where the meshes disagree the pool has several modes.
* Below it: the joint weighted density (histogram smoothed by one bin) with the regions
  holding 39.3 % and 86.5 % of the weight (:data:`CONTOUR_FRACTIONS`, a two-dimensional
  Gaussian's 1σ and 2σ), filled.
* The truth, if given, as lines and a marker in :data:`TRUTH_COLOUR`.
* Published values, if given (a real lens's, :func:`published_references`), as lines in
  :data:`PUBLISHED_COLOUR`, with their 1σ band on the diagonal (a value beyond the
  posterior's range written at that edge of the panel): Shajib et al. 2021's
  imaging-only slope, and Bolton et al. 2008's b_SIE as θ_E^AG of an SIE with their
  q_SIE (SPEC §3.3), which is a power law's θ_E only where γ = 2.
"""

import itertools
import math
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from scipy import ndimage

from mgelens.coverage import PARAMETERS
from mgelens.published import einstein_radius_ag
from mgelens.search.results import PhaseResult, unwrapped_angles

LABELS = {
    "mass.centre_x": "mass x (″)",
    "mass.centre_y": "mass y (″)",
    "mass.einstein_radius": "θ_E (″)",
    "mass.axis_ratio": "mass q",
    "mass.angle": "mass φ (°)",
    "mass.slope": "slope γ",
    "shear.gamma_1": "shear γ₁",
    "shear.gamma_2": "shear γ₂",
}
"""Axis label (with unit) of each parameter."""

CONTOUR_FRACTIONS = (1.0 - np.exp(-0.5), 1.0 - np.exp(-2.0))
"""Weight inside the filled regions of the joint panels: a 2D Gaussian's 1σ and 2σ
(0.393 and 0.865)."""

BINS = 30
"""Histogram bins per axis over each panel's range."""

TRUTH_COLOUR = "C3"
MESH_COLOURS = {"C0": "blue", "C1": "orange", "C4": "purple", "C5": "brown"}
"""Colours of the source meshes' runs on the diagonal, in order, with their names."""
PUBLISHED_COLOUR = "C2"


def published_references(published: Mapping[str, float]) -> dict[str, tuple[float, float, float]]:
    """{parameter: (value, lower error, upper error)} from one lens's row of
    :func:`mgelens.published.published_values`: Shajib's slope (its 1σ errors) and
    Bolton's b_SIE converted to θ_E^AG with q_SIE and γ = 2 (no errors: 0, 0). A value
    the tables do not have is left out."""
    references = {}
    gamma = published.get("shajib_gamma", math.nan)
    if np.isfinite(gamma):
        lower, upper = published["shajib_gamma_lo"], published["shajib_gamma_hi"]
        references["mass.slope"] = (float(gamma), float(lower), float(upper))
    b_sie, q_sie = published.get("bolton_b_sie", math.nan), published.get("bolton_q_sie", math.nan)
    if np.isfinite(b_sie) and np.isfinite(q_sie):
        references["mass.einstein_radius"] = (
            float(einstein_radius_ag(b_sie, q_sie, 2.0)),
            0.0,
            0.0,
        )
    return references


def credible_levels(density: np.ndarray, fractions: Sequence[float]) -> np.ndarray:
    """Density thresholds whose super-level sets hold ``fractions`` of the total.

    For each fraction f, the returned level t is the largest value such that the cells of
    ``density`` ≥ t hold at least f of ``density.sum()`` (highest-density regions).
    Levels are returned in the order of ``fractions``.

    Raises
    ------
    ValueError
        If the density has no positive weight or a fraction is outside (0, 1].
    """
    values = np.sort(np.asarray(density, dtype=float).ravel())[::-1]
    total = values.sum()
    if not total > 0:
        raise ValueError("the density has no positive weight")
    cumulative = np.cumsum(values) / total
    levels = []
    for fraction in fractions:
        if not 0.0 < fraction <= 1.0:
            raise ValueError(f"fractions must lie in (0, 1], got {fraction}")
        index = min(int(np.searchsorted(cumulative, fraction)), values.size - 1)
        levels.append(values[index])
    return np.array(levels)


def _mesh_parts(phase: PhaseResult, n_samples: int) -> list[slice]:
    """The sample ranges of each source mesh's run in a pooled phase (none if the phase
    did not pool, or its record does not account for every sample)."""
    counts = [mesh.get("n_samples") for mesh in phase.settings.get("meshes") or []]
    if len(counts) < 2 or None in counts or sum(counts) != n_samples:
        return []
    edges = np.concatenate([[0], np.cumsum(counts)])
    return [slice(int(a), int(b)) for a, b in itertools.pairwise(edges)]


def _sampled(table: pd.DataFrame) -> list[str]:
    """The parameters of :data:`PARAMETERS` with a spread in the phase's samples."""
    return [name for name in PARAMETERS if name in table and np.ptp(table[name]) > 0]


def _columns(phase: PhaseResult, table: pd.DataFrame, names: Sequence[str]) -> dict:
    """The samples of ``names``; an angle unwrapped near the highest-likelihood sample and
    moved by a multiple of 180° to the side of ``result.json``'s median (which
    :class:`PhaseResult` reduces to [0°, 180°))."""
    columns = {}
    for name in names:
        values = table[name].to_numpy(dtype=float)
        if name.endswith(".angle"):
            values = unwrapped_angles(values, phase.max_likelihood[name])
            middle = 0.5 * (values.min() + values.max())
            values -= 180.0 * np.round((middle - phase.median[name]) / 180.0)
        columns[name] = values
    return columns


def _truth_near(name: str, truth: float, centre: float) -> float:
    """``truth``, an angle moved by 180° multiples to within ±90° of ``centre``."""
    return float(unwrapped_angles(truth, centre)) if name.endswith(".angle") else truth


def _range(values: np.ndarray, weights: np.ndarray, marks: Sequence) -> tuple[float, float]:
    """Panel range: the samples holding weight, widened to the marked values (a mock's
    truth; None: none), padded by 5 %. Published values do not widen it: one far off would
    flatten the posterior to a line (:func:`_published_band` points to it instead)."""
    held = values[weights > 1e-6 * weights.max()]
    low, high = held.min(), held.max()
    for mark in marks:
        if mark is not None:
            low, high = min(low, mark), max(high, mark)
    pad = 0.05 * (high - low) if high > low else max(abs(low) * 1e-3, 1e-6)
    return low - pad, high + pad


def _error_text(median: float, lower: float, upper: float) -> str:
    """``median`` with its 1σ errors, to two significant digits of the larger error."""
    error = max(upper - median, median - lower, 1e-12)
    digits = max(0, 1 - int(np.floor(np.log10(error))))
    plus, minus = f"{upper - median:.{digits}f}", f"{median - lower:.{digits}f}"
    return f"{median:.{digits}f}$^{{+{plus}}}_{{-{minus}}}$"


def posterior_figure(
    phase: PhaseResult,
    truth: Mapping[str, float] | None = None,
    title: str = "",
    published: Mapping[str, tuple[float, float, float]] | None = None,
) -> Figure:
    """The corner figure of ``phase`` (see the module), with ``truth`` (parameter name →
    true value, :func:`mgelens.recovery.true_mass_parameters`) and ``published``
    (parameter name → (value, lower error, upper error), :func:`published_references`)
    marked if given.

    Raises
    ------
    ValueError
        If the phase sampled none of the mass and shear parameters.
    """
    table = phase.samples_table()
    names = _sampled(table)
    if not names:
        raise ValueError(
            f"phase {phase.phase} sampled none of the mass and shear parameters "
            f"{list(PARAMETERS)}; draw the posterior of a mass phase (e.g. results/<lens>/mass)"
        )
    columns, weights = _columns(phase, table, names), table["weight"].to_numpy(dtype=float)
    median, interval = phase.median, phase.interval(1)
    meshes = _mesh_parts(phase, len(weights))
    truths = {
        name: _truth_near(name, float(truth[name]), median[name])
        for name in names
        if truth is not None and name in truth
    }
    references = {name: published[name] for name in names if published and name in published}
    ranges = {name: _range(columns[name], weights, [truths.get(name)]) for name in names}

    n = len(names)
    size = 1.6 * n + 1.0
    figure = Figure(figsize=(size, size), layout="constrained")
    axes = figure.subplots(n, n, squeeze=False)
    for row, y_name in enumerate(names):
        for col, x_name in enumerate(names):
            axis = axes[row, col]
            if col > row:
                axis.set_visible(False)
                continue
            if col == row:
                _diagonal(axis, columns[x_name], weights, ranges[x_name], median[x_name],
                          interval[x_name], truths.get(x_name), meshes)  # fmt: skip
                _published_band(axis, references.get(x_name), ranges[x_name])
            else:
                pair = (x_name, y_name)
                _joint(axis, [columns[k] for k in pair], weights, [ranges[k] for k in pair],
                       [truths.get(k) for k in pair])  # fmt: skip
                _published_lines(axis, *(references.get(k) for k in pair))
            axis.tick_params(labelsize=7)
            if row == n - 1:
                axis.set_xlabel(LABELS[x_name], fontsize=9)
                axis.tick_params(axis="x", labelrotation=45)
            else:
                axis.set_xticklabels([])
            if col == 0 and row > 0:
                axis.set_ylabel(LABELS[y_name], fontsize=9)
            elif col != row:
                axis.set_yticklabels([])
    legend = "weighted median and 68 % interval; filled: 39 % and 86 % of the weight"
    if meshes:
        seeds = [mesh.get("kmeans_seed") for mesh in phase.settings["meshes"]]
        named = ", ".join(
            f"{seed} {name}" for seed, name in zip(seeds, MESH_COLOURS.values(), strict=False)
        )
        legend += f"; thin: each source mesh's run (k-means seed {named})"
    if truths:
        legend += "; truth in red"
    if references:
        legend += (
            "; green: published (Shajib 2021 γ ± 1σ, Bolton 2008 b_SIE as θ_E of an SIE with its q)"
        )
    figure.suptitle(
        f"{title}{' – ' if title else ''}{phase.phase} posterior "
        f"({len(weights)} samples, ln Z = {phase.output.log_evidence:.1f})\n{legend}",
        fontsize=10,
    )
    return figure


def _diagonal(axis, values, weights, limits, median, interval, truth, meshes) -> None:
    axis.hist(values, bins=BINS, range=limits, weights=weights, histtype="step", color="k")
    for part, colour in zip(meshes, MESH_COLOURS, strict=False):  # at most four drawn
        axis.hist(values[part], bins=BINS, range=limits, weights=weights[part],
                  histtype="step", color=colour, lw=0.8)  # fmt: skip
    axis.axvline(median, color="k", lw=1.0)
    for bound in interval:
        axis.axvline(bound, color="k", lw=0.8, ls="--")
    if truth is not None:
        axis.axvline(truth, color=TRUTH_COLOUR, lw=1.2)
    axis.set_xlim(limits)
    axis.set_yticks([])
    axis.set_title(_error_text(median, *interval), fontsize=8)


def _joint(axis, samples, weights, limits, truth) -> None:
    (x, y), (x_limits, y_limits), (x_truth, y_truth) = samples, limits, truth
    density, x_edges, y_edges = np.histogram2d(
        x, y, bins=BINS, range=(x_limits, y_limits), weights=weights
    )
    density = ndimage.gaussian_filter(density, 1.0)
    if density.sum() > 0:
        levels = credible_levels(density, CONTOUR_FRACTIONS)
        x_mid = 0.5 * (x_edges[1:] + x_edges[:-1])
        y_mid = 0.5 * (y_edges[1:] + y_edges[:-1])
        bounds = [levels[1], levels[0], density.max() * (1 + 1e-9)]
        if bounds[0] < bounds[1] < bounds[2]:
            axis.contourf(x_mid, y_mid, density.T, levels=bounds, colors=["#9ecae1", "#3182bd"])
            axis.contour(x_mid, y_mid, density.T, levels=bounds[:2], colors="k", linewidths=0.6)
    if x_truth is not None:
        axis.axvline(x_truth, color=TRUTH_COLOUR, lw=1.0)
    if y_truth is not None:
        axis.axhline(y_truth, color=TRUTH_COLOUR, lw=1.0)
    if x_truth is not None and y_truth is not None:
        axis.plot(x_truth, y_truth, "s", color=TRUTH_COLOUR, ms=4)
    axis.set_xlim(x_limits)
    axis.set_ylim(y_limits)


def _published_band(axis, reference, limits) -> None:
    """A published value and its 1σ band on a diagonal panel (``reference`` None: none);
    a value beyond the panel's ``limits`` is written at the edge it lies beyond."""
    if reference is None:
        return
    value, lower, upper = reference
    if limits[0] <= value <= limits[1]:
        axis.axvline(value, color=PUBLISHED_COLOUR, lw=1.2)
    else:
        left = value < limits[0]
        axis.text(
            0.02 if left else 0.98,
            0.9,
            f"{'← ' if left else ''}{value:.3g}{'' if left else ' →'}",
            transform=axis.transAxes,
            ha="left" if left else "right",
            va="top",
            color=PUBLISHED_COLOUR,
            fontsize=8,
        )
    if lower > 0 or upper > 0:
        band = (max(value - lower, limits[0]), min(value + upper, limits[1]))
        if band[0] < band[1]:
            axis.axvspan(*band, color=PUBLISHED_COLOUR, alpha=0.15, lw=0)


def _published_lines(axis, x_reference, y_reference) -> None:
    """Published values on a joint panel: a vertical and/or a horizontal line."""
    if x_reference is not None:
        axis.axvline(x_reference[0], color=PUBLISHED_COLOUR, lw=1.0, ls="-.")
    if y_reference is not None:
        axis.axhline(y_reference[0], color=PUBLISHED_COLOUR, lw=1.0, ls="-.")

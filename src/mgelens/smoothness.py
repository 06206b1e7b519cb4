"""How smoothly the log evidence follows the mass slope (the paper's Appendix A; SPEC §11).

A scan fixes every parameter of a mock at its truth, the source mesh (k-means centres of
the image pixels, weighted by the true lensed source) and the regularization coefficient
(λ = 1), and evaluates ln ε (SPEC §7, NNLS on) at slopes γ = γ_true + k·step,
k = −n … n. A smooth scheme gives a curve whose step-to-step changes follow its trend;
a scheme whose source pixels switch discretely as γ moves gives jumps.

Two source schemes, each under two edge rules (:class:`mgelens.fit_settings.FitSettings`):

* ``natural_neighbour`` interpolation with cross regularization
  (:class:`~mgelens.source.regularization.ConstantSplit`), the paper's scheme;
* ``nearest`` (nearest-cell) mapping with neighbour regularization
  (:class:`~mgelens.source.regularization.Constant`), the scheme the paper compares with;
* edge rules ``anchor`` (SPEC §4.2–4.4) and ``continuous``; edge pixels are not forced to
  zero in either (that rule adds a jump whenever a pixel joins the mesh's hull).

A **jump** is the change between adjacent steps minus the local trend, the running median
of the changes over ±:data:`TREND_HALF_WIDTH` steps (the evidence slopes by several units
per step away from its peak).
"""

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from mgelens.fit import FitDataset, LensModel, PixelizedSource, fit
from mgelens.fit_settings import FitSettings
from mgelens.grid import pixel_centres
from mgelens.imaging import Imaging
from mgelens.light import MGESet
from mgelens.mass import EPL
from mgelens.source.image_mesh import kmeans_centres, kmeans_weights
from mgelens.source.regularization import Constant, ConstantSplit

TREND_HALF_WIDTH = 5
"""Half-width, in steps, of the running median that a jump is measured against."""
STEP = 0.0004
"""The paper's slope step (Appendix A)."""
HALF_RANGE = 0.02
"""The paper's scan half-range in γ around the truth."""
SCHEMES = {
    "natural_neighbour": ("natural_neighbour", ConstantSplit),
    "nearest": ("nearest", Constant),
}
"""Scheme name: (source interpolation, regularization class with coefficient λ)."""
EDGE_RULES = ("anchor", "continuous")
"""Edge rules scanned (:attr:`mgelens.fit_settings.FitSettings.edge_rule`)."""
REGULARIZATION_COEFFICIENT = 1.0
"""λ of both schemes' constant regularization."""
KMEANS_WEIGHT_FLOOR, KMEANS_WEIGHT_POWER = 0.2, 1.0
"""k-means weights of the scan's mesh (:func:`mgelens.source.image_mesh.kmeans_weights`)."""


@dataclass(frozen=True)
class ScanModel:
    """Everything of a scan but the slope.

    Attributes
    ----------
    mass : EPL
        The true mass; the scan replaces its slope.
    light : tuple of MGESet
        Two extended MGE sets at the mass centre (intensities solved linearly).
    mesh_x, mesh_y : ndarray
        Image-plane k-means centres of the source mesh, arcsec.
    """

    mass: EPL
    light: tuple[MGESet, ...]
    mesh_x: np.ndarray
    mesh_y: np.ndarray


def scan_model(
    dataset: FitDataset,
    mass: EPL,
    adapt: np.ndarray,
    mask_radius: float,
    n_source_pixels: int,
    mesh_seed: int,
) -> ScanModel:
    """The fixed part of a scan on ``dataset``: the true ``mass``, two extended MGE sets
    (ell_comps (0.05, 0.03) and (−0.1, 0.1)) out to ``mask_radius`` (arcsec), and
    ``n_source_pixels`` k-means centres of the used pixels weighted by ``adapt`` (the
    lensed source over the used pixels) with seed ``mesh_seed``."""
    pixel_scale = dataset.imaging.pixel_scale
    x, y = pixel_centres(dataset.mask.shape, pixel_scale)
    used = ~dataset.mask
    weights = kmeans_weights(adapt, KMEANS_WEIGHT_FLOOR, KMEANS_WEIGHT_POWER)
    mesh_x, mesh_y = kmeans_centres(x[used], y[used], weights, n_source_pixels, mesh_seed)
    centre = tuple(mass.centre)
    light = (
        MGESet.extended(centre, (0.05, 0.03), pixel_scale, mask_radius),
        MGESet.extended(centre, (-0.1, 0.1), pixel_scale, mask_radius),
    )
    return ScanModel(mass, light, mesh_x, mesh_y)


def scan_slopes(truth: float, step: float = STEP, half_range: float = HALF_RANGE) -> np.ndarray:
    """γ_true + k·step for k = −n … n, n = round(half_range/step)."""
    n = round(half_range / step)
    return truth + step * np.arange(-n, n + 1)


def evidence_scan(
    dataset: FitDataset,
    model: ScanModel,
    scheme: str,
    slopes: Sequence[float],
    regularization=None,
    adapt_image: np.ndarray | None = None,
) -> np.ndarray:
    """ln ε of ``model`` at each slope on ``dataset``, with the source ``scheme`` (a key of
    :data:`SCHEMES`; its regularization with λ = 1 unless ``regularization`` is given,
    with ``adapt_image`` for an adaptive one)."""
    interpolation, regularization_class = SCHEMES[scheme]
    if regularization is None:
        regularization = regularization_class(REGULARIZATION_COEFFICIENT)
    source = PixelizedSource(model.mesh_x, model.mesh_y, regularization, interpolation, adapt_image)
    values = []
    for slope in slopes:
        mass = replace(model.mass, slope=float(slope))
        values.append(fit(dataset, LensModel((mass,), model.light, (), source)).log_evidence)
    return np.array(values)


def jumps(values: np.ndarray, half_width: int = TREND_HALF_WIDTH) -> np.ndarray:
    """|step change − running median of the step changes over ±``half_width`` steps|,
    one per step (``len(values) − 1``)."""
    steps = np.diff(values)
    trend = np.array(
        [np.median(steps[max(0, i - half_width) : i + half_width + 1]) for i in range(steps.size)]
    )
    return np.abs(steps - trend)


def mock_dataset(
    imaging: Imaging, mask: np.ndarray, centre: tuple[float, float], edge_rule: str = "anchor"
) -> FitDataset:
    """The scan's dataset: ``imaging`` in ``mask`` under ``edge_rule``, default fit settings
    otherwise but edge pixels free (``force_edge_pixels_to_zero=False``), light
    over-sampled about ``centre`` (arcsec)."""
    settings = FitSettings(force_edge_pixels_to_zero=False, edge_rule=edge_rule)
    return FitDataset.from_imaging(imaging, mask, settings, light_centre=centre)


def appendix_a_table(
    imaging: Imaging,
    mask: np.ndarray,
    model: ScanModel,
    step: float = STEP,
    half_range: float = HALF_RANGE,
) -> pd.DataFrame:
    """The Appendix A scan of ``imaging`` in ``mask``: every scheme of :data:`SCHEMES`
    under every edge rule of :data:`EDGE_RULES` (:func:`mock_dataset`), at
    :func:`scan_slopes` about ``model``'s true slope.

    Returns
    -------
    pandas.DataFrame
        One row per edge rule, scheme and slope: ``scheme``, ``edge_rule``, ``slope``,
        ``log_evidence`` and ``jump`` (the jump of the step that ends at this slope,
        :func:`jumps`; NaN on the first slope).
    """
    slopes = scan_slopes(model.mass.slope, step, half_range)
    centre = tuple(model.mass.centre)
    rows = []
    for edge_rule in EDGE_RULES:
        dataset = mock_dataset(imaging, mask, centre, edge_rule)
        for scheme in SCHEMES:
            values = evidence_scan(dataset, model, scheme, slopes)
            steps = np.concatenate([[np.nan], jumps(values)])
            rows.append(
                pd.DataFrame(
                    {
                        "scheme": scheme,
                        "edge_rule": edge_rule,
                        "slope": slopes,
                        "log_evidence": values,
                        "jump": steps,
                    }
                )
            )
    return pd.concat(rows, ignore_index=True)


def jump_summary(table: pd.DataFrame) -> pd.DataFrame:
    """Per scheme and edge rule of an :func:`appendix_a_table`: the largest, 95th-percentile
    and median jump (columns ``max_jump``, ``p95_jump``, ``median_jump``)."""
    grouped = table.dropna(subset=["jump"]).groupby(["scheme", "edge_rule"], sort=False)["jump"]
    return pd.DataFrame(
        {
            "max_jump": grouped.max(),
            "p95_jump": grouped.quantile(0.95),
            "median_jump": grouped.median(),
        }
    ).reset_index()

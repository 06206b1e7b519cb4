"""What the per-lens overview figure (the paper's Fig. 1) shows, computed from one fit.

:func:`overview_from_fit` turns the maximum-likelihood :class:`~mgelens.fit.FitResult` of
a phase into an :class:`Overview`: plain arrays and small records that
:func:`mgelens.plot.overview.overview_figure` draws without computing anything.

Conventions: native 2D arrays in the data's orientation (row index increases with +y,
SPEC §1.1), positions and lengths in arcsec, angles in degrees counter-clockwise from +x
in [0, 180), brightness in the data unit per image pixel.
"""

import logging
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from mgelens.fit import FitResult
from mgelens.geometry import axis_ratio_and_angle_from
from mgelens.grid import pixel_centres, to_native
from mgelens.imaging import Imaging
from mgelens.light import MGESet, Sersic
from mgelens.mask import SLACS_NOISE_THRESHOLD, circular
from mgelens.mass import caustic, tangential_critical_curve
from mgelens.pipeline.products import source_plane_image
from mgelens.source.mesh import VoronoiMesh

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class LightComponent:
    """Geometry of one lens-light component (MGE set or Sérsic) for the contour panel.

    Attributes
    ----------
    label : str
        Legend name: ``set <k>``, ``point set``, ``Sérsic <k>`` (``fixed`` appended for
        light an earlier phase fixed).
    centre : (float, float)
        arcsec.
    axis_ratio, angle : float
        q and PA (degrees CCW from +x, [0, 180)) from its ell_comps (SPEC §2.1), the values
        of the ``max_likelihood_fit`` record.
    semi_major : float
        Size of the ellipse drawn, arcsec: for an MGE set the flux-weighted mean major-axis
        dispersion Σ F_k σ_k/q / Σ F_k (F_k ∝ σ_k² max(I_k, 0), SPEC §2.2); for a Sérsic its
        major-axis half-light radius R_e/√q; 0 for a set whose solved fluxes are all 0.
    kind : {"mge", "point", "sersic"}
        An extended MGE set, the compact point set (SPEC §2.4; marked rather than drawn as
        an ellipse) or a Sérsic.
    """

    label: str
    centre: tuple[float, float]
    axis_ratio: float
    angle: float
    semi_major: float
    kind: str = "mge"

    @property
    def point(self) -> bool:
        return self.kind == "point"


@dataclass(frozen=True, eq=False)
class SourcePlane:
    """Source-plane reconstruction on a regular grid (:func:`source_plane_image`) over the
    square of :func:`source_window` (the whole source grid where it gives none), NaN
    outside a pixelized source's mesh.

    ``extent`` = (x_min, x_max, y_min, y_max) arcsec of the grid's outer pixel edges;
    ``mesh_edges`` (n, 2, 2) holds the finite Voronoi cell edges [(x, y), (x, y)] of a
    pixelized source, ``None`` for an MGE source. ``off_support`` (bool, the shape of
    ``image``) marks the grid points in the Voronoi cells of mesh points held at zero off
    the source's support (:mod:`mgelens.source.support`); ``None`` for a source solved on
    its whole mesh.
    """

    image: np.ndarray
    extent: tuple[float, float, float, float]
    mesh_edges: np.ndarray | None = None
    off_support: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class Overview:
    """Everything the overview figure draws.

    Attributes
    ----------
    title : str
        Figure title: lens, phase, ln ε (ln L for an MGE source) and χ²/N.
    pixel_scale : float
        Δ, arcsec per pixel of the image-plane arrays (grid origin (0, 0)).
    unit : str
        Brightness unit of the data (FITS ``BUNIT``), "" if unknown.
    data, noise_map : ndarray (n_y, n_x)
        The imaging.
    lens_light, lensed_source : ndarray (n_y, n_x)
        PSF-convolved model components, NaN outside the fit's mask.
    normalized_residuals : ndarray (n_y, n_x)
        (data − model)/σ, NaN outside the fit's mask.
    contaminants : ndarray of bool (n_y, n_x)
        Pixels inside the fit circle that the fit ignores: excluded by ``mask.fits`` or
        kept with a sentinel noise > :data:`~mgelens.mask.SLACS_NOISE_THRESHOLD` (SPEC §1.2).
    mask_centre, mask_radius : (float, float), float
        The fit circle, arcsec.
    source : SourcePlane
    critical_curve, caustic : (ndarray, ndarray) or None
        Tangential critical curve and its caustic (SPEC §3.4), ``None`` if the mass model
        has no closed tangential critical curve within ±3″.
    components : tuple of LightComponent
    """

    title: str
    pixel_scale: float
    unit: str
    data: np.ndarray
    noise_map: np.ndarray
    lens_light: np.ndarray
    lensed_source: np.ndarray
    normalized_residuals: np.ndarray
    contaminants: np.ndarray
    mask_centre: tuple[float, float]
    mask_radius: float
    source: SourcePlane
    critical_curve: tuple[np.ndarray, np.ndarray] | None
    caustic: tuple[np.ndarray, np.ndarray] | None
    components: tuple[LightComponent, ...]


def contaminant_pixels(
    imaging: Imaging,
    fit_mask: np.ndarray,
    mask_radius: float,
    mask_centre: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """Pixels inside the fit circle that carry no weight in the fit (True = contaminant).

    Either excluded from the fit although inside the circle (``fit_mask`` True there:
    ``mask.fits``) or kept with a noise above :data:`SLACS_NOISE_THRESHOLD` (the SLACS
    1e8 sentinel, SPEC §1.2).
    """
    inside = ~circular(imaging.shape, imaging.pixel_scale, mask_radius, mask_centre)
    return inside & (fit_mask | (imaging.noise_map > SLACS_NOISE_THRESHOLD))


def voronoi_edges(mesh: VoronoiMesh) -> np.ndarray:
    """Finite Voronoi cell edges of a mesh, (n_edges, 2, 2) arcsec.

    Each edge joins the circumcentres of two Delaunay triangles sharing a side; the
    unbounded edges of hull cells are left out.
    """
    triangles, sides = np.nonzero(mesh.neighbors >= 0)
    neighbours = mesh.neighbors[triangles, sides]
    once = triangles < neighbours
    return np.stack(
        [mesh.circumcentres[triangles[once]], mesh.circumcentres[neighbours[once]]], axis=1
    )


def outside_hull_blank(
    image: np.ndarray, pixel_scale: float, centre: tuple[float, float], mesh: VoronoiMesh
) -> np.ndarray:
    """A source-plane ``image`` (grid of ``pixel_scale`` about ``centre``) with NaN at the
    grid points outside the mesh's convex hull, where the reconstruction is undefined."""
    x, y = pixel_centres(image.shape, pixel_scale, centre)
    outside = mesh.delaunay.find_simplex(np.column_stack([x.ravel(), y.ravel()])) < 0
    return np.where(outside.reshape(image.shape), np.nan, image)


def off_support_cells(
    shape: tuple[int, int],
    pixel_scale: float,
    centre: tuple[float, float],
    mesh: VoronoiMesh,
    support: np.ndarray,
) -> np.ndarray:
    """Bool ``shape``: the points of a source-plane grid (``pixel_scale`` about ``centre``)
    whose Voronoi cell, the cell of their nearest mesh point, belongs to a mesh point off
    ``support`` (bool over the mesh points), whose flux the fit held at zero."""
    x, y = pixel_centres(shape, pixel_scale, centre)
    _, nearest = cKDTree(mesh.points).query(np.column_stack([x.ravel(), y.ravel()]))
    return ~np.asarray(support, dtype=bool)[nearest].reshape(shape)


def _component_label(name: str) -> str:
    if name == "point":
        return "point set"
    kind, _, index = name.rpartition("_")
    return {"set": "set", "sersic": "Sérsic"}.get(kind, kind) + f" {index}"


def light_component(name: str, profile: MGESet | Sersic, intensities: np.ndarray) -> LightComponent:
    """:class:`LightComponent` of a lens-light set or Sérsic named ``name`` (``set_<k>``,
    ``point``, ``sersic_<k>``) with its solved intensities."""
    q, angle = axis_ratio_and_angle_from(profile.ell_comps)
    if isinstance(profile, Sersic):
        kind, size = "sersic", profile.effective_radius / np.sqrt(q)
    else:
        kind = "point" if name == "point" else "mge"
        fluxes = profile.sigmas**2 * np.clip(intensities, 0.0, None)
        total = fluxes.sum()
        size = float(np.sum(fluxes * profile.sigmas / q) / total) if total > 0 else 0.0
    return LightComponent(
        _component_label(name),
        (float(profile.centre[0]), float(profile.centre[1])),
        float(q),
        float(angle),
        float(size),
        kind,
    )


def light_components(result: FitResult, names: Sequence[str]) -> tuple[LightComponent, ...]:
    """Components of a fit's lens light: the solved ones named ``names`` (the phase
    model's spec names, in order), then the fixed light (Sérsics an earlier phase fixed,
    SPEC §8.1)."""
    components, start = [], 0
    intensities = result.lens_light_intensities
    for name, profile in zip(names, result.model.lens_light, strict=True):
        solved = intensities[start : start + profile.n_columns]
        components.append(light_component(name, profile, solved))
        start += profile.n_columns
    for k, profile in enumerate(result.model.fixed_light):
        fixed = light_component(f"sersic_{k}", profile, np.array([profile.intensity]))
        components.append(replace(fixed, label=f"{fixed.label} (fixed)"))
    return tuple(components)


SOURCE_ZOOM_FRACTION = 0.05
"""The source panel zooms on the grid points at or above this fraction of the source's
peak (:func:`source_window`)."""
SOURCE_ZOOM_MARGIN = 0.25
"""... and the caustic, padded on each side by this fraction of their box's side."""
MIN_SOURCE_HALF_WIDTH = 0.25
"""Smallest half-width (arcsec) of the zoomed source panel."""


def source_window(
    image: np.ndarray,
    extent: tuple[float, float, float, float],
    caustic_line: tuple | None = None,
) -> tuple[tuple[float, float], float] | None:
    """The square (centre, half-width; arcsec) that the source panel shows.

    A compact source on a mesh that spans the whole traced mask fills only a few pixels
    of a grid over the mesh (docs/slacs.md, "Two lenses of the seventh run"). The panel
    therefore shows the box around the grid points of ``image`` (on ``extent``, row
    index increasing with +y) at or above :data:`SOURCE_ZOOM_FRACTION` of its peak,
    together with the caustic (x, y arrays) if given, padded on each side by
    :data:`SOURCE_ZOOM_MARGIN` of the box's longer side, at least
    :data:`MIN_SOURCE_HALF_WIDTH`. ``None`` (show the whole grid) when the image has no
    positive value or the window would not be smaller than the grid.
    """
    finite = np.where(np.isfinite(image), image, 0.0)
    peak = float(finite.max()) if finite.size else 0.0
    if not peak > 0.0:
        return None
    n_y, n_x = image.shape
    x_min, x_max, y_min, y_max = extent
    x = x_min + (np.arange(n_x) + 0.5) * (x_max - x_min) / n_x
    y = y_min + (np.arange(n_y) + 0.5) * (y_max - y_min) / n_y
    rows, cols = np.nonzero(finite >= SOURCE_ZOOM_FRACTION * peak)
    xs, ys = [x[cols]], [y[rows]]
    if caustic_line is not None:
        xs.append(np.asarray(caustic_line[0], dtype=float))
        ys.append(np.asarray(caustic_line[1], dtype=float))
    xs, ys = np.concatenate(xs), np.concatenate(ys)
    side = max(np.ptp(xs), np.ptp(ys))
    half_width = max(0.5 * side + SOURCE_ZOOM_MARGIN * side, MIN_SOURCE_HALF_WIDTH)
    if half_width >= 0.5 * max(x_max - x_min, y_max - y_min):
        return None
    centre = (0.5 * float(xs.min() + xs.max()), 0.5 * float(ys.min() + ys.max()))
    return centre, float(half_width)


def _grid_extent(
    image: np.ndarray, pixel_scale: float, centre: tuple[float, float]
) -> tuple[float, float, float, float]:
    """(x_min, x_max, y_min, y_max), arcsec, of a grid's outer pixel edges."""
    half_x, half_y = 0.5 * pixel_scale * image.shape[1], 0.5 * pixel_scale * image.shape[0]
    return (centre[0] - half_x, centre[0] + half_x, centre[1] - half_y, centre[1] + half_y)


def critical_lines(mass: Sequence) -> tuple[tuple | None, tuple | None]:
    """(tangential critical curve, caustic) of ``mass`` on the SPEC §3.4 grid, or
    (None, None) when it has no closed tangential critical curve within ±3″."""
    try:
        curve = tangential_critical_curve(mass)
    except ValueError as error:
        logger.warning("no critical curve drawn: %s", error)
        return None, None
    return curve, caustic(mass)


def overview_from_fit(
    result: FitResult,
    component_names: Sequence[str],
    mask_radius: float,
    mask_centre: tuple[float, float] = (0.0, 0.0),
    lens: str = "",
    phase: str = "",
) -> Overview:
    """The :class:`Overview` of a phase's maximum-likelihood fit.

    Parameters
    ----------
    result : FitResult
        :func:`mgelens.pipeline.run.scored_fit` of the problem and values of
        :func:`mgelens.pipeline.run.max_likelihood_problem`.
    component_names : sequence of str
        Names of the solved lens-light components (``spec.name`` of the phase model's
        ``lens_light``), in order.
    mask_radius, mask_centre : float, (float, float)
        The fit circle, arcsec.
    lens, phase : str
        For the title.

    The title gives the figure of merit, the log evidence ln ε of a pixelized source or
    ln L (the same number, :class:`~mgelens.fit.FitResult`) of an MGE source, and χ²/N
    over the N pixels that carry weight (inside the mask, not contaminants).
    """
    dataset = result.dataset
    imaging = dataset.imaging
    contaminants = contaminant_pixels(imaging, dataset.mask, mask_radius, mask_centre)
    weighted = int(np.count_nonzero(dataset.noise_map <= SLACS_NOISE_THRESHOLD))
    curve, caustic_line = critical_lines(result.model.mass)
    image, source_pixel, centre = source_plane_image(result)
    window = source_window(image, _grid_extent(image, source_pixel, centre), caustic_line)
    if window is not None:
        image, source_pixel, centre = source_plane_image(result, window=window)
    extent = _grid_extent(image, source_pixel, centre)
    mesh_edges = off_support = None
    if result.source is not None:
        mesh = result.source.mesh
        mesh_edges = voronoi_edges(mesh)
        image = outside_hull_blank(image, source_pixel, centre, mesh)
        if result.source.support is not None:
            off_support = off_support_cells(
                image.shape, source_pixel, centre, mesh, result.source.support
            )
    merit = "ln ε" if result.source is not None else "ln L"
    title = (
        f"{lens} · {phase}: {merit} = {result.log_evidence:.2f}, "
        f"χ²/N = {result.chi_squared / max(weighted, 1):.3f} (N = {weighted})"
    )

    def native(slim: np.ndarray) -> np.ndarray:
        return to_native(slim, dataset.mask, fill=np.nan)

    return Overview(
        title=title,
        pixel_scale=imaging.pixel_scale,
        unit=imaging.unit,
        data=np.asarray(imaging.data),
        noise_map=np.asarray(imaging.noise_map),
        lens_light=native(result.lens_light_image),
        lensed_source=native(result.lensed_source_image),
        normalized_residuals=native(result.normalized_residuals),
        contaminants=contaminants,
        mask_centre=(float(mask_centre[0]), float(mask_centre[1])),
        mask_radius=float(mask_radius),
        source=SourcePlane(image, extent, mesh_edges, off_support),
        critical_curve=curve,
        caustic=caustic_line,
        components=light_components(result, component_names),
    )

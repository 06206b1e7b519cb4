"""One model + one dataset -> model image, residuals, χ², log likelihood and log evidence.

This is the function every sampler calls (SPEC §4–7). A :class:`LensModel` holds the
mass profiles, the lens light (MGE sets whose intensities are solved linearly, plus any
fixed non-linear light) and the source: an MGE in the source plane
(:class:`MGESource`, SP phase) or a Voronoi mesh with natural-neighbour interpolation
(:class:`PixelizedSource`). All linear unknowns, ordered [lens-light Gaussians |
source Gaussians | source pixels], are solved at once, non-negative by default.

Failures of the mesh or of the linear algebra raise :class:`FitError` subclasses;
:func:`figure_of_merit` turns them into a rejected sample (SPEC §8.4).
"""

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from scipy import sparse

from mgelens import mass as mass_module
from mgelens.analytic_blur import smallest_analytic_sigma
from mgelens.convolve import trimmed_psf
from mgelens.fit_settings import FitSettings
from mgelens.grid import SubGrid, pixel_centres, sub_grid, to_native
from mgelens.imaging import Imaging
from mgelens.inversion.cholesky import InversionError, factor_log_det, upper_cholesky
from mgelens.inversion.evidence import (
    log_det_regularization,
    log_evidence,
    log_likelihood,
    noise_normalization,
)
from mgelens.inversion.solve import LinearSolution, solve_linear_system
from mgelens.inversion.system import (
    DenseTerms,
    TilePlan,
    WeightedBlurredMapping,
    curvature_matrix,
    data_vector,
    weighted_gram,
)
from mgelens.light import LightGrid, MGESet
from mgelens.light_prior import MGESmoothnessPrior, PriorTerms
from mgelens.mask import validate_mask
from mgelens.rejection import REJECTED_LOG_LIKELIHOOD
from mgelens.source.border import border_sub_pixels, relocate_to_border
from mgelens.source.image_mesh import mask_extent_centre
from mgelens.source.interpolate import natural_neighbour_weights, nearest_cell_weights
from mgelens.source.mapping import SourceWeights, mapping_matrix
from mgelens.source.mesh import MeshError, VoronoiMesh
from mgelens.source.schemes import INTERPOLATIONS
from mgelens.source.support import reached_source_pixels

BORDER_RULE_OF_EDGE_RULE = {"anchor": "nearest_point", "continuous": "polygon"}

FitError = (MeshError, InversionError, np.linalg.LinAlgError, FloatingPointError)
"""Exceptions that mean "this sample cannot be fitted" rather than a programming error."""


@dataclass(frozen=True, eq=False)
class FitDataset:
    """An :class:`Imaging` inside a mask with everything a fit precomputes once.

    Build with :meth:`from_imaging`; slim vectors are over the unmasked pixels.
    """

    imaging: Imaging
    mask: np.ndarray
    settings: FitSettings
    light_grid: LightGrid
    source_grid: SubGrid
    border: np.ndarray
    _columns_cache: dict = field(default_factory=dict, repr=False)
    _source_cache: dict = field(default_factory=dict, repr=False)
    _held_cache: dict = field(default_factory=dict, repr=False)

    @classmethod
    def from_imaging(
        cls,
        imaging: Imaging,
        mask: np.ndarray | None = None,
        settings: FitSettings | None = None,
        light_centre: tuple[float, float] = (0.0, 0.0),
    ) -> "FitDataset":
        """Precompute grids for ``imaging`` in ``mask`` (default: the imaging's own mask).

        ``light_centre`` is the lens-light prior centre around which light profiles are
        over-sampled more finely.
        """
        settings = settings or FitSettings()
        mask = imaging.mask if mask is None else mask
        if mask is None:
            raise ValueError("a fit needs a mask: pass mask= or give the Imaging a mask")
        mask = validate_mask(mask, imaging.shape)
        used = ~mask
        if not np.all(np.isfinite(imaging.data[used])) or np.any(imaging.noise_map[used] <= 0):
            raise ValueError(
                f"{imaging.name or 'imaging'}: data must be finite and noise > 0 inside the mask"
            )
        psf = trimmed_psf(imaging.psf, settings.psf_trim)
        light_grid = LightGrid.from_mask(
            mask,
            psf,
            imaging.pixel_scale,
            centre=light_centre,
            sub_size=settings.lp_sub_size,
            sub_size_centre=settings.lp_sub_size_centre,
            centre_radius=settings.lp_centre_radius,
            analytic_sigma=smallest_analytic_sigma(
                psf, imaging.pixel_scale, settings.lp_analytic_tolerance
            ),
        )
        x, y = pixel_centres(mask.shape, imaging.pixel_scale)
        source_grid = sub_grid(x[used], y[used], imaging.pixel_scale, settings.sub_size)
        border = border_sub_pixels(
            mask,
            source_grid.x,
            source_grid.y,
            settings.sub_size,
            mask_extent_centre(mask, imaging.pixel_scale),
        )
        return cls(imaging, mask, settings, light_grid, source_grid, border)

    def non_negative(self) -> "FitDataset":
        """This dataset with the non-negative solve of every linear unknown
        (``positive_only`` true): itself if it solves so already, else a copy sharing the
        grids (which the solve does not change) with empty caches (whose entries do
        depend on it)."""
        if self.settings.positive_only:
            return self
        return replace(
            self,
            settings=replace(self.settings, positive_only=True),
            _columns_cache={},
            _source_cache={},
            _held_cache={},
        )

    @cached_property
    def data(self) -> np.ndarray:
        return self.imaging.data[~self.mask]

    @cached_property
    def pixel_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) arcsec of the unmasked pixel centres, slim order."""
        x, y = pixel_centres(self.mask.shape, self.imaging.pixel_scale)
        return x[~self.mask], y[~self.mask]

    @cached_property
    def noise_map(self) -> np.ndarray:
        return self.imaging.noise_map[~self.mask]

    @cached_property
    def inverse_variance(self) -> np.ndarray:
        return 1.0 / self.noise_map**2

    @cached_property
    def noise_normalization(self) -> float:
        return noise_normalization(self.noise_map)

    @cached_property
    def median_inverse_variance(self) -> float:
        """w̄, the median 1/σ² of the fitted pixels: the scale of the lens-light prior
        (:mod:`mgelens.light_prior`)."""
        return float(np.median(self.inverse_variance))

    @property
    def convolver(self):
        return self.light_grid.convolver

    @cached_property
    def source_psf_operator(self) -> sparse.csr_matrix:
        """Mask-to-mask PSF operator B (N_I × N_I) of pixelized-source columns (SPEC §1.4)."""
        return self.convolver.operator(include_blurring=False)

    @cached_property
    def blurred_weighted_data(self) -> np.ndarray:
        """Bᵀ W d (N_I,): the pixelized source's part of the data vector before the
        mapping matrix, the same for every fit without fixed light."""
        return self.source_psf_operator.T @ (self.inverse_variance * self.data)

    @cached_property
    def tile_plan(self) -> TilePlan:
        """Tiling of the masked pixels for the source curvature matrix."""
        return TilePlan.from_mask(self.mask, self.convolver.psf)

    def lens_light_columns(self, components: tuple) -> np.ndarray:
        """PSF-convolved unit columns of the linear lens light (MGE sets, Sérsics),
        (N_I, Σ n_columns), cached.

        Phases that keep the light geometry fixed and only re-solve intensities pay for the
        columns once.
        """
        return self._lens_light_entry(components)["columns"]

    def lens_light_dense_terms(self, components: tuple) -> DenseTerms:
        """Lᵀ W L and Bᵀ W L of the lens-light columns L (:class:`DenseTerms`), cached with
        the columns: phases that keep the light geometry fixed (SPix1, SPix2, MASS) then
        leave only F_SS to the curvature tiles."""
        entry = self._lens_light_entry(components)
        if "dense_terms" not in entry:
            entry["dense_terms"] = DenseTerms.build(
                entry["columns"], self.inverse_variance, self.convolver
            )
        return entry["dense_terms"]

    def _lens_light_entry(self, components: tuple) -> dict:
        key = tuple(c.cache_key for c in components)
        if key not in self._columns_cache:
            if len(self._columns_cache) >= 4:
                self._columns_cache.pop(next(iter(self._columns_cache)))
            columns = self.light_grid.blurred_columns(list(components))
            columns.flags.writeable = False  # shared by every fit of these components
            self._columns_cache[key] = {"columns": columns}
        return self._columns_cache[key]

    def held_support(self, source: "PixelizedSource") -> np.ndarray:
        """The support of a source whose ``support_mass`` holds it: the mesh points its
        arc pixels reach when traced through that mass, computed once per source object."""
        return self._held_operator(source, source.support_mass).support

    def held_signal_weights(self, source: "PixelizedSource") -> SourceWeights:
        """The interpolation weights of ``source``'s sub-pixels traced through its
        ``signals_mass``, from which an adaptive regularization reads its pixel signals,
        computed once per source object."""
        return self._held_operator(source, source.signals_mass).weights

    def _held_operator(self, source: "PixelizedSource", mass) -> "SourceOperator":
        """``source`` traced through ``mass`` with nothing held, kept for as long as the
        same source object asks (its support and its signals, both held at SPix2's mass,
        share one trace)."""
        cache = self._held_cache
        if cache.get("source") is not source:
            cache.clear()
            cache.update(source=source, operators={})
        operators = cache["operators"]
        if mass not in operators:
            traced = replace(source, support_mass=None, signals_mass=None)
            operators[mass] = pixelized_operator(self, mass, traced)
        return operators[mass]

    def repeated_source(self, mass, source: "PixelizedSource") -> "SourceSystem | None":
        """The source's fixed part of the linear system if the previous fit had the same
        mass model and the same source object, else ``None`` (then remembered as previous).

        Phases that keep mass and source fixed (LIGHT) then pay for tracing, mesh,
        interpolation, F_SS and ln det H once; other phases pay nothing extra. Where
        F_SS + H is too ill-conditioned to factorise whole (an extreme regularization
        coefficient: the fixed part needs its Cholesky factor), this stays ``None`` for
        that mass and source, and every fit takes the general route, which factorises only
        the NNLS's passive set, as the phase that chose the source did.
        """
        cache = self._source_cache
        if cache.get("source") is source and cache.get("mass") == mass:
            if "system" not in cache:
                try:
                    cache["system"] = SourceSystem.build(self, mass, source)
                except InversionError:
                    cache["system"] = None
            return cache["system"]
        cache.clear()
        cache.update(source=source, mass=mass)
        return None


@dataclass(frozen=True)
class MGESource:
    """Parametric source: MGE sets in the source plane (the SP phase's source)."""

    sets: tuple[MGESet, ...]


@dataclass(frozen=True, eq=False)
class PixelizedSource:
    """Voronoi source mesh with its regularization (SPEC §4–5).

    Attributes
    ----------
    image_plane_x, image_plane_y : ndarray
        Image-plane mesh centres (overlay or k-means, arcsec), traced every evaluation.
    regularization : object
        A scheme from :mod:`mgelens.source.regularization` (``Constant``,
        ``AdaptiveBrightness``, ``ConstantSplit``, ``AdaptiveBrightnessSplit``).
    interpolation : {"natural_neighbour", "nearest"}
        Sibson weights (paper) or nearest-cell mapping (older scheme).
    adapt_image : ndarray or None
        Slim adapt image Ξ (lensed source of an earlier fit), for adaptive schemes.
    arc_pixels : ndarray or None
        Slim bool image pixels that hold the lensed arcs
        (:func:`mgelens.source.support.arc_pixels`). When given, only the source pixels
        their traced sub-pixels reach are solved; the others are zero and leave the
        system (:mod:`mgelens.source.support`). ``None``: the whole traced mask (paper).
    support_mass : tuple or None
        Mass profiles through which the arc pixels are traced to find the support, held
        for every fit of this source (LIGHT and MASS hold SPix2's), so that the solved
        pixels do not change with the fitted mass and the evidence stays continuous in
        it. ``None``: the fitted mass's own trace.
    signals_mass : tuple or None
        Mass profiles through which the sub-pixels are traced to compute an adaptive
        regularization's pixel signals S_j (SPEC §5.2), held for every fit of this source
        (``slam.adaptive_signals_mass: spix2``: LIGHT and MASS hold SPix2's), so that the
        source's prior, and with it ln det H, does not change with the fitted mass.
        ``None`` (anchor): the fitted mass's own trace.
    """

    image_plane_x: np.ndarray
    image_plane_y: np.ndarray
    regularization: object
    interpolation: str = "natural_neighbour"
    adapt_image: np.ndarray | None = None
    arc_pixels: np.ndarray | None = None
    support_mass: tuple | None = None
    signals_mass: tuple | None = None

    def __post_init__(self):
        if self.interpolation not in INTERPOLATIONS:
            raise ValueError(
                f"unknown interpolation {self.interpolation!r}; use one of {INTERPOLATIONS}"
            )


@dataclass(frozen=True)
class LensModel:
    """Mass profiles, lens light and source of one lens.

    Attributes
    ----------
    mass : tuple
        Mass profiles (EPL, SIE, ExternalShear, ...), deflections summed.
    lens_light : tuple of MGESet or Sersic
        Linear lens light: every Gaussian's and every Sérsic's intensity is solved (the
        profiles' own ``intensity`` is ignored).
    fixed_light : tuple
        Light with fixed intensities (e.g. a Sérsic fixed by an earlier phase), subtracted
        from the data.
    source : MGESource, PixelizedSource or None
    lens_light_prior : MGESmoothnessPrior or None
        A smoothness prior on the lens light's MGE intensities, whose terms join the
        log evidence (:mod:`mgelens.light_prior`); None (paper): the intensities carry no
        prior.
    """

    mass: tuple = ()
    lens_light: tuple = ()
    fixed_light: tuple = ()
    source: MGESource | PixelizedSource | None = None
    lens_light_prior: MGESmoothnessPrior | None = None


@dataclass(frozen=True, eq=False)
class SourceReconstruction:
    """The pixelized source of a fit: its traced mesh, the flux of every mesh point, the
    regularization matrix H of the solved pixels and, for a source with a support
    (:mod:`mgelens.source.support`), which mesh points were solved (the others are zero)."""

    mesh: VoronoiMesh
    fluxes: np.ndarray
    regularization_matrix: sparse.csc_matrix
    weights: SourceWeights
    support: np.ndarray | None = None

    def image(
        self,
        shape: tuple[int, int] = (101, 101),
        half_width: float | None = None,
        centre: tuple[float, float] | None = None,
    ):
        """Source interpolated (natural neighbour) on a regular grid for plots.

        The grid is a square of half-width ``half_width`` about ``centre`` (arcsec; by
        default the mesh's bounding box, enlarged by 5 %, about its middle). Returns
        (image, extent) with extent = (x_min, x_max, y_min, y_max) in arcsec for
        ``imshow(..., origin="lower", extent=extent)``; zero outside the mesh hull.
        """
        points = self.mesh.points
        if centre is None:
            centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
        if half_width is None:
            half_width = 0.5 * float(np.ptp(points, axis=0).max()) * 1.05
        pixel = 2.0 * half_width / shape[1]
        x, y = pixel_centres(shape, pixel, origin=(centre[0], centre[1]))
        inside = self.mesh.delaunay.find_simplex(np.column_stack([x.ravel(), y.ravel()])) >= 0
        indptr, indices, values = natural_neighbour_weights(
            self.mesh, x.ravel()[inside], y.ravel()[inside]
        )
        rows = np.repeat(np.arange(inside.sum()), np.diff(indptr))
        flat = np.zeros(x.size)
        flat[inside] = np.bincount(rows, values * self.fluxes[indices], minlength=inside.sum())
        extent = (
            centre[0] - half_width,
            centre[0] + half_width,
            centre[1] - half_width,
            centre[1] + half_width,
        )
        return flat.reshape(shape), extent


@dataclass(frozen=True, eq=False)
class FitResult:
    """Everything a fit produces; slim vectors over the unmasked pixels.

    ``residuals`` are data − model; ``normalized_residuals`` are (data − model)/σ.
    ``log_evidence`` equals ``log_likelihood`` when there is no pixelized source and no
    lens-light prior; ``lens_light_prior`` holds that prior's evidence terms (None without
    one).
    """

    dataset: FitDataset
    model: LensModel
    solution: LinearSolution
    n_lens_light: int
    n_source_light: int
    model_image: np.ndarray
    lens_light_image: np.ndarray
    lensed_source_image: np.ndarray
    chi_squared: float
    log_likelihood: float
    log_evidence: float
    regularization_term: float = 0.0
    log_det_curvature_regularization: float = 0.0
    log_det_regularization: float = 0.0
    source: SourceReconstruction | None = None
    lens_light_prior: PriorTerms | None = None

    @property
    def lens_light_intensities(self) -> np.ndarray:
        return self.solution.x[: self.n_lens_light]

    @property
    def source_light_intensities(self) -> np.ndarray:
        return self.solution.x[self.n_lens_light : self.n_lens_light + self.n_source_light]

    @property
    def residuals(self) -> np.ndarray:
        return self.dataset.data - self.model_image

    @property
    def normalized_residuals(self) -> np.ndarray:
        return self.residuals / self.dataset.noise_map

    def native(self, slim: np.ndarray) -> np.ndarray:
        """A slim vector on the native grid (zero outside the mask)."""
        return to_native(slim, self.dataset.mask)

    @property
    def passive_set(self) -> np.ndarray:
        """Bool over [lens light | source light | every mesh point]: the unknowns the
        non-negative solve left free (not clamped at zero); a warm start for :func:`fit`
        of a similar model. Mesh points off a support are not passive."""
        passive = ~self.solution.active_zero
        if self.source is None or self.source.support is None:
            return passive
        n_dense = self.n_lens_light + self.n_source_light
        points = np.zeros(self.source.support.size, dtype=bool)
        points[self.source.support] = passive[n_dense:]
        return np.concatenate([passive[:n_dense], points])


def _traced_source_positions(dataset: FitDataset, mass, source: PixelizedSource):
    grid = dataset.source_grid
    bx, by = mass_module.ray_trace(mass, grid.x, grid.y)
    mx, my = mass_module.ray_trace(mass, source.image_plane_x, source.image_plane_y)
    if dataset.settings.use_border:
        border_x, border_y = bx[dataset.border], by[dataset.border]
        rule = BORDER_RULE_OF_EDGE_RULE[dataset.settings.edge_rule]
        bx, by = relocate_to_border(bx, by, border_x, border_y, rule)
        mx, my = relocate_to_border(mx, my, border_x, border_y, rule)
    return bx, by, mx, my


@dataclass(frozen=True, eq=False)
class SourceOperator:
    """The pixelized source's part of the linear system for one mass model.

    ``mapping`` is f (N_I × N_S, sparse); the blurred mapping matrix B f is formed only
    on request (:attr:`blurred_mapping`), the fit itself never needs it. With a
    ``support`` (bool over the mesh points, :mod:`mgelens.source.support`) ``mapping``
    and ``regularization_matrix`` hold the supported pixels' columns only, and the
    linear unknowns are those pixels' fluxes.
    """

    mesh: VoronoiMesh
    weights: SourceWeights
    mapping: sparse.csr_matrix
    regularization_matrix: sparse.csc_matrix
    psf_operator: sparse.csr_matrix
    support: np.ndarray | None = None

    @property
    def edge_pixels(self) -> np.ndarray:
        """Bool over the solved pixels: those on the mesh's convex hull (SPEC §6.3)."""
        edge = self.mesh.edge_pixels
        return edge if self.support is None else edge[self.support]

    def mesh_fluxes(self, fluxes: np.ndarray) -> np.ndarray:
        """Flux of every mesh point from the solved pixels' ``fluxes`` (zero off the support)."""
        if self.support is None:
            return fluxes
        full = np.zeros(self.support.size)
        full[self.support] = fluxes
        return full

    @cached_property
    def blurred_mapping(self) -> sparse.csr_matrix:
        """M^src = B f: every column PSF-convolved inside the mask (SPEC §4.5)."""
        return (self.psf_operator @ self.mapping).tocsr()

    def image(self, fluxes: np.ndarray) -> np.ndarray:
        """Lensed, PSF-convolved source image (N_I,) of the source-pixel ``fluxes``."""
        return self.psf_operator @ (self.mapping @ fluxes)


@dataclass(frozen=True, eq=False)
class SourceSystem:
    """The parts of the linear system that depend on mass and source only: the operator,
    F_SS + H (dense) and its upper Cholesky factor, ln det H and, where it is the cheaper
    route to F_LS, W B f."""

    operator: SourceOperator
    curvature_regularization: np.ndarray
    curvature_regularization_factor: np.ndarray
    log_det_regularization: float
    weighted_blurred: WeightedBlurredMapping | None

    @property
    def log_det_curvature_regularization(self) -> float:
        """ln det(F_SS + H), from its factor."""
        return factor_log_det(self.curvature_regularization_factor)

    @classmethod
    def build(cls, dataset: FitDataset, mass, source: "PixelizedSource") -> "SourceSystem":
        operator = pixelized_operator(dataset, mass, source)
        h = operator.regularization_matrix
        none = np.zeros((dataset.data.size, 0))
        f_ss = curvature_matrix(none, operator.mapping, dataset.tile_plan, dataset.inverse_variance)
        f_ss += h.toarray()
        blurred = operator.blurred_mapping
        weighted_blurred = (
            WeightedBlurredMapping.build(blurred, dataset.inverse_variance)
            if WeightedBlurredMapping.cheaper(blurred, operator.mapping, dataset.convolver)
            else None
        )
        factor = upper_cholesky(f_ss.copy())
        return cls(operator, f_ss, factor, log_det_regularization(h), weighted_blurred)

    def curvature(self, dense: np.ndarray, dataset: FitDataset) -> np.ndarray:
        """The full [dense | source] matrix F + H for new ``dense`` columns L of
        ``dataset``. F_LS = Lᵀ (W B f) in one sparse pass where that is cheaper (large
        full-rank PSFs), else (fᵀ Bᵀ W L)ᵀ: a transposed blur, then a sparse product."""
        n_dense = dense.shape[1]
        q = np.empty((n_dense + self.curvature_regularization.shape[0],) * 2)
        if self.weighted_blurred is None:
            terms = DenseTerms.build(dense, dataset.inverse_variance, dataset.convolver)
            q[:n_dense, :n_dense] = terms.gram
            f_ls = terms.lens_source(self.operator.mapping)
        else:
            q[:n_dense, :n_dense] = weighted_gram(dense, dataset.inverse_variance)
            f_ls = self.weighted_blurred.lens_source(dense)
        q[:n_dense, n_dense:] = f_ls
        q[n_dense:, :n_dense] = f_ls.T
        q[n_dense:, n_dense:] = self.curvature_regularization
        return q


def pixelized_operator(dataset: FitDataset, mass, source: PixelizedSource) -> SourceOperator:
    """Trace, mesh, interpolate, blur and regularize a pixelized source (SPEC §4–5)."""
    bx, by, mx, my = _traced_source_positions(dataset, mass, source)
    mesh = VoronoiMesh.from_points(mx, my, dataset.settings.edge_rule)
    interpolate = (
        natural_neighbour_weights
        if source.interpolation == "natural_neighbour"
        else nearest_cell_weights
    )
    indptr, indices, values = interpolate(mesh, bx, by)
    weights = SourceWeights(indptr, indices, values, dataset.settings.sub_size, mesh.n_points)
    signal_weights = weights if source.signals_mass is None else dataset.held_signal_weights(source)
    h = source.regularization.matrix(mesh, signal_weights, source.adapt_image)
    mapping = mapping_matrix(weights)
    if source.arc_pixels is None:
        return SourceOperator(mesh, weights, mapping, h, dataset.source_psf_operator)
    support = (
        reached_source_pixels(mapping, source.arc_pixels)
        if source.support_mass is None
        else dataset.held_support(source)
    )
    if not support.any():
        raise MeshError("no source pixel is reached by the arc pixels")
    kept = np.flatnonzero(support)
    return SourceOperator(
        mesh,
        weights,
        mapping[:, kept].tocsr(),
        sparse.csc_matrix(h[kept][:, kept]),
        dataset.source_psf_operator,
        support,
    )


def source_light_columns(dataset: FitDataset, mass, sets: tuple[MGESet, ...]) -> np.ndarray:
    """PSF-convolved unit columns (N_I, Σ N_g) of source-plane MGE sets seen through ``mass``."""
    grid = dataset.light_grid.grid
    bx, by = mass_module.ray_trace(mass, grid.x, grid.y)
    traced = replace(grid, x=bx, y=by)
    columns = np.concatenate([s.columns(traced) for s in sets], axis=1)
    return dataset.convolver.blur_columns(columns, include_blurring=True)


def fit(
    dataset: FitDataset, model: LensModel, passive_start: np.ndarray | None = None
) -> FitResult:
    """Solve all linear light and source unknowns of ``model`` and score it (SPEC §6–7).

    ``passive_start`` optionally warm-starts the non-negative solve: a bool mask over
    lens light, source light and every source mesh point, e.g. the
    :attr:`FitResult.passive_set` of a similar model with the same unknowns (a source
    with a support solves its supported points only, and takes their part). The
    solution is the same (to rounding); only the NNLS's iterations change
    (:func:`~mgelens.inversion.solve.solve_linear_system`).

    Raises one of :data:`FitError` when the sample cannot be fitted (degenerate mesh,
    non-positive-definite system, NNLS iteration cap).
    """
    fixed, lens_columns, source_columns = _dense_light(dataset, model)
    if source_columns.shape[1] == 0:  # no copy of the (cached, read-only) lens columns
        dense = lens_columns
    else:
        dense = np.hstack([lens_columns, source_columns])
    operator = system = None
    if isinstance(model.source, PixelizedSource):
        system = dataset.repeated_source(model.mass, model.source)
        operator = (
            pixelized_operator(dataset, model.mass, model.source)
            if system is None
            else system.operator
        )
    if dense.shape[1] == 0 and operator is None:
        raise ValueError("the model has no linear light: give it lens light or a source")
    q, d = _normal_equations(dataset, model, dense, fixed, operator, system)
    prior = None
    if model.lens_light_prior is not None:
        prior = model.lens_light_prior.system(model.lens_light, dataset.median_inverse_variance)
        log_det_prior_block = prior.add_to(q)
    if passive_start is not None and operator is not None and operator.support is not None:
        n_dense = dense.shape[1]
        passive_start = np.concatenate(
            [passive_start[:n_dense], passive_start[n_dense:][operator.support]]
        )
    settings = dataset.settings
    fixed_zero = None
    constrained_source = settings.positive_only and not settings.free_source
    if operator is not None and constrained_source and settings.force_edge_pixels_to_zero:
        fixed_zero = np.concatenate([np.zeros(dense.shape[1], dtype=bool), operator.edge_pixels])
    solution = solve_linear_system(
        q,
        d,
        positive_only=settings.positive_only,
        fixed_zero=fixed_zero,
        source_block=slice(dense.shape[1], None) if operator is not None else None,
        passive_start=passive_start,
        unconstrained=slice(lens_columns.shape[1], None) if settings.free_source else None,
        source_log_det=None if system is None else system.log_det_curvature_regularization,
        source_factor=None if system is None else system.curvature_regularization_factor,
    )
    result = _scored(
        dataset, model, solution, fixed, lens_columns, source_columns, operator, system
    )
    if prior is None:
        return result
    terms = prior.terms(solution.x, log_det_prior_block)
    return replace(
        result,
        log_evidence=result.log_evidence + terms.log_evidence_change,
        lens_light_prior=terms,
    )


def _dense_light(dataset: FitDataset, model: LensModel) -> tuple[np.ndarray, ...]:
    """The fixed light's blurred image, and the blurred columns of the lens-light
    Gaussians and of the source Gaussians (empty when the model has none)."""
    fixed = (
        dataset.light_grid.blurred_image(list(model.fixed_light))
        if model.fixed_light
        else np.zeros(dataset.data.size)
    )
    lens_columns = (
        dataset.lens_light_columns(tuple(model.lens_light))
        if model.lens_light
        else np.zeros((dataset.data.size, 0))
    )
    source_columns = (
        source_light_columns(dataset, model.mass, model.source.sets)
        if isinstance(model.source, MGESource)
        else np.zeros((dataset.data.size, 0))
    )
    return fixed, lens_columns, source_columns


def _normal_equations(dataset, model, dense, fixed, operator, system):
    """Curvature matrix Q (with the regularization and, on the Gaussian columns, the
    ``mge_diagonal``) and data vector D of the linear unknowns [dense columns | source
    pixels] (SPEC §6.1–6.2)."""
    n_dense = dense.shape[1]
    mapping = None if operator is None else operator.mapping
    d = data_vector(
        dense,
        mapping,
        dataset.source_psf_operator,
        dataset.inverse_variance,
        dataset.data - fixed,
        None if model.fixed_light or mapping is None else dataset.blurred_weighted_data,
    )
    if system is None:
        terms = (
            dataset.lens_light_dense_terms(tuple(model.lens_light))
            if operator is not None and model.lens_light
            else None
        )
        q = curvature_matrix(
            dense, mapping, dataset.tile_plan, dataset.inverse_variance, dense_terms=terms
        )
        if operator is not None:
            q[n_dense:, n_dense:] += operator.regularization_matrix.toarray()
    else:
        q = system.curvature(dense, dataset)
    q[np.arange(n_dense), np.arange(n_dense)] += dataset.settings.mge_diagonal
    return q, d


def _scored(dataset, model, solution, fixed, lens_columns, source_columns, operator, system):
    """The :class:`FitResult` of a solution: images, χ², ln L and, for a pixelized
    source, the log evidence and its terms (SPEC §7)."""
    x = solution.x
    n_lens = lens_columns.shape[1]
    n_dense = n_lens + source_columns.shape[1]
    lens_light_image = lens_columns @ x[:n_lens] + fixed
    lensed_source_image = source_columns @ x[n_lens:n_dense]
    if operator is not None:
        lensed_source_image = lensed_source_image + operator.image(x[n_dense:])
    model_image = lens_light_image + lensed_source_image
    chi_squared = float(np.sum((dataset.data - model_image) ** 2 * dataset.inverse_variance))
    log_like = log_likelihood(chi_squared, dataset.noise_normalization)
    common = dict(
        dataset=dataset,
        model=model,
        solution=solution,
        n_lens_light=n_lens,
        n_source_light=n_dense - n_lens,
        model_image=model_image,
        lens_light_image=lens_light_image,
        lensed_source_image=lensed_source_image,
        chi_squared=chi_squared,
        log_likelihood=log_like,
    )
    if operator is None:
        return FitResult(**common, log_evidence=log_like)

    h = operator.regularization_matrix
    fluxes = x[n_dense:]
    regularization_term = float(fluxes @ (h @ fluxes))
    log_det_fh = solution.log_det_source
    log_det_h = log_det_regularization(h) if system is None else system.log_det_regularization
    return FitResult(
        **common,
        log_evidence=log_evidence(
            chi_squared, regularization_term, log_det_fh, log_det_h, dataset.noise_normalization
        ),
        regularization_term=regularization_term,
        log_det_curvature_regularization=log_det_fh,
        log_det_regularization=log_det_h,
        source=SourceReconstruction(
            operator.mesh, operator.mesh_fluxes(fluxes), h, operator.weights, operator.support
        ),
    )


def figure_of_merit(
    dataset: FitDataset, model: LensModel, passive_start: np.ndarray | None = None
) -> tuple[float, str]:
    """Log evidence of ``model``, or (−1e99, reason) if the sample must be rejected: the
    fit raised one of :data:`FitError`, or a numerical failure that raised nothing left
    the log evidence NaN or infinite (SPEC §8.4). ``passive_start``: as in :func:`fit`."""
    try:
        value = fit(dataset, model, passive_start).log_evidence
    except FitError as error:
        return REJECTED_LOG_LIKELIHOOD, f"{type(error).__name__}: {error}"
    if not np.isfinite(value):
        return REJECTED_LOG_LIKELIHOOD, f"log evidence is {value}"
    return value, ""

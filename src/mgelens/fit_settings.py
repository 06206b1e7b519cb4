"""Numerical choices of a fit (SPEC §1.3, §4.2, §6): one frozen, validated record.

It carries no numerics, so configuration (:mod:`mgelens.pipeline.settings`) reads and
checks it without loading the fitting code; :class:`mgelens.fit.FitDataset` applies it.
"""

import dataclasses
from dataclasses import dataclass

from mgelens import values
from mgelens.source.schemes import EDGE_RULES


@dataclass(frozen=True)
class FitSettings:
    """Numerical choices of a fit (SPEC §1.3, §4.2, §6).

    Attributes
    ----------
    positive_only : bool
        Non-negative solve of all linear unknowns ("nn-MGE", default) or unconstrained ("pn").
    free_source : bool
        With ``positive_only``: keep only the lens light's intensities ≥ 0 and leave the
        source's (source Gaussians, source pixels) free, as the paper's 3×Sérsic runs
        (SPEC §8.1: source fluxes not constrained positive). Refused with
        ``positive_only`` false, which frees every unknown already.
        ``force_edge_pixels_to_zero`` does not apply to a free source.
    sub_size : int
        s of the s×s sub-grid that maps image pixels onto the source mesh (4).
    lp_sub_size, lp_sub_size_centre, lp_centre_radius : int, int, float
        Light-profile over-sampling: ``lp_sub_size`` everywhere, ``lp_sub_size_centre``
        within ``lp_centre_radius`` arcsec of the lens-light centre (4, 16, 0.3″).
    use_border : bool
        Relocate traced positions beyond the mask border onto it (SPEC §4.2).
    mge_diagonal : float
        μ added to the curvature diagonal of unregularized linear columns (1e−3).
    force_edge_pixels_to_zero : bool
        Fix convex-hull source pixels to zero in the non-negative solve (SPEC §6.3).
    edge_rule : {"anchor", "continuous"}
        How the source mesh treats its edges. ``"anchor"`` (SPEC §4.2–4.4): border radius
        of the nearest border point, queries outside the hull take their nearest mesh
        point, unbounded cells count as −1 in the area percentile; each makes the log
        evidence jump as the mass model moves a point across a hull, border or
        nearest-point boundary. ``"continuous"``: the border polygon's radius
        (:func:`~mgelens.source.border.relocate_to_border`), and Sibson weights and cell
        areas of the mesh embedded in a distant ring of auxiliary points
        (:attr:`~mgelens.source.mesh.VoronoiMesh.ringed`): the evidence is then continuous
        in the mass parameters, provided ``force_edge_pixels_to_zero`` is off (hull
        membership is discrete) and adaptive regularization uses ``signals="weighted"``.
    psf_trim : float
        The PSF is cut to the smallest centred kernel holding every entry ≥ this fraction
        of its peak (:func:`mgelens.convolve.trimmed_psf`; 0 keeps it whole). The default
        1e−10 only removes wings that cannot change a model image.
    lp_analytic_tolerance : float
        Lens-light Gaussians whose minor-axis σ is wide enough that the closed-form
        pixel-integrated, PSF-blurred column (:mod:`mgelens.analytic_blur`) is within this
        fraction of the column's peak of the exact convolution, for this PSF, take that
        route instead of the sub-grid and the convolution. 0 (default) keeps every column
        on the sub-grid.
    """

    positive_only: bool = True
    free_source: bool = False
    sub_size: int = 4
    lp_sub_size: int = 4
    lp_sub_size_centre: int = 16
    lp_centre_radius: float = 0.3
    use_border: bool = True
    mge_diagonal: float = 1e-3
    force_edge_pixels_to_zero: bool = True
    edge_rule: str = "anchor"
    psf_trim: float = 1e-10
    lp_analytic_tolerance: float = 0.0

    def __post_init__(self):
        """Check every field's type and range and store it in its canonical type; a
        ValueError starts with the field's name."""
        checked = {
            "positive_only": values.boolean("positive_only", self.positive_only),
            "free_source": values.boolean("free_source", self.free_source),
            "use_border": values.boolean("use_border", self.use_border),
            "force_edge_pixels_to_zero": values.boolean(
                "force_edge_pixels_to_zero", self.force_edge_pixels_to_zero
            ),
            "edge_rule": values.choice("edge_rule", self.edge_rule, EDGE_RULES),
            "lp_centre_radius": values.number("lp_centre_radius", self.lp_centre_radius, 0.0),
            "mge_diagonal": values.number("mge_diagonal", self.mge_diagonal, 0.0),
            "psf_trim": values.number(
                "psf_trim", self.psf_trim, 0.0, maximum=1.0, open_maximum=True
            ),
            "lp_analytic_tolerance": values.number(
                "lp_analytic_tolerance",
                self.lp_analytic_tolerance,
                0.0,
                maximum=1.0,
                open_maximum=True,
            ),
        }
        for name in ("sub_size", "lp_sub_size", "lp_sub_size_centre"):
            checked[name] = values.integer(name, getattr(self, name), 1)
        if checked["free_source"] and not checked["positive_only"]:
            raise ValueError(
                "free_source applies to the non-negative solve (positive_only true); with "
                "positive_only false every unknown is free already"
            )
        for name, value in checked.items():
            object.__setattr__(self, name, value)

    def to_dict(self) -> dict:
        """JSON-ready form."""
        return dataclasses.asdict(self)

"""Settings of the SLaM chain: speed profiles and the ``slam:`` section of a YAML file.

Two profiles give the defaults (:data:`PROFILES`):

* ``paper``: the paper's settings (SPEC §8.1, §8.3): live points 200 / 150 / 100 / 150 /
  150, nautilus where the paper used it, 1500 k-means source pixels, a 34×34 overlay.
* ``quick`` (default): nautilus with one network and 3 live points per parameter in SP,
  dynesty random walks with few live points and a looser stopping criterion from SPix1
  to LIGHT, nautilus with 30 live points in MASS (whose posterior is the result) on each
  of two source meshes, pooled, 500 k-means source pixels, a 24×24
  overlay, a 2×2 source sub-grid (paper 4×4), light profiles over-sampled 2×2 (8×8
  within 0.3″ of the centre) and the PSF cut at 1e−4 of its peak, for the embedded
  default sample (M1–M3) on two cores. Its source mesh follows the continuous edge rule
  (``edge_rule: continuous``, hull pixels solved, weighted adaptive signals), under
  which the log evidence is a continuous function of the mass: with the anchor's rules
  M2's MASS maximum sat on a spike 36 above the smooth trend of ln ε around it. MASS
  holds the adaptive signals at SPix2's mass (``adaptive_signals_mass: spix2``), so that
  the source's prior does not act as a prior on the mass. The MGE
  itself is not simplified (30 Gaussians per set, SPEC §2.4).

A YAML file may override any field under a top-level ``slam:`` key; other top-level keys
(the workflow's own configuration) are ignored. The fit's numerical settings go under
``slam: fit:`` and per-phase sampler settings under ``slam: samplers: <phase>:``; both are
merged into the profile's. Unknown keys and values of the wrong type or range raise
:class:`SettingsError` naming the key by its dotted path (``slam.fit.sub_size``,
``slam.samplers.mass.n_live``; :mod:`mgelens.values`). Example::

    slam:
      lens_light_model: sersic    # the 3×Sérsic comparison, its light non-negative
      fit: {positive_only: true, free_source: true}   # and its source free
      samplers:
        mass: {n_live: 80}

What differs from lens to lens is a :class:`LensSpec` (mask radius and centre, pixel
scale, the LIGHT phase's MGE sets and point set), which the workflow builds from the
sample sheet and passes as ``mgelens phase`` options; a ``slam:`` section naming one of
these is refused.
"""

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import yaml

from mgelens import values
from mgelens.fit_settings import FitSettings
from mgelens.search.sampler_settings import SamplerSettings
from mgelens.source.schemes import (
    INTERPOLATIONS,
    KMEANS_SEEDINGS,
    SIGNAL_AVERAGES,
    SIGNAL_MASSES,
)

PHASES = ("sp", "spix1", "spix2", "light", "mass")
"""Phase names in chain order; each is also the name of the phase's result folder."""

N_GAUSSIANS = 30
"""Gaussians per extended MGE set (paper; not a setting)."""

LENS_LIGHT_MODELS = ("mge", "sersic")
MGE_SET_CHOICES = (2, 4, 6)
SPIX1_REGULARIZATIONS = ("constant", "constant_split")
KMEANS_SCHEMES = ("2023", "2024")
CROSS_OFFSETS = ("anchor", "paper")
SOURCE_SUPPORTS = ("mask", "arcs")
PRIOR_PASSING_RULES = ("paper", "2024")
SP_STARTS = ("prior", "search")
SP_MASS_CENTRES = ("free", "light")
LENS_LIGHT_PRIORS = ("none", "smoothness")


FIT_KEYS = frozenset(f.name for f in dataclasses.fields(FitSettings))
"""The keys of a ``slam: fit:`` mapping (:class:`~mgelens.fit_settings.FitSettings`)."""


class SettingsError(ValueError):
    """Invalid settings: the message names the file, the key and the accepted values."""


@dataclass(frozen=True)
class SlamSettings:
    """Every choice of the SLaM chain (SPEC §1.3, §4–8).

    Attributes
    ----------
    profile : {"quick", "paper"}
        Speed profile the defaults came from (recorded in results).
    lens_light_model : {"mge", "sersic"}
        The lens light: the MGE (paper's method) or the paper's 3×Sérsic comparison
        (SPEC §8.1): 2 Sérsics with a shared centre in SP, fixed entirely (intensities
        too) in SPix1 and SPix2, 3 Sérsics in LIGHT, fitted together with the EPL in MASS.
        All Sérsic intensities are solved linearly. The paper's Sérsic runs did not
        constrain the source positive, unlike its MGE runs (``fit: {positive_only: true,
        free_source: true}``: Sérsic intensities ≥ 0, source free), so a settings mapping
        (YAML ``slam:`` section or ``--slam``) that sets ``lens_light_model: sersic`` must
        set ``fit.positive_only`` too (:func:`settings_from_mapping` refuses it otherwise).
    lens_light_prior : {"none", "smoothness"}
        The MGE lens light's intensities: free (``none``, the paper's, SPEC §7), or under
        the smoothness prior of :mod:`mgelens.light_prior` (``smoothness``), whose
        coefficient ``lens_light.smoothness`` LIGHT samples (LogUniform(1e−3, 1e7)) and
        MASS keeps at LIGHT's maximum-likelihood value; the prior's terms join the log
        evidence. The workflow passes it to LIGHT and MASS only. Not with
        ``lens_light_model: sersic``.
    source_pixels : int or tuple of int
        k-means source pixels of SPix2, LIGHT and MASS (paper 1500), or two or more
        candidate counts (a YAML list, kept in increasing order), of which SPix2's
        Bayesian evidence chooses one (:mod:`mgelens.pipeline.pixel_choice`): the
        workflow fits SPix2 once per count and LIGHT and MASS keep the chosen SPix2's
        count (:meth:`source_pixel_candidates`). SPix2 itself fits one count.
    mass_source_pixels : int or None
        k-means source pixels of MASS's meshes alone, with SPix2's hyper-parameters (with
        ``mass_mesh_tuning``, their own); None (both profiles): SPix2's count. The
        workflow passes it to MASS only, so setting it reruns MASS and what follows. At
        500 pixels the mesh SPix2 tuned its hyper-parameters on stands far above other
        k-means seeds and the meshes' slopes differ (docs/coverage.md, "The source mesh").
    source_support : {"mask", "arcs"}
        Where SPix2's, LIGHT's and MASS's pixelized source may hold light: wherever the
        traced mask lands (``mask``, the paper's model), or only in the source pixels that
        the lensed arcs reach, the image pixels where SPix1's adapt image exceeds
        ``mesh.arc_threshold`` of its peak, a hyper-parameter SPix2 samples with the
        regularization and passes on (``arcs``, :mod:`mgelens.source.support`). Outside the
        ring the image plane is singly imaged, and there the paper's source copies the
        lens light's outer wings (docs/recovery.md, "The source's support"). The quick
        profile's default is ``arcs``, the paper profile's ``mask``.
    arc_noise_floor : float
        With the arcs' support, an arc pixel's adapt image must also exceed this many
        times the pixel's noise (arcs detected at k σ); 0 (both profiles): no floor, the
        threshold alone. A relative threshold low enough to reach an earlier source's
        faint smooth light lets the support cover the whole mask (docs/recovery.md,
        "A noise floor for the arcs"). Only with ``source_support: arcs``.
    overlay_shape : (int, int)
        (n_y, n_x) of the SPix1 overlay grid (paper 34×34).
    spix1_regularization : {"constant", "constant_split"}
        SPix1 regularization: neighbour gradient (paper) or cross ("split") constant.
    kmeans_scheme : {"2023", "2024"}
        k-means weight formula (SPEC §4.1; 2023 = paper era).
    kmeans_seed : int
        Fixed seed of the k-means mesh (SPEC §4.1).
    kmeans_seeding : {"kmeans++", "systematic"}
        Initial centres of the k-means mesh (:func:`mgelens.source.image_mesh.kmeans_centres`):
        the anchor's k-means++ (paper), or a systematic draw along a Hilbert curve, whose
        mesh, and with it SPix2's ln ε, changes smoothly with the k-means weights instead
        of jumping by tens in ln ε when they change by a part in 10⁴.
    mass_meshes : int
        Source-mesh realisations of the MASS phase (k-means seeds ``kmeans_seed`` onwards,
        SPix2's hyper-parameters in each, or with ``mass_mesh_tuning`` each its own): one
        nested-sampling run per mesh, the posteriors pooled with equal weights
        (:func:`mgelens.pipeline.run.chain_settings`). 1 (paper) samples SPix2's own mesh
        only, and the posterior is then conditional on where k-means put its centres. With
        ``samplers: mass: n_processes`` ≥ 2 the runs go side by side, one process each,
        with the one-process samples
        (:func:`mgelens.pipeline.run._sample_runs`).
    mass_mesh_tuning : bool
        Give each MASS mesh whose k-means seed is not SPix2's its own hyper-parameters: a
        local search of SPix2's ln ε on that mesh from SPix2's values
        (:mod:`mgelens.pipeline.mesh_tuning`; on in the quick profile). Off (paper), every
        mesh carries SPix2's values, which were chosen on SPix2's own mesh, and another
        mesh is then an ordinary draw, tens to hundreds lower in ln ε, whose mass
        posterior can lie in another basin (docs/coverage.md, "Each mesh its own
        hyper-parameters").
    interpolation : {"natural_neighbour", "nearest"}
        Source-plane interpolation.
    cross_offset : {"anchor", "paper"}
        Cross-point offset of the split regularization (½√A or √(A/2), SPEC §5.3).
    adaptive_signals : {"anchor", "weighted"}
        How the adaptive regularization's pixel signals average the adapt image: per
        sub-pixel count (SPEC §5.2, anchor) or weighted by the interpolation weights, which
        is continuous as the mesh moves
        (:func:`mgelens.source.regularization.adaptive_pixel_signals`).
    adaptive_signals_mass : {"fitted", "spix2"}
        The mass through which LIGHT's and MASS's fixed source (SPix2's mesh and
        hyper-parameters) traces the adapt image into its pixel signals S_j: every fitted
        mass's own (``fitted``, the anchor's and the paper profile's), or SPix2's, held
        for the whole phase (``spix2``, the quick profile's). With ``fitted`` the
        source's prior changes with the mass MASS samples, and its ln det H term then
        acts as a prior on the mass: one source pixel's signal sets the normalisation
        max_j S_j, and a shift of a few per cent in it moves ln det H by hundreds
        (docs/coverage.md, "The adaptive signals as a mass prior"). LIGHT's mass is
        SPix2's, so only MASS differs.
    prior_passing : {"paper", "2024"}
        Prior-passing rule (SPEC §8.2).
    sp_start : {"prior", "search"}
        SP's priors: the anchor's (``prior``, SPEC §3, §8.1; the paper profile), or SLaM's
        passed priors around a maximum-a-posteriori point found from the lensed arcs
        before sampling (``search``, :mod:`mgelens.pipeline.sp_start`; the quick profile,
        and set by the real samples' configs ``config/slacs.yaml`` and
        ``config/paper.yaml`` for either profile). Without it SP settled in a degenerate
        mass on real imaging (docs/slacs.md), and on M1–M3 it needs fewer calls
        (docs/slam.md, "SP's start in the quick profile").
    spix1_rescan : bool
        Before SPix1 samples, scan θ_E with its pixelized source around SP's mass and, if a
        basin beyond SP's is better by far, re-centre SPix1's passed mass and shear priors
        on it (:mod:`mgelens.pipeline.mass_rescan`; on in the quick profile, off in the
        paper's): SP's parametric source can prefer a wrong mass that no later phase
        leaves (docs/coverage.md, "P05").
    sp_mass_centre : {"free", "light"}
        SP's SIE centre: free with the anchor's prior N(c, 0.1″) (``free``, SPEC §3.1), or
        tied to the lens light's shared centre (``light``: 15 free parameters instead of
        17). SPix1 frees it either way, with the passed prior N(SP's centre, 0.05″) of a
        centre that was tied (SPEC §8.2), so the mass can leave the light from SPix1 on.
    positions_penalty : bool
        Require the multiple images of SP's source centre to re-converge in the source
        plane in SPix1 and MASS (SPEC §12.21; off in the paper profile, on in quick, where
        the few live points otherwise lose the physical mode to demagnified solutions).
    positions_factor, positions_minimum : float
        Threshold = max(factor × SP's own source-plane scatter, minimum arcsec) (3, 0.2″).
    allow_unconverged : bool
        Let a phase build on an earlier phase whose sampler did not converge (its
        ``result.json`` says ``converged: false``, e.g. capped by ``max_calls``). Off, such a
        phase stops with a message naming the file (:func:`mgelens.pipeline.problem.read_phase`);
        on, for smoke tests of the plumbing.
    fit : FitSettings
        The fit's numerical choices (:class:`mgelens.fit_settings.FitSettings`), YAML
        ``slam: fit:``: ``positive_only`` (non-negative solve of all linear unknowns,
        "nn-MGE", or unconstrained, "pn-MGE", in every phase), the sub-grids, border,
        ``force_edge_pixels_to_zero`` and ``edge_rule`` (the anchor's rules, SPEC §4.2–4.4,
        or continuous ones under which the evidence is a continuous function of the mass
        parameters, with ``force_edge_pixels_to_zero`` off and ``adaptive_signals:
        weighted``), ``psf_trim`` and ``lp_analytic_tolerance``. Quick's ``psf_trim`` 1e−4
        cuts the mock's 21×21 Gaussian PSF (σ = 1 pixel) to 9×9, losing 6e−6 of its flux,
        and leaves the SLACS 15×15 PSFs whole; its 2×2 source sub-grid (paper 4×4) makes a
        pixelized evaluation about 20 % faster and leaves the MASS posterior as it was
        (docs/design_notes.md, "Source sub-grid"); its ``lp_analytic_tolerance`` 1e−4 gives
        the lens-light Gaussians wider than ≈0.4″ (HST PSFs) their closed-form blurred
        columns, closer to the exact pixel integral than the 2×2 sub-grid they replace
        (docs/benchmarks.md, "Wide Gaussians in closed form").
    samplers : mapping of phase name to SamplerSettings
        The non-linear search of each phase.

    What differs from lens to lens (mask, pixel scale, MGE sets) is not here but in
    :class:`LensSpec`.
    """

    profile: str = "quick"
    lens_light_model: str = "mge"
    lens_light_prior: str = "none"
    source_pixels: int | tuple[int, ...] = 1500
    mass_source_pixels: int | None = None
    source_support: str = "mask"
    arc_noise_floor: float = 0.0
    overlay_shape: tuple[int, int] = (34, 34)
    spix1_regularization: str = "constant"
    kmeans_scheme: str = "2023"
    kmeans_seed: int = 0
    kmeans_seeding: str = "kmeans++"
    mass_meshes: int = 1
    mass_mesh_tuning: bool = False
    interpolation: str = "natural_neighbour"
    cross_offset: str = "anchor"
    adaptive_signals: str = "anchor"
    adaptive_signals_mass: str = "fitted"
    prior_passing: str = "paper"
    sp_start: str = "prior"
    spix1_rescan: bool = False
    sp_mass_centre: str = "free"
    positions_penalty: bool = False
    positions_factor: float = 3.0
    positions_minimum: float = 0.2
    allow_unconverged: bool = False
    fit: FitSettings = field(default_factory=FitSettings)
    samplers: Mapping[str, SamplerSettings] = field(default_factory=dict)

    def __post_init__(self):
        try:
            checked = _checked_fields(self)
        except ValueError as error:
            raise SettingsError(str(error)) from None
        missing = [p for p in PHASES if p not in self.samplers]
        if missing:
            raise SettingsError(f"sampler settings missing for phases {missing}")
        if not isinstance(self.fit, FitSettings):
            raise SettingsError(f"slam.fit must be FitSettings, got {self.fit!r}")
        for name, value in checked.items():
            object.__setattr__(self, name, value)
        if self.arc_noise_floor > 0.0 and self.source_support != "arcs":
            raise SettingsError(
                f"slam.arc_noise_floor: {self.arc_noise_floor} applies to the arcs' support "
                f"only, not to source_support: {self.source_support}; set "
                "source_support: arcs or arc_noise_floor: 0"
            )
        if self.lens_light_prior != "none" and self.lens_light_model != "mge":
            raise SettingsError(
                f"slam.lens_light_prior: {self.lens_light_prior} applies to the MGE lens "
                f"light only, not to lens_light_model: {self.lens_light_model}; set "
                "lens_light_prior: none"
            )
        object.__setattr__(self, "samplers", MappingProxyType(dict(self.samplers)))

    @property
    def source_pixel_candidates(self) -> tuple[int, ...]:
        """The k-means pixel counts SPix2 may fit: ``source_pixels`` as a tuple (one count
        where it is a single one), increasing."""
        if isinstance(self.source_pixels, tuple):
            return self.source_pixels
        return (self.source_pixels,)

    def mass_pixels(self, spix2_pixels: int) -> int:
        """k-means source pixels of MASS's meshes: ``mass_source_pixels``, or
        ``spix2_pixels`` (the count of the SPix2 result MASS reads) where it is None."""
        return spix2_pixels if self.mass_source_pixels is None else self.mass_source_pixels

    def to_dict(self) -> dict:
        """JSON-ready form (recorded in every result file)."""
        content = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        content["overlay_shape"] = list(self.overlay_shape)
        content["fit"] = self.fit.to_dict()
        content["samplers"] = {name: s.to_dict() for name, s in self.samplers.items()}
        return content


def _checked_fields(settings: SlamSettings) -> dict:
    """Every field of ``settings`` but ``samplers`` checked (type, range or choice) and in
    its canonical type; a ValueError names the field as ``slam.<field>``."""
    checked = {}
    for f in dataclasses.fields(settings):
        name, value = f.name, getattr(settings, f.name)
        key = f"slam.{name}"
        if name in _CHOICES:
            checked[name] = values.choice(key, value, _CHOICES[name])
        elif name in _INTEGERS:
            checked[name] = values.integer(key, value, _INTEGERS[name])
        elif name in _NUMBERS:
            checked[name] = values.number(key, value, **_NUMBERS[name])
        elif f.type is bool:
            checked[name] = values.boolean(key, value)
    checked["source_pixels"] = _pixel_counts(settings.source_pixels)
    if settings.mass_source_pixels is not None:
        checked["mass_source_pixels"] = values.integer(
            "slam.mass_source_pixels", settings.mass_source_pixels, 3
        )
    checked["overlay_shape"] = values.pair(
        "slam.overlay_shape",
        settings.overlay_shape,
        lambda name, n: values.integer(name, n, 2),
        "two integers >= 2 (n_y, n_x)",
    )
    kmeans_scheme = settings.kmeans_scheme
    if isinstance(kmeans_scheme, int) and not isinstance(kmeans_scheme, bool):
        kmeans_scheme = str(kmeans_scheme)  # YAML reads `kmeans_scheme: 2024` as a number
    checked["kmeans_scheme"] = values.choice("slam.kmeans_scheme", kmeans_scheme, KMEANS_SCHEMES)
    return checked


_CHOICES = {
    "profile": ("quick", "paper"),
    "lens_light_model": LENS_LIGHT_MODELS,
    "spix1_regularization": SPIX1_REGULARIZATIONS,
    "interpolation": INTERPOLATIONS,
    "cross_offset": CROSS_OFFSETS,
    "adaptive_signals": SIGNAL_AVERAGES,
    "adaptive_signals_mass": SIGNAL_MASSES,
    "prior_passing": PRIOR_PASSING_RULES,
    "sp_start": SP_STARTS,
    "sp_mass_centre": SP_MASS_CENTRES,
    "lens_light_prior": LENS_LIGHT_PRIORS,
    "source_support": SOURCE_SUPPORTS,
    "kmeans_seeding": KMEANS_SEEDINGS,
}
"""Fields taking one of a few strings."""


def _pixel_counts(value) -> int | tuple[int, ...]:
    """``slam.source_pixels`` as an int >= 3, or a list of two or more distinct ones as
    an increasing tuple."""
    if not isinstance(value, list | tuple):
        return values.integer("slam.source_pixels", value, 3)
    counts = sorted({values.integer("slam.source_pixels", n, 3) for n in value})
    if len(counts) < 2:
        raise ValueError(
            f"slam.source_pixels must be an integer >= 3 or a list of two or more distinct "
            f"ones (candidates chosen by SPix2's evidence), got {value!r}"
        )
    return tuple(counts)


_INTEGERS = {
    "kmeans_seed": 0,
    "mass_meshes": 1,
}
"""Integer fields and their minimum."""
_NUMBERS = {
    "positions_factor": {"minimum": 0.0, "open_minimum": True},
    "positions_minimum": {"minimum": 0.0},
    "arc_noise_floor": {"minimum": 0.0},
}
"""Real-valued fields and their range (:func:`mgelens.values.number`)."""


LENS_KEYS = {
    "mask_radius": "--mask-radius, or the sample sheet's mask_radius column",
    "mask_centre": "--mask-centre",
    "pixel_scale": "--pixel-scale, or the sample sheet's pixel_scale column",
    "mge_sets": "--mge-sets, or the sample sheet's mge_sets column",
    "point_set": "--point-set, or the sample sheet's point_set column",
    "contaminants": "--contaminants, or the sample sheet's contaminants column",
}
"""What a :class:`LensSpec` holds, and where each value is given."""


@dataclass(frozen=True)
class LensSpec:
    """What the chain fits differently from lens to lens (the sample sheet's columns).

    Attributes
    ----------
    mask_radius : float or None
        Radius of the circular fit mask in arcsec; ``None`` takes ``mask_radius`` from the
        lens folder's ``truth.json`` (mocks). The MGE σ grid runs from Δ/5 to this radius.
    mask_centre : (float, float)
        Mask centre (x, y) in arcsec; also the centre of the SP lens-light and mass priors.
    pixel_scale : float or None
        Arcsec per image pixel; ``None`` takes it from the imaging folder (``info.json``,
        else the data header's ``PIXSCALE`` or celestial WCS). A value here wins over both,
        with a warning if the header differs (:meth:`~mgelens.imaging.Imaging.from_folder`).
    mge_sets : {2, 4, 6}
        Extended 30-Gaussian sets of the LIGHT phase (SP always uses 2).
    point_set : bool
        Add the 10-Gaussian point set (own centre and ell_comps) in the LIGHT phase.
    contaminants : tuple of (x, y, radius)
        Circles (arcsec) of neighbours that the input's noise map does not mark; every phase
        treats their pixels as contaminant sentinels (:func:`mgelens.mask.contaminants`),
        and the quality check and figures read them from the phase's record.

    Only LIGHT reads ``mge_sets`` and ``point_set`` (MASS takes LIGHT's lens light from its
    record), so the workflow passes them to LIGHT alone and the other phases record the
    defaults.
    """

    mask_radius: float | None = None
    mask_centre: tuple[float, float] = (0.0, 0.0)
    pixel_scale: float | None = None
    mge_sets: int = 4
    point_set: bool = True
    contaminants: tuple[tuple[float, float, float], ...] = ()

    def __post_init__(self):
        """Check every field; a :class:`SettingsError` names the field and where it is set."""
        try:
            checked = {
                "mask_centre": values.pair(
                    "mask_centre", self.mask_centre, values.number, "two numbers (x, y) in arcsec"
                ),
                "mge_sets": values.choice(
                    "mge_sets", values.integer("mge_sets", self.mge_sets, 1), MGE_SET_CHOICES
                ),
                "point_set": values.boolean("point_set", self.point_set),
                "contaminants": _circles(self.contaminants),
            }
            for name in ("mask_radius", "pixel_scale"):
                if getattr(self, name) is not None:
                    checked[name] = values.number(name, getattr(self, name), 0.0, open_minimum=True)
        except ValueError as error:
            name = str(error).split()[0]
            raise SettingsError(f"{error} ({LENS_KEYS[name]})") from None
        for name, value in checked.items():
            object.__setattr__(self, name, value)

    def to_dict(self) -> dict:
        """JSON-ready form (recorded in every result file)."""
        content = dataclasses.asdict(self)
        content["mask_centre"] = list(self.mask_centre)
        content["contaminants"] = [list(circle) for circle in self.contaminants]
        return content


def _circles(circles) -> tuple[tuple[float, float, float], ...]:
    """``circles`` as a tuple of (x, y, radius > 0) number triples."""
    what = "a list of circles [x, y, radius] in arcsec with radius > 0"
    if not isinstance(circles, list | tuple):
        raise ValueError(f"contaminants must be {what}, got {circles!r}")
    checked = []
    for circle in circles:
        if not isinstance(circle, list | tuple) or len(circle) != 3:
            raise ValueError(f"contaminants must be {what}, got {circle!r} in it")
        try:
            x, y = (values.number("contaminants", value) for value in circle[:2])
            radius = values.number("contaminants", circle[2], 0.0, open_minimum=True)
        except ValueError:
            raise ValueError(f"contaminants must be {what}, got {circle!r} in it") from None
        checked.append((x, y, radius))
    return tuple(checked)


_PAPER_SAMPLERS = {
    "sp": SamplerSettings(method="dynesty_static", n_live=200),
    "spix1": SamplerSettings(method="nautilus", n_live=150),
    "spix2": SamplerSettings(method="dynesty_static", n_live=100),
    "light": SamplerSettings(method="nautilus", n_live=150),
    "mass": SamplerSettings(method="nautilus", n_live=150),
}

_QUICK = {"method": "dynesty_static", "sample": "rwalk", "dlogz": 1.0}
_QUICK_NAUTILUS = {"method": "nautilus", "n_eff": 300, "f_live": 0.05}
_QUICK_SAMPLERS = {
    "sp": SamplerSettings(
        n_live=51, n_networks=1, peak_restarts=1, peak_evaluations=0, **_QUICK_NAUTILUS
    ),
    "spix1": SamplerSettings(n_live=24, plateau_restarts=2, **_QUICK),
    "spix2": SamplerSettings(n_live=12, plateau_restarts=2, **_QUICK),
    "light": SamplerSettings(n_live=30, **_QUICK),
    "mass": SamplerSettings(n_live=30, peak_restarts=2, peak_tolerance=2.0, **_QUICK_NAUTILUS),
}
"""Quick-profile samplers. SP to LIGHT hand their maximum-likelihood model on. SP, the
most multimodal phase (17 parameters): nautilus with 51 live points (3 per parameter)
and one neural network per bound, stopped like MASS; it reached higher maxima than
dynesty's random walks with 60 live points in a third to a half of the calls, and one
network trains in a quarter of the time of nautilus's default four, which on SP's cheap
calls decided whether nautilus saved time at all. It is sampled again with twice the
live points if its posterior falls more than 2 in ln L short of its start
(``peak_restarts`` with the start as the reference point, no local search: on
slacs1627-0053 dynesty's 60 live points settled in a mode 83 below the start's).
SPix1 to LIGHT: dynesty random walks (5 steps) with a loose stopping criterion; SPix1
3 n_dim (24), SPix2 and LIGHT about 2 n_dim + 2 (dynesty needs more than 2 n_dim).
ln ε has spikes over SPix2's k-means weights, and over SPix1's mass when the lens light
is unconstrained (pn-MGE), on which the walks can collapse, every live point a copy of
one, and stop short of convergence: SPix1 and SPix2 then start afresh with twice the
live points, up to twice (24, 48, 96 and 12, 24, 48); the real samples' configs (config/slacs.yaml,
config/paper.yaml) start SPix2 at 24. MASS, whose posterior is the result: nautilus with
30 live points per source mesh (two meshes), stopped when the live set holds 5 % of the
evidence and 300 effective samples are drawn; a run whose highest-posterior sample a
local search raises by more than 2 in ln L + ln prior missed the peak of a narrow slope–θ_E ridge
and is sampled again with 60, then 120 live points (``peak_restarts``), as is a restart
whose best sample falls more than 2 below the run it replaced. The measurements
behind each choice are in docs/slam.md, "Quick-profile samplers"."""

PROFILES: Mapping[str, SlamSettings] = MappingProxyType(
    {
        "paper": SlamSettings(profile="paper", samplers=_PAPER_SAMPLERS),
        "quick": SlamSettings(
            profile="quick",
            positions_penalty=True,
            adaptive_signals="weighted",
            adaptive_signals_mass="spix2",
            sp_start="search",
            spix1_rescan=True,
            source_support="arcs",
            mass_meshes=2,
            mass_mesh_tuning=True,
            source_pixels=500,
            overlay_shape=(24, 24),
            fit=FitSettings(
                sub_size=2,
                lp_sub_size=2,
                lp_sub_size_centre=8,
                psf_trim=1e-4,
                lp_analytic_tolerance=1e-4,
                force_edge_pixels_to_zero=False,
                edge_rule="continuous",
            ),
            samplers=_QUICK_SAMPLERS,
        ),
    }
)
"""Default settings of each speed profile."""

DEFAULT_PROFILE = "quick"


def profile_settings(profile: str = DEFAULT_PROFILE) -> SlamSettings:
    """Default settings of ``profile`` ("quick" or "paper")."""
    if profile not in PROFILES:
        raise SettingsError(f"unknown profile {profile!r}; choose one of {sorted(PROFILES)}")
    return PROFILES[profile]


def settings_from_mapping(
    content: Mapping, profile: str | None = None, origin: str = "settings"
) -> SlamSettings:
    """Settings from a ``slam:`` mapping applied on top of a profile's defaults.

    Parameters
    ----------
    content : mapping
        Field values of :class:`SlamSettings` (``samplers`` maps phase names to partial
        :class:`~mgelens.search.sampler_settings.SamplerSettings` dictionaries). It may name the
        profile under ``profile``.
    profile : str, optional
        Profile whose defaults are used; wins over ``content["profile"]``.
    origin : str
        Where ``content`` came from, for error messages.

    Raises
    ------
    SettingsError
        For an unknown key (named with its ``slam.`` path) or an invalid value.
    """
    content = dict(content)
    lens_keys = sorted(set(content) & set(LENS_KEYS))
    if lens_keys:
        raise SettingsError(
            f"{origin}: slam.{lens_keys[0]} is set per lens, not in slam: settings: give it "
            f"with {LENS_KEYS[lens_keys[0]]}"
        )
    fit_section = content.pop("fit", None) or {}
    if not isinstance(fit_section, Mapping):
        raise SettingsError(
            f"{origin}: slam.fit must be a mapping of fit settings (e.g. {{sub_size: 2}}), "
            f"got {fit_section!r}"
        )
    if content.get("lens_light_model") == "sersic" and "positive_only" not in fit_section:
        raise SettingsError(
            f"{origin}: slam.lens_light_model: sersic needs slam.fit.positive_only set too: "
            "true with free_source: true for the paper's 3×Sérsic solve (lens light "
            "non-negative, source free, SPEC §8.1), true alone for every unknown "
            "non-negative, false for every unknown free; the default (true) is the MGE's"
        )
    profile = profile or content.pop("profile", None) or DEFAULT_PROFILE
    content.pop("profile", None)
    if profile not in PROFILES:
        raise SettingsError(
            f"{origin}: slam.profile must be one of {sorted(PROFILES)}, got {profile!r}"
        )
    base = profile_settings(profile)
    known = {f.name for f in dataclasses.fields(SlamSettings)} - {"profile"}
    unknown = sorted(set(content) - known)
    moved = [key for key in unknown if key in FIT_KEYS]
    if moved:
        raise SettingsError(
            f"{origin}: slam.{moved[0]} is a fit setting: give it as slam.fit.{moved[0]}"
        )
    if unknown:
        raise SettingsError(f"{origin}: unknown key slam.{unknown[0]}; known keys: {sorted(known)}")
    fit_settings = _merged_fit(base.fit, fit_section, origin)
    samplers = _merged_samplers(base.samplers, content.pop("samplers", None), origin)
    try:
        return dataclasses.replace(base, fit=fit_settings, samplers=samplers, **content)
    except (TypeError, ValueError) as error:
        raise SettingsError(f"{origin}: {error}") from error


def _merged_samplers(
    base: Mapping[str, SamplerSettings], section, origin: str
) -> dict[str, SamplerSettings]:
    """``base`` with each phase's entry of a ``slam: samplers:`` mapping merged into it."""
    samplers = dict(base)
    section = section or {}
    if not isinstance(section, Mapping):
        raise SettingsError(
            f"{origin}: slam.samplers must be a mapping of phase names to sampler settings, "
            f"got {section!r}"
        )
    for phase, overrides in section.items():
        if phase not in PHASES:
            raise SettingsError(
                f"{origin}: unknown key slam.samplers.{phase}; phases are {list(PHASES)}"
            )
        if not isinstance(overrides or {}, Mapping):
            raise SettingsError(
                f"{origin}: slam.samplers.{phase} must be a mapping of sampler settings "
                f"(e.g. {{n_live: 80}}), got {overrides!r}"
            )
        merged = {**samplers[phase].to_dict(), **(overrides or {})}
        try:
            samplers[phase] = SamplerSettings.from_dict(merged)
        except (TypeError, ValueError) as error:  # the message starts with the key
            raise SettingsError(f"{origin}: slam.samplers.{phase}.{error}") from error
    return samplers


def _merged_fit(base: FitSettings, overrides: Mapping, origin: str) -> FitSettings:
    """``base`` with the fields of a ``slam: fit:`` mapping replaced."""
    unknown = sorted(set(overrides) - FIT_KEYS)
    if unknown:
        raise SettingsError(
            f"{origin}: unknown key slam.fit.{unknown[0]}; known keys: {sorted(FIT_KEYS)}"
        )
    try:
        return dataclasses.replace(base, **overrides)
    except ValueError as error:  # the message starts with the key
        raise SettingsError(f"{origin}: slam.fit.{error}") from error


def load_settings(
    path: str | Path | None = None,
    profile: str | None = None,
    overrides: Mapping | None = None,
) -> SlamSettings:
    """Settings of ``profile`` overridden by the ``slam:`` section of the YAML file ``path``,
    then by the mapping ``overrides`` (same content as a ``slam:`` section).

    Without a file (or without a ``slam:`` section) and overrides the profile's defaults are
    returned. A profile named by ``profile`` wins over one named in the file or overrides.
    """
    section: dict = {}
    origin = "settings"
    if path is not None:
        path = Path(path)
        origin = str(path)
        try:
            document = yaml.safe_load(path.read_text()) or {}
        except (OSError, yaml.YAMLError) as error:
            raise SettingsError(f"{path}: cannot read the settings file: {error}") from error
        if not isinstance(document, Mapping):
            raise SettingsError(f"{path}: expected a YAML mapping at the top level")
        section = document.get("slam") or {}
        if not isinstance(section, Mapping):
            raise SettingsError(f"{path}: `slam:` must be a mapping of settings")
        section = dict(section)
    if overrides:
        origin = "--slam" if path is None else f"{origin} and --slam"
        samplers = dict(section.get("samplers") or {})
        for phase, values in (overrides.get("samplers") or {}).items():
            samplers[phase] = {**(samplers.get(phase) or {}), **(values or {})}
        fit = {**(section.get("fit") or {}), **(overrides.get("fit") or {})}
        section = {**section, **overrides}
        if samplers:
            section["samplers"] = samplers
        if fit:
            section["fit"] = fit
    return settings_from_mapping(section, profile, origin=origin)

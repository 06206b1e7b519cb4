"""Fit-quality flag: coherent lens-light residuals away from the lensed source (issue #29).

The paper counts a SLACS fit as failed when it leaves correlated lens-light residuals above
3σ (SPEC §11: 35/38 fitted to the noise). This module turns that into a number computed
from a phase's ``model.fits`` (:mod:`mgelens.pipeline.products`) and the lens's noise map.

Definition (all arrays native, row index = +y, SPEC §1.1):

1. **Pixels.** r = NRESID = (data − model)/σ. A pixel is *used* if the fit used it (``mask``
   False), it is not a contaminant sentinel (σ ≤ :data:`mgelens.mask.SLACS_NOISE_THRESHOLD`)
   and the lensed-source model is below the noise there, LENSED < σ. So the statistic
   looks at the lens light only, not at the arcs that the pixelized source fits.
2. **Blocks.** The image is tiled by k×k-pixel blocks, k = round(:data:`BLOCK_SIZE` /
   pixel scale) (at least 2), with a block corner at the image centre (a centred dipole
   falls into different blocks instead of cancelling inside one). A block is *kept* if at
   least :data:`MIN_BLOCK_FILL` of its k² pixels are used. For a kept block b with n_b
   used pixels, z_b = Σ r_i / √n_b: N(0, 1) for white unit noise.
3. **Noise scale.** Noise correlated on the PSF scale (drizzled data, a model that absorbs
   part of the noise) widens z_b by a factor τ that white noise does not have. τ is
   measured from the differences Δz of kept blocks two blocks apart along x or y (far
   enough apart for PSF-scale noise to be independent, close enough for a residual smooth
   on that scale to cancel): τ² = median(Δz²) / (2 · 0.4549), with 0.4549 the median of
   χ²₁ (τ = 1 for white noise).
4. **Statistics.** Coherence S = √(mean_b z_b²) / τ over the B kept blocks (≈ 1 for noise
   of any short-range correlation, > 1 when blocks share an offset); its significance
   K = (S² − 1)·√(B/2) (B·S² would be χ²_B for known τ: K is the excess in units of its
   standard deviation, comparable between lenses with different B); peak
   z_max = max_b |z_b| / τ and its block; n_4 = number of blocks with |z_b| / τ > 4.
5. **Flag.** K > :data:`COHERENCE_THRESHOLD` or z_max > :data:`PEAK_THRESHOLD`. Both
   thresholds are calibrated by Monte Carlo on white and PSF-correlated Gaussian noise
   and by injected lens-light errors in docs/slacs.md ("Fit-quality flag"): the
   false-flag probability per lens is below 10⁻³ when τ rests on at least
   :data:`MIN_PAIRS` block pairs.
6. **τ from the sky** when the judged blocks give fewer than :data:`MIN_PAIRS` pairs (a
   lensed source, or a source model, covering most of the mask). The noise of the same
   image is then measured beyond the fit: pixels more than :data:`SKY_GAP` outside the fit
   circle, not contaminants and not in the folder's mask, as (data − running median of
   side :data:`SKY_FILTER`)/σ (:func:`sky_residual_map`), blocked and paired as in steps 2–3.
   The running median removes the galaxy's smooth light and leaves PSF-scale noise: for
   white and Gaussian-correlated noise this τ equals the residuals' τ within 2 %. It
   does not see noise that a model absorbs (so it is ≥ the residuals' τ for a good fit) nor
   sky structure (which raises it): both make the flag more conservative, never less.
   With fewer than :data:`MIN_PAIRS` sky pairs too, or no judged block: no statistic
   (``measured`` False, no flag). ``noise_scale_from`` says which τ was used.

Units: x, y in arcsec (SPEC §1.1 grid, origin at the image centre); r, z, S dimensionless.

**Lensing check** (:func:`lensing_check`), a second flag that the residuals cannot give: a
mass model that does not multiply image inside the fit circle lets a pixelized source
reproduce the image itself, arcs included, with residuals of pure noise. Flagged: no closed
tangential critical curve (SPEC §3.4) within ``mask_radius`` of the mask centre, or a
needle-thin one, whose circle-equivalent radius √(area/π) is below
:data:`MIN_CURVE_ROUNDNESS` of its half length (an elliptical curve of axis ratio q_c has
the ratio √q_c: 0.45 for an SIE of q = 0.2), or one that does not enclose the lens-light
centre (a small curve of a mass beside the galaxy). All three are failure modes of SP on
real data (docs/slacs.md, "First real lens" and "slacs1250+0523"). Also flagged: a mass
centre more than :data:`MAX_CENTRE_OFFSET` from the lens-light centre. Such a mass still
lenses, but an isolated elliptical's mass and light share a centre to within a pixel; an
offset mass traded against an aligned external shear reproduces θ_E while its centre, q
and shear are not physical (slacs1250+0523, docs/slacs.md).
"""

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy import ndimage

from mgelens.grid import pixel_centres
from mgelens.mask import SLACS_NOISE_THRESHOLD, circular
from mgelens.mass import MassProfile, circle_equivalent_radius, tangential_critical_curve

BLOCK_SIZE = 0.25
"""Arcsec side of a block (5 pixels at 0.05″, a few HST PSF widths)."""
MIN_BLOCK_FILL = 0.5
"""Smallest fraction of a block's pixels that must be used for the block to be kept."""
MIN_PAIRS = 100
"""Fewest block pairs measuring τ for which the statistic is defined (calibrated range)."""
COHERENCE_THRESHOLD = 15.0
"""Flag when the coherence significance K exceeds this (docs/slacs.md, "Fit-quality flag")."""
PEAK_THRESHOLD = 6.0
"""Flag when the peak block z_max exceeds this (docs/slacs.md, "Fit-quality flag")."""
BLOCK_OUTLIER = 4.0
"""|z_b| / τ above which a block counts in ``n_outlier_blocks``."""
MIN_CURVE_ROUNDNESS = 0.25
"""Smallest √(area/π) / half-length of a tangential critical curve (a curve axis ratio of
about 0.06) that :func:`lensing_check` accepts."""
MAX_CENTRE_OFFSET = 0.1
"""Largest mass–light centre distance (arcsec, two HST ACS pixels) that
:func:`lensing_check` accepts."""
SKY_GAP = 0.5
"""Arcsec between the fit circle and the sky pixels that measure τ in step 6."""
SKY_FILTER = 1.25
"""Arcsec side of the running median removed from the sky in step 6: long enough that
blocks two apart share most of it, so that the noise's τ comes out unbiased (25 pixels at
0.05″; a 0.75″ median lowers τ by 6 % for white noise and 18 % for noise correlated over
1.5 pixels)."""
CHI2_1_MEDIAN = 0.454936423119572
"""Median of the χ² distribution with one degree of freedom."""


@dataclass(frozen=True)
class BlockResiduals:
    """Kept blocks of a residual map (step 2 of the module definition).

    Attributes
    ----------
    z : ndarray (n_by, n_bx)
        z_b = Σ r / √n_b; NaN for blocks not kept.
    counts : ndarray of int (n_by, n_bx)
        Used pixels per block.
    x, y : ndarray (n_by, n_bx)
        Arcsec centroid of each block's used pixels (NaN if none).
    block : int
        Block side k in pixels.
    """

    z: np.ndarray
    counts: np.ndarray
    x: np.ndarray
    y: np.ndarray
    block: int

    @property
    def kept(self) -> np.ndarray:
        return np.isfinite(self.z)


@dataclass(frozen=True)
class QualityStatistic:
    """The fit-quality numbers of one residual map (module definition, steps 1–5).

    ``coherence`` S, ``significance`` K, ``peak`` z_max, ``n_outlier_blocks`` n_4,
    ``noise_scale`` τ, ``coherence_white`` √(mean z_b²) (S for τ = 1); ``worst_x``,
    ``worst_y`` (arcsec) the used-pixel centroid of the block of z_max; ``n_pixels`` the
    used pixels in kept blocks, ``n_blocks`` B, ``n_pairs`` the block pairs behind τ,
    ``block_pixels`` k and ``block_arcsec`` its side. NaN statistics and ``flag`` False when
    not ``measured``.
    """

    measured: bool
    flag: bool
    coherence: float
    significance: float
    peak: float
    n_outlier_blocks: int
    noise_scale: float
    coherence_white: float
    worst_x: float
    worst_y: float
    n_pixels: int
    n_blocks: int
    n_pairs: int
    block_pixels: int
    block_arcsec: float
    noise_scale_from: str = ""
    sky_noise_scale: float = math.nan
    n_sky_pairs: int = 0
    coherence_threshold: float = COHERENCE_THRESHOLD
    peak_threshold: float = PEAK_THRESHOLD

    def to_dict(self) -> dict:
        """JSON-ready dictionary (NaN as ``None``)."""
        return {
            k: None if isinstance(v, float) and math.isnan(v) else v
            for k, v in asdict(self).items()
        }


def block_pixels(pixel_scale: float, block_arcsec: float = BLOCK_SIZE) -> int:
    """Block side k in pixels: round(block_arcsec / pixel_scale), at least 2."""
    if not pixel_scale > 0 or not block_arcsec > 0:
        raise ValueError(
            f"pixel_scale ({pixel_scale}) and block size ({block_arcsec}) must be positive arcsec"
        )
    return max(2, round(block_arcsec / pixel_scale))


def used_pixels(
    nresid: np.ndarray, lensed: np.ndarray, noise_map: np.ndarray, mask: np.ndarray
) -> np.ndarray:
    """Bool map of the pixels the statistic uses (step 1): fitted, not a contaminant, and
    lensed source below the noise (LENSED < σ).

    Raises
    ------
    ValueError
        If the arrays are not 2D of one shape.
    """
    arrays = {"NRESID": nresid, "LENSED": lensed, "noise map": noise_map, "mask": mask}
    shapes = {name: np.shape(a) for name, a in arrays.items()}
    if len(set(shapes.values())) != 1 or len(shapes["NRESID"]) != 2:
        described = ", ".join(f"{name} {shape}" for name, shape in shapes.items())
        raise ValueError(
            f"residual, lensed-source, noise and mask arrays must be 2D of one shape: {described}"
        )
    noise_map = np.asarray(noise_map, dtype=float)
    return (
        ~np.asarray(mask, dtype=bool)
        & np.isfinite(nresid)
        & (noise_map <= SLACS_NOISE_THRESHOLD)
        & (np.asarray(lensed, dtype=float) < noise_map)
    )


def _tile(image: np.ndarray, block: int) -> np.ndarray:
    """``image`` padded with zeros so that a block corner falls at the image centre
    (index n // 2 on each axis), reshaped to (n_by, k, n_bx, k)."""
    pads = []
    for n in image.shape:
        before = (block - (n // 2) % block) % block
        after = (-(n + before)) % block
        pads.append((before, after))
    padded = np.pad(image, pads)
    n_by, n_bx = padded.shape[0] // block, padded.shape[1] // block
    return padded.reshape(n_by, block, n_bx, block)


def block_residuals(
    residuals: np.ndarray, used: np.ndarray, pixel_scale: float, block: int
) -> BlockResiduals:
    """z_b, counts and used-pixel centroids of the k×k blocks (step 2)."""
    used = np.asarray(used, dtype=bool)
    r = np.where(used, residuals, 0.0)
    x, y = pixel_centres(used.shape, pixel_scale)
    counts = _tile(used.astype(np.int64), block).sum(axis=(1, 3))
    sums = _tile(r, block).sum(axis=(1, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        cx = _tile(np.where(used, x, 0.0), block).sum(axis=(1, 3)) / counts
        cy = _tile(np.where(used, y, 0.0), block).sum(axis=(1, 3)) / counts
        z = sums / np.sqrt(counts)
    kept = counts >= MIN_BLOCK_FILL * block * block
    return BlockResiduals(np.where(kept, z, np.nan), counts, cx, cy, block)


def pair_differences(z: np.ndarray, step: int = 2) -> np.ndarray:
    """Δz of the pairs of kept blocks ``step`` blocks apart along x or y (step 3)."""
    differences = np.concatenate(
        [(z[step:, :] - z[:-step, :]).ravel(), (z[:, step:] - z[:, :-step]).ravel()]
    )
    return differences[np.isfinite(differences)]


def noise_scale(differences: np.ndarray) -> float:
    """τ = √(median(Δz²) / (2 · 0.4549)) of :func:`pair_differences` (NaN if empty)."""
    if differences.size == 0:
        return math.nan
    return float(np.sqrt(np.median(differences**2) / (2.0 * CHI2_1_MEDIAN)))


def sky_pixels(
    data: np.ndarray,
    noise_map: np.ndarray,
    pixel_scale: float,
    mask_radius: float,
    mask_centre: tuple[float, float] = (0.0, 0.0),
    excluded: np.ndarray | None = None,
    gap: float = SKY_GAP,
) -> np.ndarray:
    """Bool map of the sky pixels of step 6: farther than ``mask_radius + gap`` (arcsec)
    from ``mask_centre``, finite data, 0 < σ ≤ :data:`mgelens.mask.SLACS_NOISE_THRESHOLD`
    (no contaminant) and not ``excluded`` (e.g. the folder's ``mask.fits``, True = excluded).
    """
    noise_map = np.asarray(noise_map, dtype=float)
    good = np.isfinite(data) & np.isfinite(noise_map) & (noise_map > 0.0)
    good &= noise_map <= SLACS_NOISE_THRESHOLD
    sky = circular(np.shape(data), pixel_scale, mask_radius + gap, mask_centre) & good
    if excluded is not None:
        sky &= ~np.asarray(excluded, dtype=bool)
    return sky


def sky_residual_map(
    data: np.ndarray,
    noise_map: np.ndarray,
    sky: np.ndarray,
    pixel_scale: float,
    filter_arcsec: float = SKY_FILTER,
) -> np.ndarray:
    """(data − running median)/σ on the ``sky`` pixels, NaN elsewhere (step 6).

    The median's side is the odd number of pixels nearest ``filter_arcsec`` / pixel scale;
    non-finite data enter it as 0. Data units cancel; the result is dimensionless.
    """
    data = np.asarray(data, dtype=float)
    side = 2 * round(0.5 * (filter_arcsec / pixel_scale - 1.0)) + 1
    smooth = ndimage.median_filter(np.where(np.isfinite(data), data, 0.0), size=side)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(sky, (data - smooth) / noise_map, np.nan)


def judged_blocks(
    nresid: np.ndarray,
    lensed: np.ndarray,
    noise_map: np.ndarray,
    mask: np.ndarray,
    pixel_scale: float,
    block_arcsec: float = BLOCK_SIZE,
) -> BlockResiduals:
    """The blocks of the pixels the statistic judges (steps 1–2; arguments as in
    :func:`quality_statistic`)."""
    used = used_pixels(nresid, lensed, noise_map, mask)
    block = block_pixels(pixel_scale, block_arcsec)
    return block_residuals(np.asarray(nresid, dtype=float), used, pixel_scale, block)


def quality_statistic(
    nresid: np.ndarray,
    lensed: np.ndarray,
    noise_map: np.ndarray,
    mask: np.ndarray,
    pixel_scale: float,
    block_arcsec: float = BLOCK_SIZE,
    coherence_threshold: float = COHERENCE_THRESHOLD,
    peak_threshold: float = PEAK_THRESHOLD,
    sky_residuals: np.ndarray | None = None,
) -> QualityStatistic:
    """The fit-quality statistic of a residual map (module definition).

    Parameters
    ----------
    nresid : ndarray (n_y, n_x)
        Normalised residuals (data − model)/σ (``model.fits`` NRESID).
    lensed : ndarray (n_y, n_x)
        PSF-convolved lensed-source model, data units (``model.fits`` LENSED).
    noise_map : ndarray (n_y, n_x)
        1σ noise, data units (contaminants: above ``SLACS_NOISE_THRESHOLD``).
    mask : ndarray of bool (n_y, n_x)
        The fit's mask, True = excluded.
    pixel_scale : float
        Arcsec per pixel.
    block_arcsec, coherence_threshold, peak_threshold : float
        Block side (arcsec) and flag thresholds (defaults: the calibrated ones).
    sky_residuals : ndarray (n_y, n_x), optional
        :func:`sky_residual_map` of the same image (NaN off the sky), for step 6.

    Returns
    -------
    QualityStatistic
        ``measured`` False (NaN statistics, no flag) when neither the judged blocks nor the
        sky give ``MIN_PAIRS`` block pairs, or no block is judged.
    """
    blocks = judged_blocks(nresid, lensed, noise_map, mask, pixel_scale, block_arcsec)
    differences = pair_differences(blocks.z)
    sky_tau, n_sky_pairs = math.nan, 0
    if sky_residuals is not None:
        sky_blocks = block_residuals(
            np.asarray(sky_residuals, dtype=float),
            np.isfinite(sky_residuals),
            pixel_scale,
            blocks.block,
        )
        sky_differences = pair_differences(sky_blocks.z)
        sky_tau, n_sky_pairs = noise_scale(sky_differences), int(sky_differences.size)
    if differences.size >= MIN_PAIRS:
        tau, source = noise_scale(differences), "residuals"
    elif n_sky_pairs >= MIN_PAIRS:
        tau, source = sky_tau, "sky"
    else:
        tau, source = math.nan, ""
    return scaled_statistic(
        blocks,
        tau,
        pixel_scale,
        noise_scale_from=source,
        n_pairs=int(differences.size),
        sky_noise_scale=sky_tau,
        n_sky_pairs=n_sky_pairs,
        coherence_threshold=coherence_threshold,
        peak_threshold=peak_threshold,
    )


def scaled_statistic(
    blocks: BlockResiduals,
    tau: float,
    pixel_scale: float,
    noise_scale_from: str,
    n_pairs: int,
    sky_noise_scale: float = math.nan,
    n_sky_pairs: int = 0,
    coherence_threshold: float = COHERENCE_THRESHOLD,
    peak_threshold: float = PEAK_THRESHOLD,
) -> QualityStatistic:
    """Steps 4–5 for judged ``blocks`` (:func:`judged_blocks`) and a noise scale ``tau``;
    not ``measured`` if ``tau`` is not positive or no block is kept. The other arguments
    are recorded as they are (:class:`QualityStatistic`)."""
    kept = blocks.kept
    n_blocks = int(kept.sum())
    common = {
        "n_pixels": int(blocks.counts[kept].sum()),
        "n_blocks": n_blocks,
        "n_pairs": n_pairs,
        "block_pixels": blocks.block,
        "block_arcsec": blocks.block * float(pixel_scale),
        "sky_noise_scale": sky_noise_scale,
        "n_sky_pairs": n_sky_pairs,
        "coherence_threshold": coherence_threshold,
        "peak_threshold": peak_threshold,
    }
    if not tau > 0 or n_blocks == 0:
        nan = math.nan
        return QualityStatistic(False, False, nan, nan, nan, 0, nan, nan, nan, nan, **common)
    z = blocks.z[kept]
    white = float(np.sqrt(np.mean(z**2)))
    coherence = white / tau
    significance = (coherence**2 - 1.0) * math.sqrt(n_blocks / 2.0)
    scaled = np.abs(blocks.z) / tau
    worst = np.unravel_index(np.nanargmax(scaled), scaled.shape)
    peak = float(scaled[worst])
    return QualityStatistic(
        measured=True,
        flag=bool(significance > coherence_threshold or peak > peak_threshold),
        coherence=coherence,
        significance=significance,
        peak=peak,
        n_outlier_blocks=int(np.count_nonzero(scaled[kept] > BLOCK_OUTLIER)),
        noise_scale=tau,
        coherence_white=white,
        worst_x=float(blocks.x[worst]),
        worst_y=float(blocks.y[worst]),
        noise_scale_from=noise_scale_from,
        **common,
    )


@dataclass(frozen=True)
class LensingCheck:
    """Whether a mass model multiply images inside the fit circle (module docstring).

    ``critical_curve_einstein_radius`` is √(area/π) of the tangential critical curve in
    arcsec (``None`` without a closed curve in the circle); ``centre_offset`` is the
    distance in arcsec from the first mass profile's centre to the lens-light centre
    (``None`` when no light centre was given); ``flag`` is True when there is no such
    curve, it is needle-thin, it leaves the lens-light centre outside or the offset
    exceeds :data:`MAX_CENTRE_OFFSET`, with the ``reason``.
    """

    critical_curve_einstein_radius: float | None
    flag: bool
    reason: str
    centre_offset: float | None = None

    def to_dict(self) -> dict:
        return asdict(self)


def encloses(x: np.ndarray, y: np.ndarray, point: tuple[float, float]) -> bool:
    """Whether the closed polyline (x, y) encloses ``point`` (even-odd rule: a ray from the
    point towards +x crosses the polyline an odd number of times)."""
    x0, y0 = point
    x1, y1, x2, y2 = x[:-1], y[:-1], x[1:], y[1:]
    straddles = (y1 > y0) != (y2 > y0)
    with np.errstate(divide="ignore", invalid="ignore"):
        crossing = x1 + (y0 - y1) * (x2 - x1) / (y2 - y1)
    return bool(np.count_nonzero(straddles & (crossing > x0)) % 2)


def lensing_check(
    mass: tuple[MassProfile, ...],
    mask_radius: float,
    mask_centre: tuple[float, float] = (0.0, 0.0),
    grid_spacing: float = 0.02,
    light_centre: tuple[float, float] | None = None,
) -> LensingCheck:
    """Flag a mass model without a closed tangential critical curve inside the circle of
    ``mask_radius`` (arcsec) around ``mask_centre``, with a needle-thin one, or (given the
    lens-light centre ``light_centre``, arcsec) with one that does not enclose it or a first
    mass profile centred more than :data:`MAX_CENTRE_OFFSET` from it (SPEC §3.4 grid of
    ``grid_spacing``; module docstring)."""
    offset = None
    if light_centre is not None:
        offset = math.dist(mass[0].centre, light_centre)
    half_width = abs(mask_centre[0]) + abs(mask_centre[1]) + mask_radius
    try:
        x, y = tangential_critical_curve(mass, grid_spacing, half_width)
    except ValueError:
        return LensingCheck(
            None, True, f"no closed tangential critical curve within {half_width:.2f}″", offset
        )
    outside = np.hypot(x - mask_centre[0], y - mask_centre[1]).max()
    if outside > mask_radius:
        return LensingCheck(
            None,
            True,
            f"the tangential critical curve reaches {outside:.2f}″ from the mask centre, "
            f"beyond the {mask_radius:g}″ fit circle",
            offset,
        )
    radius = circle_equivalent_radius(x, y)
    if light_centre is not None and not encloses(x, y, light_centre):
        return LensingCheck(
            radius,
            True,
            f"the tangential critical curve (√(area/π) = {radius:.2f}″, centred near "
            f"({np.mean(x):.2f}, {np.mean(y):.2f})″) does not enclose the lens-light centre "
            f"({light_centre[0]:.2f}, {light_centre[1]:.2f})″",
            offset,
        )
    half_length = 0.5 * float(np.max(np.hypot(x[:, None] - x, y[:, None] - y)))
    if radius < MIN_CURVE_ROUNDNESS * half_length:
        return LensingCheck(
            radius,
            True,
            f"needle-thin tangential critical curve: √(area/π) = {radius:.2f}″ against a "
            f"half length of {half_length:.2f}″",
            offset,
        )
    if offset is not None and offset > MAX_CENTRE_OFFSET:
        return LensingCheck(
            radius,
            True,
            f"the mass centre ({mass[0].centre[0]:.2f}, {mass[0].centre[1]:.2f})″ is "
            f"{offset:.2f}″ from the lens-light centre ({light_centre[0]:.2f}, "
            f"{light_centre[1]:.2f})″, beyond {MAX_CENTRE_OFFSET:g}″",
            offset,
        )
    return LensingCheck(radius, False, "", offset)


NO_FLAG = "none"
"""What :func:`flagged_checks` gives for a record that no check flags."""


def flagged_checks(record) -> str:
    """The checks of a ``mgelens quality`` record (``quality.json``) that flag its fit, as
    text: ``residuals`` (coherent residuals, when measured), ``lensing``
    (:func:`lensing_check`) and ``singly imaged``
    (:func:`mgelens.image_multiplicity.multiplicity_check`; records written before it
    have none), joined by ``"; "``, or :data:`NO_FLAG`. Raises ``KeyError`` on a record
    without the residual or lensing check."""
    names = []
    if record["measured"] and record["flag"]:
        names.append("residuals")
    if record["lensing"]["flag"]:
        names.append("lensing")
    if (record.get("multiplicity") or {}).get("flag"):
        names.append("singly imaged")
    return "; ".join(names) or NO_FLAG

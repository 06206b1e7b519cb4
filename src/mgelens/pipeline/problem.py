"""What every phase is built from: the lens's imaging in the fit mask, the earlier phases'
results, and the :class:`PhaseProblem` a phase samples (SPEC §8.1).

A phase reads only earlier phases' ``result.json`` and ``samples.csv`` (and SPix1's adapt
image), so any phase can be rerun alone. :func:`read_phase` refuses an earlier phase that
is missing or whose sampler did not converge, naming the file and the command that makes
it. :func:`load_dataset` reads the imaging in the circular mask of the settings.
"""

import contextlib
import functools
import json
import logging
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mgelens import mask as mask_module
from mgelens.fit import FitDataset
from mgelens.imaging import DATA_FILE, INFO_FILE, MASK_FILE, Imaging
from mgelens.pipeline import fittable, models, products
from mgelens.pipeline.records import (
    ADAPT_IMAGE_FILE,
    PhaseInputError,
    light_components,
    profiles_from_record,
    read_fit_record,
)
from mgelens.pipeline.settings import LensSpec, SlamSettings
from mgelens.search.model import ParameterSpace
from mgelens.search.results import RESULT_FILE, SAMPLES_FILE, PhaseResult

logger = logging.getLogger("mgelens.pipeline")

LOG_FILE = "phase.log"


IMAGING_FILES = ("data.fits", "noise_map.fits", "psf.fits", MASK_FILE, INFO_FILE)


# -- logging --------------------------------------------------------------------------


@contextlib.contextmanager
def phase_log(folder: Path) -> Iterator[None]:
    """Copy ``mgelens`` log records of INFO and above into ``folder/phase.log``."""
    handler = logging.FileHandler(folder / LOG_FILE)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    handler.setLevel(logging.INFO)
    package = logging.getLogger("mgelens")
    level = package.level
    if package.getEffectiveLevel() > logging.INFO:
        package.setLevel(logging.INFO)
    package.addHandler(handler)
    try:
        yield
    finally:
        package.removeHandler(handler)
        package.setLevel(level)
        handler.close()


# -- inputs ---------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class EarlierPhase:
    """A finished phase read from its folder: result and maximum-likelihood fit record."""

    folder: Path
    result: PhaseResult
    record: dict

    @property
    def files(self) -> list[Path]:
        return [self.folder / RESULT_FILE, self.folder / SAMPLES_FILE]

    @property
    def lens_light_kind(self) -> str:
        """ "mge" or "sersic": the kind of the phase's lens light."""
        components = light_components(self.record)
        return "sersic" if any(c["kind"] == "sersic" for c in components) else "mge"

    @property
    def lens_light_specs(self) -> tuple[models.LightSpec, ...]:
        """Specs of the phase's linear (solved) lens light."""
        return tuple(
            models.SersicSpec(c["name"])
            if c["kind"] == "sersic"
            else models.LightSetSpec(c["name"], np.asarray(c["sigmas"], dtype=float))
            for c in light_components(self.record)
            if not c.get("fixed", False)
        )

    @property
    def smoothness_prior(self) -> bool:
        """Whether the phase's lens light carried the smoothness prior (its space holds
        ``lens_light.smoothness``)."""
        return any(p.name == models.SMOOTHNESS for p in self.result.space.parameters)

    def source_pixels(self, settings: SlamSettings) -> int:
        """The k-means pixel count of this (SPix2's) source, which LIGHT and MASS keep.

        Raises
        ------
        PhaseInputError
            If the record has no k-means source, or its count is not among the settings'
            ``source_pixels`` (SPix2 fitted with other settings).
        """
        source = self.record.get("source", {})
        if source.get("mesh") != "kmeans":
            raise PhaseInputError(
                f"{self.folder / RESULT_FILE} has no k-means source: rerun phase 'spix2'"
            )
        n_pixels = int(source["n_pixels"])
        if n_pixels not in settings.source_pixel_candidates:
            raise PhaseInputError(
                f"{self.folder / RESULT_FILE} was fitted with {n_pixels} source pixels but "
                f"the settings ask for slam.source_pixels = {settings.source_pixels!r}: "
                "rerun phase 'spix2' (and the phases after it) with these settings"
            )
        return n_pixels

    def check_lens_light(self, settings: SlamSettings, prior: bool = False) -> None:
        """Raise :class:`PhaseInputError` unless the phase used the settings' lens light
        and, with ``prior``, their ``lens_light_prior``."""
        if self.lens_light_kind != settings.lens_light_model:
            raise PhaseInputError(
                f"{self.folder / RESULT_FILE} was fitted with lens_light_model = "
                f"{self.lens_light_kind!r} but the settings ask for "
                f"{settings.lens_light_model!r}: rerun phase {self.folder.name!r} (and the "
                "phases after it) with these settings"
            )
        fitted = "smoothness" if self.smoothness_prior else "none"
        if prior and fitted != settings.lens_light_prior:
            raise PhaseInputError(
                f"{self.folder / RESULT_FILE} was fitted with lens_light_prior = {fitted!r} "
                f"but the settings ask for {settings.lens_light_prior!r}: rerun phase "
                f"{self.folder.name!r} (and the phases after it) with these settings"
            )


def read_phase(results_dir: str | Path, name: str, allow_unconverged: bool = False) -> EarlierPhase:
    """The finished phase ``name`` in ``results_dir``.

    Raises
    ------
    PhaseInputError
        If its ``result.json`` is missing, naming the command that makes it, or records a
        sampler that did not converge (unless ``allow_unconverged``,
        ``slam.allow_unconverged``).
    """
    folder = Path(results_dir) / name
    if not (folder / RESULT_FILE).is_file():
        raise PhaseInputError(
            f"{folder / RESULT_FILE} not found: run phase {name!r} first "
            f"(mgelens phase {name} --results {results_dir} ...)"
        )
    record = read_fit_record(folder)
    result = PhaseResult.read(folder)
    if not (result.output.converged or allow_unconverged):
        raise PhaseInputError(
            f"{folder / RESULT_FILE} is not converged ({result.output.stop_reason}): rerun "
            f"phase {name!r} without the cap or with more live points, or set "
            "slam.allow_unconverged: true to build on it anyway"
        )
    return EarlierPhase(folder, result, record)


def earlier_phases(
    results_dir: str | Path, settings: SlamSettings, *names: str
) -> tuple[EarlierPhase, ...]:
    """The finished phases ``names`` (:func:`read_phase` with the settings'
    ``allow_unconverged``)."""
    return tuple(read_phase(results_dir, name, settings.allow_unconverged) for name in names)


def resolve_mask_radius(lens_dir: Path, lens: LensSpec) -> float:
    """Mask radius (arcsec): the lens spec's, else ``mask_radius`` of ``truth.json``."""
    if lens.mask_radius is not None:
        return float(lens.mask_radius)
    truth = lens_dir / "truth.json"
    if truth.is_file():
        radius = json.loads(truth.read_text()).get("mask_radius")
        if radius is not None:
            return float(radius)
    raise PhaseInputError(
        f"no mask radius for {lens_dir}: pass --mask-radius (the sample sheet's mask_radius "
        "column), or give the folder a truth.json with mask_radius"
    )


def load_dataset(
    lens_dir: Path, settings: SlamSettings, lens: LensSpec, light_centre: tuple[float, float]
) -> tuple[FitDataset, float]:
    """Imaging of ``lens_dir`` in the lens's circular mask, under the settings' fit
    settings, and the mask radius.

    A ``mask.fits`` in the folder is combined with the circle (a pixel is used only if
    both use it); only the pixels used must hold finite data and a positive noise. The
    lens's ``contaminants`` circles get the sentinel noise (:func:`mgelens.mask.contaminants`).
    ``light_centre`` (arcsec) is where light profiles are over-sampled.

    Raises
    ------
    ImagingError
        Naming ``data.fits``, for a circle reaching beyond the image or data without
        light inside it (:mod:`mgelens.pipeline.fittable`), and for unreadable or invalid
        files (:class:`~mgelens.imaging.Imaging`).
    """
    radius = resolve_mask_radius(lens_dir, lens)
    data_file = lens_dir / DATA_FILE
    circle = functools.partial(_fit_circle, data_file, radius, lens.mask_centre)
    imaging = Imaging.from_folder(lens_dir, pixel_scale=lens.pixel_scale, mask_from=circle)
    if lens.contaminants:
        imaging = mask_module.contaminants(imaging, lens.contaminants)
    mask = imaging.mask
    fittable.check_signal(data_file, imaging, mask, radius)
    return FitDataset.from_imaging(imaging, mask, settings.fit, light_centre), radius


def _fit_circle(
    data_file: Path,
    radius: float,
    centre: tuple[float, float],
    shape: tuple[int, int],
    pixel_scale: float,
) -> np.ndarray:
    """The fit's circular mask on an image of ``shape`` (True = excluded), refused if it
    reaches beyond the image."""
    fittable.check_circle_inside(data_file, shape, pixel_scale, radius, centre)
    return mask_module.circular(shape, pixel_scale, radius, centre)


def imaging_files(lens_dir: Path) -> list[Path]:
    """The imaging files of ``lens_dir`` that exist (inputs of every phase)."""
    return [lens_dir / f for f in IMAGING_FILES if (lens_dir / f).is_file()]


# -- the problem and what phases share ------------------------------------------------


@dataclass(frozen=True, eq=False)
class PhaseProblem:
    """Everything a phase samples: data, parameter space, model mapping, input files."""

    name: str
    dataset: FitDataset
    space: ParameterSpace
    model: models.PhaseModel
    inputs: tuple[Path, ...]
    mask_radius: float
    positions: models.PositionsPenalty | None = None
    reference: dict[str, float] | None = None
    """Values whose ln L the sampled posterior must reach (SP's start; the sampler's peak
    check, ``SamplerSettings.peak_restarts``)."""


def positions_penalty(
    sp: EarlierPhase, settings: SlamSettings, spix1: EarlierPhase | None = None
) -> models.PositionsPenalty | None:
    """The positions penalty if the settings ask for it (and at least two images were
    found), else ``None``: SP's image positions, or those SPix1 sampled with when
    ``spix1`` is given (MASS), which differ from SP's where SPix1's rescan moved the mass
    (:mod:`mgelens.pipeline.mass_rescan`)."""
    if not settings.positions_penalty:
        return None
    record = sp.record.get("positions")
    if spix1 is not None and spix1.result.settings.get("positions"):
        record = spix1.result.settings["positions"]
    record = record or {"positions": []}
    positions = np.asarray(record["positions"], dtype=float).reshape(-1, 2)
    if len(positions) < 2:
        logger.warning(
            "SP found %d image(s) of its source centre: no positions penalty", len(positions)
        )
        return None
    logger.info(
        "positions penalty: %d images, threshold %.3g arcsec", len(positions), record["threshold"]
    )
    return models.PositionsPenalty(positions, float(record["threshold"]))


def sp_light_model(sp: EarlierPhase, source: models.SourceModel) -> models.PhaseModel:
    """SPix1/SPix2 model: SP's MGE geometry with intensities re-solved, or SP's Sérsics
    fixed entirely (intensities included, SPEC §8.1)."""
    if sp.lens_light_kind == "sersic":
        return models.PhaseModel((), source, fixed_light=profiles_from_record(sp.record))
    return models.PhaseModel(sp.lens_light_specs, source)


def kmeans_source(
    dataset: FitDataset, results_dir: Path, settings: SlamSettings, n_pixels: int
) -> tuple[models.KMeansSourceModel, Path]:
    """SPix2's k-means source model of ``n_pixels`` pixels on SPix1's adapt image, and the
    adapt image's path (an input of SPix2, LIGHT and MASS)."""
    path = Path(results_dir) / "spix1" / ADAPT_IMAGE_FILE
    if not path.is_file():
        raise PhaseInputError(f"{path} not found: rerun phase 'spix1'")
    adapt = products.read_adapt_image(path, dataset.mask)
    x, y = dataset.pixel_centres
    source = models.KMeansSourceModel.from_settings(
        x, y, adapt, settings, n_pixels, dataset.noise_map
    )
    return source, path

r"""mgelens against PyAutoLens 2024.5.16 (the paper-era anchor) on configuration R.

Builds the imaging, k-means image-plane mesh, MGE sets and mass model of
``bench_likelihood.py`` (configuration R) and hands them to PyAutoLens's ``FitImaging``
with ``VoronoiNN`` natural-neighbour interpolation, ``AdaptiveBrightnessSplit``
regularization, the positive-only solver and 4×4 over-sampling of the light profiles
and the pixelization. The image-plane mesh (and w-tilde) is preloaded, as in a
PyAutoLens search, so neither code runs k-means inside the timed call, and mgelens
reuses nothing between calls either. Prints, on the same machine and thread count:

* the median time per log evidence of both codes (PyAutoLens with w-tilde and with its
  mapping-matrix formalism);
* the log evidence and its terms (χ², sᵀHs, ln det(F + H), ln det H) of both codes for R
  and for configuration A (R with the 34×34 overlay mesh and ConstantSplit(1), whose
  inputs are pure geometry; ``tests/test_anchor_agreement.py`` holds its numbers);
* the largest difference between the two mapping matrices (ray tracing, border
  relocation and natural-neighbour weights of every sub-pixel).

Measured on 2026-11-23: mapping matrices equal to 2e-9; ln det(F + H) equal to 1e-3; ln det H
equal to 1e-3 for A and 1.3 apart for R, where the anchor drives the signal of its last
source pixel towards 0 (see ``mgelens.source.regularization.adaptive_pixel_signals``); χ²
1.4–1.7 apart (1.5e-4 relative) and log evidences 0.1 (R) and 0.7 (A) apart.

PyAutoLens is not a dependency of mgelens and needs older numpy/scipy/scikit-learn, so
run this from its own environment (the repository root as working directory)::

    python -m venv /tmp/pal && /tmp/pal/bin/pip install "autolens==2024.5.16.0" "numba<0.60"
    (cd /tmp/pal/lib/python3.11/site-packages/autoarray/util/nn/src/nn &&
     bash ./configure && cp makefile_autolens makefile && make)
    /tmp/pal/bin/pip install --no-deps -e .
    LD_LIBRARY_PATH=/tmp/pal/lib/python3.11/site-packages/autoarray/util/nn/src/nn \
        /tmp/pal/bin/python benchmarks/compare_pyautolens.py
"""

import sys

import numpy as np
from bench_likelihood import (
    MASS,
    PIXEL,
    RADIUS,
    fresh_fit,
    lens_light_sets,
    make_model,
    mock_imaging,
)
from common import median_time, report, set_threads

from mgelens.fit import FitDataset, LensModel, PixelizedSource, fit, pixelized_operator
from mgelens.fit_settings import FitSettings
from mgelens.geometry import axis_ratio_and_angle_from, ell_comps_from
from mgelens.source.image_mesh import floored_adapt_image, overlay_centres
from mgelens.source.regularization import ConstantSplit

try:
    import autolens as al
except ImportError:
    sys.exit("compare_pyautolens.py needs autolens==2024.5.16.0 (see the module docstring)")


def anchor_ell_comps(ell_comps: tuple[float, float]) -> tuple[float, float]:
    """mgelens (e1, e2) → the anchor's order (sin part, cos part) (SPEC §12.2)."""
    return ell_comps[1], ell_comps[0]


def yx(point) -> tuple[float, float]:
    """(x, y) → the anchor's (y, x) (SPEC §12.3)."""
    return float(point[1]), float(point[0])


def anchor_array(native: np.ndarray):
    """An mgelens image (row index = +y) as an anchor Array2D (row 0 at the top)."""
    return al.Array2D.no_mask(np.flipud(native), pixel_scales=PIXEL)


def anchor_galaxies(regularization):
    """Lens (2×30 + 10 MGE, EPL + shear) and pixelized source galaxies of configuration R,
    with ``regularization`` (AdaptiveBrightnessSplit or ConstantSplit)."""
    basis = []
    for mge in lens_light_sets():
        ell = anchor_ell_comps(mge.ell_comps)
        q, _ = axis_ratio_and_angle_from(mge.ell_comps)
        # mgelens σ is the major-axis dispersion; the anchor's `sigma` is the minor one
        # (SPEC §12.1: its profile is exp[−(q²x′² + y′²)/2σ²]).
        basis += [
            al.lp_linear.Gaussian(centre=yx(mge.centre), ell_comps=ell, sigma=s * q)
            for s in mge.sigmas
        ]
    epl, shear = MASS
    lens = al.Galaxy(
        redshift=0.5,
        bulge=al.lp_basis.Basis(light_profile_list=basis),
        mass=al.mp.PowerLaw(
            centre=yx(epl.centre),
            ell_comps=anchor_ell_comps(ell_comps_from(epl.axis_ratio, epl.angle)),
            einstein_radius=epl.einstein_radius,
            slope=epl.slope,
        ),
        shear=al.mp.ExternalShear(gamma_1=shear.gamma_1, gamma_2=shear.gamma_2),
    )
    if isinstance(regularization, ConstantSplit):
        anchor_regularization = al.reg.ConstantSplit(coefficient=regularization.coefficient)
    else:
        anchor_regularization = al.reg.AdaptiveBrightnessSplit(
            inner_coefficient=regularization.inner_coefficient,
            outer_coefficient=regularization.outer_coefficient,
            signal_scale=regularization.signal_scale,
        )
    pixelization = al.Pixelization(
        image_mesh=al.image_mesh.KMeans(pixels=1500),  # replaced by the preloaded mesh
        mesh=al.mesh.VoronoiNN(),
        regularization=anchor_regularization,
    )
    source = al.Galaxy(redshift=1.0, pixelization=pixelization)
    return lens, source


def report_terms(name: str, log_evidence, chi2, reg, log_det_fh, log_det_h) -> None:
    """The log evidence and its terms (SPEC §7) as ``<name>_<term>``, to 1e-3."""
    for term, value in (
        ("log_evidence", log_evidence),
        ("chi2", chi2),
        ("regularization_term", reg),
        ("log_det_curvature_regularization", log_det_fh),
        ("log_det_regularization", log_det_h),
    ):
        print(f"{name}_{term}: {value:.3f}")


def report_mgelens_terms(name: str, result) -> None:
    terms = (result.chi_squared, result.regularization_term)
    terms += (result.log_det_curvature_regularization, result.log_det_regularization)
    report_terms(name, result.log_evidence, *terms)


def report_anchor_terms(name: str, anchor) -> None:
    inversion = anchor.inversion
    terms = (anchor.chi_squared, inversion.regularization_term)
    terms += (inversion.log_det_curvature_reg_matrix_term,)
    report_terms(name, anchor.figure_of_merit, *terms, inversion.log_det_regularization_matrix_term)


def anchor_imaging_of(imaging):
    """The masked imaging with 4×4 over-sampling of light profiles and pixelization."""
    mask = al.Mask2D.circular(shape_native=imaging.shape, pixel_scales=PIXEL, radius=RADIUS)
    anchor_imaging = al.Imaging(
        data=anchor_array(imaging.data),
        noise_map=anchor_array(imaging.noise_map),
        psf=al.Kernel2D.no_mask(np.flipud(imaging.psf), pixel_scales=PIXEL),
    ).apply_mask(mask)
    return anchor_imaging.apply_over_sampling(
        over_sampling=al.OverSamplingUniform(sub_size=4),
        over_sampling_pixelization=al.OverSamplingUniform(sub_size=4),
    )


def anchor_fitter(anchor_imaging, model, lensed: np.ndarray, use_w_tilde: bool):
    """A function returning the anchor's FitImaging of ``model`` as a search evaluates it:
    the image-plane mesh (and w-tilde, if used) preloaded, everything else computed."""
    mask = anchor_imaging.mask
    lens, source = anchor_galaxies(model.source.regularization)
    # The anchor's analysis floors adapt images before a fit (SPEC §12.11); mgelens's
    # regularization does the same inside.
    adapt_slim = floored_adapt_image(np.flipud(lensed)[~np.asarray(mask)])
    adapt = al.Array2D(values=adapt_slim, mask=mask)
    adapt_images = al.AdaptImages(galaxy_image_dict={source: adapt})
    mesh_yx = np.column_stack([model.source.image_plane_y, model.source.image_plane_x])
    mesh = [[], [al.Grid2DIrregular(values=mesh_yx)]]
    extra = {"w_tilde": anchor_imaging.w_tilde} if use_w_tilde else {}
    preloads = al.Preloads(use_w_tilde=use_w_tilde, image_plane_mesh_grid_pg_list=mesh, **extra)
    settings = al.SettingsInversion(
        use_w_tilde=use_w_tilde, use_positive_only_solver=True, use_border_relocator=True
    )

    def anchor_fit():
        return al.FitImaging(
            dataset=anchor_imaging,
            tracer=al.Tracer(galaxies=[lens, source]),
            adapt_images=adapt_images,
            settings_inversion=settings,
            preloads=preloads,
        )

    return anchor_fit


def overlay_model(dataset: FitDataset, model) -> LensModel:
    """Configuration A: R with the 34×34 overlay mesh and ConstantSplit(1) regularization,
    whose inputs are pure geometry (no k-means, no adapt image)."""
    x, y = overlay_centres(dataset.mask, PIXEL, (34, 34))
    source = PixelizedSource(x, y, ConstantSplit(1.0))
    return LensModel(mass=model.mass, lens_light=model.lens_light, source=source)


def main() -> None:
    set_threads(2)
    imaging, lensed = mock_imaging()
    dataset = FitDataset.from_imaging(imaging, light_centre=MASS[0].centre)
    # the anchor's uniform 4×4 light over-sampling instead of 16×16 within 0.3″ (SPEC §13)
    uniform = FitDataset.from_imaging(
        imaging, settings=FitSettings(lp_sub_size_centre=4), light_centre=MASS[0].centre
    )
    model = make_model(dataset, lensed[~dataset.mask], 1500)
    anchor_imaging = anchor_imaging_of(imaging)

    report("mgelens_likelihood_R_s", median_time(lambda: fresh_fit(dataset, model)))
    for name, use_w_tilde in (("w_tilde", True), ("mapping_matrix", False)):
        anchor_fit = anchor_fitter(anchor_imaging, model, lensed, use_w_tilde)
        seconds = median_time(lambda f=anchor_fit: f().figure_of_merit, repeats=3)
        report(f"pyautolens_{name}_likelihood_R_s", seconds)
    report_mgelens_terms("mgelens_R", fit(dataset, model))
    report_mgelens_terms("mgelens_uniform_4x4_R", fit(uniform, model))
    anchor = anchor_fit()
    report_anchor_terms("pyautolens_R", anchor)
    # the mapping matrices (border relocation + natural-neighbour weights of every sub-pixel)
    slim = np.full(imaging.shape, -1)
    slim[~dataset.mask] = np.arange(np.sum(~dataset.mask))
    rows = np.flipud(slim)[~np.asarray(anchor_imaging.mask)]  # anchor order → mgelens slim
    ours = pixelized_operator(dataset, model.mass, model.source).mapping.toarray()[rows]
    theirs = np.asarray(anchor.inversion.linear_obj_list[-1].mapping_matrix)
    report("mapping_matrix_max_abs_difference_R", float(np.abs(ours - theirs).max()))

    overlay = overlay_model(uniform, model)
    report_mgelens_terms("mgelens_uniform_4x4_A", fit(uniform, overlay))
    report_anchor_terms("pyautolens_A", anchor_fitter(anchor_imaging, overlay, lensed, False)())


if __name__ == "__main__":
    main()

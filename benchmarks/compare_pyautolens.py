"""Configuration R's log evidence timed in PyAutoLens 2024.5.16 on the same data.

Builds the imaging, k-means image-plane mesh, MGE sets and mass model of
``bench_likelihood.py`` (configuration R) and hands them to PyAutoLens's ``FitImaging``:
the paper-era anchor (SPEC §12.20) with ``VoronoiNN`` natural-neighbour interpolation,
``AdaptiveBrightnessSplit`` regularization, the positive-only solver and 4×4
over-sampling of both the light profiles and the pixelization. The image-plane mesh is
passed as a preload, as a PyAutoLens search does after its first two fits, so neither
code runs k-means inside the timed call. Prints the median time per log evidence of
both codes on the same machine and thread count, and both log evidences.

PyAutoLens is not a dependency of mgelens and needs older numpy/scipy/scikit-learn, so
run this from its own environment (the repository root as working directory)::

    python -m venv /tmp/pal && /tmp/pal/bin/pip install "autolens==2024.5.16.0" "numba<0.60"
    (cd /tmp/pal/lib/python3.11/site-packages/autoarray/util/nn/src/nn &&
     bash ./configure && cp makefile_autolens makefile && make)
    /tmp/pal/bin/pip install --no-deps -e .
    /tmp/pal/bin/python benchmarks/compare_pyautolens.py

The two log evidences are not expected to agree to the digit: the MGE columns are
over-sampled differently (mgelens uses 16×16 within 0.3″ of the centre, SPEC §13) and
PyAutoLens sets its own numerical defaults. They show that both codes fit the same model.
"""

import sys

import numpy as np
from bench_likelihood import MASS, PIXEL, RADIUS, lens_light_sets, make_model, mock_imaging
from common import median_time, report, set_threads

from mgelens.fit import FitDataset, FitSettings, fit, pixelized_operator
from mgelens.geometry import axis_ratio_and_angle_from, ell_comps_from
from mgelens.source.image_mesh import floored_adapt_image

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
    """Lens (2×30 + 10 MGE, EPL + shear) and pixelized source galaxies of configuration R."""
    basis = []
    for mge in lens_light_sets():
        ell = anchor_ell_comps(mge.ell_comps)
        q, _ = axis_ratio_and_angle_from(mge.ell_comps)
        # mgelens σ is the major-axis dispersion; the anchor's `sigma` is the minor one.
        basis += [
            al.lp_linear.Gaussian(centre=yx(mge.centre), ell_comps=ell, sigma=s * np.sqrt(q))
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
    pixelization = al.Pixelization(
        image_mesh=al.image_mesh.KMeans(pixels=1500),
        mesh=al.mesh.VoronoiNN(),
        regularization=al.reg.AdaptiveBrightnessSplit(
            inner_coefficient=regularization.inner_coefficient,
            outer_coefficient=regularization.outer_coefficient,
            signal_scale=regularization.signal_scale,
        ),
    )
    source = al.Galaxy(redshift=1.0, pixelization=pixelization)
    return lens, source


def report_terms(code: str, log_evidence, chi2, reg, log_det_fh, log_det_h) -> None:
    """The log evidence and its terms (SPEC §7) under ``<code>_...`` names, to 1e-3."""
    for term, value in (
        ("log_evidence", log_evidence),
        ("chi2", chi2),
        ("regularization_term", reg),
        ("log_det_curvature_regularization", log_det_fh),
        ("log_det_regularization", log_det_h),
    ):
        print(f"{code}_{term}_R: {value:.3f}")


def main() -> None:
    set_threads(2)
    imaging, lensed = mock_imaging()
    dataset = FitDataset.from_imaging(imaging, light_centre=MASS[0].centre)
    model = make_model(dataset, lensed[~dataset.mask], 1500)
    report("mgelens_likelihood_R_s", median_time(lambda: fit(dataset, model)))
    # the anchor's uniform 4×4 light over-sampling instead of 16×16 within 0.3″ (SPEC §13)
    uniform = FitDataset.from_imaging(
        imaging, settings=FitSettings(lp_sub_size_centre=4), light_centre=MASS[0].centre
    )
    for code, data in (("mgelens", dataset), ("mgelens_uniform_4x4", uniform)):
        r = fit(data, model)
        terms = (r.chi_squared, r.regularization_term, r.log_det_curvature_regularization)
        report_terms(code, r.log_evidence, *terms, r.log_det_regularization)

    mask = al.Mask2D.circular(shape_native=imaging.shape, pixel_scales=PIXEL, radius=RADIUS)
    anchor_imaging = al.Imaging(
        data=anchor_array(imaging.data),
        noise_map=anchor_array(imaging.noise_map),
        psf=al.Kernel2D.no_mask(np.flipud(imaging.psf), pixel_scales=PIXEL),
    ).apply_mask(mask)
    anchor_imaging = anchor_imaging.apply_over_sampling(
        over_sampling=al.OverSamplingUniform(sub_size=4),
        over_sampling_pixelization=al.OverSamplingUniform(sub_size=4),
    )
    lens, source = anchor_galaxies(model.source.regularization)
    source_x, source_y = model.source.image_plane_x, model.source.image_plane_y
    # The anchor's analysis floors adapt images before a fit (SPEC §12.11); mgelens's
    # regularization does the same inside.
    floored = floored_adapt_image(np.flipud(lensed)[~mask])
    adapt = al.Array2D(values=floored, mask=mask)
    adapt_images = al.AdaptImages(galaxy_image_dict={source: adapt})
    mesh = [[], [al.Grid2DIrregular(values=np.column_stack([source_y, source_x]))]]
    for name, use_w_tilde in (("w_tilde", True), ("mapping_matrix", False)):
        # A search preloads the image-plane mesh and, for the w-tilde formalism, w-tilde.
        extra = {"w_tilde": anchor_imaging.w_tilde} if use_w_tilde else {}
        preloads = al.Preloads(use_w_tilde=use_w_tilde, image_plane_mesh_grid_pg_list=mesh, **extra)
        settings = al.SettingsInversion(
            use_w_tilde=use_w_tilde, use_positive_only_solver=True, use_border_relocator=True
        )

        def anchor_fit(settings=settings, preloads=preloads):
            return al.FitImaging(
                dataset=anchor_imaging,
                tracer=al.Tracer(galaxies=[lens, source]),
                adapt_images=adapt_images,
                settings_inversion=settings,
                preloads=preloads,
            )

        report(
            f"pyautolens_{name}_likelihood_R_s",
            median_time(lambda f=anchor_fit: f().figure_of_merit, repeats=3),
        )
    anchor = anchor_fit()
    inversion = anchor.inversion
    report_terms(
        "pyautolens",
        anchor.figure_of_merit,
        anchor.chi_squared,
        inversion.regularization_term,
        inversion.log_det_curvature_reg_matrix_term,
        inversion.log_det_regularization_matrix_term,
    )
    # the mapping matrices (border relocation + natural-neighbour weights of every sub-pixel)
    slim = np.full(imaging.shape, -1)
    slim[~dataset.mask] = np.arange(np.sum(~dataset.mask))
    rows = np.flipud(slim)[~np.asarray(mask)]  # anchor pixel order → mgelens slim index
    ours = pixelized_operator(dataset, model.mass, model.source).mapping.toarray()[rows]
    theirs = np.asarray(inversion.linear_obj_list[-1].mapping_matrix)
    report("mapping_matrix_max_abs_difference", float(np.abs(ours - theirs).max()))


if __name__ == "__main__":
    main()

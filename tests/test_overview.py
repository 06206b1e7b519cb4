"""Per-lens overview figure (the paper's Fig. 1): critical curves where theory puts them,
orientation, residual scale, contaminant pixels, MGE-set legend and the command end to
end on a capped SP → SPix1 run of a small mock with contaminants."""

import io
import json
from dataclasses import replace

import numpy as np
import pytest
from astropy.io import fits
from matplotlib import colors
from scipy.spatial import Voronoi
from test_pipeline import small_mock

from mgelens.cli import main
from mgelens.fit import fit
from mgelens.geometry import ell_comps_from, to_profile_frame
from mgelens.grid import pixel_centres
from mgelens.imaging import Imaging
from mgelens.light import MGESet, Sersic
from mgelens.mask import circular
from mgelens.mass import SIE
from mgelens.overview import (
    MIN_SOURCE_HALF_WIDTH,
    SOURCE_ZOOM_FRACTION,
    SOURCE_ZOOM_MARGIN,
    LightComponent,
    Overview,
    SourcePlane,
    contaminant_pixels,
    critical_lines,
    light_component,
    off_support_cells,
    overview_from_fit,
    source_window,
    voronoi_edges,
)
from mgelens.pipeline import run
from mgelens.pipeline.products import source_plane_image
from mgelens.pipeline.settings import LensSpec, settings_from_mapping
from mgelens.plot.overview import (
    CONTOUR_RANGE,
    RESIDUAL_LIMIT,
    contour_levels,
    image_extent,
    overview_figure,
)
from mgelens.search.results import PhaseResult
from mgelens.source.mesh import VoronoiMesh

PIXEL = 0.1
MASK_RADIUS = 1.4
LENS = LensSpec(mask_radius=MASK_RADIUS)
SENTINEL = 1e8


def panel(figure, title: str):
    """The axes of ``figure`` whose title starts with ``title``."""
    (ax,) = [ax for ax in figure.axes if ax.get_title().startswith(title)]
    return ax


def synthetic_overview(**changes) -> Overview:
    """A 21×21 overview at 0.1″ with a bright blob at (+0.5″, +0.3″) in every image."""
    x, y = pixel_centres((21, 21), PIXEL)
    blob = np.exp(-((x - 0.5) ** 2 + (y - 0.3) ** 2) / (2 * 0.1**2))
    fields = dict(
        title="test",
        pixel_scale=PIXEL,
        unit="electron/s",
        data=blob + 0.01,
        noise_map=np.full(x.shape, 0.01),
        lens_light=blob + 0.01,
        lensed_source=blob,
        normalized_residuals=3.0 * blob,
        contaminants=np.zeros(x.shape, dtype=bool),
        mask_centre=(0.0, 0.0),
        mask_radius=1.0,
        source=SourcePlane(blob, image_extent(blob.shape, PIXEL)),
        critical_curve=None,
        caustic=None,
        components=(LightComponent("set 0", (0.0, 0.0), 0.8, 30.0, 0.3),),
    )
    return Overview(**{**fields, **changes})


# -- critical curves --------------------------------------------------------------------
def test_sis_critical_curve_is_the_einstein_circle_and_is_drawn_there():
    curve, caustic = critical_lines([SIE((0.0, 0.0), 1.2, 1.0, 0.0)])
    assert np.hypot(*curve) == pytest.approx(1.2, abs=0.01)
    assert np.hypot(*caustic).max() < 0.02  # the SIS caustic is a point
    figure = overview_figure(synthetic_overview(critical_curve=curve, caustic=caustic))
    (line,) = [
        ln for ln in panel(figure, "lensed source").lines if ln.get_label() == "critical curve"
    ]
    np.testing.assert_array_equal(line.get_xydata(), np.column_stack(curve))
    (drawn,) = [ln for ln in panel(figure, "source").lines if ln.get_label() == "caustic"]
    np.testing.assert_array_equal(drawn.get_xydata(), np.column_stack(caustic))


def test_sie_critical_curve_is_its_half_convergence_ellipse():
    """For an isothermal lens |γ| = κ, so λ_t = 1 − 2κ: the tangential critical curve is
    the κ = ½ ellipse η = 2θ_E/(1 + q) along the mass's angle."""
    q, angle, theta_e = 0.7, 30.0, 1.2
    (x, y), _ = critical_lines([SIE((0.1, -0.05), theta_e, q, angle)])
    xp, yp = to_profile_frame(x, y, (0.1, -0.05), angle)
    np.testing.assert_allclose(np.hypot(xp, yp / q), 2 * theta_e / (1 + q), atol=0.01)


def test_a_mass_without_critical_curve_gives_none_and_a_note(caplog):
    """SP of slacs1020+1122 found θ_E = 5.3″, q = 0.03: no closed curve within ±3″."""
    assert critical_lines([SIE((0.0, 0.0), 5.0, 1.0, 0.0)]) == (None, None)
    assert "no critical curve drawn" in caplog.text
    figure = overview_figure(synthetic_overview())
    for title, label in (("lensed source", "critical curve"), ("source", "caustic")):
        (note,) = panel(figure, title).texts
        assert note.get_text().startswith(f"no {label}: no closed")


# -- figure conventions ----------------------------------------------------------------
def test_a_blob_at_plus_x_plus_y_is_drawn_in_the_upper_right():
    figure = overview_figure(synthetic_overview())
    for title in ("data", "lens light", "lensed source", "normalised residuals", "source"):
        ax = panel(figure, title)
        image = ax.images[0]
        assert image.origin == "lower"
        left, right, bottom, top = image.get_extent()
        assert left < right
        assert bottom < top
        assert ax.get_xlim()[0] < ax.get_xlim()[1]
        assert ax.get_ylim()[0] < ax.get_ylim()[1]
        array = np.asarray(image.get_array())
        row, col = np.unravel_index(np.argmax(array), array.shape)
        x = left + (col + 0.5) * (right - left) / array.shape[1]
        y = bottom + (row + 0.5) * (top - bottom) / array.shape[0]
        assert (x, y) == (pytest.approx(0.5), pytest.approx(0.3)), title
        display = ax.transData.transform((x, y))
        centre = ax.transAxes.transform((0.5, 0.5))
        assert display[0] > centre[0], title
        assert display[1] > centre[1], title


def test_image_extent_is_the_pixel_edges_of_the_grid():
    assert image_extent((21, 31), 0.1) == pytest.approx((-1.55, 1.55, -1.05, 1.05))


def test_residuals_on_a_fixed_plus_minus_3_5_scale_and_units_on_every_colour_bar():
    figure = overview_figure(synthetic_overview())
    image = panel(figure, "normalised residuals").images[0]
    assert (image.norm.vmin, image.norm.vmax) == (-RESIDUAL_LIMIT, RESIDUAL_LIMIT) == (-3.5, 3.5)
    labels = {ax.get_ylabel() for ax in figure.axes if ax.get_label() == "<colorbar>"}
    assert labels == {"σ", "electron/s per pixel"}
    assert isinstance(panel(figure, "data").images[0].norm, colors.AsinhNorm)


def test_contaminants_are_the_ignored_pixels_inside_the_fit_circle():
    shape = (21, 21)
    noise = np.ones(shape)
    noise[10, 12] = noise[2, 2] = SENTINEL  # inside the circle / in the corner, outside it
    excluded = circular(shape, PIXEL, 0.8)
    excluded[10, 8] = True  # mask.fits pixel inside the circle
    imaging = Imaging(np.zeros(shape), noise, np.ones((1, 1)), PIXEL)
    found = contaminant_pixels(imaging, excluded, 0.8)
    assert sorted(zip(*np.nonzero(found), strict=True)) == [(10, 8), (10, 12)]
    figure = overview_figure(synthetic_overview(contaminants=found))
    for title in ("data", "normalised residuals"):
        (layer,) = [im for im in panel(figure, title).images if im.get_gid() == "contaminants"]
        shown = ~np.ma.getmaskarray(layer.get_array())
        np.testing.assert_array_equal(shown, found)


def test_lens_light_contours_are_log_spaced_below_the_peak():
    overview = synthetic_overview()
    levels = contour_levels(overview.lens_light)
    ratios = levels[1:] / levels[:-1]
    np.testing.assert_allclose(ratios, ratios[0])
    assert levels[-1] < overview.lens_light.max()
    assert levels[0] >= CONTOUR_RANGE * overview.lens_light.max()
    (lines,) = panel(overview_figure(overview), "lens-light contours").collections
    np.testing.assert_allclose(lines.levels, levels)


def test_a_fit_without_light_still_draws():
    """A capped fit can zero every lens-light and source intensity."""
    zero = np.zeros((21, 21))
    overview = synthetic_overview(
        lens_light=zero, lensed_source=zero, source=SourcePlane(zero, image_extent(zero.shape, 0.1))
    )
    figure = overview_figure(overview)
    figure.savefig(io.BytesIO(), format="png", dpi=30)
    assert contour_levels(zero).size == 0
    assert "no positive lens light" in [t.get_text() for t in panel(figure, "lens-light").texts]


def test_voronoi_edges_are_scipys_finite_ridges():
    rng = np.random.default_rng(2)
    points = rng.uniform(-1, 1, (40, 2))
    edges = voronoi_edges(VoronoiMesh.from_points(*points.T))
    reference = Voronoi(points)
    finite = [r for r in reference.ridge_vertices if -1 not in r]
    assert len(edges) == len(finite)
    ours = {tuple(np.round(np.sort(e, axis=0).ravel(), 8)) for e in edges}
    theirs = {tuple(np.round(np.sort(reference.vertices[r], axis=0).ravel(), 8)) for r in finite}
    assert ours == theirs


def test_component_geometry_of_a_set_and_a_sersic():
    q, angle = 0.6, 125.0
    mge = MGESet((0.1, 0.2), ell_comps_from(q, angle), np.array([0.05, 0.2, 0.8]))
    one = light_component("set_1", mge, np.array([0.0, 3.0, 0.0]))
    assert (one.label, one.axis_ratio, one.angle) == (
        "set 1",
        pytest.approx(q),
        pytest.approx(angle),
    )
    assert one.semi_major == pytest.approx(0.2 / q)  # the one lit Gaussian's major-axis σ
    assert light_component("set_0", mge, np.zeros(3)).semi_major == 0.0
    assert light_component("point", mge, np.ones(3)).point
    sersic = light_component("sersic_2", Sersic((0, 0), ell_comps_from(q, angle), 0.9, 4.0), [1])
    assert sersic.label == "Sérsic 2"
    assert sersic.semi_major == pytest.approx(0.9 / np.sqrt(q))


def source_grid(n: int = 151, half: float = 1.5):
    """Pixel-centre coordinates (X, Y) of an n × n source grid over ±``half`` arcsec
    (row index increasing with +y) and its extent."""
    x = -half + (np.arange(n) + 0.5) * 2.0 * half / n
    return *np.meshgrid(x, x), (-half, half, -half, half)


def test_source_window_zooms_on_a_compact_source():
    X, Y, extent = source_grid()
    image = np.exp(-((X - 0.4) ** 2 + (Y + 0.2) ** 2) / (2 * 0.03**2))
    image[np.hypot(X, Y) > 1.4] = np.nan  # outside a mesh's hull
    (cx, cy), half_width = source_window(image, extent)
    assert abs(cx - 0.4) < 0.02
    assert abs(cy + 0.2) < 0.02
    # the 5 % contour (radius 0.03 √(2 ln 20) = 0.073″) is narrower than the minimum
    assert half_width == MIN_SOURCE_HALF_WIDTH
    bright = image >= SOURCE_ZOOM_FRACTION * np.nanmax(image)
    assert np.all(np.abs(X[bright] - cx) < half_width)
    assert np.all(np.abs(Y[bright] - cy) < half_width)


def test_source_window_holds_the_caustic_with_its_margin():
    X, Y, extent = source_grid()
    image = np.exp(-((X - 0.4) ** 2 + (Y + 0.2) ** 2) / (2 * 0.03**2))
    angle = np.linspace(0.0, 2 * np.pi, 200)
    caustic = (0.3 * np.cos(angle), 0.3 * np.sin(angle))
    (cx, cy), half_width = source_window(image, extent, caustic)
    bright = image >= SOURCE_ZOOM_FRACTION * image.max()
    xs = np.concatenate([X[bright], caustic[0]])
    ys = np.concatenate([Y[bright], caustic[1]])
    side = max(np.ptp(xs), np.ptp(ys))
    assert half_width == pytest.approx((0.5 + SOURCE_ZOOM_MARGIN) * side)
    assert cx == pytest.approx(0.5 * (xs.min() + xs.max()))
    assert cy == pytest.approx(0.5 * (ys.min() + ys.max()))
    for values, middle in ((xs, cx), (ys, cy)):
        assert np.all(np.abs(values - middle) <= half_width - SOURCE_ZOOM_MARGIN * side + 1e-12)


def test_source_window_keeps_an_extended_or_empty_source_whole():
    X, Y, extent = source_grid()
    assert source_window(np.exp(-(X**2 + Y**2) / (2 * 1.0**2)), extent) is None
    assert source_window(np.zeros_like(X), extent) is None
    assert source_window(np.full_like(X, np.nan), extent) is None


@pytest.mark.parametrize("phase", ["sp", "spix1"])
def test_a_zoomed_source_image_samples_the_same_source(capped_run, mock_dir, phase):
    """A window a third of the grid's width about one of its pixel centres: every third
    zoomed pixel centre is a pixel centre of the whole grid, and the two images agree
    there (an MGE source in SP, the Voronoi reconstruction in SPix1)."""
    fitted, _ = rebuilt(capped_run, phase, mock_dir)
    full, pixel, centre = source_plane_image(fitted, shape=(31, 31))
    row, col = 17, 14
    window = ((centre[0] + (col - 15) * pixel, centre[1] + (row - 15) * pixel), pixel * 31 / 6)
    zoomed, zoomed_pixel, zoomed_centre = source_plane_image(fitted, (31, 31), window)
    assert zoomed_pixel == pytest.approx(pixel / 3)
    assert zoomed_centre == pytest.approx(window[0])
    coincident = full[row - 5 : row + 6, col - 5 : col + 6]
    assert np.count_nonzero(coincident) > 60
    np.testing.assert_allclose(
        zoomed[0::3, 0::3], coincident, rtol=1e-9, atol=1e-12 * np.abs(full).max()
    )


def test_off_support_cells_are_the_nearest_mesh_points_off_the_support():
    """Every grid point takes the support flag of its Voronoi cell: checked against the
    brute-force nearest mesh point."""
    rng = np.random.default_rng(4)
    mesh = VoronoiMesh.from_points(*rng.uniform(-1.0, 1.0, (60, 2)).T)
    support = rng.random(60) < 0.5
    off = off_support_cells((41, 37), 0.05, (0.1, -0.05), mesh, support)
    x, y = pixel_centres((41, 37), 0.05, (0.1, -0.05))
    distance = np.hypot(x[..., None] - mesh.points[:, 0], y[..., None] - mesh.points[:, 1])
    np.testing.assert_array_equal(off, ~support[np.argmin(distance, axis=-1)])
    assert 0 < off.sum() < off.size


def test_cells_off_the_support_are_veiled_and_named_in_the_legend():
    blob = synthetic_overview().source.image
    off = np.zeros(blob.shape, dtype=bool)
    off[:, :5] = True
    veiled = synthetic_overview(
        source=SourcePlane(blob, image_extent(blob.shape, PIXEL), None, off)
    )
    ax = panel(overview_figure(veiled), "source")
    (layer,) = [im for im in ax.get_images() if im.get_gid() == "off_support"]
    np.testing.assert_array_equal(~np.ma.getmaskarray(layer.get_array()), off)
    assert [t.get_text() for t in ax.get_legend().get_texts()] == [
        "held at zero (off the arcs' support)"
    ]
    plain = panel(overview_figure(synthetic_overview()), "source")
    assert [im.get_gid() for im in plain.get_images()] == [None]


# -- end to end on a capped SP -> SPix1 run ---------------------------------------------
@pytest.fixture(scope="module")
def mock_dir(tmp_path_factory):
    """tests/test_pipeline.py's 31×31 M1-like mock at 0.1″ (noise ×100), with a contaminant:
    a bright 3×3 blob at (−0.7″, +0.5″) whose noise is the SLACS sentinel, and one pixel at
    (+0.5″, −0.5″) excluded by mask.fits."""
    data, noise, imaging = small_mock()
    data[19:22, 7:10] += 50.0
    noise[19:22, 7:10] = SENTINEL
    mask = np.zeros(noise.shape, dtype=bool)
    mask[10, 20] = True
    folder = tmp_path_factory.mktemp("mock")
    Imaging(data, noise, imaging.psf, PIXEL, mask=mask, unit=imaging.unit).to_fits(folder)
    return folder


@pytest.fixture(scope="module")
def capped_run(mock_dir, tmp_path_factory):
    """SP (2 MGE sets, MGE source) and SPix1 (overlay Voronoi mesh), samplers capped."""
    capped = {"method": "dynesty_static", "progress_every": 1e9}
    settings = settings_from_mapping(
        {
            "fit": {"lp_sub_size_centre": 4},
            "overlay_shape": [8, 8],
            "allow_unconverged": True,
            "samplers": {
                "sp": {**capped, "n_live": 36, "max_iterations": 40},
                "spix1": {**capped, "n_live": 18, "max_iterations": 15},
            },
        }
    )
    results = tmp_path_factory.mktemp("results")
    for phase in ("sp", "spix1"):
        run.run_phase(phase, mock_dir, results, settings, LENS, seed=2, threads=1)
    return results


def rebuilt(results, phase, mock_dir):
    result_record = PhaseResult.read(results / phase)
    problem, values = run.max_likelihood_problem(result_record, mock_dir, results)
    fitted = fit(problem.dataset, problem.model.build(values))
    names = [spec.name for spec in problem.model.lens_light]
    return fitted, overview_from_fit(fitted, names, problem.mask_radius, lens="M", phase=phase)


def test_sp_overview_legend_matches_the_fit_record(capped_run, mock_dir):
    fitted, overview = rebuilt(capped_run, "sp", mock_dir)
    record = json.loads((capped_run / "sp" / "result.json").read_text())["max_likelihood_fit"]
    figure = overview_figure(overview)
    legend = [t.get_text() for t in panel(figure, "lens-light contours").get_legend().get_texts()]
    expected = [
        f"set {k}: q={c['axis_ratio']:.2f}, PA={c['angle']:.0f}°"
        for k, c in enumerate(record["lens_light"]["components"])
    ]
    assert [text.removesuffix(" (no flux)") for text in legend] == expected
    assert overview.source.mesh_edges is None  # MGE source: no mesh
    assert len(panel(figure, "source (MGE)").collections) == 0
    chi2_n = fitted.chi_squared / np.count_nonzero(fitted.dataset.noise_map < 1e3)
    assert figure.get_suptitle() == (
        f"M · sp: ln L = {record['log_evidence']:.2f}, χ²/N = {chi2_n:.3f} "
        f"(N = {np.count_nonzero(fitted.dataset.noise_map < 1e3)})"
    )


def test_overview_command_on_a_pixelized_phase(capped_run, mock_dir, tmp_path):
    fitted, overview = rebuilt(capped_run, "spix1", mock_dir)
    expected = np.zeros(overview.data.shape, dtype=bool)
    expected[19:22, 7:10] = True
    expected[10, 20] = True
    np.testing.assert_array_equal(overview.contaminants, expected)
    assert len(overview.source.mesh_edges) > 64
    written = fits.getdata(capped_run / "spix1" / "model.fits", extname="SRCPLANE")
    image = overview.source.image
    blank = np.isnan(image)
    assert 0 < blank.sum() < image.size / 2  # outside the mesh's hull
    np.testing.assert_allclose(image[~blank], written[~blank], rtol=1e-9, atol=1e-12)
    assert np.all(written[blank] == 0.0)
    assert np.isnan(overview.normalized_residuals[fitted.dataset.mask]).all()
    out = tmp_path / "figures" / "overview.png"
    arguments = ["overview", "--phase", str(capped_run / "spix1"), "--lens-dir", str(mock_dir)]
    assert main([*arguments, "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in out.parent.iterdir()] == ["overview.png"]  # no temporary left


def test_an_arcs_support_veils_the_unsolved_cells_of_the_overview(capped_run, mock_dir):
    """SPix1's fit again with the source solved only where its three brightest lensed pixels
    reach: the veiled grid points are those whose cell the fit held at zero."""
    fitted, _ = rebuilt(capped_run, "spix1", mock_dir)
    lensed = fitted.lensed_source_image
    arcs = lensed >= np.sort(lensed)[-3]  # its three brightest pixels
    model = replace(fitted.model, source=replace(fitted.model.source, arc_pixels=arcs))
    supported = fit(fitted.dataset, model)
    support = supported.source.support
    assert 0 < support.sum() < support.size
    problem, _ = run.max_likelihood_problem(
        PhaseResult.read(capped_run / "spix1"), mock_dir, capped_run
    )
    names = [spec.name for spec in problem.model.lens_light]
    overview = overview_from_fit(supported, names, MASK_RADIUS)
    source = overview.source
    inside = np.isfinite(source.image)
    assert source.off_support[inside].any()
    assert (~source.off_support[inside]).any()
    x_min, x_max, y_min, y_max = source.extent
    pixel = (x_max - x_min) / source.image.shape[1]
    x, y = pixel_centres(source.image.shape, pixel, (0.5 * (x_min + x_max), 0.5 * (y_min + y_max)))
    points = supported.source.mesh.points
    nearest = np.argmin(np.hypot(x[..., None] - points[:, 0], y[..., None] - points[:, 1]), -1)
    fluxes = supported.source.fluxes
    assert np.all(fluxes[nearest[inside & source.off_support]] == 0.0)  # held at zero
    assert np.all(support[nearest[inside & ~source.off_support]])


def test_bad_phase_gives_a_one_line_error(mock_dir, capped_run, tmp_path, caplog):
    out = tmp_path / "overview.png"
    missing = tmp_path / "nowhere"
    arguments = ["overview", "--phase", str(missing), "--lens-dir", str(mock_dir)]
    assert main([*arguments, "--out", str(out)]) == 1
    (message,) = [r.getMessage() for r in caplog.records if r.levelname == "ERROR"]
    assert "\n" not in message
    assert f"{missing / 'result.json'} not found" in message
    assert "results/<lens>/mass" in message
    caplog.clear()
    arguments = ["overview", "--phase", str(capped_run / "sp"), "--lens-dir", str(missing)]
    assert main([*arguments, "--out", str(out)]) == 1
    (message,) = [r.getMessage() for r in caplog.records if r.levelname == "ERROR"]
    assert "\n" not in message
    assert str(missing) in message
    assert not out.exists()

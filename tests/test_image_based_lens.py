"""Image-based lens model (Heidrich et al.) preprocessing: backward trace = forward trace
reversed, COP fit of rays through a known point, single projection for a small field, subdivision
below the threshold, bad inputs."""
from __future__ import annotations

import os
import warnings

import numpy as np
import pytest

from clpost.errors import InputError
from clpost.optics import get_lens
from clpost.optics.trace import trace
from clpost.render.image_based_lens import angle_errors_deg, build, fit_cop, mirrored_table, trace_back


def test_backward_trace_retraced_forward_returns_to_the_film_point():
    lens = get_lens("thorlabs-ac254-050-a")
    pres = lens.focused(3000.0, 8.0)
    table, zf = mirrored_table(pres, lens.stop_radius_mm(8.0))
    film = np.array([[0.0, 0.0], [1.5, -0.7], [-2.0, 1.0]])
    q, d, ok = trace_back(table, zf, film, np.array([0.3, -0.2, lens.paraxial.z_exit_pupil_mm]))
    assert ok.all()
    fwd = trace(pres, q, -d, stop_radius_mm=lens.stop_radius_mm(8.0))
    assert fwd.ok.all()
    err = np.abs(fwd.pos[:, :2] - film).max()
    assert err < 1e-9, f"max {err} mm"


def test_cop_fit_recovers_the_common_point_of_exact_pinhole_rays(rng):
    e_true = np.array([0.4, -0.3, 2.0])
    d = rng.normal(size=(40, 3)) * [0.2, 0.2, 0.0] + [0, 0, -1.0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    q = e_true + rng.uniform(3, 9, (40, 1)) * d
    e = fit_cop(q, d, np.zeros(3))
    assert np.linalg.norm(e - e_true) < 1e-6
    assert angle_errors_deg(q, d, e).max() < 1e-5  # arccos resolves ~1e-6° near cos = 1


@pytest.mark.parametrize("lens", ["thorlabs-ac254-050-a", "thorlabs-lb1471"])
def test_small_field_is_one_projection_per_sample_and_wide_field_is_subdivided_below_threshold(lens):
    warnings.simplefilter("ignore")
    small = build(lens, 3.0, 8.0, sensor_mm=(4.0, 4.0), pupil_n=2)
    assert small.projections_per_sample().tolist() == [1, 1, 1, 1]
    assert small.max_angle_deg < 0.05
    wide = build(lens, 3.0, 8.0, sensor_mm=(12.0, 8.0), pupil_n=2, threshold_deg=0.05)
    assert wide.projections_per_sample().max() > 1
    assert wide.max_angle_deg < 0.05
    one = build(lens, 3.0, 8.0, sensor_mm=(12.0, 8.0), pupil_n=2, threshold_deg=0.05, max_depth=0)
    assert one.max_angle_deg > 0.05  # without subdivision the error is above the threshold
    for p in wide.projections:
        assert np.all(np.isfinite(p.tex)) and np.all(p.weight >= 0) and p.weight.max() > 0


@pytest.mark.parametrize("kw, word", [(dict(lens="nope"), "lens_data"), (dict(grid=1), "grid"),
                                      (dict(pupil_n=0), "pupil_n"), (dict(threshold_deg=0.0), "threshold_deg"),
                                      (dict(pupil_pattern="hex"), "pupil_pattern"),
                                      (dict(sensor_mm=(36.0, -1.0)), "sensor_mm")])
def test_bad_inputs_name_the_fix(kw, word):
    args = dict(lens="thorlabs-lb1471", focus_distance_m=3.0, f_number=8.0)
    args.update(kw)
    with pytest.raises(InputError, match=word):
        build(**args)


# -- rendering (sec. 3.5) ----------------------------------------------------------------------

from clpost.render.image_based_lens import (WarpCell, Warper, pixel_to_film, render_image_based,  # noqa: E402
                                            warp_cells, warp_reference)


def _random_cell(rng, size, box, src_size, g=(7, 5)):
    i0, i1, j0, j1 = box
    nodes = np.zeros((g[1], g[0], 4))
    sw, sh = src_size
    # texture coordinates that overshoot the render on purpose (the clamp), weights with zeros
    nodes[..., 0] = rng.uniform(-3, sw + 2, (g[1], g[0]))
    nodes[..., 1] = rng.uniform(-3, sh + 2, (g[1], g[0]))
    nodes[..., 2] = np.where(rng.random((g[1], g[0])) < 0.25, 0.0, rng.uniform(0, 5, (g[1], g[0])))
    step = ((i1 - i0) / (g[0] - 1) * 1.03, (j1 - j0) / (g[1] - 1) * 1.03)
    return WarpCell(0, box, nodes, (i0 - 0.4, j0 - 0.3), step, src_size, 1.0, (0.0, 0.0), np.zeros(3))


def test_warp_kernel_matches_the_float64_reference_on_odd_sizes(rng):
    size = (37, 23)
    warper = Warper(size)
    ref = np.zeros((23, 37, 3))
    for box, src_size in (((0, 20, 0, 11), (13, 9)), ((20, 37, 0, 11), (29, 17)), ((0, 37, 11, 23), (41, 3))):
        src = rng.uniform(0, 10, (src_size[1], src_size[0], 3)).astype(np.float32)
        src[0, 0] = 1e6  # a hot texel at the clamped corner
        cell = _random_cell(rng, size, box, src_size)
        warper.add(src, cell)
        warp_reference(ref, src, cell)
    out = warper.result()
    assert out.dtype == np.float32 and np.all(np.isfinite(out))
    err = np.abs(out - ref) / np.maximum(np.abs(ref), 1.0)
    at = np.unravel_index(int(err.argmax()), err.shape)
    assert err.max() < 2e-4, f"max relative error {err.max():.3g} at (y, x, c) = {at}"
    assert np.count_nonzero(out) > 0.5 * out.size


def _const(cop, f, c, size):
    return np.ones((size[1], size[0], 3))


@pytest.mark.parametrize("lens", ["thorlabs-ac254-050-a", "thorlabs-lb1471"])
def test_uniform_white_scene_gives_the_relative_illumination_of_the_pupil_samples(lens):
    """Weights: a unit-radiance scene gives Σ_i W_i(x') / Σ_i W_i(0) — 1 on the axis and the
    exact exit-pupil integral of the samples elsewhere (independent closed form per pixel), and
    within the pupil-sampling error of the traced relative-illumination curve."""
    warnings.simplefilter("ignore")
    model = build(lens, 3.0, 4.0, sensor_mm=(12.0, 8.0), pupil_n=3, threshold_deg=0.5)
    size = (61, 41)
    img, stats = render_image_based(model, size, _const)
    assert stats["projections"] == len(model.projections)
    assert np.allclose(img[..., 0], img[..., 2])
    xs, ys = pixel_to_film(np.arange(61), np.arange(41), size, 12.0)
    assert abs(img[20, 30, 0] - 1.0) < 1e-3  # the axis (pixel centre 30, 20 is film 0, 0)
    # closed form at a few pixels: sum over samples of cos²/d² for passing rays
    lens_ = get_lens(lens)
    pres = lens_.focused(3000.0, model.f_number)
    table, zf = mirrored_table(pres, lens_.stop_radius_mm(model.f_number))
    axial = sum((p[2] - zf) ** 2 / (p[0] ** 2 + p[1] ** 2 + (p[2] - zf) ** 2) ** 2 for p in model.pupil_samples_mm)
    for j, i in ((0, 0), (40, 60), (5, 47), (33, 12)):
        film = np.array([[xs[i], ys[j]]])
        tot = 0.0
        for p in model.pupil_samples_mm:
            if trace_back(table, zf, film, p)[2][0]:
                dz = p[2] - zf
                d2 = (p[0] - film[0, 0]) ** 2 + (p[1] - film[0, 1]) ** 2 + dz * dz
                tot += dz * dz / d2 / d2
        assert abs(img[j, i, 0] - tot / axial) < 2e-3, (i, j, img[j, i, 0], tot / axial)
    # against the traced RI curve (the pupil area that passes × cos factors, optics.curves)
    from clpost.camera import Camera

    ri = Camera(lens=lens, f_number=model.f_number, focus_scale_m=3.0, sensor_mm=(12.0, 8.0)).lens_curves()
    r = np.hypot(xs[None, :], ys[:, None])
    curve = ri.at("relative_illumination", r)
    assert curve.min() < 0.96  # the corner falls off: the comparison can fail
    assert np.abs(img[..., 0] - curve).max() < 0.03


def test_single_projection_doublet_renders_an_in_focus_plane_like_the_pinhole():
    """The achromat at f/8 over a 4×4 mm film is one projection per pupil sample (the paper's
    case); a fronto-parallel checker plane at the focus distance then images as the pinhole image
    at the lens's magnification, sharp, with the small field's cos⁴ fall-off."""
    from clpost.camera import Camera
    from clpost.render.demo_scene import DemoScene, Material, Plane, RigidMotion, SceneObject, rotation
    from clpost.render.image_based_lens import pyvista_render_fn
    from clpost.render.pyvista_renderer import PyVistaRenderer

    warnings.simplefilter("ignore")
    lens = get_lens("thorlabs-ac254-050-a")
    model = build("thorlabs-ac254-050-a", 3.0, 8.0, sensor_mm=(4.0, 4.0), pupil_n=2)
    assert model.projections_per_sample().tolist() == [1, 1, 1, 1]
    face = tuple(tuple(r) for r in rotation((1.0, 0.0, 0.0), np.pi / 2))
    z_e = lens.paraxial.z_entrance_pupil_mm
    zf = float(lens.focused(3000.0, 8.0).vertex_z[-1] + lens.focused(3000.0, 8.0).surfaces[-1].thickness_mm)
    depth = 3.0 - (zf - z_e) / 1000.0  # the focus plane, 3 m from the film, from the entrance pupil
    scene = DemoScene(objects=(SceneObject("plane", Plane(1.0), Material(albedo=(0.9, 0.9, 0.9), albedo2=(0.1, 0.1, 0.1),
                                                                          texture="checker", texture_scale_m=0.04),
                                           RigidMotion(position_m=(0.013, depth, 1.0), base_rotation=face)),),
                      camera_motion=RigidMotion.camera((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
                      sun_irradiance=0.0, ambient=2.0, emitter_lighting=False)
    size = (45, 45)
    r = PyVistaRenderer(scene)
    try:
        img, _ = render_image_based(model, size, pyvista_render_fn(r), supersample=2.0)
        # magnification of the focus plane: trace the chief ray of a film point back to the plane
        pres = lens.focused(3000.0, 8.0)
        table, zf2 = mirrored_table(pres, lens.stop_radius_mm(8.0))
        q, d, ok = trace_back(table, zf2, np.array([[1.0, 0.0]]), np.array([0.0, 0.0, lens.paraxial.z_exit_pupil_mm]))
        t = (zf2 - 3000.0 - q[0, 2]) / d[0, 2]
        m = 1.0 / abs(q[0, 0] + t * d[0, 0])  # film mm per object mm
        f_px = m * depth * 1000.0 / (4.0 / 45)
        cam = Camera(lens="thin:50", f_number=8.0, focus_distance_m=3.0, sensor_mm=(4.0, 4.0))
        pin = r.render(cam, size, 0, intrinsics=(f_px, f_px, 22.0, 22.0)).color
    finally:
        r.close()
    xs, ys = pixel_to_film(np.arange(45), np.arange(45), size, 4.0)
    rr = np.hypot(xs[None, :], ys[:, None])
    v = lens.focus(3000.0, 8.0).image_distance_mm
    expect = pin * ((1 + (rr / v) ** 2) ** -2)[..., None]
    err = np.abs(img - expect).mean(-1) / expect.mean()
    at = np.unravel_index(int(err.argmax()), err.shape)
    if os.environ.get("CLPOST_TEST_IMAGES"):
        np.save(os.environ["CLPOST_TEST_IMAGES"] + "/plane.npy", np.stack([img, expect]))
    # tolerance: 4.5 % mean (|Δ| / mean level); the residue sits on the checker edges (bilinear
    # resampling of the 2× renders against the aliased pinhole: 0.037 measured, best at zero
    # sub-pixel shift, 0.056 at 0.2 px); a one-pixel misregistration costs more than twice as
    # much, so the test sees geometry errors
    assert err.mean() < 0.045 and err.max() < 0.45, f"mean {err.mean():.3f}, max {err.max():.3f} at {at}"
    shifted = np.abs(img[:, 1:] - expect[:, :-1]).mean(-1) / expect.mean()
    assert shifted.mean() > 2 * err.mean()


def test_rendering_bad_inputs_name_the_fix():
    warnings.simplefilter("ignore")
    model = build("thorlabs-lb1471", 3.0, 8.0, sensor_mm=(4.0, 4.0), pupil_n=1)
    with pytest.raises(InputError, match="size"):
        render_image_based(model, (1, 5), _const)
    with pytest.raises(InputError, match="node_spacing_px"):
        warp_cells(model, (20, 20), node_spacing_px=0.0)
    with pytest.raises(InputError, match="supersample"):
        warp_cells(model, (20, 20), supersample=100.0)
    with pytest.raises(InputError, match="render_fn"):
        render_image_based(model, (20, 20), lambda cop, f, c, s: np.ones((3, 3, 3)))
    from clpost.camera import Camera
    from clpost.render.image_based_lens import model_for_camera

    with pytest.raises(InputError, match="lens_data"):
        model_for_camera(Camera(lens="thin:50"))


# -- seams between quad-tree cells ---------------------------------------------------------------


def _boundary_jump(img: np.ndarray, cells) -> tuple[float, float]:
    """Largest step across the cells' shared edges and across every other pixel edge: the
    first difference at an edge minus the mean of its neighbours' (a smooth image has none),
    relative to the image mean."""
    I = img[..., 0].astype(np.float64)

    def jumps(a, cols):
        return max((np.abs((a[:, i] - a[:, i - 1]) - 0.5 * ((a[:, i - 1] - a[:, i - 2]) + (a[:, i + 1] - a[:, i]))).max()
                    for i in cols if 2 <= i < a.shape[1] - 1), default=0.0)

    bx = {c.box[0] for c in cells} - {0}
    by = {c.box[2] for c in cells} - {0}
    at_edges = max(jumps(I, bx), jumps(I.T, by))
    inside = max(jumps(I, set(range(I.shape[1])) - bx), jumps(I.T, set(range(I.shape[0])) - by))
    return at_edges / I.mean(), inside / I.mean()


@pytest.mark.parametrize("lens, depth", [("thorlabs-ac254-050-a", 1), ("thorlabs-lb1471", 4)])
def test_no_step_across_cell_boundaries_for_uniform_and_in_focus_scenes(lens, depth):
    """Seams (docs/image_based_lens.md): a uniform scene tests that W is continuous across cells;
    a smooth radiance ramp on the plane of focus tests the texture coordinates — neighbouring
    cells have different COPs and must still map their shared edge to the same scene point.
    With the image plane 1 mm before the lens (the first version) the ramp's step at the edges
    was 0.020 (achromat, depth 1, fit error 0.15°) and 0.0072 (singlet, 0.03°) of the mean,
    2–20× the steps inside cells; anchored at the focus plane they match the inside's."""
    warnings.simplefilter("ignore")
    model = build(lens, 3.0, 4.0, sensor_mm=(12.0, 8.0), pupil_n=1, max_depth=depth)
    assert model.projections_per_sample()[0] >= 4  # subdivided: there are shared edges
    lens_ = get_lens(lens)
    pres = lens_.focused(3000.0, model.f_number)
    zf = float(pres.vertex_z[-1] + pres.surfaces[-1].thickness_mm)
    z_cam = 3.0 - (zf - lens_.paraxial.z_entrance_pupil_mm) / 1000.0  # focus plane, camera space

    def ramp(cop, f, c, size):
        u, v = np.meshgrid(np.arange(size[0]), np.arange(size[1]))
        t = z_cam - cop[2]
        x, y = cop[0] + t * (u - c[0]) / f, cop[1] + t * (v - c[1]) / f
        return np.repeat((2.0 + 3.0 * x + 3.0 * y + 0.3 * np.sin(40.0 * x))[..., None], 3, -1)

    size = (121, 81)
    cells, _ = warp_cells(model, size)
    for fn, tol in ((_const, 2e-4), (ramp, 2e-3)):
        img, _ = render_image_based(model, size, fn)
        at_edges, inside = _boundary_jump(img, cells)
        assert at_edges < tol and at_edges < 1.5 * inside + 1e-4, (fn.__name__, at_edges, inside)


def test_spiral_pupil_samples_are_stratified_in_area_and_angle():
    """The Vogel spiral (ghost copies fill the blur disc instead of lining up in rows): n² points
    inside the passing radius, equal counts in equal-area annuli and in equal sectors, centred."""
    from clpost.render.image_based_lens import pupil_samples

    lens = get_lens("thorlabs-ac254-050-a")
    pres = lens.focused(3000.0, 4.0)
    table, zf = mirrored_table(pres, lens.stop_radius_mm(4.0))
    z_x = lens.paraxial.z_exit_pupil_mm
    grid = pupil_samples(pres, table, zf, z_x, 6, "grid")
    spiral = pupil_samples(pres, table, zf, z_x, 6, "spiral")
    assert spiral.shape == grid.shape == (36, 3) and np.all(spiral[:, 2] == z_x)
    r_max = np.hypot(grid[:, 0], grid[:, 1]).max() / (5 / 6)  # concentric map: outer cell centres at r = 5/6
    r = np.hypot(spiral[:, 0], spiral[:, 1])
    assert r.max() <= r_max * (1 + 1e-9)
    assert np.abs(spiral[:, :2].mean(0)).max() < 0.05 * r_max
    rings = np.bincount(np.minimum((r / r_max) ** 2 * 6, 5.999).astype(int), minlength=6)
    sectors = np.bincount(((np.arctan2(spiral[:, 1], spiral[:, 0]) + np.pi) / (2 * np.pi) * 6).astype(int) % 6, minlength=6)
    assert rings.tolist() == [6] * 6 and np.abs(sectors - 6).max() <= 1, (rings, sectors)
    # every sample passes the iris from the axial film point
    assert all(trace_back(table, zf, np.zeros((1, 2)), p)[2][0] for p in spiral)


def test_spiral_pupil_count_gives_any_number_of_samples_and_needs_the_spiral():
    warnings.simplefilter("ignore")
    model = build("thorlabs-ac254-050-a", 3.0, 8.0, sensor_mm=(3.0, 3.0), pupil_pattern="spiral", pupil_count=10)
    assert len(model.pupil_samples_mm) == 10
    # the paper's first row: 10 pupil samples of one projection each, below 0.05°
    assert model.projections_per_sample().tolist() == [1] * 10 and model.max_angle_deg < 0.05
    with pytest.raises(InputError, match="pupil_count"):
        build("thorlabs-ac254-050-a", 3.0, 8.0, sensor_mm=(3.0, 3.0), pupil_count=10)


def test_batched_warp_kernel_matches_the_float64_reference_with_overlapping_pupil_samples(rng):
    """ibl_warp_cells (all projections in one launch, interleaved renders) against the sum of
    warp_reference over the cells: two pupil samples whose cells overlap, odd sizes, clamped
    texture coordinates, vignetted nodes."""
    size = (37, 23)
    boxes = ((0, 20, 0, 11), (20, 37, 0, 11), (0, 37, 11, 23), (0, 37, 0, 23), (5, 30, 3, 19))
    cells, srcs = [], []
    ref = np.zeros((23, 37, 3))
    for k, box in enumerate(boxes):
        src_size = (int(rng.integers(3, 40)), int(rng.integers(3, 30)))
        src = rng.uniform(0, 10, (src_size[1], src_size[0], 3)).astype(np.float32)
        src[0, 0] = 1e6
        cell = _random_cell(rng, size, box, src_size)
        cells.append(cell)
        srcs.append(src)
        warp_reference(ref, src, cell)
    warper = Warper(size)
    for _ in range(2):  # the second frame re-uses the staged buffers and the cells' metadata
        warper.reset()
        warper.add_cells(srcs, cells)
        out = warper.result()
        err = np.abs(out - ref) / np.maximum(np.abs(ref), 1.0)
        at = np.unravel_index(int(err.argmax()), err.shape)
        assert err.max() < 2e-4, f"max relative error {err.max():.3g} at (y, x, c) = {at}"
    assert np.count_nonzero(out) > 0.5 * out.size
    with pytest.raises(InputError, match="render of shape"):
        warper.add_cells([s[:-1] for s in srcs], cells)


def test_pack_tiles_places_renders_without_overlap_and_equal_renders_in_one_column(rng):
    """pack_tiles: every tile inside its page, no two tiles of a page overlapping; ten equal
    renders (the paper's 10-sample frame) stack into one column with no pixel wasted; renders that
    do not fit one page go on to the next."""
    from clpost.render.ibl_warp import pack_tiles

    equal = pack_tiles([(262, 262)] * 10)
    assert equal.pages == ((262, 2620),) and [t[1:] for t in equal.tiles] == [(0, 262 * k) for k in range(10)]
    for sizes, side in (([tuple(int(v) for v in rng.integers(3, 90, 2)) for _ in range(60)], 4096),
                        ([(70, 70)] * 5 + [(134, 133)] * 9 + [(263, 262)] * 7, 600)):
        layout = pack_tiles(sizes, side)
        assert len(layout.tiles) == len(sizes)
        for p, (pw, ph) in enumerate(layout.pages):
            assert pw <= side and ph <= side
            cover = np.zeros((ph, pw), int)
            for (q, x, y), (w, h) in zip(layout.tiles, sizes):
                if q == p:
                    assert x >= 0 and y >= 0 and x + w <= pw and y + h <= ph
                    cover[y:y + h, x:x + w] += 1
            assert cover.max() == 1
    assert len(pack_tiles([(263, 262)] * 7, 600).pages) > 1
    with pytest.raises(InputError, match="exceeds"):
        pack_tiles([(700, 10)], 600)


def test_warp_of_tiled_pages_equals_the_warp_of_separate_renders(rng):
    """Warper.map_pages (renders as tiles of shared pages, a row stride per cell) against
    map_cells (each render alone) and the float64 reference, same cells and renders."""
    size = (37, 23)
    boxes = ((0, 20, 0, 11), (20, 37, 0, 11), (0, 37, 11, 23), (5, 30, 3, 19))
    cells, srcs = [], []
    ref = np.zeros((23, 37, 3))
    for box in boxes:
        src_size = (int(rng.integers(3, 40)), int(rng.integers(3, 30)))
        src = rng.uniform(0, 10, (src_size[1], src_size[0], 3)).astype(np.float32)
        cell = _random_cell(rng, size, box, src_size)
        cells.append(cell)
        srcs.append(src)
        warp_reference(ref, src, cell)
    warper = Warper(size)
    warper.add_cells(srcs, cells)
    separate = warper.result()
    warper.reset()
    layout, pages = warper.map_pages(cells)
    assert len(layout.pages) == 1 and len(set(t[1:] for t in layout.tiles)) == len(cells)
    pages[0][:] = np.nan  # page pixels outside every tile must never be read
    for src, (p, x, y), cell in zip(srcs, layout.tiles, cells):
        w, h = cell.render_size
        pages[p][y:y + h, x:x + w, :3] = src[::-1]  # rows bottom-up
    warper.launch_cells()
    tiled = warper.result()
    np.testing.assert_array_equal(tiled, separate)
    err = np.abs(tiled - ref) / np.maximum(np.abs(ref), 1.0)
    assert err.max() < 2e-4


# -- the rasterizer path (baked radiance, VTK float framebuffer) ------------------------------

def _rasterizer(scene):
    from clpost.render.ibl_raster import FloatRasterizer, RasterUnavailable

    try:
        return FloatRasterizer(scene)
    except RasterUnavailable as e:  # a VTK without offscreen float framebuffers
        pytest.skip(f"rasterizer path unavailable here: {e}")


def test_rasterizer_path_matches_the_numpy_shading_path():
    """The same model and scene (the Kolb comparison's checker planes at 1.5, 3, 7 and 25 m) through
    per-projection numpy shading and through baked textures + VTK: a subdivided model (47 cells of
    several sizes, 2 pupil samples, 3 planes in view). Tolerance: 3 % mean |Δ| / mean, 20 % at the
    99th percentile; the residue sits on checker edges and silhouettes (a texel's box filter read
    bilinearly against the per-pixel box filter: measured 1.8 % / 12.5 % here, 0.9 % / 9.6 % at
    twice the size). A one-pixel shift of the numpy image costs 19 %, so the test sees geometry
    errors."""
    from clpost.render.image_based_lens import pyvista_render_fn, rasterizer_render_fn
    from clpost.render.kolb_trace import planes_scene
    from clpost.render.pyvista_renderer import PyVistaRenderer

    warnings.simplefilter("ignore")
    scene = planes_scene()
    raster = _rasterizer(scene)
    r = PyVistaRenderer(scene)
    model = build("thorlabs-lb1471", 3.0, 8.0, sensor_mm=(12.0, 8.0), pupil_pattern="spiral", pupil_count=2)
    assert len(model.projections) > 10 * len(model.pupil_samples_mm)  # subdivided: cells of several sizes
    size = (120, 80)
    try:
        ref, _ = render_image_based(model, size, pyvista_render_fn(r, 0))
        img, stats = render_image_based(model, size, rasterizer_render_fn(raster, 0))
        assert raster.baked_texels > 0
        again, _ = render_image_based(model, size, rasterizer_render_fn(raster, 0))
        assert raster.baked_texels == 0  # the same frame: no bake
    finally:
        r.close()
        raster.close()
    assert stats["projections"] == len(model.projections) and img.dtype == np.float32
    np.testing.assert_array_equal(img, again)
    d = np.abs(img - ref).mean(-1) / ref.mean()
    assert d.mean() < 0.03 and np.percentile(d, 99) < 0.20, (d.mean(), np.percentile(d, 99), d.max())
    shifted = np.abs(ref[:, 1:] - ref[:, :-1]).mean(-1) / ref.mean()
    assert shifted.mean() > 6 * d.mean()


def test_rasterizer_framebuffer_is_float_not_clipped_or_quantised():
    """An emitter of radiance 37.25 and a flat plane of albedo 0.123457 under ambient light come
    back exactly (float32): an 8-bit framebuffer would give 1.0 and a multiple of 1/255. A sky
    pixel gets the sky of its direction."""
    from clpost.render.demo_scene import DemoScene, Material, Plane, RigidMotion, SceneObject, rotation
    from clpost.render.ibl_warp import WarpCell
    from clpost.render.pyvista_renderer import _sky

    face = tuple(tuple(r) for r in rotation((1.0, 0.0, 0.0), np.pi / 2))
    objs = (SceneObject("lamp", Plane(0.1), Material(albedo=(0.5, 0.5, 0.5), emission=(37.25, 0.5, 2.0)),
                        RigidMotion(position_m=(-0.25, 3.0, 1.0), base_rotation=face), casts_shadow=False),
            SceneObject("grey", Plane(0.1), Material(albedo=(0.123457, 0.5, 0.75)),
                        RigidMotion(position_m=(0.25, 3.0, 1.0), base_rotation=face), casts_shadow=False))
    scene = DemoScene(objects=objs, camera_motion=RigidMotion.camera((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
                      sun_irradiance=0.0, ambient=2.0, emitter_lighting=False)
    raster = _rasterizer(scene)
    f, size = 200.0, (81, 41)
    c = (40.0, 20.0)
    cell = WarpCell(0, (0, 81, 0, 41), np.zeros((2, 2, 4)), (0.0, 0.0), (80.0, 40.0), size, f, c, np.zeros(3))
    try:
        raster.prepare([cell], 0)
        img = raster.render(np.zeros(3), f, c, size)
    finally:
        raster.close()
    # 0.25 m at 3 m with f = 200 px: the planes' centres at x = 40 ∓ 16.7 px, 13 px wide
    lamp, grey = img[20, 40 - 17], img[20, 40 + 17]
    np.testing.assert_allclose(lamp, (37.25, 0.5, 2.0), rtol=1e-6)
    # ambient · ½(1 + n_z) with n_z = 0
    np.testing.assert_allclose(grey, np.array([0.123457, 0.5, 0.75]) * 2.0 * 0.5, rtol=1e-5)
    sky_dir = np.array([[(0 - c[0]) / f, 0.0, 1.0]])  # pixel (0, 20): camera axes = world (x, z, −y)…
    assert img[20, 0].min() > 0 and np.all(np.isfinite(img))
    cam = scene.camera_pose(0)
    np.testing.assert_allclose(img[20, 0], _sky(sky_dir @ cam[:3, :3].T, scene)[0], rtol=1e-6)


def test_tiled_frame_with_the_warp_kernels_sky_equals_per_projection_renders_with_numpy_sky():
    """The rasterizer path's frame (all projections as tiles of one page, the sky of alpha-0
    texels computed by ibl_warp_cells) against the same frame rendered one projection at a time
    with the sky filled in numpy (render_into): a wide view of the checker planes without the
    backdrop, so about half the frame is sky. Equal up to float32 rounding (measured 3e-5 of the
    mean at most); a sky off by 1 % would fail."""
    import dataclasses

    from clpost.render.image_based_lens import rasterizer_render_fn
    from clpost.render.kolb_trace import planes_scene

    warnings.simplefilter("ignore")
    scene = planes_scene()
    raster = _rasterizer(dataclasses.replace(scene, objects=scene.objects[:3]))
    model = build("thorlabs-ac254-050-a", 3.0, 8.0, sensor_mm=(36.0, 24.0), pupil_pattern="spiral", pupil_count=3,
                  max_depth=1)
    tiled = rasterizer_render_fn(raster, 0)

    class OneByOne:  # the per-projection interface only: render_into fills the sky in numpy
        prepare = tiled.prepare
        render_into = tiled.render_into

    try:
        img, _ = render_image_based(model, (120, 80), tiled)
        ref, _ = render_image_based(model, (120, 80), OneByOne())
        table = tiled.warp_sky(warp_cells(model, (120, 80))[0])[0]
        tiled.warp_sky = lambda cells: (table, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))  # a black sky
        dark, _ = render_image_based(model, (120, 80), tiled)
    finally:
        raster.close()
    d = np.abs(img - ref).max(-1) / ref.mean()
    assert d.max() < 1e-3, d.max()
    sky = (img - dark).max(-1) > 1e-3  # pixels that see some sky
    assert 0.2 < sky.mean() < 0.95, sky.mean()


def test_rasterizer_refuses_scenes_it_cannot_bake_and_open_rasterizer_falls_back():
    from clpost.render.demo_scene import DemoScene
    from clpost.render.ibl_raster import FloatRasterizer, RasterUnavailable
    from clpost.render.image_based_lens import open_rasterizer

    scene = DemoScene.default()
    with pytest.raises(RasterUnavailable, match="planes only"):
        FloatRasterizer(scene)
    said = []
    assert open_rasterizer(scene, log=said.append) is None
    assert "using the numpy path" in said[0]


def test_bake_region_is_the_frustum_on_the_plane_and_nothing_behind_the_pinhole():
    """A fronto-parallel plane at depth 3 m seen by one 101×51 px projection (f = 100 px): the
    baked region is the frustum's footprint (±50.5 px × 3 m / 100, ±25.5 px × …) clipped to the
    plane, the footprint 3 m / 100 px; the same plane behind the pinhole is not baked."""
    from clpost.render.demo_scene import RigidMotion, rotation
    from clpost.render.ibl_raster import bake_region
    from clpost.render.ibl_warp import WarpCell

    cam_pose = RigidMotion.camera((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)).matrix(0)
    face = rotation((1.0, 0.0, 0.0), np.pi / 2)
    cell = WarpCell(0, (0, 101, 0, 51), np.zeros((2, 2, 4)), (0.0, 0.0), (100.0, 50.0), (101, 51), 100.0,
                    (50.0, 25.0), np.zeros(3))
    for y, expect in ((3.0, True), (-3.0, False)):
        pose = np.eye(4)
        pose[:3, :3] = face
        pose[:3, 3] = (0.0, y, 1.0)
        got = bake_region([cell], cam_pose, pose, 10.0)
        if not expect:
            assert got is None
            continue
        region, footprint, spread = got
        np.testing.assert_allclose(np.abs(region), [1.515, 1.515, 0.765, 0.765], rtol=1e-9)
        assert footprint == pytest.approx(0.03) and spread == pytest.approx(1.0)
        small = bake_region([cell], cam_pose, pose, 0.5)[0]  # a plane smaller than the view: all of it
        np.testing.assert_allclose(np.abs(small), [0.5, 0.5, 0.5, 0.5])


def test_sequences_take_the_rasterizer_path_where_they_can_and_say_why_not():
    """render_image_based_sequence(rasterizer=True): the planes scene through the rasterizer path
    (recorded in the metadata, within the numpy path's tolerance), the demo scene through the
    numpy path with the reason logged."""
    from clpost.camera import Camera
    from clpost.render.demo_scene import DemoScene
    from clpost.render.image_based_lens import render_image_based_sequence
    from clpost.render.kolb_trace import planes_scene

    warnings.simplefilter("ignore")
    _rasterizer(planes_scene()).close()  # skips where VTK has no float framebuffers
    cam = Camera(lens="thorlabs-lb1471", f_number=8.0, focus_distance_m=3.0, sensor_mm=(6.0, 4.0))
    kw = dict(pupil_n=1, max_depth=2)
    said = []
    numpy_frames = render_image_based_sequence(cam, (60, 40), 2, scene=planes_scene(), **kw)
    raster_frames = render_image_based_sequence(cam, (60, 40), 2, scene=planes_scene(), rasterizer=True,
                                                log=said.append, **kw)
    assert [f.metadata["image_based_lens"]["projection_path"] for f in numpy_frames + raster_frames] == \
        ["numpy"] * 2 + ["raster"] * 2
    d = np.abs(raster_frames[1].color - numpy_frames[1].color).mean(-1) / numpy_frames[1].color.mean()
    assert d.mean() < 0.03, d.mean()
    demo = render_image_based_sequence(cam, (24, 16), 1, scene=DemoScene.default(), rasterizer=True,
                                       log=said.append, pupil_n=1, max_depth=0)
    assert demo[0].metadata["image_based_lens"]["projection_path"] == "numpy"
    assert any("rasterizer path unavailable" in m and "are not planes" in m for m in said), said


def test_a_rasterizer_that_fails_at_its_first_render_falls_back_to_the_numpy_path(monkeypatch):
    """The float framebuffer is only checked when the first projection renders (a VTK without
    float framebuffers): the sequence then takes the numpy path for that frame on, with the reason
    logged, instead of raising."""
    from clpost.camera import Camera
    from clpost.render import ibl_raster
    from clpost.render.image_based_lens import render_image_based_sequence
    from clpost.render.kolb_trace import planes_scene

    warnings.simplefilter("ignore")
    _rasterizer(planes_scene()).close()  # skips where the rasterizer cannot even open

    def no_float(self, *args, **kw):
        raise ibl_raster.RasterUnavailable("VTK's framebuffer pass gave an 8-bit texture (simulated)")

    monkeypatch.setattr(ibl_raster.FloatRasterizer, "render_into", no_float)
    monkeypatch.setattr(ibl_raster.FloatRasterizer, "render", no_float)
    monkeypatch.setattr(ibl_raster.FloatRasterizer, "render_pages", no_float)  # the frame's tiled render
    cam = Camera(lens="thorlabs-lb1471", f_number=8.0, focus_distance_m=3.0, sensor_mm=(6.0, 4.0))
    said = []
    frames = render_image_based_sequence(cam, (30, 20), 2, scene=planes_scene(), rasterizer=True,
                                         log=said.append, pupil_n=1, max_depth=1)
    assert [f.metadata["image_based_lens"]["projection_path"] for f in frames] == ["numpy", "numpy"]
    assert np.all(np.isfinite(frames[0].color)) and frames[0].color.mean() > 0
    assert sum("8-bit texture (simulated)" in m for m in said) == 1, said

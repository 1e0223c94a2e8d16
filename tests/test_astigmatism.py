"""astigmatism: planning, kernel vs float64 reference, ellipse axes of a point source, energy,
stability at the extremes, the traced lens."""
import math

import numpy as np
import pytest

from clpost import Camera, Frame, InputError, Pipeline
from clpost.stages import _field as fld
from clpost.stages import astigmatism as ast
from clpost.stages.astigmatism_cl import device_plan

from conftest import assert_planned, odd_frame

FLAGSHIP = "zeiss-planar-50-f1.4"


def _max_err(out, ref):
    err = np.abs(out.astype(np.float64) - ref)
    j = np.unravel_index(int(np.argmax(err)), err.shape)
    return err.max(), f"max abs error {err.max():.3g} at (x={j[1]}, y={j[0]}, c={j[2]})"


def test_not_planned_without_offsets_and_identity_when_skipped(rng):
    frame = odd_frame(rng)
    for cam in (Camera(), Camera(field_curvature_mm=0.0, astigmatism_mm=0.0),
                Camera(lens=FLAGSHIP, f_number=2.0, field_curvature_mm=0.0, astigmatism_mm=0.0)):
        pipe = Pipeline(cam, stages=["astigmatism"])
        assert pipe.plan(frame) == []
        assert np.array_equal(pipe.run(frame).color, frame.color)
    assert "astigmatism" in Pipeline(Camera(lens=FLAGSHIP, f_number=1.4)).plan(frame)
    assert Pipeline(Camera(astigmatism_mm=0.1), stages=["astigmatism"]).plan(frame) == ["astigmatism"]


@pytest.mark.parametrize("w,h,kw", [
    (37, 23, dict(lens="thin:50", f_number=1.4, field_curvature_mm=-0.2, astigmatism_mm=0.3)),
    (23, 37, dict(lens="thin:24", f_number=0.7, focus_distance_m=0.3, astigmatism_mm=-0.05)),
    (41, 29, dict(lens=FLAGSHIP, f_number=1.4)),
])
def test_kernel_matches_reference(rng, w, h, kw):
    frame = odd_frame(rng, w=w, h=h, scale=10.0)
    depth = frame.depth.copy()
    depth[0, :5] = [1e-9, 1e-4, 0.05, 1e30, np.inf]  # adversarial: 0+, inside f, far, sky
    depth[-1, -3:] = np.inf
    frame = Frame(frame.color, depth=depth)
    pipe = Pipeline(Camera(**kw), stages=["astigmatism"])
    assert_planned(pipe, frame, "astigmatism")
    out = pipe.run(frame).color
    ref = pipe.reference(frame)
    err, where = _max_err(out, ref)
    assert err < 1e-3 * 10.0, where  # LUT vs exact curve, float32 taps
    assert np.all(np.isfinite(out)) and out.dtype == np.float32


@pytest.mark.parametrize("fc,a", [(8.0, 6.0), (-8.0, 6.0)])  # axes 4.5–11 px
def test_point_source_gives_the_closed_form_ellipse(fc, a):
    w, h = 201, 135
    cam = Camera(lens="thin:50", f_number=2.0, focus_distance_m=3.0, field_curvature_mm=fc, astigmatism_mm=a)
    x0 = 170  # on the horizontal axis through the centre: radial = x, sagittal = y
    cx = (w - 1) / 2
    pitch = 36.0 / w
    r_mm = (x0 - cx) * pitch
    # closed form in focus (v g = 1): c = D |δ| / (v + δ)
    rc = math.hypot(36, 24) / 2
    v, d = cam.image_distance_mm, 50.0 / 2.0
    ds, dt = (fc - a / 2) * (r_mm / rc) ** 2, (fc + a / 2) * (r_mm / rc) ** 2
    want_s, want_t = d * abs(ds) / (v + ds) / pitch, d * abs(dt) / (v + dt) / pitch
    got_s, got_t = ast.point_source_axes_px(cam, r_mm, 3.0, w)
    assert got_s == pytest.approx(want_s, rel=1e-9) and got_t == pytest.approx(want_t, rel=1e-9)
    color = np.zeros((h, w, 3), np.float32)
    color[(h - 1) // 2, x0] = 1.0
    frame = Frame(color, depth=np.full((h, w), 3.0, np.float32))
    out = Pipeline(cam, stages=["astigmatism"]).run(frame).color[..., 1].astype(np.float64)
    assert out.sum() == pytest.approx(1.0, rel=0.02)
    meas_s, meas_t = ast.splat_axes_px(out, 64)
    assert meas_t == pytest.approx(want_t, rel=0.05), (meas_t, want_t)
    assert meas_s == pytest.approx(want_s, rel=0.05), (meas_s, want_s)


def test_rims_or_spokes_sharp_not_both():
    """δ_s = 0: the sagittal focus is on the film — a circle's rim is blurred only along the
    radius, and a spoke (radial line) keeps its width; δ_t = 0 is the other way round."""
    w, h = 121, 81
    cx, cy = (w - 1) / 2, (h - 1) / 2
    ys, xs = np.mgrid[0:h, 0:w]
    spoke = ((np.abs(ys - cy) < 0.5) & (xs > cx + 20)).astype(np.float32)  # horizontal radial line
    depth = np.full((h, w), 3.0, np.float32)
    frame = Frame(np.repeat(spoke[..., None], 3, -1), depth=depth)
    col = int(cx + 50)

    def width_across(camera):
        out = Pipeline(camera, stages=["astigmatism"]).run(frame).color[:, col, 0].astype(np.float64)
        m = out / out.sum()
        return math.sqrt((m * (np.arange(h) - cy) ** 2).sum())

    sag_sharp = Camera(f_number=1.4, field_curvature_mm=4.0, astigmatism_mm=8.0)   # δ_s = 0
    tan_sharp = Camera(f_number=1.4, field_curvature_mm=4.0, astigmatism_mm=-8.0)  # δ_t = 0
    # blurred only along itself (a neighbour row's radius converges to the centre: a small leak)
    sharp, blurred = width_across(sag_sharp), width_across(tan_sharp)
    assert sharp < 0.25 and blurred > 8 * sharp, (sharp, blurred)


def test_uniform_field_is_unchanged_and_depth_extremes_are_finite():
    w, h = 45, 31
    depth = np.geomspace(1e-9, 1e6, w * h).reshape(h, w).astype(np.float32)
    depth[::7, ::5] = np.inf
    for kw in (dict(f_number=0.7, astigmatism_mm=1e3, field_curvature_mm=-1e3),
               dict(f_number=64.0, astigmatism_mm=1e-6), dict(f_number=0.7, focus_distance_m=0.051, astigmatism_mm=5.0)):
        cam = Camera(**kw)
        frame = Frame(np.full((h, w, 3), 7.0, np.float32), depth=depth)
        out = Pipeline(cam, stages=["astigmatism"]).run(frame).color
        assert np.all(np.isfinite(out))
        np.testing.assert_allclose(out, 7.0, rtol=1e-5)
        a_s, a_t, _, _ = ast.Astigmatism().semi_axes_px(cam, frame)
        assert np.all(np.isfinite(a_s)) and a_s.max() <= ast.MAX_SEMI_PX and a_t.max() <= ast.MAX_SEMI_PX


def test_quadrature_ownership_with_depth_defocus():
    """Out of focus, this stage adds √(c_s² − c_0²): with dof's disc c_0 the second moments sum
    to the lens's c_s² (variances of convolved PSFs add)."""
    cam = Camera(f_number=2.0, focus_distance_m=3.0, field_curvature_mm=-0.1, astigmatism_mm=0.2)
    d, v, f = ast.thin_lens(cam)
    for z in (1.0, 2.5, 3.0, 10.0, math.inf):
        cs, ct, c0 = ast.axes_mm(np.array(-0.2), np.array(0.0), np.array(z), d, v, f)
        a = 2 * ast.residual_semi_px(cs, c0, 1.0)
        assert float(a) ** 2 + float(c0) ** 2 == pytest.approx(max(float(cs), float(c0)) ** 2, rel=1e-9)
        # thin-lens closed form of c_0: D |1 - v (1/f - 1/z)|
        assert float(c0) == pytest.approx(d * abs(1 - v * (1 / f - (0 if math.isinf(z) else 1 / (z * 1000)))), rel=1e-9)


def test_flagship_wide_open_is_anisotropic_in_the_corner():
    cam = Camera(lens=FLAGSHIP, f_number=1.4, focus_distance_m=3.0)
    s, t = ast.point_source_axes_px(cam, 16.5, 3.0, 1280)
    assert s > 1.0 and t > 1.0 and abs(s - t) > 1.0
    assert ast.point_source_axes_px(cam, 0.0, 3.0, 1280) == (0.0, 0.0)  # the axis belongs to dof/SA
    s8, t8 = ast.point_source_axes_px(cam.with_(f_number=8.0), 16.5, 3.0, 1280)
    assert s8 < s and t8 < t


def test_without_depth_it_is_not_planned_and_bad_coefficients_are_refused():
    frame = Frame(np.ones((5, 7, 3), np.float32))
    entry = {e.stage: e for e in Pipeline(Camera(astigmatism_mm=0.1), stages=["astigmatism"]).explain(frame)}["astigmatism"]
    assert not entry.planned and "depth" in entry.reason  # colour-only frames keep working
    with pytest.raises(InputError, match="astigmatism_mm"):
        Camera(astigmatism_mm=float("nan"))
    with pytest.raises(InputError, match="field_curvature_mm"):
        Camera(field_curvature_mm="x")


def test_cli_options_set_the_parametric_coefficients():
    from clpost.cli import build_parser, camera_from_args

    args = build_parser().parse_args(["process", "in.exr", "-o", "out.exr", "--astigmatism", "0.2",
                                      "--field-curvature", "-0.1", "--coma", "0.05", "--lateral-color", "0.01"])
    cam = camera_from_args(args)
    assert (cam.astigmatism_mm, cam.field_curvature_mm, cam.coma_mm, cam.lateral_color_mm) == (0.2, -0.1, 0.05, 0.01)
    assert cam.describe()["clpost.astigmatism_mm"] == "0.2"
    assert "clpost.coma_mm" not in Camera().describe()


@pytest.mark.parametrize("n,focus", [(0.7, 0.45), (64.0, math.inf)])
def test_traced_lens_at_the_extremes_is_finite_and_matches_the_references(n, focus):
    """f/0.7 clamps to the lens's f/1.4 and f/64 to its f/16 (with a warning); closest focus and
    infinity; depths from 1e-9 to 1e9 m through all three aberration stages."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cam = Camera(lens=FLAGSHIP, f_number=n, focus_distance_m=focus)
    rng = np.random.default_rng(0)
    frame = Frame((rng.random((23, 37, 3)) * 10).astype(np.float32),
                  depth=np.geomspace(1e-9, 1e9, 23 * 37).reshape(23, 37).astype(np.float32))
    pipe = Pipeline(cam, stages=["astigmatism", "coma", "lateral_color"])
    assert pipe.plan(frame) == ["astigmatism", "coma", "lateral_color"]
    out = pipe.run(frame).color
    assert np.all(np.isfinite(out))
    err, where = _max_err(out, pipe.reference(frame))
    assert err < 5e-3, where  # values 0–10: LUTs of the traced curves vs np.interp


def test_a_sharp_highlight_is_not_copied_into_blurred_neighbours():
    """An in-focus lamp against the (far, strongly blurred) sky: the sky pixels' large ellipses
    reach the lamp, but the lamp's own small ellipse does not reach them — its light stays
    (a plain gather would add each sky pixel's share of the lamp: +30 % here; weighted: −0.2 %)."""
    w, h = 301, 201
    color = np.zeros((h, w, 3), np.float32)
    color[100, 250] = 1000.0
    depth = np.full((h, w), np.inf, np.float32)
    depth[100, 250] = 3.0
    cam = Camera(f_number=1.4, focus_distance_m=3.0, field_curvature_mm=-1.0, astigmatism_mm=0.4)
    stage = ast.Astigmatism()
    a_s, a_t, _, _ = stage.semi_axes_px(cam, Frame(color, depth=depth))
    assert a_s[100, 245] > 2 * a_s[100, 250] and a_s[100, 245] > 2.0  # the sky blurs much more
    out = Pipeline(cam, stages=["astigmatism"]).run(Frame(color, depth=depth)).color
    assert out.sum() == pytest.approx(3000.0, rel=0.03)


def test_tile_classes_copy_and_fewer_taps_match_the_reference(rng):
    """A frame whose tiles span every class (copied, 4 … 64 taps, exact): kernel vs reference,
    and the copied tiles are the input bit for bit."""
    w, h = 131, 77
    frame = odd_frame(rng, w=w, h=h, scale=10.0)
    cam = Camera(lens="thin:50", f_number=2.0, focus_distance_m=3.0, field_curvature_mm=-0.3, astigmatism_mm=0.25)
    depth = np.full((h, w), 3.0, np.float32)
    depth[:, 100:] = np.geomspace(1.0, 50.0, w - 100)  # defocused columns: larger ellipses, depth edges
    frame = Frame(frame.color, depth=depth)
    stage = ast.Astigmatism("final")
    *_, exact, taps = stage.tile_plan(cam, frame)
    assert len(set(np.unique(taps[~exact])) & {0, 4, 8, 16, 32}) >= 4, np.unique(taps)
    pipe = Pipeline(cam, stages=["astigmatism"], quality="final")
    assert_planned(pipe, frame, "astigmatism")
    out = pipe.run(frame).color
    err, where = _max_err(out, pipe.reference(frame))
    assert err < 1e-3 * 10.0, where
    copied = fld.per_pixel(taps == 0, w, h) & ~fld.per_pixel(exact, w, h)
    assert copied.any() and np.array_equal(out[copied], frame.color[copied])


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_tile_tap_count_rule(quality):
    stage = ast.Astigmatism(quality)
    n = stage.taps
    bound = np.array([0.0, 0.019, 0.021, 0.24, 0.26, 0.49, 0.51, 0.99, 1.01, 2.1, 4.1, 15.0])
    got = stage.tile_taps(bound)
    assert got[0] == got[1] == 0 and got[2] == 4  # copied below COPY_PX
    # a reduced count is never sparser than the quality's N on an ellipse of FULL_AT_PX
    fewer = (got > 0) & (got < n)
    assert fewer.sum() >= 4 and np.all(bound[fewer] / got[fewer] <= ast.FULL_AT_PX / n)
    more = (got > 4) & (got < n)  # ... and the fewest such (half as many would be too sparse)
    assert more.any() and np.all(bound[more] / (got[more] / 2) > ast.FULL_AT_PX / n)
    assert np.all(got[bound > ast.FULL_AT_PX] == n) and np.all(np.diff(got) >= 0)
    assert stage.tap_classes()[-1] == n and stage.tap_classes()[0] == 4


def test_copy_threshold_error_bound():
    """What copying a tile below COPY_PX costs: on a unit step edge and a unit point, the full
    gather with the largest ellipse that is still copied changes no pixel by more than 1 % / 2 %
    (measured 0.86 % / 1.7 %), i.e. copying is invisible next to the edge's own contrast."""
    h = w = 33
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    stage = ast.Astigmatism("final")
    a = np.full((h, w), ast.COPY_PX)
    ex, ey = np.ones((h, w)), np.zeros((h, w))
    worst = {}
    for kind, img in (("edge", (xs > 16).astype(float)), ("edge45", (xs + ys > 32).astype(float)),
                      ("point", (np.hypot(xs - 16, ys - 16) < 0.5).astype(float))):
        col = np.repeat(img[..., None], 3, -1)
        out = stage._gather(col, a, a, a, a, ex, ey, own=True)
        worst[kind] = np.abs(out - col).max()
    assert max(worst["edge"], worst["edge45"]) < 0.01 and worst["point"] < 0.02, worst
    assert worst["point"] > 0.005  # a real (small) blur: the bound is not vacuous


@pytest.mark.parametrize("fn,fc,a,kinds", [(2.0, -0.3, 0.25, {"copy", "gather"}),
                                         (1.4, -0.5, 0.6, {"gather", "exact"})])
def test_inner_tiles_read_the_source_and_the_pad_fills_only_the_ring(rng, fn, fc, a, kinds):
    """Tiles whose reads stay inside the frame read the source planes, and astigmatism_pad leaves
    the padded copy's inside unwritten (stale from the previous frame): a second, different frame
    must still match the reference everywhere, with inner tiles of every kind (copied, gathered,
    exact; two cameras) and partial tiles beside the ring (odd size)."""
    w, h = 131, 101
    cam = Camera(lens="thin:50", f_number=fn, focus_distance_m=3.0, field_curvature_mm=fc, astigmatism_mm=a)
    depth = np.full((h, w), 3.0, np.float32)
    depth[:, 70:] = np.geomspace(1.0, 50.0, w - 70)  # defocused columns inside the ring
    depth[40:60, 75:90] = 3.0  # and a depth edge there
    stage = ast.Astigmatism("final")
    inner = stage.inner_tiles(w, h)
    x0, x1, y0, y1 = stage.ring(w, h)
    assert 0 < x0 < x1 <= w and 0 < y0 < y1 <= h and 0.1 < inner.mean() < 0.9
    pipe = Pipeline(cam, stages=["astigmatism"], quality="final")
    for scale in (1e4, 3.0):  # a bright frame first: stale values would show in the second
        frame = Frame(odd_frame(rng, w=w, h=h, scale=scale).color, depth=depth)
        *_, exact, taps = stage.tile_plan(cam, frame)
        got = {"exact" if e else ("copy" if t == 0 else "gather") for e, t in zip(exact[inner], taps[inner])}
        assert kinds <= got, got
        assert_planned(pipe, frame, "astigmatism")
        out, ref = pipe.run(frame).color, pipe.reference(frame)
        err = np.abs(out - ref) / np.maximum(np.abs(ref), 1.0)
        j = np.unravel_index(int(np.argmax(err)), err.shape)
        assert err.max() < 1e-3, f"scale {scale}: max rel error {err.max():.3g} at (x={j[1]}, y={j[0]}, c={j[2]})"


def test_reach_test_is_skipped_only_where_every_reach_weight_is_one(rng):
    """astigmatism_reach's per-tile flag vs numpy: a tile may skip the reach test only if every
    pixel within PAD px (edge-repeated) has a_s + 1/2 >= the tile's B_s and a_t + 1/2 >= B_t —
    then each tap's q^2 <= |v|^2 < 1 and its reach weight is 1. A smooth depth ramp with a near
    block: most tiles skip, the tiles around the block do not, and the output matches the
    reference."""
    import pyopencl as cl

    w, h = 131, 101
    cam = Camera(lens="thin:50", f_number=1.4, focus_distance_m=3.0, field_curvature_mm=-0.5, astigmatism_mm=0.6)
    depth = np.tile(np.geomspace(1.0, 50.0, w).astype(np.float32), (h, 1))
    depth[40:60, 60:80] = 0.4  # near block: large ellipses beside small ones
    frame = Frame(odd_frame(rng, w=w, h=h, scale=10.0).color, depth=depth)
    stage = ast.Astigmatism("draft")
    pipe = Pipeline(cam, stages=["astigmatism"], quality="draft")
    assert_planned(pipe, frame, "astigmatism")
    err, where = _max_err(pipe.run(frame).color, pipe.reference(frame))
    assert err < 1e-3 * 10.0, where
    rt = pipe.runtime
    flags = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
    planar = np.ascontiguousarray(np.moveaxis(frame.color[..., :3], -1, 0), np.float32)
    src = cl.Buffer(rt.context, flags, hostbuf=planar)
    aux = {"depth": cl.Buffer(rt.context, flags, hostbuf=depth)}
    stage.enqueue(rt, cam, frame, src, rt.empty((3, h, w)), aux)
    ntx, nty = fld.tiles(w, h)
    reach = np.empty((nty, ntx), np.int32)
    cl.enqueue_copy(rt.queue, reach, device_plan(stage, rt, cam, w, h)["reach"], is_blocking=True)
    a_s, a_t, _, _ = stage.semi_axes_px(cam, frame)
    bs, bt, *_ = stage.tile_plan(cam, frame)
    ps, pt = np.pad(a_s, fld.PAD, mode="edge"), np.pad(a_t, fld.PAD, mode="edge")
    need = np.zeros((nty, ntx), bool)
    for ty in range(nty):
        for tx in range(ntx):
            win = np.s_[ty * fld.TILE_H:min((ty + 1) * fld.TILE_H, h) + 2 * fld.PAD,
                        tx * fld.TILE_W:min((tx + 1) * fld.TILE_W, w) + 2 * fld.PAD]
            need[ty, tx] = ps[win].min() + 0.5 < bs[ty, tx] - 1e-4 or pt[win].min() + 0.5 < bt[ty, tx] - 1e-4
    assert not np.any(need & (reach == 0)), np.argwhere(need & (reach == 0))
    assert 0.3 < (reach == 0).mean() and need.any() and reach.any()


def test_dof_and_astigmatism_share_the_sharp_plane_of_a_traced_lens():
    from clpost.stages.dof import coc_mm

    cam = Camera(lens=FLAGSHIP, focus_distance_m=0.6)  # the depth that is sharp
    u = cam.focused_depth_m
    assert u == 0.6 and cam.focus_from_film_m > 0.6  # the lens-scale distance adds pupil → film
    d, v, f = ast.thin_lens(cam)
    z = np.array([0.48, u, 0.75])
    np.testing.assert_allclose(np.abs(coc_mm(cam, z)), ast.axes_mm(0, 0, z, d, v, f)[2],
                               rtol=1e-9, atol=1e-12)
    assert Camera(focus_distance_m=2.0).focused_depth_m == 2.0  # thin lens: exactly the focus


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_program_has_one_gather_per_tap_class_and_the_plan_is_built_once(rng, quality):
    """Tap-class kernels and the kernels' constants are generated from Python; the device plan
    (source, tables, buffers) is made once per camera and size, not per frame."""
    from clpost.stages.astigmatism_cl import program_source

    stage = ast.Astigmatism(quality)
    cam = Camera(field_curvature_mm=0.05, astigmatism_mm=0.1, f_number=2.0)
    src = program_source(tuple(stage.tap_classes()))
    for n in stage.tap_classes()[:-1]:
        assert f"__kernel void astigmatism_t{n}(" in src
    assert f"#define ASTIGMATISM_MIN_SEMI {float(np.float32(ast.MIN_SEMI_PX))!r}f" in src
    w, h = 37, 23
    pipe = Pipeline(cam, stages=["astigmatism"], quality=quality)
    depth = np.full((h, w), 1.5, np.float32)
    frame = Frame(rng.random((h, w, 3), dtype=np.float32), depth=depth)
    pipe.run(frame)
    st = next(s for s in pipe._stages if s.name == "astigmatism")
    plan = device_plan(st, pipe.runtime, cam, w, h)
    pipe.run(frame)
    assert device_plan(st, pipe.runtime, cam, w, h) is plan and plan["offsets_done"]
    assert {f"astigmatism_t{n}" for n in stage.tap_classes()[:-1]} <= {
        k.function_name for k in pipe.runtime.program(src, "astigmatism", {**stage.defines(cam), "ASTIGMATISM_WHOLE_TILES": 0}).all_kernels()}


@pytest.mark.parametrize("w,h", [(131, 77), (128, 64)])  # partial tiles, whole tiles
def test_one_pixel_per_work_item_gather_matches_the_sixteen_wide_one(rng, monkeypatch, w, h):
    """The gather's one-pixel form (a GPU's: a tile per work-group of 16 × 8 work-items) gives the
    16-wide form's image (the same arithmetic per pixel) over every tile class, and the reference."""
    from clpost.runtime import Runtime

    frame = odd_frame(rng, w=w, h=h, scale=10.0)
    depth = np.full((h, w), 3.0, np.float32)
    depth[:, w * 3 // 4:] = np.geomspace(1.0, 50.0, w - w * 3 // 4)
    frame = Frame(frame.color, depth=depth)
    cam = Camera(lens="thin:50", f_number=2.0, focus_distance_m=3.0, field_curvature_mm=-0.3, astigmatism_mm=0.25)
    wide = Pipeline(cam, stages=["astigmatism"], quality="final")
    assert_planned(wide, frame, "astigmatism")
    want = wide.run(frame).color
    monkeypatch.setattr(Runtime, "wide", property(lambda self: False))
    pipe = Pipeline(cam, stages=["astigmatism"], quality="final")
    got = pipe.run(frame).color
    rcam = pipe.camera_for(frame)
    stage = pipe.plan_for(frame, rcam).stages[0]
    assert device_plan(stage, pipe.runtime, rcam, w, h, fld.frame_geometry(rcam, frame))["lanes"] == 1
    np.testing.assert_allclose(got, want, rtol=2e-6, atol=2e-6)
    err, where = _max_err(got, pipe.reference(frame))
    assert err < 1e-3 * 10.0, where


def _point_class_frame(rng, w=801, h=45, tall=False):
    """A strip whose ends take both point classes (semi-axes 4–15 px, far enough from the centre
    for the tile model), with a depth step, a hot pixel and every other tile class between;
    ``tall``: the same strip transposed (h × w), so the class boundaries run along tile rows."""
    color = odd_frame(rng, w=w, h=h, scale=10.0).color.copy()
    color[20, w - 41] = 500.0
    depth = np.full((h, w), 3.0, np.float32)
    depth[:, w * 3 // 8:w * 3 // 8 + 20] = 2.0
    if tall:
        color, depth, w, h = np.ascontiguousarray(color.transpose(1, 0, 2)), np.ascontiguousarray(depth.T), h, w
    cam = Camera(lens="thin:50", f_number=2.0, focus_distance_m=3.0, field_curvature_mm=-0.4, astigmatism_mm=0.15,
                 sensor_mm=(w * 0.006, h * 0.006))
    return cam, Frame(color, depth=depth)


def _rounding_ties(stage, cam, frame, eps=1e-4):
    """Per pixel: on a point tile one of whose taps lands within ``eps`` px of a pixel edge. A point
    tap reads the box at floor(x + o); there the kernel's float32 offset and the reference's
    float64 one may floor to neighbouring box samples (a step of one tap's share of the box's
    difference), where a bilinear tap is continuous."""
    bs, bt, tex, tey, exact, _ = stage.tile_plan(cam, frame)
    point = stage.point_taps(cam, frame, exact)
    tie = np.zeros(point.shape, bool)
    for ty, tx in zip(*np.nonzero(point)):
        u = fld.vogel_disc(int(point[ty, tx])).astype(np.float64)
        us = math.sqrt(bs[ty, tx] ** 2 - ast.POINT_SHRINK_PX2) * u[:, 0]
        ut = math.sqrt(bt[ty, tx] ** 2 - ast.POINT_SHRINK_PX2) * u[:, 1]
        o = np.concatenate([-tey[ty, tx] * us + tex[ty, tx] * ut, tex[ty, tx] * us + tey[ty, tx] * ut])
        tie[ty, tx] = np.abs(o - np.round(o)).min() < eps
    return fld.per_pixel(tie, frame.width, frame.height) > 0


@pytest.mark.parametrize("quality,wide,tall", [("draft", True, False), ("final", True, False),
                                               ("final", False, False), ("final", True, True)])
def test_point_classes_match_the_reference(rng, monkeypatch, quality, wide, tall):
    """Tiles whose pixels' semi-axes are all >= 4 px take point taps of the 4 × 4 box-filtered
    colour (point_classes): kernel vs reference with every point class and the other classes in
    one frame (the box plane is filled only near point tiles: a missing tile would read garbage —
    across tile columns in the wide strip, across tile rows in the tall one); the 16-lane form and
    a GPU's one-pixel form. On the tiles with a rounding tie (:func:`_rounding_ties`) the bound is
    one flipped tap's share of the box's step instead."""
    from clpost.runtime import Runtime

    monkeypatch.setattr(Runtime, "wide", property(lambda self: wide))
    cam, frame = _point_class_frame(rng, tall=tall)
    stage = ast.Astigmatism(quality)
    *_, exact, taps = stage.tile_plan(cam, frame)
    point = stage.point_taps(cam, frame, exact)
    assert {n for _, n in ast.point_classes(stage.taps)} <= set(np.unique(point)), np.unique(point)
    assert (point == 0).mean() > 0.3 and len(set(np.unique(taps[point == 0]))) >= 3
    pipe = Pipeline(cam, stages=["astigmatism"], quality=quality)
    assert_planned(pipe, frame, "astigmatism")
    out = pipe.run(frame).color
    ref = pipe.reference(frame)
    tie = _rounding_ties(stage, cam, frame)
    err, where = _max_err(np.where(tie[..., None], ref, out), ref)
    assert err < 1e-3 * 10.0, where
    err, where = _max_err(out, ref)
    assert err < 0.1, where
    assert out.sum() == pytest.approx(frame.color.sum(), rel=1e-3)


@pytest.mark.parametrize("fc,a", [(-3.0, 1.0), (-5.0, 0.5), (5.0, -0.5)])
def test_point_taps_keep_a_ramp_in_place(fc, a):
    """Closed form: a gather of a linear ramp C = x (and y) returns the ramp at the pixel up to its
    taps' weighted mean offset. A point tap reads the box at floor(x + o), centred at floor(x + o) +
    ½ (module docstring, "Point taps"): unbiased, within ½ px of the tap. A box centred elsewhere in
    the kernel and the reference alike, which their comparison cannot see, moves every point tile:
    centred on floor(x + o) by ½ px, one pixel off by 1 px (that mutation: mean −0.99). Measured:
    mean within 0.03 px, max 0.28 (the bilinear tiles: 0.08)."""
    w, h = 601, 81
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    color = np.stack([xs + 10, ys + 10, np.ones_like(xs)], axis=-1).astype(np.float32)
    cam = Camera(lens="thin:50", f_number=2.0, focus_distance_m=3.0, field_curvature_mm=fc, astigmatism_mm=a)
    frame = Frame(color, depth=np.full((h, w), 3.0, np.float32))
    point = fld.per_pixel(ast.Astigmatism("final").point_taps(cam, frame), w, h)
    sel = (point > 0) & (xs >= 20) & (xs < w - 20) & (ys >= 20) & (ys < h - 20)  # off the edge clamp
    assert sel.sum() > 3000
    out = Pipeline(cam, stages=["astigmatism"]).run(frame).color.astype(np.float64)
    for c, coord in ((0, xs), (1, ys)):
        d = out[..., c][sel] - (coord[sel] + 10)
        assert abs(d.mean()) < 0.1 and np.abs(d).max() < 0.4, (c, d.mean(), np.abs(d).max())


def test_point_classes_keep_huge_finite_values_finite(rng):
    """Adversarial input: four pixels at 1e38 (finite, above FLT_MAX / 16) on a point tile. The box
    plane is their mean; summed before the division the 16 terms overflowed to inf (408 pixels
    of this frame), where the bilinear taps stay finite."""
    cam, frame = _point_class_frame(rng)
    stage = ast.Astigmatism("final")
    assert stage.point_taps(cam, frame)[20 // fld.TILE_H, 760 // fld.TILE_W] > 0
    color = frame.color.copy()
    color[20, 760:764] = 1e38
    frame = Frame(color, depth=frame.depth)
    pipe = Pipeline(cam, stages=["astigmatism"], quality="final")
    out = pipe.run(frame).color
    assert np.isfinite(out).all(), np.argwhere(~np.isfinite(out))[:3]
    err, where = _max_err(out, pipe.reference(frame))
    assert err < 1e-5 * 1e38, where


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_every_path_keeps_huge_finite_colour_finite(rng, quality):
    """The strip of every class (bilinear tap classes, point classes, exact, copy) scaled by 2^119:
    its hot pixel at 3.3e38, the rest up to ~1e37 (finite, near FLT_MAX = 3.4e38). The gathers
    scale each weight by 1/ntaps, so their sums stay below the largest colour; summed unscaled,
    the bilinear and exact tiles' sums overflowed to inf. Power-of-two scaling is exact, so the
    output is the unscaled frame's, scaled."""
    cam, frame = _point_class_frame(rng)
    stage = ast.Astigmatism(quality)
    *_, exact, taps = stage.tile_plan(cam, frame)
    point = stage.point_taps(cam, frame, exact)
    assert exact.any() and (point > 0).any() and ((point == 0) & ~exact & (taps > 0)).any()
    k = 2.0 ** 119
    assert 3e38 < frame.color.max() * k < np.finfo(np.float32).max
    pipe = Pipeline(cam, stages=["astigmatism"], quality=quality)
    small = pipe.run(frame).color
    huge = pipe.run(Frame(frame.color * np.float32(k), depth=frame.depth)).color
    assert np.isfinite(huge).all(), np.argwhere(~np.isfinite(huge))[:3]
    np.testing.assert_allclose(huge, small.astype(np.float64) * k, rtol=1e-6, atol=0)


def _device_classes(stage, rt, cam, w, h):
    """Per tile: the class astigmatism_tiles put it in (its lists and counts of the last run)."""
    import pyopencl as cl

    b = device_plan(stage, rt, cam, w, h)
    n = b["ntx"] * b["nty"]
    lists, counts = np.empty((b["nclass"], n), np.int32), np.empty(b["nclass"], np.int32)
    cl.enqueue_copy(rt.queue, lists, b["lists"], is_blocking=True)
    cl.enqueue_copy(rt.queue, counts, b["counts"], is_blocking=True)
    out = np.full(n, -1)
    for c in range(b["nclass"]):
        out[lists[c, :counts[c]]] = c
    return out.reshape(b["nty"], b["ntx"])


@pytest.mark.parametrize("depth,tile,px", [(3.55023193359375, 10, 8.0), (3.0374646186828613, 38, 4.0)])
def test_point_class_thresholds_tie_like_the_device(rng, depth, tile, px):
    """A frame built to straddle a point-class threshold: at this (float32) depth the tile's
    smallest semi-axis is just below ``px`` in float64 (exact curves: 7.99992, 3.99991) and at or
    above it on the device (LUT, float32: 8.0000010, 4.0000033). The reference classifies on the
    device's float32 semi-axes (Astigmatism.semi_axes_px32, bit-equal: checked here), so both put
    every tile in the same class and the outputs agree; classified from the float64 values, the
    tile took bilinear taps in the reference and point taps on the device."""
    import pyopencl as cl

    w, h = 801, 45
    cam, _ = _point_class_frame(rng)
    color = odd_frame(rng, w=w, h=h, scale=10.0).color
    frame = Frame(color, depth=np.full((h, w), depth, np.float32))
    stage = ast.Astigmatism("final")
    a_s, a_t, _, _ = stage.semi_axes_px(cam, frame)
    lo64 = np.minimum(a_s, a_t)[:, tile * fld.TILE_W:(tile + 1) * fld.TILE_W].min()
    assert px - 1e-3 < lo64 < px, lo64  # the float64 value: just below the threshold
    pipe = Pipeline(cam, stages=["astigmatism"], quality="final")
    assert_planned(pipe, frame, "astigmatism")
    out = pipe.run(frame).color
    ref = pipe.reference(frame)
    rt = pipe.runtime
    st = next(s for s in pipe._stages if s.name == "astigmatism")
    b = device_plan(st, rt, cam, w, h)
    # the reference's classes = the device's, tile by tile
    _, _, _, _, exact, taps = stage.tile_plan(cam, frame)
    point = stage.point_taps(cam, frame, exact)
    nt = len(stage.tap_classes())
    pclass = {n: nt + 1 + k for k, (_, n) in enumerate(ast.point_classes(stage.taps))}
    want = np.where(exact, b["nclass"] - 1,
                    np.where(point > 0, np.vectorize(lambda n: pclass.get(n, -1))(point),
                             np.searchsorted([0] + stage.tap_classes(), taps)))
    got = _device_classes(st, rt, cam, w, h)
    assert np.array_equal(got, want), np.argwhere(got != want)
    assert point[:, tile].all()
    # within 0.5 px of the centre (semi-axes < 0.5 px) the float32 c^2 - c0^2 cancels (0.046 px
    # on the device where the reference has 0.036 px): a looser bound there
    tie = _rounding_ties(stage, cam, frame) | (np.minimum(a_s, a_t) < 0.5)
    err, where = _max_err(np.where(tie[..., None], ref, out), ref)
    assert err < 1e-3 * 10.0, where
    err, where = _max_err(out, ref)
    assert err < 0.1, where
    axes = np.empty((4, b["ph"], b["pw"]), np.float32)
    cl.enqueue_copy(rt.queue, axes, b["axes"], is_blocking=True)
    p = fld.PAD
    dev = axes[:2, p:p + h, p:p + w]
    assert np.array_equal(dev, np.stack(stage.semi_axes_px32(cam, frame)))
    assert dev.min(0)[:, tile * fld.TILE_W:(tile + 1) * fld.TILE_W].min() >= px  # the device's: at or above


@pytest.mark.parametrize("fc,a,x0,n", [(-3.0, 1.0, 551, 64), (-4.5, -1.0, 515, 64),
                                       (-5.0, 0.5, 551, 32), (5.0, -0.5, 551, 32)])
def test_point_classes_give_the_closed_form_ellipse(fc, a, x0, n):
    """A point source on a point-class tile: the splat's second moments are the closed-form
    ellipse's (the box's and the rounding's variance are taken from the ellipse: semi-axes
    √(a² − POINT_SHRINK_PX2)). Measured with the class's spiral as in the test above. The splat is a
    patchwork of tile kernels (so is the 64-tap bilinear one's): 6 % on the axes and 4 % on energy are
    the point classes' largest errors over 20 such highlights (docs/benchmarks.md, "astigmatism:
    point classes"; tools/astigmatism_point_check.py)."""
    w, h = 601, 81
    cy, cx = (h - 1) // 2, (w - 1) / 2
    cam = Camera(lens="thin:50", f_number=2.0, focus_distance_m=3.0, field_curvature_mm=fc, astigmatism_mm=a)
    want_s, want_t = ast.point_source_axes_px(cam, (x0 - cx) * 36.0 / w, 3.0, w)
    color = np.zeros((h, w, 3), np.float32)
    color[cy, x0] = 1.0
    frame = Frame(color, depth=np.full((h, w), 3.0, np.float32))
    stage = ast.Astigmatism("final")
    exact = stage.tile_plan(cam, frame)[4]
    assert stage.point_taps(cam, frame, exact)[cy // fld.TILE_H, x0 // fld.TILE_W] == n
    out = Pipeline(cam, stages=["astigmatism"]).run(frame).color[..., 1].astype(np.float64)
    assert out.sum() == pytest.approx(1.0, abs=0.04)
    meas_s, meas_t = ast.splat_axes_px(out, n)
    assert meas_t == pytest.approx(want_t, rel=0.06), (meas_t, want_t)
    assert meas_s == pytest.approx(want_s, rel=0.06), (meas_s, want_s)

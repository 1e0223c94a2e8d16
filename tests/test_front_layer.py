"""front_layer: the kernel against the float64 scatter on odd sizes, closed forms (no coverage:
the image; in focus: plain over; energy), the depth pass's missed samples, the frame's contract
and bad input."""
import math

import numpy as np
import pytest

from clpost import Camera, Frame, Pipeline
from clpost.errors import InputError
from clpost.frame import front_layer
from clpost.stages import front_layer as FL
from clpost.stages.dof import coc_px

from conftest import assert_planned

STAGES = ["dof", "front_layer"]


def camera(**kw):
    base = dict(lens="thin:50", f_number=1.4, focus_distance_m=3.0, depth_of_field=True, blades=6,
                sensor_mm=(6.0, 4.0), luminance_scale=1.0)
    return Camera(**{**base, **kw})


def layered(w, h, seed=0, partial=True, far_bg=False, front_depth=(0.5, 1.2)):
    """A background (at the focus, or far) under a front layer: a box with soft rows and a
    column of its own, premultiplied colour up to 3, depths in ``front_depth``."""
    rng = np.random.default_rng(seed)
    bg = rng.uniform(0.0, 1.0, (h, w, 3)).astype(np.float32)
    depth = np.full((h, w), 30.0 if far_bg else 3.0, np.float32)
    a = np.zeros((h, w), np.float32)
    a[h // 4:max(h // 4 + 1, 3 * h // 4), w // 5:max(w // 5 + 1, 3 * w // 5)] = 1.0
    if partial and h > 4 and w > 4:
        a[h // 4 - 1, w // 5:3 * w // 5] = 0.35
        a[:, w - 2] = rng.uniform(0.0, 1.0, h)  # a soft column touching the frame's edges
    c = (rng.uniform(0.0, 3.0, (h, w, 3)) * a[..., None]).astype(np.float32)
    d = np.where(a > 0, rng.uniform(*front_depth, (h, w)), np.inf).astype(np.float32)
    return Frame(color=bg, depth=depth, front=front_layer(c, a, d))


def run(cam, frame, quality="final"):
    pipe = Pipeline(cam, quality=quality, stages=STAGES)
    assert_planned(pipe, frame, "front_layer")
    return pipe.run(frame)


def reference(cam, frame, quality="final"):
    """The float64 scatter over dof's own output (dof runs first in the plan)."""
    back = Pipeline(cam, quality=quality, stages=["dof"]).run(frame.replace(front=None)).color
    return FL.FrontLayer(quality).reference(cam, frame, np.asarray(back, np.float64))


@pytest.mark.parametrize("w, h, quality, kw", [
    (53, 37, "final", {}),
    (41, 67, "draft", dict(blades=5, blade_rotation_deg=17.0)),
    (29, 23, "preview", dict(blades=7, aperture_roundness=0.4, f_number=2.8)),
    (64, 9, "final", dict(blades=0)),
    (1, 1, "final", {}),
    (3, 5, "draft", dict(blades=6, blade_rotation_deg=90.0)),
])
def test_kernel_matches_the_float64_scatter(w, h, quality, kw):
    cam = camera(**kw)
    frame = layered(w, h, seed=w + h, far_bg=True)
    out = run(cam, frame, quality).color
    ref = reference(cam, frame, quality)
    # N(r) from a table at 1/256 px, linear: its kinks (an offset entering the ramp) leave ≤ 1e-3
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-3 * max(1.0, float(np.abs(ref).max())))
    assert np.isfinite(out).all()


def test_radii_reach_the_quality_limit_and_edges_clamp():
    # a near front layer at f/0.9 on a wide frame: radii up to the final limit (64 px), cut by
    # the frame's edges on every side
    cam = camera(f_number=0.9, sensor_mm=(1.5, 1.0))
    frame = layered(141, 95, seed=5, front_depth=(0.2, 0.4))
    r = np.abs(coc_px(cam, frame.front[..., 4][frame.front[..., 3] > 0], 141, math.inf))
    assert r.max() > 64
    np.testing.assert_allclose(run(cam, frame).color, reference(cam, frame), rtol=0, atol=1e-3 * 3)


def _synthetic_front(h=120, w=200):
    """A bar, a disc and a thin line in front (checker colour), at 0.25, 0.4 and 0.6 m."""
    yy, xx = np.mgrid[0:h, 0:w]
    a = np.zeros((h, w))
    a[20:100, 30:45] = 1
    a[(yy - 60) ** 2 + (xx - 120) ** 2 < 25 ** 2] = 1
    a[50:52, 60:190] = 1
    col = np.stack([(xx // 6 + yy // 6) % 2 + 0.2, 0.5 + 0 * xx, yy / h], -1) * a[..., None]
    d = np.where(a > 0, np.where(xx < 60, 0.25, np.where(xx < 150, 0.4, 0.6)), np.inf)
    return front_layer(col, a, d)


@pytest.mark.parametrize("quality, min_db", [("draft", 37.0), ("final", 47.0)])
def test_the_levels_stay_close_to_the_exact_scatter(quality, min_db):
    # radii up to 12.7 px (levels 0-1 at final, 0-2 at draft) against every pixel spread at full
    # resolution; measured 39.1 / 49.0 dB (LEVEL_SHRINK_PX2 = 2: 38.7 / 49.0 at 1.5, 37.3 / 48.9 at 1)
    from clpost import fidelity as fd

    cam = fd.cycles_camera({"focal_mm": 50.0, "sensor_mm": 36.0, "f_number": 2.0, "focus_m": 3.0, "blades": 6,
                            "rotation_deg": 0.0}, 200, 120)
    f = _synthetic_front()
    r = FL.front_radius(cam, f[..., 4], 200, quality)
    assert FL.level_of(r[f[..., 3] > 0], quality).max() >= (1 if quality == "final" else 2)
    bg = np.zeros((120, 200, 3))
    exact = FL.front_scatter(f, np.where(f[..., 3] > 0, r, 0.0), bg, 6, 0.0, 0.0)
    levels = FL.front_reference(f, r, bg, quality, 6, 0.0, 0.0)
    assert fd.psnr_srgb(exact, levels) >= min_db
    # radii below 2R spread at full resolution: the levels are the exact scatter there
    near = f.copy()
    near[..., 4] = np.where(f[..., 3] > 0, 1.7, np.inf)
    r = FL.front_radius(cam, near[..., 4], 200, quality)
    assert (r[f[..., 3] > 0] < 2 * FL.LEVEL_RADIUS[quality]).all()
    np.testing.assert_allclose(FL.front_reference(near, r, bg, quality, 6, 0.0, 0.0),
                               FL.front_scatter(near, np.where(f[..., 3] > 0, r, 0.0), bg, 6, 0.0, 0.0), atol=1e-9)


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_the_cpu_and_gpu_forms_agree(quality):
    # the 16-pixel spreads (Runtime.wide: front_layer_gather16 + front_layer_add) against the
    # one-pixel kernels, on rows not a multiple of 16 with radii over every level; PoCL gives the
    # same bits (same taps, same order), the bound leaves room for another compiler's contraction
    import pyopencl as cl

    from clpost.runtime import Runtime

    cam = camera(f_number=0.9, sensor_mm=(1.5, 1.0))
    frame = layered(141, 95, seed=5, front_depth=(0.2, 3.0))
    outs, launched = {}, {True: set(), False: set()}
    enqueue = cl.enqueue_nd_range_kernel
    for wide in (True, False):
        def record(queue, kernel, *a, _wide=wide, **kw):
            launched[_wide].add(kernel.function_name)
            return enqueue(queue, kernel, *a, **kw)

        cl.enqueue_nd_range_kernel = record
        try:
            with Runtime.forced_width(wide):
                outs[wide] = Pipeline(cam, quality=quality, stages=STAGES).run(frame).color
        finally:
            cl.enqueue_nd_range_kernel = enqueue
    assert {"front_layer_gather16", "front_layer_add"} <= launched[True]
    assert {"front_layer_gather", "front_layer"} <= launched[False] and "front_layer_gather16" not in launched[False]
    np.testing.assert_allclose(outs[True], outs[False], rtol=0, atol=1e-6 * float(np.abs(outs[False]).max()))
    assert not np.array_equal(outs[True], frame.color)


def test_no_coverage_leaves_the_image_unchanged():
    cam = camera()
    frame = layered(47, 31, far_bg=True)
    empty = frame.replace(front=front_layer(np.zeros((31, 47, 3)), np.zeros((31, 47)), np.full((31, 47), np.inf)))
    back = Pipeline(cam, stages=["dof"]).run(frame.replace(front=None)).color
    np.testing.assert_array_equal(run(cam, empty).color, back)


def test_a_front_layer_in_focus_is_plain_over():
    cam = camera()
    frame = layered(45, 33, front_depth=(3.0, 3.0))  # at the focus: every radius 0
    f = frame.front
    want = f[..., :3] + (1 - f[..., 3:4]) * frame.color  # the background at the focus: dof skipped
    np.testing.assert_allclose(run(cam, frame).color, want, rtol=1e-6, atol=1e-6)
    # depth of field off: the same composite, at any depth
    off = layered(45, 33)
    g = off.front
    want = g[..., :3] + (1 - g[..., 3:4]) * off.color
    out = Pipeline(camera(depth_of_field=False), stages=STAGES).run(off).color
    np.testing.assert_allclose(out, want, rtol=1e-6, atol=1e-6)


def test_light_and_coverage_are_conserved():
    # the layer's discs all inside the frame: its premultiplied light and its coverage are spread,
    # not made or lost (over a black background the output holds exactly the layer's light)
    cam = camera(f_number=2.0)
    h, w = 61, 79
    a = np.zeros((h, w), np.float32)
    a[25:35, 30:50] = 1.0
    a[24, 30:50] = 0.5
    c = np.zeros((h, w, 3), np.float32)
    c[..., 0], c[..., 1], c[..., 2] = 2.0 * a, 0.5 * a, a
    d = np.where(a > 0, np.linspace(0.8, 1.6, w)[None, :], np.inf).astype(np.float32)
    frame = Frame(color=np.zeros((h, w, 3), np.float32), depth=np.full((h, w), 3.0, np.float32),
                  front=front_layer(c, a, d))
    r = np.abs(coc_px(cam, d[a > 0], w))
    assert 3 < r.max() < 20
    out = run(cam, frame).color
    np.testing.assert_allclose(out.sum(axis=(0, 1)), c.sum(axis=(0, 1)), rtol=2e-4)
    assert (out[..., 0] > 0).sum() > 1.5 * (a > 0).sum()  # and it did spread


def test_a_missed_depth_sample_takes_the_layer_s_nearest_neighbour():
    a = np.zeros((5, 7), np.float32)
    a[1:4, 1:5] = 1.0
    a[2, 6] = 0.2  # an isolated speck: no covered neighbour with a depth
    d = np.full((5, 7), np.inf, np.float32)
    d[1:4, 1:5] = 2.0
    d[2, 2] = 1.5
    d[1, 1] = d[3, 4] = np.inf  # the depth pass's one sample missed the layer there
    f = front_layer(a[..., None] * np.ones(3), a, d)
    assert f[1, 1, 4] == 1.5 and f[3, 4, 4] == 2.0
    assert np.isinf(f[2, 6, 4]) and np.isinf(f[0, 0, 4])
    np.testing.assert_array_equal(f[..., :3], a[..., None] * np.ones(3))  # premultiplied as given
    g = front_layer(np.full((5, 7, 3), 2.0), a, d, premultiplied=False)
    np.testing.assert_allclose(g[..., 0], 2.0 * a)
    # a partly covered edge whose one depth sample hit what lies behind (a held-out wall at 30 m)
    # takes the layer's depth; a fully covered pixel keeps its own, even beside a nearer one
    a2 = a.copy()
    a2[1:4, 5] = 0.4
    d2 = d.copy()
    d2[1:4, 5] = 30.0
    f2 = front_layer(a2[..., None] * np.ones(3), a2, d2)
    np.testing.assert_array_equal(f2[1:4, 5, 4], [2.0, 2.0, 2.0])
    assert f2[2, 3, 4] == 2.0 and f2[2, 2, 4] == 1.5


def test_the_output_frame_has_no_front_layer_and_the_plan_needs_one_every_frame():
    cam = camera()
    frame = layered(33, 21)
    pipe = Pipeline(cam, stages=STAGES)
    out = pipe.run(frame)
    assert out.front is None
    plan = pipe.plan_for(frame)
    with pytest.raises(InputError, match="front_layer.*front"):
        plan.run(frame.replace(front=None))
    # Pipeline.run plans again without it
    assert "front_layer" not in pipe.plan(frame.replace(front=None))


def test_a_front_layer_is_never_dropped_silently():
    frame = layered(33, 21)
    with pytest.raises(InputError, match="front layer.*add front_layer to --stages"):
        Pipeline(camera(), stages=["dof"]).run(frame)
    with pytest.raises(InputError, match="'front_layer' works on the output of the 'dof' stage"):
        Pipeline(camera(), stages=["front_layer"]).run(layered(33, 21, far_bg=True))


@pytest.mark.parametrize("bad, match", [
    (np.zeros((21, 33, 4), np.float32), r"shape \(21, 33, 4\) is not \(H, W, 5\)"),
    (np.zeros((20, 33, 5), np.float32), r"is not \(H, W, 5\)"),
    ("nan", "non-finite colour or alpha"),
    ("alpha", r"alpha outside \[0, 1\]"),
    ("depth", "depth NaN, <= 0"),
    (np.zeros((21, 33, 5), np.int32), "not a float type"),
])
def test_bad_front_layers_are_refused_with_one_line(bad, match):
    f = layered(33, 21).front.copy()
    if isinstance(bad, str):
        if bad == "nan":
            f[3, 4, 1] = np.nan
        elif bad == "alpha":
            f[3, 4, 3] = 1.5
        else:
            f[3, 4, 4] = 0.0
        bad = f
    with pytest.raises(InputError, match=match) as e:
        Frame(color=np.zeros((21, 33, 3), np.float32), front=bad)
    assert "\n" not in str(e.value)
    if "x=" in str(e.value):
        assert "(x=4, y=3)" in str(e.value)

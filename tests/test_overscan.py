"""Overscan: a render's data window beyond its display window feeds the distortion stage, the
overscan a calibration needs (``clpost render-size``) and ``--fill crop|border|overscan``."""
import math
import subprocess
import sys
import warnings

import numpy as np
import pytest

from clpost import Camera, Frame, Pipeline, exr
from clpost.calibration import OpenCVModel, overscan_px, undistort_newton
from clpost.frame import Windows
from clpost.render_size import render_size
from conftest import assert_planned

cv2 = pytest.importorskip("cv2")

# a barrel lens (k1 < 0): a render of the calibration's own size leaves its border unfilled
MODEL = OpenCVModel(96, 64, 80.0, 80.0, 47.5, 31.5, k1=-0.25, k2=0.05, p1=0.002)


def _scene(x, y):
    """A smooth image of the undistorted normalised coordinates (x, y) (RGB, > 0)."""
    return np.stack([1.0 + 0.5 * np.sin(3 * x) * np.cos(2 * y), 1.0 + 0.5 * np.cos(4 * x + y), 1.2 + 0.3 * x], -1)


def _render(model, left, top, right, bottom):
    """The pinhole render of :func:`_scene` with the calibration's K and the given overscan, as a
    Frame whose windows say so (display = the calibration's image)."""
    w, h = model.width + left + right, model.height + top + bottom
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    x = (u - left - model.cx) / model.fx
    y = (v - top - model.cy) / model.fy
    win = Windows(((-left, -top), (model.width - 1 + right, model.height - 1 + bottom)),
                  ((0, 0), (model.width - 1, model.height - 1)))
    return Frame(_scene(x, y).astype(np.float32), metadata={"windows": win})


def _truth(model, scale=1.0):
    """The distorted image's exact values: the scene at each output pixel's undistorted point
    (the output magnified by ``scale`` about c for --fill crop)."""
    v, u = np.mgrid[0:model.height, 0:model.width].astype(np.float64)
    m = OpenCVModel(model.width, model.height, model.fx * scale, model.fy * scale, model.cx, model.cy,
                    k1=model.k1, k2=model.k2, p1=model.p1)
    x, y, ok = undistort_newton(m, u, v)
    assert ok.all()
    return _scene(x, y)


def _brute_force_overscan(model, margin_px=2.0):
    """The overscan from OpenCV alone: project a dense grid of undistorted normalised points with
    cv2.projectPoints and keep those that land in the image; how far their bounds reach beyond the
    image's edges in pixels of the calibration's K, plus the margin where they do (the grid step
    bounds the error, 1/4 px)."""
    step = 1.0 / (4 * model.fx)
    xs = np.arange(-1.1, 1.1, step)
    ys = np.arange(-0.9, 0.9, step)
    gx, gy = np.meshgrid(xs, ys)
    pts = np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)], -1).reshape(-1, 1, 3)
    k = np.array([[model.fx, 0, model.cx], [0, model.fy, model.cy], [0, 0, 1]])
    uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), k, np.array(model.vector()))
    uv = uv.reshape(-1, 2)
    inside = (uv[:, 0] >= -0.5) & (uv[:, 0] <= model.width - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= model.height - 0.5)
    x, y = gx.ravel()[inside], gy.ravel()[inside]
    u0, u1 = model.fx * x.min() + model.cx, model.fx * x.max() + model.cx
    v0, v1 = model.fy * y.min() + model.cy, model.fy * y.max() + model.cy
    short = (-0.5 - u0, -0.5 - v0, u1 - (model.width - 0.5), v1 - (model.height - 0.5))
    return tuple(t + margin_px if t > 0 else 0.0 for t in short)  # a side inside the image needs none


def test_overscan_numbers_agree_with_a_brute_force_opencv_projection():
    # small images: the brute force's grid has (4 f)² points per unit² of the normalised plane
    for model in (MODEL, OpenCVModel(192, 108, 140.0, 140.0, 95.5, 53.5, k1=-0.12, k2=0.03),
                  OpenCVModel(160, 120, 125.0, 127.5, 75.0, 62.5, k1=-0.3, k2=0.1, p2=-0.003)):
        need = overscan_px(model)
        exact = _brute_force_overscan(model)
        for n, e in zip(need, exact):
            # the grid's outermost landing point lies within one grid step (1/4 px) inside the true
            # bound, and overscan_px rounds the true bound up to whole pixels
            assert max(0, math.ceil(e - 1e-9)) <= n <= max(0, math.ceil(e + 0.25 + 1e-9)), (need, exact)
        r = render_size(model)
        (x0, y0), (x1, y1) = r.data_window
        assert (x0, y0) == (-need[0], -need[1]) and (x1, y1) == (model.width - 1 + need[2], model.height - 1 + need[3])
    # a pincushion lens needs none
    assert overscan_px(OpenCVModel(96, 64, 80.0, 80.0, 47.5, 31.5, k1=0.2)) == (0, 0, 0, 0)


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_distortion_samples_the_overscan_and_leaves_no_black_border(quality):
    need = overscan_px(MODEL)
    assert min(need) > 0
    frame = _render(MODEL, *need)
    pipe = Pipeline(Camera(distortion=MODEL), quality=quality, stages=["distortion"])
    assert_planned(pipe, frame, "distortion")
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message="distortion:")  # enough overscan: no warning
        out = pipe.run(frame)
    assert out.size == (MODEL.width, MODEL.height)
    assert out.alpha is not None and np.all(out.alpha == 1.0)  # every output pixel has data
    truth = _truth(MODEL)
    err = np.abs(out.color - truth)
    # a smooth scene: the resampling error is the filter's, far below the scene's contrast (0.5)
    assert err.max() < (0.02 if quality == "draft" else 0.005), err.max()
    assert out.windows == Windows.full(MODEL.width, MODEL.height)


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_a_data_window_that_moves_between_frames_of_one_size_is_followed(quality):
    """Frames of one array size whose overscan is split differently (a render's bounding box moves):
    the plan's recorded launches must not be replayed with the first frame's principal point."""
    left, top, right, bottom = overscan_px(MODEL)
    pipe = Pipeline(Camera(distortion=MODEL), quality=quality, stages=["distortion"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        first = pipe.run(_render(MODEL, left, top, right, bottom))
        moved = _render(MODEL, left + 3, top + 2, right - 3, bottom - 2)
        again = pipe.run(moved)
        fresh = Pipeline(Camera(distortion=MODEL), quality=quality, stages=["distortion"]).run(moved)
    assert np.array_equal(again.color, fresh.color)
    # the scene moved in the arrays, not in the image: the same output, within the filter's error
    tol = 0.02 if quality == "draft" else 0.005
    for out in (first, again):
        assert np.all(out.alpha == 1.0) and np.abs(out.color - _truth(MODEL)).max() < tol


def test_without_overscan_the_border_is_black_with_alpha_0_and_one_warning_names_the_fix():
    frame = _render(MODEL, 0, 0, 0, 0)
    pipe = Pipeline(Camera(distortion=MODEL), quality="draft", stages=["distortion"])
    with pytest.warns(UserWarning, match=r"distortion: \d+ output pixel\(s\) have no data .*"
                      r"overscan .*render-size.*--fill crop.*--fill border") as rec:
        out = pipe.run(frame)
        pipe.run(frame)  # the same map: no second warning
    assert len([w for w in rec if "distortion:" in str(w.message)]) == 1
    hole = out.alpha == 0
    assert hole.any() and hole[0, 0] and hole[-1, -1] and not hole[MODEL.height // 2, MODEL.width // 2]
    assert np.all(out.color[hole] == 0)


def test_fill_border_keeps_the_border_without_a_warning():
    frame = _render(MODEL, 0, 0, 0, 0)
    pipe = Pipeline(Camera(distortion=MODEL, fill="border"), quality="draft", stages=["distortion"])
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message="distortion:")
        out = pipe.run(frame)
    assert (out.alpha == 0).sum() > 0


def test_fill_crop_magnifies_just_enough_to_fill_every_pixel():
    from clpost.stages.distortion import crop_scale

    frame = _render(MODEL, 0, 0, 0, 0)
    s = crop_scale(MODEL, frame.size, (MODEL.fx, MODEL.fy, MODEL.cx, MODEL.cy))
    assert 1.0 < s < 1.5
    pipe = Pipeline(Camera(distortion=MODEL, fill="crop"), quality="final", stages=["distortion"])
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message="distortion:")
        out = pipe.run(frame)
    assert np.all(out.alpha == 1.0)
    err = np.abs(out.color - _truth(MODEL, s))
    assert err.max() < 0.005, err.max()
    # the least such factor: 0.1 % less leaves a pixel without data
    from clpost.stages.distortion import _covered

    assert not _covered(MODEL, frame.size, (MODEL.fx, MODEL.fy, MODEL.cx, MODEL.cy), s * 0.999)
    # with enough overscan there is nothing to crop
    need = overscan_px(MODEL)
    big = _render(MODEL, *need)
    assert crop_scale(MODEL, big.size, (MODEL.fx, MODEL.fy, MODEL.cx + need[0], MODEL.cy + need[1])) == 1.0


def test_overscan_render_round_trips_through_exr_and_process(tmp_path):
    need = overscan_px(MODEL)
    frame = _render(MODEL, *need)
    exr.write_frame(tmp_path / "plate.exr", frame)
    head = exr.read_header(tmp_path / "plate.exr")[0]
    assert head.data_window == ((-need[0], -need[1]), (MODEL.width - 1 + need[2], MODEL.height - 1 + need[3]))
    back = exr.read_frame(tmp_path / "plate.exr")
    assert back.windows == frame.windows
    out = Pipeline(Camera(distortion=MODEL), quality="draft", stages=["distortion"]).run(back)
    assert np.all(out.alpha == 1.0)
    exr.write_frame(tmp_path / "out.exr", out)
    head = exr.read_header(tmp_path / "out.exr")[0]
    full = ((0, 0), (MODEL.width - 1, MODEL.height - 1))
    assert head.data_window == full and head.display_window == full


def test_render_size_cli_prints_the_overscan_and_the_blender_render(tmp_path):
    cal = tmp_path / "cam.yaml"
    cal.write_text("%YAML:1.0\n---\nimage_width: 96\nimage_height: 64\ncamera_matrix: !!opencv-matrix\n"
                   "   rows: 3\n   cols: 3\n   dt: d\n   data: [ 80., 0., 47.5, 0., 80., 31.5, 0., 0., 1. ]\n"
                   "distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n"
                   "   data: [ -0.25, 0.05, 0.002, 0., 0. ]\n")
    r = subprocess.run([sys.executable, "-m", "clpost.cli", "render-size", "--calibration", str(cal)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    left, top, right, bottom = overscan_px(MODEL)
    assert f"left {left}, top {top}, right {right}, bottom {bottom} px" in r.stdout
    assert f"data window ({-left},{-top})-({95 + right},{63 + bottom})" in r.stdout
    rs = render_size(MODEL)
    assert f"resolution {rs.big[0]}x{rs.big[1]}" in r.stdout and "shift x" in r.stdout
    r = subprocess.run([sys.executable, "-m", "clpost.cli", "render-size", "--lens", "zeiss-planar-50-f1.4"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "--size WxH" in r.stderr and "\n" not in r.stderr.strip()


def test_blender_shift_puts_the_optical_axis_where_the_larger_render_has_it():
    """The shift formula inverted: Blender's c_x = (W−1)/2 − s_x max(W, H), c_y = (H−1)/2 + s_y max(W, H)."""
    r = render_size(OpenCVModel(96, 64, 80.0, 80.0, 40.0, 35.0, k1=-0.25))
    w, h = r.big
    side = max(w, h)
    assert math.isclose((w - 1) / 2 - r.blender_shift[0] * side, r.big_c[0], abs_tol=1e-9)
    assert math.isclose((h - 1) / 2 + r.blender_shift[1] * side, r.big_c[1], abs_tol=1e-9)


def test_explain_states_the_windows_and_the_overscan_the_calibration_needs(tmp_path, capsys):
    from clpost.cli import main

    cal = tmp_path / "cam.yaml"
    cal.write_text("%YAML:1.0\n---\nimage_width: 96\nimage_height: 64\ncamera_matrix: !!opencv-matrix\n"
                   "   rows: 3\n   cols: 3\n   dt: d\n   data: [ 80., 0., 47.5, 0., 80., 31.5, 0., 0., 1. ]\n"
                   "distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n"
                   "   data: [ -0.25, 0.05, 0.002, 0., 0. ]\n")
    need = overscan_px(MODEL)
    exr.write_frame(tmp_path / "plate.exr", _render(MODEL, *need))
    assert main(["process", str(tmp_path / "plate.exr"), "-o", str(tmp_path / "o.exr"), "--calibration", str(cal),
                 "--explain"]) == 0
    text = capsys.readouterr().out
    (x0, y0), (x1, y1) = render_size(MODEL).data_window
    assert f"windows: display (0,0)-(95,63), data ({x0},{y0})-({x1},{y1})" in text
    assert f"needs {'/'.join(map(str, need))} px overscan" in text and f"the frame has {'/'.join(map(str, need))}" in text


FIELD = {"dof": dict(depth_of_field=True), "vignetting": dict(vignetting="natural"),
         "astigmatism": dict(astigmatism_mm=0.08), "coma": dict(coma_mm=0.02),
         "lateral_color": dict(lateral_color_mm=0.01)}


@pytest.mark.parametrize("stage", sorted(FIELD))
def test_stages_before_distortion_see_the_image_not_the_overscan(stage):
    """An overscan frame's pixels are the image's pixels: its pitch comes from the display
    window's width and its optical centre from the display window's place in the arrays, so the
    processed overscan frame, cut to its display window, is the processed image (away from the
    edges, where the image alone lacks the overscan's neighbours; the field stages' tiles start at
    the arrays' corner, so their per-tile shapes may differ by a sub-pixel amount)."""
    w, h, left, top, right, bottom = 96, 64, 11, 5, 7, 9
    big_w, big_h = w + left + right, h + top + bottom
    yy, xx = np.mgrid[0:big_h, 0:big_w]
    # detail at 4–9 px (what the blurs change), not white noise (which the field stages' per-tile
    # tap patterns, placed from the arrays' corner, would turn into sampling differences)
    color = np.stack([0.6 + 0.4 * np.sin(xx / 2.3) * np.cos(yy / 3.1), 0.6 + 0.4 * np.cos((xx + yy) / 2.9),
                      0.6 + 0.4 * np.sin((xx - 2 * yy) / 4.1)], -1).astype(np.float32)
    depth = np.where(np.arange(big_w)[None, :] % 23 < 11, 1.2, 7.0) * np.ones((big_h, 1))
    win = Windows(((-left, -top), (w - 1 + right, h - 1 + bottom)), ((0, 0), (w - 1, h - 1)))
    over = Frame(color, depth=depth.astype(np.float32), metadata={"windows": win})
    image = Frame(np.ascontiguousarray(color[top:top + h, left:left + w]),
                  depth=np.ascontiguousarray(depth[top:top + h, left:left + w]).astype(np.float32))
    cam = Camera(lens="thin:35", f_number=1.4, focus_distance_m=1.2, **FIELD[stage])
    out_over = Pipeline(cam, quality="final", stages=[stage]).run(over)
    out_image = Pipeline(cam, quality="final", stages=[stage]).run(image)
    cut = out_over.color[top:top + h, left:left + w]
    m = 0 if stage == "vignetting" else 20  # the gathers' reach
    a, b = cut[m:h - m, m:w - m], out_image.color[m:h - m, m:w - m]
    if stage in ("astigmatism", "coma"):
        # their kernels place tap patterns per 16×8 tile from the arrays' corner, within their
        # documented ½ px: compare the per-pixel PSF geometry of their oracles instead
        from clpost.stages import _field as fld
        from clpost.stages.astigmatism import Astigmatism
        from clpost.stages.coma import Coma

        if stage == "astigmatism":
            geo = [np.stack(Astigmatism("final").semi_axes_px(cam, f)[:2]) for f in (over, image)]
        else:
            geo = [np.stack(Coma("final").c_px(cam, f.width, f.height, fld.frame_geometry(cam, f))[::3])
                   for f in (over, image)]
        np.testing.assert_allclose(geo[0][:, top:top + h, left:left + w], geo[1], rtol=1e-9, atol=1e-12)
        return
    assert np.abs(a - b).max() < 1e-4 * np.abs(b).max(), np.abs(a - b).max()

"""ST maps (clpost/stmap.py): Nuke's convention, agreement with OpenCV's own undistortPoints /
projectPoints (an independent implementation of the same models), the round trip distort →
undistort, the domain (alpha, NO_PREIMAGE), the EXR header, and the command's bad-input paths."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.ndimage import binary_erosion, map_coordinates

from clpost import Camera, Frame, Pipeline, exr
from clpost.calibration import OpenCVModel, lens_distortion_model, load_calibration, model_from_header
from clpost.cli import main
from clpost.stmap import NO_PREIMAGE, make_stmap, map_points, st_from_xy, xy_from_st

# Held-out models: none of them is used to develop the code; sizes small for speed.
MODELS = {
    "radtan-k1-k6": OpenCVModel(320, 200, 260.0, 262.0, 161.3, 98.6, k1=0.3, k2=0.1, p1=2e-3, p2=-1e-3, k3=0.02,
                                k4=0.1, k5=0.01, k6=0.001),
    "strong-barrel": OpenCVModel(320, 200, 250.0, 250.0, 159.5, 99.5, k1=-0.38, k2=0.14, p1=1e-3, p2=5e-4),
    "strong-pincushion": OpenCVModel(320, 200, 250.0, 251.0, 158.0, 101.0, k1=0.28, k2=0.09),
    "thin-prism-tilt": OpenCVModel(320, 200, 255.0, 255.0, 160.2, 99.1, k1=-0.1, k2=0.02, s1=1e-3, s2=-2e-4,
                                   s3=5e-4, s4=1e-4, tau_x=0.01, tau_y=-0.02),
    "fisheye": OpenCVModel(320, 200, 150.0, 150.5, 160.4, 99.3, k1=0.04, k2=-0.012, k3=0.004, k4=-0.0008,
                           distortion_model="fisheye"),
}
CRIT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)


def _grid(m):
    yy, xx = np.mgrid[0:m.height, 0:m.width].astype(np.float64)
    return xx, yy


def _positions(st):
    m = st.model
    return xy_from_st(st.st[..., 0], st.st[..., 1], m.width, m.height)


def test_st_convention_is_nukes():
    # pixel (0, 0) of a 4x2 image: the centre of the top-left pixel → s = 0.5/4, t = 1 - 0.5/2
    s, t = st_from_xy(np.array([0.0, 3.0]), np.array([0.0, 1.0]), 4, 2)
    np.testing.assert_allclose(s, [0.125, 0.875])
    np.testing.assert_allclose(t, [0.75, 0.25])  # origin bottom-left: the bottom row has the small t
    np.testing.assert_allclose(xy_from_st(s, t, 4, 2), [[0, 3], [0, 1]])


@pytest.mark.parametrize("name", MODELS)
def test_distort_map_agrees_with_opencv_undistortPoints(name):
    m = MODELS[name]
    st = make_stmap(m, "distort")
    assert st.st.dtype == np.float64 and st.rgba().dtype == np.float32
    xx, yy = _grid(m)
    pts = np.stack([xx.ravel(), yy.ravel()], -1)[:, None, :]
    if m.is_fisheye:
        ref = cv2.fisheye.undistortPoints(pts, m.matrix(), m.coefficients(), P=m.matrix(), criteria=CRIT)[:, 0]
    else:
        ref = cv2.undistortPoints(pts, m.matrix(), m.vector(), P=m.matrix(), criteria=CRIT)[:, 0]
    x, y = _positions(st)
    ok = (st.st[..., 0] != NO_PREIMAGE).ravel()
    assert ok.all(), name  # no fold inside these images
    err = np.hypot(x.ravel() - ref[:, 0], y.ravel() - ref[:, 1])
    # OpenCV's fixed-point iteration does not converge everywhere for the strongest models: compare where
    # OpenCV's own answer projects back onto the pixel (its residual < 1e-6 px)
    back = _project_cv(m, (ref[:, 0] - m.cx) / m.fx, (ref[:, 1] - m.cy) / m.fy)
    conv = np.hypot(back[:, 0] - pts[:, 0, 0], back[:, 1] - pts[:, 0, 1]) < 1e-6
    assert conv.mean() > 0.95, (name, conv.mean())
    assert err[conv].max() < 1e-3, (name, err[conv].max())


def _project_cv(m, xn, yn):
    obj = np.stack([xn, yn, np.ones_like(xn)], -1)[:, None, :]
    if m.is_fisheye:
        return cv2.fisheye.projectPoints(obj, np.zeros(3), np.zeros(3), m.matrix(), m.coefficients())[0][:, 0]
    return cv2.projectPoints(obj, np.zeros(3), np.zeros(3), m.matrix(), m.vector())[0][:, 0]


@pytest.mark.parametrize("name", MODELS)
def test_undistort_map_agrees_with_opencv_projectPoints(name):
    m = MODELS[name]
    st = make_stmap(m, "undistort")
    xx, yy = _grid(m)
    ref = _project_cv(m, ((xx - m.cx) / m.fx).ravel(), ((yy - m.cy) / m.fy).ravel())
    u, v = _positions(st)
    err = np.hypot(u.ravel() - ref[:, 0], v.ravel() - ref[:, 1])
    assert err.max() < 1e-3, (name, err.max())


@pytest.mark.parametrize("name", MODELS)
def test_the_two_maps_are_each_others_inverse(name):
    # exact composition: every undistorted pixel p → plate position q (undistort map) → the distort map
    # evaluated at q gives p back
    m = MODELS[name]
    xx, yy = _grid(m)
    qx, qy, ok = map_points(m, "undistort", xx, yy)
    px, py, ok2 = map_points(m, "distort", qx, qy)
    assert ok.all() and ok2.all()
    assert np.hypot(px - xx, py - yy).max() < 1e-5


@pytest.mark.parametrize("name,size,order", [("strong-barrel", (960, 600), 1), ("strong-pincushion", (960, 600), 1),
                                             ("fisheye", (960, 600), 3), ("radtan-k1-k6", (640, 400), 3)])
def test_round_trip_through_images_returns_each_pixel_within_1e3_px(name, size, order):
    """As in Nuke: a plate whose pixels hold their own (x, y) is distorted with the distort map, then
    undistorted with the undistort map; each pixel must come back to its own position. Only pixels
    whose samples stay inside the images count (elsewhere there is no data without overscan).
    Sampling: bilinear (order 1), or cubic B-spline interpolation (order 3, the distortion stage's
    final filter) where bilinear's own error is larger — a bilinear round trip of the fisheye at this
    size is off by up to 1.8e-3 px (its map bends more per pixel): the filter's error, not the maps'
    (their exact composition: test_the_two_maps_are_each_others_inverse)."""
    m = MODELS[name].scaled_to(*size)
    d, u = make_stmap(m, "distort"), make_stmap(m, "undistort")
    w, h = size
    xx, yy = _grid(m)
    plate = np.stack([xx, yy])  # the undistorted plate: each pixel its own position

    def stmap_node(image, st):  # Nuke's STMap: sample image at the map's (s, t)
        x, y = xy_from_st(st.st[..., 0], st.st[..., 1], w, h)
        return np.stack([map_coordinates(c, [y, x], order=order, mode="nearest") for c in image]), x, y

    distorted, dx, dy = stmap_node(plate, d)
    back, ux, uy = stmap_node(distorted, u)
    e = 0 if order == 1 else 6  # the spline's prefilter feels the edge padding a few pixels in
    inside = (u.alpha > 0) & (ux >= e) & (ux <= w - 1 - e) & (uy >= e) & (uy <= h - 1 - e)
    # the distorted pixels each undistorted pixel reads must themselves have read inside the plate
    dok = (d.alpha > 0) & (dx >= e) & (dx <= w - 1 - e) & (dy >= e) & (dy <= h - 1 - e)
    dok = binary_erosion(dok, iterations=e).astype(float) if e else dok.astype(float)
    inside &= map_coordinates(dok, [uy, ux], order=1, mode="nearest") > 1 - 1e-9
    assert inside.mean() > 0.6
    err = np.hypot(back[0] - xx, back[1] - yy)[inside]
    assert err.max() < 1e-3, (name, err.max())


def test_domain_alpha_and_no_preimage():
    # barrel: the distorted image's corners see beyond the undistorted frame (overscan: s outside
    # [0, 1], alpha 0, values kept); pincushion: the undistorted frame's corners lie outside the plate
    d = make_stmap(MODELS["strong-barrel"], "distort")
    assert d.alpha[0, 0] == 0 and d.st[0, 0, 0] < 0 and d.st[0, 0, 0] != NO_PREIMAGE
    assert d.alpha[100, 160] == 1 and 0 < d.st[100, 160, 0] < 1
    u = make_stmap(MODELS["strong-pincushion"], "undistort")
    assert u.alpha[0, 0] == 0 and u.alpha[100, 160] == 1
    np.testing.assert_array_equal(u.alpha > 0, (u.st[..., 0] >= 0) & (u.st[..., 0] <= 1)
                                  & (u.st[..., 1] >= 0) & (u.st[..., 1] <= 1))
    # a model that folds: k1 < 0 alone turns back at r = 1/sqrt(-3 k1); beyond that no preimage
    fold = OpenCVModel(320, 200, 80.0, 80.0, 159.5, 99.5, k1=-0.3)
    for direction in ("distort", "undistort"):
        st = make_stmap(fold, direction)
        none = st.st[..., 0] == NO_PREIMAGE
        assert none.any() and not none[100, 160]
        assert (st.alpha[none] == 0).all() and (st.st[none] == NO_PREIMAGE).all()


@pytest.mark.parametrize("m", [OpenCVModel(97, 61, 90.0, 91.0, 47.0, 29.5, k1=-0.2, k2=0.03, p1=1e-3),
                               OpenCVModel(97, 61, 60.0, 60.0, 48.0, 30.0, k1=0.02, k2=0.01,
                                           distortion_model="fisheye")], ids=["radtan", "fisheye"])
def test_the_distort_map_carries_the_distortion_stage_s_distortion(m):
    # the same model through `clpost process` (draft: bilinear) and through the map (bilinear): one distortion
    rng = np.random.default_rng(7)
    img = rng.random((61, 97, 3)).astype(np.float32)
    out = Pipeline(Camera(distortion=m), stages=["distortion"], quality="draft").run(Frame(img))
    st = make_stmap(m)
    x, y = _positions(st)
    ref = np.stack([map_coordinates(img[..., c].astype(np.float64), [y, x], order=1, mode="nearest")
                    for c in range(3)], -1)
    inside = out.alpha > 0.999
    assert inside.mean() > 0.6
    np.testing.assert_array_equal(inside, st.alpha > 0)
    assert np.abs(out.color[inside] - ref[inside]).max() < 1e-4


def _run(argv, capsys):
    try:
        rc = main(argv)
    except SystemExit as e:  # argparse's usage errors
        rc = e.code
    return rc, capsys.readouterr()


CALIB = """%YAML:1.0
---
image_width: 64
image_height: 40
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 55., 0., 31.7, 0., 55.5, 19.2, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ -0.21, 0.04, 1.e-03, -5.e-04, 0. ]
"""


def test_cli_writes_float32_rgba_with_its_header(tmp_path, capsys):
    (tmp_path / "cam.yaml").write_text(CALIB)
    out = tmp_path / "st.exr"
    rc, io = _run(["stmap", "-o", str(out), "--calibration", str(tmp_path / "cam.yaml")], capsys)
    assert rc == 0, io.err
    m = load_calibration(tmp_path / "cam.yaml")
    f = exr.read_frame(out)
    assert f.color.dtype == np.float32 and f.color.shape == (40, 64, 3) and f.alpha is not None
    ref = make_stmap(m)
    np.testing.assert_array_equal(f.color[..., :2], ref.st.astype(np.float32))
    assert (f.color[..., 2] == 0).all()
    _, strings = exr.read_attributes(out)
    assert strings["clpost.stmap.direction"] == "distort" and strings["clpost.stmap.size"] == "64x40"
    assert strings["clpost.stmap.source"].endswith("cam.yaml")
    assert model_from_header(strings["clpost.distortion"]) == m
    rc, io = _run(["stmap", "-o", str(tmp_path / "u.exr"), "--calibration", str(tmp_path / "cam.yaml"),
                   "--undistort", "--size", "128x80"], capsys)
    assert rc == 0, io.err
    _, strings = exr.read_attributes(tmp_path / "u.exr")
    assert strings["clpost.stmap.direction"] == "undistort" and strings["clpost.stmap.size"] == "128x80"


def test_cli_lens_map_is_the_traced_model(tmp_path, capsys):
    out = tmp_path / "lens.exr"
    rc, io = _run(["stmap", "-o", str(out), "--lens", "zeiss-planar-50-f1.4", "--f-number", "2", "--focus", "3",
                   "--size", "96x64"], capsys)
    assert rc == 0, io.err
    m = lens_distortion_model(Camera(lens="zeiss-planar-50-f1.4", f_number=2.0, focus_distance_m=3.0), (96, 64))
    f = exr.read_frame(out)
    np.testing.assert_array_equal(f.color[..., :2], make_stmap(m).st.astype(np.float32))


@pytest.mark.parametrize("argv,msg", [
    (["--calibration", "{d}/missing.yaml"], "not found"),
    (["--lens", "thin:50"], "thin lens"),
    ([], "give --calibration"),
    (["--calibration", "{d}/cam.yaml", "--size", "100x100"], "aspect"),
])
def test_cli_bad_input_is_one_line_exit_2_nothing_written(tmp_path, capsys, argv, msg):
    (tmp_path / "cam.yaml").write_text(CALIB)
    out = tmp_path / "st.exr"
    rc, io = _run(["stmap", "-o", str(out)] + [a.format(d=tmp_path) for a in argv], capsys)
    assert rc == 2 and msg in io.err and len(io.err.strip().splitlines()) == 1, io.err
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["cam.yaml"]


def test_cli_never_overwrites_or_writes_over_its_input(tmp_path, capsys):
    (tmp_path / "cam.yaml").write_text(CALIB)
    out = tmp_path / "st.exr"
    out.write_bytes(b"keep")
    rc, io = _run(["stmap", "-o", str(out), "--calibration", str(tmp_path / "cam.yaml")], capsys)
    assert rc == 2 and "--overwrite" in io.err and out.read_bytes() == b"keep"
    rc, io = _run(["stmap", "-o", str(tmp_path / "st.png"), "--calibration", str(tmp_path / "cam.yaml")], capsys)
    assert rc == 2 and ".exr" in io.err and not (tmp_path / "st.png").exists()
    rc, io = _run(["stmap", "-o", str(out), "--calibration", str(tmp_path / "cam.yaml"), "--overwrite"], capsys)
    assert rc == 0 and exr.read_frame(out).color.shape == (40, 64, 3)


def test_the_readmes_matchmove_commands_run(tmp_path, capsys, monkeypatch):
    # every `clpost stmap` / `clpost calibration` line of README's "Matchmove workflow" section, on a real file
    import shlex
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    section = readme.split("## Matchmove workflow", 1)[1].split("\n## ", 1)[0]
    lines = [ln.split("#", 1)[0].strip() for ln in section.splitlines()
             if ln.startswith(("clpost stmap", "clpost calibration"))]
    assert len(lines) >= 5
    (tmp_path / "cam.yaml").write_text(CALIB)
    monkeypatch.chdir(tmp_path)
    for ln in lines:
        argv = shlex.split(ln)[1:]
        if "--lens" in argv:  # the README's 1920x1080 traced map: the same command, smaller
            argv[argv.index("--size") + 1] = "96x54"
        rc, io = _run(argv + (["--overwrite"] if argv[0] == "stmap" else []), capsys)
        assert rc == 0, (ln, io.err)

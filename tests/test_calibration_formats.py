"""Calibration formats (clpost/calibration/formats.py, writers.py, header.py): files written the
way OpenCV, ROS, COLMAP and Kalibr write them (tests/data/calibration/, each citing its format's
documentation), OpenCV's own FileStorage as an independent reader of what clpost writes, every
writer read back exactly, the refusals, the EXR header's named fields (and the old bare list), and
``clpost calibration convert``."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from clpost import Camera
from clpost.calibration import (FORMATS, OpenCVModel, calibration_text, header_text, load_calibration,
                                model_from_header, write_calibration)
from clpost.cli import main
from clpost.errors import InputError

DATA = Path(__file__).parent / "data" / "calibration"


def _same(a: OpenCVModel, b: OpenCVModel) -> bool:
    return replace(a, source="") == replace(b, source="")


# (file, expected fields) — the numbers as the fixture holds them; COLMAP's principal point is 0.5 px
# further (its pixel-corner origin)
EXPECTED = {
    "opencv_tutorial.yml": dict(width=1280, height=720, fx=1.0468541860435474e+03, cy=3.6218311457916224e+02,
                                k1=-2.2916487298553811e-01, p2=1.1930263214418234e-03, k3=-5.8512004712101946e-02),
    "opencv_fisheye_K_D.yml": dict(width=1920, distortion_model="fisheye", k1=3.8402651493112461e-02,
                                   k4=-8.5436787451021483e-04, fx=6.1261218768358215e+02),
    "opencv_tutorial.xml": dict(width=640, height=480, fy=5.3222935238437823e+02, k3=1.6324785543123567e-01,
                                k4=1.2e-02, k6=5.1e-02),
    "opencv_mtx_dist.json": dict(width=800, fx=8.2012345678901234e+02, p1=4.0000000000000001e-03),
    "ros_plumb_bob.yaml": dict(width=640, fx=430.21554, cx=306.6913, k1=-0.337173, p2=-0.000263),
    "ros_equidistant.yaml": dict(height=800, distortion_model="fisheye", k3=-0.0389, k4=0.0069),
    "ros_rational.yaml": dict(width=1920, k4=1.87, k6=0.13, p1=-0.0003),
    "ros2_camera_info_echo.yaml": dict(width=640, height=480, fx=430.21554, k2=0.093903),
    "cameras.txt#1": dict(width=3072, fx=2559.81, fy=2559.81, cx=1535.5, cy=1151.5, k1=0.0),
    "cameras.txt#2": dict(fx=2560.56, cx=1535.5),
    "cameras.txt#3": dict(k1=-0.0218531, cy=1151.5),
    "cameras.txt#4": dict(k1=-0.12, k2=0.034, cx=959.75),
    "cameras.txt#5": dict(fx=1650.1, fy=1648.7, cx=960.8, p1=0.0011, p2=-0.0007),
    "cameras.txt#6": dict(k3=0.02, k4=0.52, k5=0.09, k6=0.004),
    "cameras.txt#7": dict(distortion_model="fisheye", cx=642.31, k1=-0.0074, k4=0.0069),
    "cameras.txt#8": dict(distortion_model="fisheye", fx=290.5, k1=0.021, k2=0.0),
    "camchain.yaml#cam0": dict(width=752, height=480, fx=461.629, cx=362.680, k1=-0.27695497, p2=0.00011556),
    "camchain.yaml#1": dict(distortion_model="fisheye", fy=457.296, k1=-0.0084, k4=0.0061),
    "cameras.txt#9": dict(distortion_model="fov", fx=285.72, cx=642.31, omega=0.93),
    "cameras.txt#10": dict(distortion_model="thinprism", fy=286.0, k1=0.01, k2=0.02, p1=0.001, p2=0.002, k3=0.0003,
                           k4=0.0004, s1=0.0001, s3=0.0002, cx=639.5),
    "camchain.yaml#cam2": dict(distortion_model="ucm", xi=0.8, fx=461.629, cx=362.680, k1=-0.27695497,
                               p2=0.00011556),
    "camchain_ds.yaml#cam0": dict(distortion_model="ds", xi=-0.2, alpha=0.59, fx=347.0, cy=510.8, width=1024),
    "camchain_ds.yaml#cam1": dict(distortion_model="fov", omega=0.92, fx=276.3, cx=376.8),
}


@pytest.mark.parametrize("name", EXPECTED)
def test_each_tools_file_reads_as_written(name):
    m = load_calibration(DATA / name)
    for key, value in EXPECTED[name].items():
        assert getattr(m, key) == value, (name, key, getattr(m, key), value)
    if m.distortion_model == "opencv" and "distortion_model" not in EXPECTED[name]:
        assert not m.is_fisheye


@pytest.mark.parametrize("name", ["opencv_tutorial.yml", "opencv_fisheye_K_D.yml", "opencv_tutorial.xml",
                                  "opencv_mtx_dist.json"])
def test_opencv_files_agree_with_opencvs_own_reader(name):
    m = load_calibration(DATA / name)
    fs = cv2.FileStorage(str(DATA / name), cv2.FILE_STORAGE_READ)
    k = next(fs.getNode(n).mat() for n in ("camera_matrix", "K", "mtx") if not fs.getNode(n).empty())
    d = next(fs.getNode(n).mat() for n in ("distortion_coefficients", "D", "dist") if not fs.getNode(n).empty())
    np.testing.assert_array_equal(m.matrix(), k)
    np.testing.assert_array_equal(m.coefficients()[:d.size], d.ravel())
    assert (m.width, m.height) == (int(fs.getNode("image_width").real()), int(fs.getNode("image_height").real()))


@pytest.mark.parametrize("name,msg", [
    ("cameras.txt", "10 cameras"),
    ("camchain.yaml", "3 cameras"),
    ("camchain.yaml#cam7", "no camera 'cam7'"),
])
def test_models_clpost_cannot_express_are_refused_in_one_line_naming_them(name, msg):
    with pytest.raises(InputError, match=msg) as e:
        load_calibration(DATA / name)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("text,msg", [
    ("image_width: 6\nimage_height: 4\nK: [5, 0, 1, 0, 5, 1, 0, 0, 1]\ncamera_matrix: [6, 0, 1, 0, 5, 1, 0, 0, 1]\n"
     "D: [0, 0, 0, 0]\n", "given twice"),
    ("image_width: 6\nimage_height: 4\nK: [5, 0, 1, 0, 5, 1, 0, 0, 1]\nD: [0, 0, 0, 0]\ndistortion_model: kb8\n",
     "'kb8' is not a model"),
    ("image_width: 6\nimage_height: 4\nK: [5, 0, 1, 0, 5, 1, 0, 0, 1]\nD: [0, 0, 0, 0]\ndistortion_model: fov\n",
     "fov model needs omega"),
    ("1 RAD_TAN_THIN_PRISM_FISHEYE 640 480 500 500 320 240 0 0 0 0 0 0 0 0 0 0 0 0\n",
     "COLMAP model RAD_TAN_THIN_PRISM_FISHEYE is not supported"),
    ("cam0:\n  camera_model: omni\n  intrinsics: [0.8, 1, 1, 1, 1]\n  distortion_model: equidistant\n"
     "  distortion_coeffs: [0, 0, 0, 0]\n  resolution: [4, 4]\n", "omni-equidistant is not supported"),
    ("cam0:\n  camera_model: eucm\n  intrinsics: [0.6, 1.1, 1, 1, 1, 1]\n  distortion_model: none\n"
     "  distortion_coeffs: []\n  resolution: [4, 4]\n", "camera_model 'eucm' is not supported"),
    ("cam0:\n  camera_model: ds\n  intrinsics: [0.1, 0.6, 1, 1, 1]\n  distortion_model: none\n"
     "  distortion_coeffs: []\n  resolution: [4, 4]\n", r"ds intrinsics must be \[xi, alpha, fx, fy, cx, cy\]"),
    ("image_width: 6\nimage_height: 4\nK: [5, 0, 1, 0, 5, 1, 0, 0, 1]\nD: [0, 0, 0, 0, 0]\n"
     "distortion_model: equidistant\n", "fisheye .*has 4"),
    ("cam0:\n  camera_model: pinhole\n  intrinsics: [1, 1, 1, 1]\n  distortion_model: radtan\n"
     "  distortion_coeffs: [0.1, 0.2]\n  resolution: [4, 4]\n", "needs 4 distortion_coeffs"),
    ('<?xml version="1.0"?>\n<storage><a>1</a></storage>\n', "not an OpenCV FileStorage"),
    ("1 OPENCV 640 480 500 500 320 240\n", "needs 8 parameters"),
])
def test_bad_files_are_one_line_naming_the_fix(tmp_path, text, msg):
    p = tmp_path / "bad.yaml"
    p.write_text(text)
    with pytest.raises(InputError, match=msg) as e:
        load_calibration(p)
    assert "\n" not in str(e.value)


MODELS = {
    "plumb_bob": OpenCVModel(640, 480, 501.123456789012, 500.5, 319.25, 239.75, k1=-0.1234567890123, k2=1e-5,
                             p1=1e-4, p2=-3.3e-5, k3=0.01),
    "rational": OpenCVModel(1920, 1080, 1500.0, 1501.0, 959.5, 539.5, k1=0.3, k2=0.1, k3=0.02, k4=0.1, k5=0.01,
                            k6=0.001),
    "radtan4": OpenCVModel(752, 480, 461.629, 460.152, 362.68, 246.049, k1=-0.27695497, k2=0.06712482,
                           p1=0.00087538, p2=0.00011556),
    "fisheye": OpenCVModel(1280, 800, 285.72, 286.05, 642.31, 398.77, k1=-0.0074, k2=0.0411, k3=-0.0389,
                           k4=0.0069, distortion_model="fisheye"),
    "pinhole": OpenCVModel(320, 200, 300.0, 300.0, 159.5, 99.5),
    "thin_prism_tilt": OpenCVModel(640, 480, 500.0, 500.0, 319.5, 239.5, k1=-0.1, s1=1e-3, tau_y=0.01),
    "ucm": OpenCVModel(752, 480, 461.629, 460.152, 362.68, 246.049, xi=0.8, k1=-0.27695497, p2=0.00011556,
                       distortion_model="ucm"),
    "ucm_plain": OpenCVModel(752, 480, 461.629, 460.152, 362.68, 246.049, xi=1.2, distortion_model="ucm"),
    "ds": OpenCVModel(1024, 1024, 347.0, 346.5, 511.2, 510.8, xi=-0.2, alpha=0.59, distortion_model="ds"),
    "fov": OpenCVModel(752, 480, 276.3, 276.1, 376.8, 239.9, omega=0.92, distortion_model="fov"),
    "ftheta": OpenCVModel(1920, 1208, 530.1, 530.1, 959.2, 603.7, k1=-0.012, k2=0.0031, k3=-4e-4, k4=1e-5,
                          distortion_model="ftheta"),
    "thinprism": OpenCVModel(1280, 800, 285.0, 286.0, 639.5, 399.5, k1=0.01, k2=0.02, p1=0.001, p2=0.002,
                             k3=0.0003, k4=0.0004, s1=0.0001, s3=0.0002, distortion_model="thinprism"),
}
CANNOT = {("rational", "kalibr"), ("thin_prism_tilt", "ros"), ("thin_prism_tilt", "colmap"),
          ("thin_prism_tilt", "kalibr"), ("plumb_bob", "kalibr")}
CANNOT |= {(n, "ros") for n in ("ucm", "ucm_plain", "ds", "fov", "ftheta", "thinprism")}
CANNOT |= {(n, "colmap") for n in ("ucm", "ucm_plain", "ds", "ftheta")}
CANNOT |= {(n, "kalibr") for n in ("ftheta", "thinprism")}


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("name", MODELS)
def test_every_writer_reads_back_exactly_or_refuses(tmp_path, fmt, name):
    m = MODELS[name]
    out = tmp_path / ("cameras.txt" if fmt == "colmap" else f"cam{FORMATS[fmt][0]}")
    if (name, fmt) in CANNOT:
        with pytest.raises(InputError, match="cannot express") as e:
            write_calibration(m, out, fmt)
        assert "\n" not in str(e.value) and not out.exists()
        return
    assert write_calibration(m, out, fmt) == fmt
    back = load_calibration(out)
    assert _same(back, m), (fmt, back, m)
    if fmt.startswith("opencv"):  # OpenCV reads what clpost writes, to the bit
        fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
        np.testing.assert_array_equal(fs.getNode("camera_matrix").mat(), m.matrix())
        node = fs.getNode("distortion_coefficients")
        d = node.mat().ravel() if not node.empty() else np.zeros(0)
        ref = np.array([getattr(m, n) for n in m.coeff_names if n not in ("xi", "alpha", "omega")])
        np.testing.assert_array_equal(d, ref[:d.size])
        if m.distortion_model in ("opencv", "fisheye"):
            assert not np.any(m.coefficients()[d.size:])
        assert int(fs.getNode("fisheye_model").real()) == int(m.is_fisheye)


def test_writers_use_the_formats_model_names():
    assert "distortion_model: plumb_bob" in calibration_text(MODELS["plumb_bob"], "ros")
    assert "distortion_model: rational_polynomial" in calibration_text(MODELS["rational"], "ros")
    assert "distortion_model: equidistant" in calibration_text(MODELS["fisheye"], "ros")
    assert "1 FULL_OPENCV 1920 1080 1500.0 1501.0 960.0 540.0 " in calibration_text(MODELS["rational"], "colmap")
    assert "1 OPENCV_FISHEYE" in calibration_text(MODELS["fisheye"], "colmap")
    assert "1 PINHOLE 320 200 300.0 300.0 160.0 100.0\n" in calibration_text(MODELS["pinhole"], "colmap")
    assert "distortion_model: equidistant" in calibration_text(MODELS["fisheye"], "kalibr")
    y = calibration_text(MODELS["plumb_bob"], "opencv-yaml")
    assert y.startswith("%YAML:1.0\n---\n") and "camera_matrix: !!opencv-matrix" in y and "cols: 5" in y
    assert "cols: 8" in calibration_text(MODELS["rational"], "opencv-yaml")
    assert "cols: 14" in calibration_text(MODELS["thin_prism_tilt"], "opencv-yaml")


@pytest.mark.parametrize("name", MODELS)
def test_header_named_fields_read_back_exactly(name):
    m = MODELS[name]
    text = header_text(m)
    assert text.startswith(f"model={m.distortion_model} width={m.width} height={m.height} fx=")
    assert _same(model_from_header(text), m)
    if m.distortion_model == "opencv":
        assert "k1=" in text and "p2=" in text and "k3=" in text


def test_header_still_reads_the_old_bare_list():
    old = "640 480 500 500 319.5 239.5 -0.1 0 0 0 0 0 0 0 0 0 0 0 0 0"  # what describe() wrote before issue 19
    m = model_from_header(old)
    assert _same(m, OpenCVModel(640, 480, 500.0, 500.0, 319.5, 239.5, k1=-0.1))
    with pytest.raises(InputError, match="unknown fields"):
        model_from_header("model=opencv width=4 height=4 fx=1 fy=1 cx=1 cy=1 q9=3")
    with pytest.raises(InputError, match="lacks"):
        model_from_header("model=opencv width=4 height=4 fx=1")


def test_camera_from_keeps_a_fisheye_calibration_exactly():
    from clpost.camera_sources import values_from_header

    cam = Camera(distortion=MODELS["fisheye"])
    assert cam.describe()["clpost.distortion"].startswith("model=fisheye ")
    assert Camera(**values_from_header(cam.describe(), "x.exr", Camera)) == cam


def _run(argv, capsys):
    try:
        rc = main(argv)
    except SystemExit as e:
        rc = e.code
    return rc, capsys.readouterr()


def test_cli_convert_between_formats_and_from_an_outputs_header(tmp_path, capsys):
    src = DATA / "opencv_tutorial.yml"
    rc, io = _run(["calibration", "convert", str(src), "-o", str(tmp_path / "cameras.txt")], capsys)
    assert rc == 0, io.err
    assert _same(load_calibration(tmp_path / "cameras.txt"), load_calibration(src))
    rc, io = _run(["calibration", "convert", str(DATA / "camchain.yaml#cam1"), "-o", str(tmp_path / "ros.yaml"),
                   "--format", "ros"], capsys)
    assert rc == 0, io.err
    assert load_calibration(tmp_path / "ros.yaml").is_fisheye
    # the effective camera recorded in an output's header (an STMap's, as `clpost process` writes it)
    rc, io = _run(["stmap", "-o", str(tmp_path / "st.exr"), "--calibration", str(DATA / "ros_plumb_bob.yaml"),
                   "--size", "160x120"], capsys)
    assert rc == 0, io.err
    rc, io = _run(["calibration", "convert", str(tmp_path / "st.exr"), "-o", str(tmp_path / "back.xml")], capsys)
    assert rc == 0, io.err
    assert _same(load_calibration(tmp_path / "back.xml"), load_calibration(DATA / "ros_plumb_bob.yaml").scaled_to(160, 120))
    rc, io = _run(["calibration", "show", str(DATA / "ros_rational.yaml")], capsys)
    assert rc == 0 and "model=opencv width=1920 height=1200" in io.out and "k6=0.13" in io.out


@pytest.mark.parametrize("argv,msg", [
    (["{d}/cam.yaml", "-o", "{d}/cam.yaml"], "is the input"),
    (["{d}/cam.yaml", "-o", "{d}/out.cfg"], "cannot tell the format"),
    (["{d}/cam.yaml", "-o", "{d}/exists.yaml"], "--overwrite"),
    (["{d}/cam.yaml", "-o", "{d}/k.yaml", "--format", "kalibr"], "cannot express"),
    (["{d}/nope.yaml", "-o", "{d}/x.yaml"], "not found"),
])
def test_cli_convert_bad_input_one_line_exit_2_nothing_touched(tmp_path, capsys, argv, msg):
    (tmp_path / "cam.yaml").write_text(calibration_text(MODELS["rational"], "opencv-yaml"))
    (tmp_path / "exists.yaml").write_text("keep")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    rc, io = _run(["calibration", "convert"] + [a.format(d=tmp_path) for a in argv], capsys)
    assert rc == 2 and msg in io.err and len(io.err.strip().splitlines()) == 1, io.err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before

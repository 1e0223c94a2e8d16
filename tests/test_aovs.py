"""Diagnostic passes (--aovs): thin-lens CoC, focus matte and motion-blur length against closed
forms in float64, device vs oracle, the EXR channels the CLI writes, bad requests in one line."""
import math

import numpy as np
import pytest

from clpost import Camera, Frame, aovs, exr
from clpost.cli import main
from clpost.errors import InputError
from clpost.runtime import get_runtime

W, H = 37, 23


def _frame(rng, depth=True, velocity=True):
    d = rng.uniform(0.25, 60.0, (H, W)) if depth else None
    if depth:
        d[0, :5] = np.inf  # sky: the finite far limit
        d[1, :5] = 3.0     # exactly in focus
    v = rng.normal(0.0, 8.0, (H, W, 2)) if velocity else None
    return Frame(rng.random((H, W, 3)).astype(np.float32), depth=None if d is None else d.astype(np.float32),
                 velocity=None if v is None else v.astype(np.float32))


def thin_lens_coc_px(f_mm, n, focus_m, depth_m, pitch_mm):
    """Classic thin-lens blur-circle diameter, signed (far > 0): c = f² (S − u) / (N S (u − f)),
    all lengths in mm, over the pixel pitch — written independently of clpost's form."""
    u, s = focus_m * 1e3, np.asarray(depth_m, np.float64) * 1e3
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.where(np.isinf(s), f_mm ** 2 / (n * (u - f_mm)), f_mm ** 2 * (s - u) / (n * s * (u - f_mm)))
    return c / pitch_mm


CAM = Camera(lens="thin:50", f_number=2.0, focus_distance_m=3.0, frame_rate_fps=24.0, shutter_s=1 / 48,
             sensor_mm=(36.0, 24.0))


def test_coc_is_the_closed_form_thin_lens_coc(rng):
    f = _frame(rng)
    want = thin_lens_coc_px(50.0, 2.0, 3.0, f.depth.astype(np.float64), 36.0 / W)
    ref = aovs.reference(CAM, f, ("coc",))["coc.Y"]
    np.testing.assert_allclose(ref, want, rtol=1e-12, atol=1e-12)
    dev = aovs.compute(get_runtime(), CAM, f, ("coc",))["coc.Y"]
    assert dev.dtype == np.float32
    np.testing.assert_allclose(dev, want, rtol=2e-6, atol=1e-5)
    # sign convention: near < 0, far > 0, 0 on the focus plane; the sky at the finite far limit
    assert np.all(ref[f.depth < 3.0] < 0) and np.all(ref[f.depth > 3.0] > 0)
    assert np.all(ref[1, :5] == 0.0)
    np.testing.assert_allclose(ref[0, 0], 50.0 ** 2 / (2.0 * 2950.0) / (36.0 / W), rtol=1e-12)


def test_focus_matte_is_one_inside_the_depth_of_field(rng):
    assert math.isclose(aovs.coc_limit_mm(CAM), math.hypot(36, 24) / 1500)
    big = Camera(lens="thin:50", f_number=2.0, focus_distance_m=3.0)
    w = 4000  # 9 µm pixels: the CoC limit is 3.2 px
    lim_px = aovs.coc_limit_mm(big) / (36.0 / w)
    # depths whose CoC is 0, ½, 1, 1.5, 2, 3 limits behind the focus: solve the closed form for S
    k = 50.0 ** 2 / (2.0 * (3000.0 - 50.0)) / (36.0 / w)  # c(S) = k (1 − u/S)
    ratios = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 3.0])
    s = 3.0 / (1.0 - ratios * lim_px / k)
    depth = np.full((1, w), 3.0)
    depth[0, :6] = s
    frame = Frame(np.zeros((1, w, 3), np.float32), depth=depth.astype(np.float32))
    ref = aovs.reference(big, frame, ("coc", "focus"))
    np.testing.assert_allclose(ref["coc.Y"][0, :6] / lim_px, ratios, atol=1e-6)  # float32 depths
    want = np.array([1.0, 1.0, 1.0, 0.5, 0.0, 0.0])
    np.testing.assert_allclose(ref["focus.A"][0, :6], want, atol=1e-6)
    dev = aovs.compute(get_runtime(), big, frame, ("focus",))["focus.A"]
    np.testing.assert_allclose(dev[0, :6], want, atol=1e-4)
    # and the pass itself at a small size: 1 exactly where |c| <= limit
    f = _frame(rng)
    ref = aovs.reference(CAM, f, ("coc", "focus"))
    lim_small = aovs.coc_limit_mm(CAM) / (36.0 / W)
    inside = np.abs(ref["coc.Y"]) <= lim_small
    assert inside.any() and (~inside).any()
    assert np.all(ref["focus.A"][inside] == 1.0)
    assert np.all(ref["focus.A"][np.abs(ref["coc.Y"]) >= 2 * lim_small] == 0.0)
    dev = aovs.compute(get_runtime(), CAM, f, ("focus",))
    assert list(dev) == ["focus.A"]
    np.testing.assert_allclose(dev["focus.A"], ref["focus.A"], atol=1e-4)


def test_blur_is_velocity_times_the_shutter_fraction(rng):
    v = np.zeros((H, W, 2), np.float32)
    v[..., 0], v[..., 1] = 3.0, 4.0  # 5 px per frame
    f = Frame(np.zeros((H, W, 3), np.float32), velocity=v)
    ref = aovs.reference(CAM, f, ("blur",))["blur.Y"]
    np.testing.assert_allclose(ref, 5.0 * (1 / 48) * 24.0, rtol=1e-12)  # 180° shutter: half the motion
    f = _frame(rng)
    ref = aovs.reference(CAM, f, ("blur",))["blur.Y"]
    want = np.hypot(f.velocity[..., 0].astype(np.float64), f.velocity[..., 1]) * 0.5
    np.testing.assert_allclose(ref, want, rtol=1e-12)
    dev = aovs.compute(get_runtime(), CAM, f, ("blur",))["blur.Y"]
    np.testing.assert_allclose(dev, want, rtol=1e-6, atol=1e-6)


def test_bad_requests_are_one_line():
    with pytest.raises(InputError, match="unknown pass 'bokeh'"):
        aovs.parse_aovs("coc,bokeh")
    assert aovs.parse_aovs("blur, coc,blur") == ("blur", "coc")
    f = Frame(np.zeros((4, 5, 3), np.float32))
    with pytest.raises(InputError, match="needs the frame's depth buffer"):
        aovs.reference(CAM, f, ("coc",))
    with pytest.raises(InputError, match="needs the frame's velocity buffer"):
        aovs.reference(CAM, f, ("blur",))
    f = Frame(np.zeros((4, 5, 3), np.float32), velocity=np.zeros((4, 5, 2), np.float32))
    with pytest.raises(InputError, match="needs --fps"):
        aovs.reference(Camera(f_number=2.0), f, ("blur",))


def test_cli_writes_the_passes_as_exr_channels(tmp_path, rng, capsys):
    f = _frame(rng)
    exr.write_frame(tmp_path / "in.exr", f)
    out = tmp_path / "out.exr"
    args = ["process", tmp_path / "in.exr", "-o", out, "--quiet", "--f-number", "2", "--focus", "3",
            "--fps", "24", "--shutter-angle", "180", "--stages", "exposure"]
    assert main([str(a) for a in args + ["--aovs", "coc,focus,blur"]]) == 0
    import OpenEXR

    ch = OpenEXR.File(str(out)).channels()
    assert {"coc.Y", "focus.A", "blur.Y"} <= set(ch)
    ref = aovs.reference(CAM, f, ("coc", "focus", "blur"))
    for name in ("coc.Y", "focus.A", "blur.Y"):
        assert ch[name].pixels.dtype == np.float32
        np.testing.assert_allclose(ch[name].pixels, ref[name], rtol=2e-6, atol=1e-5)
    back = exr.read_frame(out)  # the colour layout still reads
    np.testing.assert_array_equal(back.depth, f.depth)
    assert main([str(a) for a in args[:3] + [tmp_path / "o.png", "--aovs", "coc"]]) == 2
    assert "written as EXR channels" in capsys.readouterr().err


def test_passes_follow_the_output_geometry_after_distortion(rng):
    import warnings
    from dataclasses import replace

    from clpost import Pipeline
    from clpost.calibration import OpenCVModel

    h, w = 40, 64
    f = Frame(rng.random((h, w, 3)).astype(np.float32), depth=rng.uniform(1, 20, (h, w)).astype(np.float32),
              velocity=rng.normal(0, 3, (h, w, 2)).astype(np.float32))
    cam = replace(CAM, distortion=OpenCVModel.from_camera(CAM, (w, h), k1=-0.12, k2=0.03))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pipe = Pipeline(cam, stages=["distortion"], quality="draft")
        out = pipe.run(f)
    assert "distortion" in pipe.plan(f)
    used = out.metadata["resolved_camera"]
    got = aovs.compute(pipe.runtime, used, out, ("coc", "blur"))
    ref = aovs.reference(used, out, ("coc", "blur"))  # from the resampled depth and velocity
    assert got["coc.Y"].shape == out.depth.shape
    np.testing.assert_allclose(got["coc.Y"], ref["coc.Y"], atol=1e-5)
    np.testing.assert_allclose(got["blur.Y"], ref["blur.Y"], atol=1e-5)
    assert not np.allclose(ref["coc.Y"], aovs.reference(used, f, ("coc",))["coc.Y"])  # not the input's

"""Regression tests for problems found in review: each was reproduced before its fix."""
import math
import warnings

import numpy as np
import pytest

from clpost import Camera, Frame, InputError, Pipeline
from clpost.cli import main
from clpost.metering import metered_luminance, resolve
from clpost.photometry import camera_bellows_factor
from clpost.stages import astigmatism, dof

FLAGSHIP = "zeiss-planar-50-f1.4"


def test_dof_and_astigmatism_share_the_sharp_plane_of_a_traced_lens():
    cam = Camera(lens=FLAGSHIP, focus_distance_m=0.6)  # measured from the film plane
    u = cam.focused_depth_m
    assert 0.5 < u < 0.6  # the thin-lens conjugate lies in front of the film-plane distance
    d, v, f = astigmatism.thin_lens(cam)
    z = np.array([0.48, u, 0.75])
    np.testing.assert_allclose(np.abs(dof.coc_mm(cam, z)), astigmatism.axes_mm(0, 0, z, d, v, f)[2],
                               rtol=1e-9, atol=1e-12)
    assert Camera(focus_distance_m=2.0).focused_depth_m == 2.0  # thin lens: exactly the focus


def test_a_one_pixel_frame_runs_through_a_traced_lens():
    frame = Frame(np.ones((1, 1, 3), np.float32), depth=np.full((1, 1), 2.0, np.float32))
    out = Pipeline(Camera(lens=FLAGSHIP)).run(frame)
    assert np.isfinite(out.color).all()


def test_shutter_priority_stays_in_the_lens_range_and_says_by_how_much():
    frame = Frame(np.ones((8, 8, 3), np.float32))
    cam = Camera(lens=FLAGSHIP, f_number=None, shutter_s=1 / 1000, luminance_scale=100.0)
    with pytest.warns(UserWarning, match=r"f/1\.4.*EV off the meter"):
        got = resolve(cam, frame)
    assert got.f_number == pytest.approx(cam.optics.max_aperture)


def test_working_f_number_uses_the_pupil_magnification():
    thin = Camera(focus_distance_m=0.5)
    assert camera_bellows_factor(thin) == pytest.approx(thin.image_distance_mm / thin.focal_length_mm)
    tele = Camera(lens="telephoto-250", focus_distance_m=3.0)
    p = tele.optics.paraxial.pupil_magnification
    m = tele.image_distance_mm / tele.focal_length_mm - 1
    assert p != pytest.approx(1.0, abs=0.05)
    assert camera_bellows_factor(tele) == pytest.approx(1 + m / p, rel=1e-12)


def test_metering_reads_luminance_in_the_working_space():
    red = Frame(np.tile(np.array([1.0, 0.0, 0.0], np.float32), (4, 4, 1)))
    y709 = metered_luminance(Camera(shutter_s=None, luminance_scale=1.0), red)
    yaces = metered_luminance(Camera(shutter_s=None, luminance_scale=1.0, working_space="acescg"), red)
    assert y709 == pytest.approx(0.2126, abs=1e-4) and yaces == pytest.approx(0.2722, abs=1e-3)


def test_meter_options_without_auto_exposure_are_an_error(tmp_path, capsys):
    from clpost import exr

    exr.write_frame(tmp_path / "a.exr", Frame(np.ones((4, 6, 3), np.float32)))
    assert main(["process", str(tmp_path / "a.exr"), "-o", str(tmp_path / "b.exr"), "--ev", "2"]) == 2
    assert "only in auto-exposure" in capsys.readouterr().err
    assert main(["process", str(tmp_path / "a.exr"), "-o", str(tmp_path / "b.exr"), "--ev", "2",
                 "--shutter", "auto", "--explain"]) == 0
    with pytest.raises(SystemExit) as exc:
        main(["demo", str(tmp_path / "d"), "--depth-of-field", "enabled"])
    assert exc.value.code == 2
    assert "is not on/off" in capsys.readouterr().err


def test_stages_after_a_resampling_stage_run_at_its_size():
    """A traced lens distorts by default; film grain (a gather) after it used to be refused."""
    from clpost.calibration import lens_distortion_model, required_render

    cam = Camera(lens=FLAGSHIP, film="kodak-gold-200", f_number=2.0, shutter_s=1 / 100,
                 luminance_scale=200.0)
    cam = cam.with_(distortion=lens_distortion_model(cam, (48, 32)))
    spec = required_render(cam.distortion)
    rng = np.random.default_rng(3)
    frame = Frame((rng.random((spec.height, spec.width, 3)) * 2).astype(np.float32),
                  depth=np.full((spec.height, spec.width), 3.0, np.float32),
                  metadata={"intrinsics": spec.intrinsics(), "frame_index": 7})
    pipe = Pipeline(cam, stages=["distortion", "exposure", "film", "grain", "print"])
    assert pipe.plan(frame) == ["distortion", "exposure", "film", "grain", "print"]
    out = pipe.run(frame)
    assert out.color.shape == (32, 48, 3) and out.depth.shape == (32, 48)
    ref = pipe.reference(frame)
    assert ref.shape == out.color.shape
    np.testing.assert_allclose(out.color, ref, rtol=2e-3, atol=2e-3)


def test_a_calibration_that_disagrees_with_the_camera_is_named():
    from clpost.calibration import OpenCVModel

    model = OpenCVModel(37, 23, 20.0, 20.0, 18.0, 11.0, k1=-0.1)
    frame = Frame(np.ones((23, 37, 3), np.float32))
    with pytest.warns(UserWarning, match="f_x = 20 px but the camera"):
        Pipeline(Camera(distortion=model)).camera_for(frame)
    fx = Camera().intrinsics(37, 23)[0]
    agree = OpenCVModel(37, 23, fx, fx, 18.0, 11.0, k1=-0.1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Pipeline(Camera(distortion=agree)).camera_for(frame)

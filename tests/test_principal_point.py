"""The field-dependent stages that run before distortion (astigmatism, coma, lateral colour)
measure image height from the render's principal point: a calibration's (c_x, c_y) at its own
size, the extended frustum's at ``required_render``'s size, else the frame's centre."""
import warnings

import numpy as np
import pytest

from clpost import Camera, Frame, Pipeline
from clpost.calibration import OpenCVModel, required_render
from clpost.stages import _field as fld
from clpost.stages.astigmatism import Astigmatism
from clpost.stages.coma import Coma
from clpost.stages.lateral_color import LateralColor

from conftest import assert_planned, odd_frame

W, H = 61, 41
OFF = OpenCVModel(W, H, 80.0, 80.0, 12.0, 30.0)  # principal point far from the centre (30, 20)


def test_principal_point_follows_the_calibration_and_its_extended_frustum():
    assert fld.principal_point_px(Camera(), W, H) == (30.0, 20.0)
    cam = Camera(distortion=OFF)
    assert fld.principal_point_px(cam, W, H) == (12.0, 30.0)
    barrel = OpenCVModel(W, H, 80.0, 80.0, 12.0, 30.0, k1=-0.2)
    spec = required_render(barrel)
    assert fld.principal_point_px(Camera(distortion=barrel), spec.width, spec.height) == (spec.cx, spec.cy)
    assert fld.principal_point_px(cam, W + 2, H) == (0.5 * (W + 1), 0.5 * (H - 1))  # not a render of it


def test_the_stages_are_centred_on_the_principal_point():
    cam = Camera(distortion=OFF, field_curvature_mm=-0.3, astigmatism_mm=0.2, coma_mm=0.5,
                 lateral_color_mm=0.3, f_number=2.0)
    frame = Frame(np.ones((H, W, 3), np.float32), depth=np.full((H, W), 3.0, np.float32))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a_s, a_t, _, _ = Astigmatism("final").semi_axes_px(cam, frame)
        c = Coma("final").c_px(cam, W, H)[0]
        sx, sy, _ = LateralColor("final").exact_positions(cam, W, H)
    yy, xx = np.mgrid[0:H, 0:W]
    for field in (a_s, a_t, np.abs(c)):
        j = np.unravel_index(int(np.argmin(field)), field.shape)
        assert abs(xx[j] - 12) <= 1 and abs(yy[j] - 30) <= 1
    shift = np.hypot(sx - xx, sy - yy).max(axis=0)
    assert shift[30, 12] < 1e-9 and shift[20, 30] > 1e-3


@pytest.mark.parametrize("stage", ["astigmatism", "coma", "lateral_color"])
def test_off_centre_kernels_match_their_references(rng, stage):
    cam = Camera(distortion=OFF, field_curvature_mm=-0.3, astigmatism_mm=0.2, coma_mm=0.5,
                 lateral_color_mm=0.3, f_number=2.0)
    frame = odd_frame(rng, w=W, h=H, scale=10.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pipe = Pipeline(cam, stages=[stage])
        assert_planned(pipe, frame, stage)
        out = pipe.run(frame).color
        ref = pipe.reference(frame)
    err = np.abs(out - ref)
    j = np.unravel_index(int(np.argmax(err)), err.shape)
    assert err.max() < 2e-3, f"{stage}: max abs error {err.max():.3g} (values 0–10) at (x={j[1]}, y={j[0]}, c={j[2]})"


def test_a_recorded_render_principal_point_is_the_one_every_stage_uses(rng):
    """A render that records its pinhole intrinsics (frame.metadata["intrinsics"], as the pyvista
    renderer does) is centred there for the field stages and vignetting alike — one definition
    (``_field.principal_point_px``), not one per stage."""
    k = (80.0, 80.0, 12.0, 30.0)
    assert fld.principal_point_px(Camera(), W, H, k) == (12.0, 30.0)
    flat = np.ones((H, W, 3), np.float32)
    frame = Frame(flat, depth=np.full((H, W), 3.0, np.float32), metadata={"intrinsics": k})
    # vignetting: brightest where the optical axis meets the sensor
    out = Pipeline(Camera(vignetting="natural", f_number=2.0), stages=["vignetting"]).run(frame).color
    y, x = np.unravel_index(np.argmax(out[..., 1]), out.shape[:2])
    assert (x, y) == (12, 30)
    # lateral colour: the green channel's magnification is centred on the same point
    cam = Camera(lateral_color_mm=0.3, f_number=2.0)
    sx, sy, _ = LateralColor("final").exact_positions(cam, W, H, k)
    np.testing.assert_allclose([sx[1, 30, 12], sy[1, 30, 12]], [12.0, 30.0], atol=1e-9)
    # kernel vs reference with the recorded point (odd content so a wrong centre shows)
    frame = Frame(rng.uniform(0, 2, (H, W, 3)).astype(np.float32), depth=frame.depth, metadata={"intrinsics": k})
    for stages, kw in ((["lateral_color"], dict(lateral_color_mm=0.3)), (["coma"], dict(coma_mm=0.5)),
                       (["astigmatism"], dict(field_curvature_mm=-0.3, astigmatism_mm=0.2))):
        pipe = Pipeline(Camera(f_number=2.0, **kw), stages=stages)
        assert_planned(pipe, frame, *stages)
        got = pipe.run(frame).color
        np.testing.assert_allclose(got, pipe.reference(frame), rtol=2e-3, atol=2e-3)
        centred = Pipeline(Camera(f_number=2.0, **kw), stages=stages).run(frame.replace(metadata={})).color
        assert np.abs(got - centred).max() > 1e-3

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

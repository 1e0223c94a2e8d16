"""vignetting: cos⁴θ closed form, LUT kernel vs float64 reference, energy, tables, plan."""
import math

import numpy as np
import pytest
from scipy import integrate

from clpost import Camera, Frame, InputError, Pipeline
from clpost.calibration import OpenCVModel
from clpost.stages import vignetting as vig
from clpost.stages.vignetting import Vignetting

from conftest import assert_planned, odd_frame

DATA = __import__("pathlib").Path(__file__).parent / "data"


def test_off_by_default_so_existing_plans_are_unchanged(rng):
    frame = odd_frame(rng)
    assert Pipeline(Camera(luminance_scale=1.0)).plan(frame) == ["exposure"]
    e = {x.stage: x for x in Pipeline(Camera(luminance_scale=1.0)).explain(frame)}["vignetting"]
    assert not e.planned and "off" in e.reason


def test_natural_is_cos4_of_the_field_angle():
    cam = Camera(luminance_scale=1.0, lens="thin:50", focus_distance_m=math.inf, vignetting="natural")
    ri = vig.relative_illumination(cam)
    for r in (0.0, 10.0, 21.63):
        theta = math.atan(r / 50.0)
        assert ri(np.array(r)) == pytest.approx(math.cos(theta) ** 4, rel=1e-12)
    # focus moves the exit pupil's distance to the film: v = f u/(u - f)
    near = Camera(luminance_scale=1.0, lens="thin:50", focus_distance_m=0.5, vignetting="natural")
    assert vig.relative_illumination(near)(np.array(20.0)) > ri(np.array(20.0))


@pytest.mark.parametrize("lens,w,h", [("thin:12", 37, 23), ("thin:50", 64, 43), ("thin:200", 23, 37)])
def test_kernel_matches_reference(rng, lens, w, h):
    cam = Camera(luminance_scale=1.0, lens=lens, vignetting="natural")
    frame = odd_frame(rng, w=w, h=h, scale=1e4)
    pipe = Pipeline(cam)
    assert_planned(pipe, frame, "vignetting", "exposure")
    assert pipe.kernels(frame) == ["vignetting__exposure"]
    out = pipe.run(frame).color
    ref = pipe.reference(frame)
    rel = np.abs(out / ref - 1)
    j = np.unravel_index(int(np.argmax(rel)), rel.shape)
    assert rel.max() < 2e-5, f"max rel error {rel.max():.3g} at (x={j[1]}, y={j[0]})"
    assert np.all(np.isfinite(out)) and out.dtype == np.float32


def test_energy_of_a_uniform_field_is_the_integral_of_cos4_over_the_sensor():
    cam = Camera(luminance_scale=1.0, lens="thin:24", vignetting="natural", focus_distance_m=math.inf)
    w, h = 360, 240
    frame = Frame(np.ones((h, w, 3), np.float32))
    out = Pipeline(cam, stages=["vignetting"]).run(frame).color
    v = 24.0
    exact, _ = integrate.dblquad(lambda y, x: (1 + (x * x + y * y) / v ** 2) ** -2, -18, 18, -12, 12)
    assert out.mean() == pytest.approx(exact / (36 * 24), rel=2e-5)
    assert out.max() <= 1.0 and out.min() > 0


def test_principal_point_of_the_calibration_is_the_centre(rng):
    m = OpenCVModel(37, 23, 30, 30, 10.0, 15.0)
    cam = Camera(luminance_scale=1.0, lens="thin:12", vignetting="natural", distortion=m)
    frame = Frame(np.ones((23, 37, 3), np.float32))
    assert_planned(Pipeline(cam, stages=["vignetting"]), frame, "vignetting")
    out = Pipeline(cam, stages=["vignetting"]).run(frame).color[..., 0]
    assert np.unravel_index(int(np.argmax(out)), out.shape) == (15, 10)
    np.testing.assert_allclose(out, Pipeline(cam, stages=["vignetting"]).reference(frame)[..., 0], rtol=2e-5)


def test_table_file_and_its_errors(tmp_path):
    cam = Camera(luminance_scale=1.0, vignetting=f"table:{DATA / 'ri_table.csv'}")
    ri = vig.relative_illumination(cam)
    assert ri(np.array(7.5)) == pytest.approx((0.980 + 0.925) / 2)
    frame = Frame(np.ones((23, 37, 3), np.float32))
    assert_planned(Pipeline(cam, stages=["vignetting"]), frame, "vignetting")
    np.testing.assert_allclose(Pipeline(cam, stages=["vignetting"]).run(frame).color,
                               Pipeline(cam, stages=["vignetting"]).reference(frame), rtol=5e-5)  # LUT vs table kinks
    bad = tmp_path / "t.csv"
    bad.write_text("0 1\n10 0.9\n")
    vig.read_table.cache_clear()
    with pytest.raises(InputError, match="source"):
        vig.relative_illumination(Camera(luminance_scale=1.0, vignetting=f"table:{bad}"))
    bad = tmp_path / "t2.csv"  # read_table is cached per path
    bad.write_text("# source: x\n0 1\n10 0.9\n")
    with pytest.raises(InputError, match="half diagonal"):
        vig.relative_illumination(Camera(luminance_scale=1.0, vignetting=f"table:{bad}"))
    bad = tmp_path / "t3.csv"
    bad.write_text("# source: x\n0 100\n30 90\n")
    with pytest.raises(InputError, match="percentages"):
        vig.relative_illumination(Camera(luminance_scale=1.0, vignetting=f"table:{bad}"))


def test_lens_mode_uses_the_traced_curve_or_says_what_to_do(rng):
    with pytest.raises(InputError, match="--vignetting natural"):
        vig.relative_illumination(Camera(luminance_scale=1.0, lens="thin:35", vignetting="lens"))
    cam = Camera(luminance_scale=1.0, lens="zeiss-planar-50-f1.4", f_number=1.4, vignetting="lens")
    curves = cam.lens_curves()
    frame = odd_frame(rng)
    out = Pipeline(cam, stages=["vignetting"]).run(frame).color
    # the pixel at the image corner gets the traced RI at the corner's image height
    pitch = cam.pixel_pitch_mm(frame.width)
    r = pitch * np.hypot((frame.width - 1) / 2, (frame.height - 1) / 2)
    expected = float(np.clip(curves.at("relative_illumination", np.array([r])), 0, 1)[0])
    np.testing.assert_allclose(out[0, 0], expected * frame.color[0, 0], rtol=2e-4)
    assert out[0, 0, 0] / frame.color[0, 0, 0] < out[11, 18, 0] / frame.color[11, 18, 0]  # darker corner


def test_wide_open_flagship_vignettes_more_than_stopped_down(rng):
    frame = odd_frame(rng)
    wide = Pipeline(Camera(luminance_scale=1.0, lens="zeiss-planar-50-f1.4", f_number=1.4, vignetting="lens"), stages=["vignetting"])
    f8 = Pipeline(Camera(luminance_scale=1.0, lens="zeiss-planar-50-f1.4", f_number=8, vignetting="lens"), stages=["vignetting"])
    assert (wide.run(frame).color[0, 0] < f8.run(frame).color[0, 0]).all()


def test_bad_mode_is_refused():
    with pytest.raises(InputError, match="natural"):
        Camera(luminance_scale=1.0, vignetting="cos4")


def test_a_focus_pull_builds_each_frames_plane_on_the_device(rng):
    """The RI plane is built on the device from the LUT (a focus pull changes the LUT every
    frame): what the kernel reads equals the host's float64 interpolation (``ri_plane``) to
    float32 rounding, for each focus of a pull run through one plan, and the host makes no
    plane (the stage's host-plane cache stays empty)."""
    import pyopencl as cl

    w, h = 61, 37
    frame = Frame(rng.uniform(0.1, 1.0, (h, w, 3)).astype(np.float32))
    cam = Camera(luminance_scale=1.0, lens="thin:20", f_number=2.0, vignetting="natural")
    plan = Pipeline(cam, stages=["vignetting"]).plan_for(frame)
    stage = plan.stages[0]
    planes = []
    for focus in (0.3, 0.6, 4.0):
        c = cam.with_(focus_distance_m=focus)
        out = plan.run(frame, c).color
        assert stage._plane == (None, None)  # no per-frame pass over the pixels on the host
        got = np.empty((h, w), np.float32)
        cl.enqueue_copy(plan.runtime.queue, got, plan.buffers.args[("vignetting", "ri")], is_blocking=True)
        want = stage.ri_plane(c, frame)
        stage._plane = (None, None)
        np.testing.assert_allclose(got, want, rtol=0, atol=2e-6)
        np.testing.assert_allclose(out, plan.reference(frame, c), rtol=2e-5)
        planes.append(got)
    assert all(np.max(np.abs(a - b)) > 1e-3 for a, b in zip(planes, planes[1:]))  # the pull changes the plane

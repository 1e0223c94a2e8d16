"""Long exposure (clpost.expose, `clpost expose`) and the sub-frame motion-blur reference."""
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, strategies as st

from clpost import Camera, Frame, exr
from clpost.cli import main
from clpost.errors import InputError
from clpost.expose import (ExposureAccumulator, as_time, expose, exposure_weights, frame_interval,
                           frames_needed)

FPS = 24


@given(a=st.fractions(Fraction(-2), Fraction(5), max_denominator=1000),
       length=st.fractions(Fraction(1, 1000), Fraction(3), max_denominator=1000))
def test_weights_are_exact_overlaps_summing_to_the_open_time(a, length):
    b = a + length
    w = exposure_weights(frames_needed(FPS, a, b), FPS, a, b)
    assert sum(w.values()) == b - a                          # exact, not approximately
    for n, x in w.items():
        lo, hi = frame_interval(n, FPS)
        assert 0 < x <= hi - lo


def test_weights_for_a_shutter_between_frame_boundaries():
    w = exposure_weights(range(10), 24, "1/48", "5/48")      # half of frame 0, all of 1, half of 2
    assert w == {0: Fraction(1, 48), 1: Fraction(1, 24), 2: Fraction(1, 48)}


@pytest.mark.parametrize("t0, t1", [("0", "1"), ("1/96", "7/48"), ("0.013", "0.0131"), ("2/7", "19/7")])
def test_static_scene_over_any_interval_equals_a_single_frame(rng, t0, t1):
    frame = (rng.random((23, 37, 3)) ** 3 * 1e4).astype(np.float32)
    part = expose(lambda n: frame, range(-5, 100), FPS, t0, t1)
    np.testing.assert_allclose(part.mean(), frame, rtol=2e-7)
    assert part.seconds == as_time(t1, "t1") - as_time(t0, "t0")
    np.testing.assert_allclose(part.exposure(), frame * float(part.seconds), rtol=1e-6)


def test_piecewise_constant_sequence_integrates_exactly(rng):
    frames = {n: np.full((3, 5, 3), float(n * n + 1), np.float32) for n in range(12)}
    t0, t1 = Fraction(7, 100), Fraction(41, 100)
    part = expose(frames.__getitem__, frames, FPS, t0, t1)
    exact = sum(float(w) * (n * n + 1) for n, w in exposure_weights(frames, FPS, t0, t1).items())
    np.testing.assert_allclose(part.exposure(), exact, rtol=1e-6)


def test_partials_combine_to_the_whole(rng):
    frames = {n: (rng.random((9, 11, 3)) * 100).astype(np.float32) for n in range(20)}
    whole = expose(frames.__getitem__, frames, FPS, "0.01", "0.8")
    a = expose(frames.__getitem__, frames, FPS, "0.01", "0.3")
    b = expose(frames.__getitem__, frames, FPS, "0.3", "0.8")
    both = a.combine(b)
    assert both.seconds == whole.seconds and both.count == whole.count + 1   # frame 7 is split
    np.testing.assert_allclose(both.exposure(), whole.exposure(), rtol=1e-6)


def test_many_frames_keep_precision():
    # 3000 frames of 1 + 1e-4: compensated sum keeps ~1 ulp; a naive float32 sum would drift ~1e-4
    acc = ExposureAccumulator((4, 3), 1000)
    img = np.full((3, 4, 3), 1.0001, np.float32)
    for _ in range(3000):
        acc.add(img, Fraction(1, 1000))
    np.testing.assert_allclose(acc.partial().mean(), np.float32(1.0001), rtol=1e-7)


def test_bad_intervals_and_missing_frames():
    with pytest.raises(InputError, match="later than --open"):
        exposure_weights(range(3), 24, "0.5", "0.5")
    with pytest.raises(InputError, match="missing"):
        expose(lambda n: np.zeros((2, 2, 3), np.float32), [0, 1, 3], 24, 0, "4/24")
    with pytest.raises(InputError, match="fps"):
        frame_interval(0, 0)
    acc = ExposureAccumulator((4, 3), 24)
    with pytest.raises(InputError, match="one size"):
        acc.add(np.zeros((4, 4, 3), np.float32), Fraction(1, 24))


def test_cli_expose_average_equals_library(tmp_path, rng):
    frames = {}
    for n in range(1, 6):
        c = (rng.random((7, 9, 3)) * 10).astype(np.float32)
        frames[n] = c
        exr.write_frame(tmp_path / f"in.{n:04d}.exr", Frame(c))
    out = tmp_path / "long.exr"
    rc = main(["expose", str(tmp_path / "in.####.exr"), "--open", "0.05", "--close", "0.2",
               "--fps", "24", "-o", str(out), "--quiet", "--average"])
    assert rc == 0
    got = exr.read_frame(out).color
    # times count from the start of the first frame on disk (frame 1), not from a frame 0
    want = expose(frames.__getitem__, frames, 24, "0.05", "0.2", first=1).mean()
    np.testing.assert_allclose(got, want, rtol=1e-6)
    assert main(["expose", str(tmp_path / "in.####.exr"), "--open", "0.05", "--close", "0.2",
                 "--fps", "24", "-o", str(out), "--quiet", "--average"]) == 2          # exists: refused
    # [0, 0.25) needs frames 1-6 and frame 6 is not on disk
    assert main(["expose", str(tmp_path / "in.####.exr"), "--open", "0", "--close", "0.25",
                 "--fps", "24", "-o", str(tmp_path / "x.exr"), "--quiet", "--average"]) == 2
    assert not (tmp_path / "x.exr").exists()


def test_cli_shutter_angle_sets_shutter(tmp_path):
    from clpost.cli import build_parser, camera_from_args

    args = build_parser().parse_args(["process", "a.exr", "-o", "b.exr", "--fps", "24", "--shutter-angle", "180"])
    cam = camera_from_args(args)
    assert cam.shutter_s == pytest.approx(1 / 48) and cam.frame_rate_fps == 24
    args = build_parser().parse_args(["process", "a.exr", "-o", "b.exr", "--shutter-angle", "180"])
    with pytest.raises(InputError, match="--fps"):
        camera_from_args(args)


@pytest.mark.slow
def test_subframe_reference_renders_and_blurs_the_mover():
    from clpost.render import DemoScene, PyVistaRenderer
    from clpost.render.motion import render_motion_blur_reference

    cam = Camera(frame_rate_fps=24, shutter_s=1 / 24)
    size = (96, 64)
    r = PyVistaRenderer(DemoScene.default())
    try:
        sharp = r.render(cam, size, 0)
        one = render_motion_blur_reference(cam, size, 0, subframes=1, renderer=r)
        np.testing.assert_array_equal(one.color, sharp.color)          # K = 1: the frame itself
        ref = render_motion_blur_reference(cam, size, 0, subframes=6, renderer=r)
        ids = sharp.metadata["object_id"]
        names = sharp.metadata["object_names"]
        mover = ids == names.index("mover")
        still = ids == names.index("tower_50m")
        assert np.abs(ref.color - sharp.color)[mover].mean() > 1e-3
        np.testing.assert_allclose(ref.color[still], sharp.color[still], rtol=1e-5, atol=1e-6)
        rolling = render_motion_blur_reference(cam.with_(readout_time_s=1 / 48), size, 0, subframes=3, renderer=r)
        assert np.isfinite(rolling.color).all() and not np.array_equal(rolling.color, ref.color)
    finally:
        r.close()


@pytest.mark.slow
def test_demo_writes_the_reference_and_refuses_it_without_a_frame_rate(tmp_path):
    rc = main(["demo", str(tmp_path / "d"), "--frames", "1", "--size", "48x32", "--fps", "24",
               "--shutter-angle", "180", "--reference-subframes", "2"])
    assert rc == 0
    ref = exr.read_frame(tmp_path / "d" / "render" / "reference_blur.0001.exr")
    assert ref.color.shape == (32, 48, 3) and ref.velocity is not None
    assert (tmp_path / "d" / "preview" / "reference_blur.0001.png").is_file()
    assert main(["demo", str(tmp_path / "e"), "--frames", "1", "--size", "48x32",
                 "--reference-subframes", "2"]) == 2

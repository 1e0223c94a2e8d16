"""The calibration package: its public names, and the per-(model, size) caches of the render
frustum that stages ask for every frame (a Newton inverse of the image border; docs/measurements.md)."""
from dataclasses import replace

import numpy as np
import pytest

import clpost.calibration as cal
from clpost import Camera
from clpost.calibration import frustum, lens_distortion_model, render_intrinsics, required_render


def test_every_public_name_is_importable_from_the_package():
    for name in cal.__all__:
        assert getattr(cal, name) is not None, name
    for name in ("OpenCVModel", "load_calibration", "required_render", "render_intrinsics",
                 "lens_distortion_model", "undistort_newton", "undistort", "HeikkilaInverse",
                 "inverse_residual_px", "RenderSpec", "COEFF_NAMES"):
        assert name in cal.__all__, name


def _barrel(k1: float) -> cal.OpenCVModel:
    return cal.OpenCVModel(97, 61, 90.0, 91.0, 47.0, 29.5, k1=k1, k2=0.01, p1=2e-4)


def test_the_frustum_is_solved_once_per_model_and_reused(monkeypatch):
    calls = []
    newton = frustum.undistort_newton

    def counting(*a, **kw):
        calls.append(1)
        return newton(*a, **kw)

    monkeypatch.setattr(frustum, "undistort_newton", counting)
    m = _barrel(-0.2345)  # coefficients no other test uses: the cache starts empty for it
    spec = required_render(m)
    assert spec.width > m.width and spec.height > m.height  # barrel: a larger render
    k = render_intrinsics(m, (spec.width, spec.height))
    for _ in range(5):
        # an equal model built anew (what a per-frame camera resolution gives) hits the cache
        again = replace(m, source="another file")
        assert render_intrinsics(again, [spec.width, spec.height]) == k
        assert required_render(again) is spec
    assert len(calls) == 1
    assert k == spec.intrinsics()


def test_the_cache_keys_on_every_coefficient_size_and_margin():
    m = _barrel(-0.2)
    spec = required_render(m)
    # the cached result is the uncached computation
    assert spec == frustum._required_render.__wrapped__(m, 2.0)
    assert required_render(replace(m, k1=-0.25)) != spec
    assert required_render(replace(m, p2=1e-3)) != spec
    assert required_render(m, margin_px=6) != spec
    assert required_render(m, margin_px=6) == frustum._required_render.__wrapped__(m, 6.0)
    assert render_intrinsics(m, (m.width, m.height)) == (m.fx, m.fy, m.cx, m.cy)
    assert render_intrinsics(m, (spec.width + 1, spec.height)) is None
    assert render_intrinsics(replace(m, k1=-0.25), (spec.width, spec.height)) is None


def test_a_traced_lens_model_is_one_object_per_camera_and_size():
    cam = Camera(lens="thorlabs-lb1471", f_number=8.0, focus_distance_m=3.0)  # a singlet: quick to trace
    m = lens_distortion_model(cam, (96, 64))
    assert m is not None and lens_distortion_model(cam.with_(), (96, 64)) is m
    assert (m.width, m.height) == (96, 64) and (m.fx, m.fy, m.cx, m.cy) == pytest.approx(cam.intrinsics(96, 64))
    other = lens_distortion_model(cam.with_(focus_distance_m=1.0), (96, 64))
    assert other is not m and other.fx != m.fx
    assert lens_distortion_model(cam, (192, 128)).fx == pytest.approx(2 * m.fx)
    assert lens_distortion_model(cam.with_(lens_distortion=False), (96, 64)) is None


def test_an_extended_frustum_sequence_checks_input_sizes_not_output_sizes(tmp_path):
    # The render for a barrel calibration is larger than the calibration's image; every frame of the
    # sequence must be checked against the first *input* (the serial loop compared the next input with
    # the previous output and stopped at frame 2, while --workers went through).
    from clpost import Frame, Pipeline, exr
    from clpost.batch import FrameJob, process_sequence

    m = _barrel(-0.2)
    spec = required_render(m)
    rng = np.random.default_rng(3)
    jobs = []
    for n in (1, 2, 3):
        src, dst = tmp_path / f"in.{n:04d}.exr", tmp_path / f"out.{n:04d}.exr"
        exr.write_frame(src, Frame(rng.random((spec.height, spec.width, 3), dtype=np.float32)))
        jobs.append(FrameJob(n, src, dst))
    report = process_sequence(Pipeline(Camera(distortion=m), stages=["distortion"]), jobs)
    assert report.done == [1, 2, 3] and not report.failed
    assert all(exr.read_frame(j.dst).size == (m.width, m.height) for j in jobs)

import math

import pytest

from clpost import Camera, InputError


def test_thin_lens_image_distance_closed_form():
    cam = Camera(lens="thin:50", focus_distance_m=2.0)
    # 1/u + 1/v = 1/f  ->  v = f u / (u - f) = 50*2000/1950
    assert cam.image_distance_mm == pytest.approx(50 * 2000 / 1950, rel=1e-12)
    assert Camera(focus_distance_m=math.inf).image_distance_mm == 50.0


def test_field_of_view_of_a_50mm_on_full_frame():
    cam = Camera(lens="thin:50")
    # published: 39.6° horizontal, 27.0° vertical, 46.8° diagonal for 36x24 mm
    assert cam.field_of_view_deg() == pytest.approx(39.60, abs=0.01)
    assert cam.field_of_view_deg(24.0) == pytest.approx(26.99, abs=0.01)
    assert cam.field_of_view_deg(math.hypot(36, 24)) == pytest.approx(46.79, abs=0.01)
    assert cam.field_of_view_focused_deg < cam.field_of_view_deg()  # focus breathing


def test_intrinsics_and_pixel_pitch():
    cam = Camera(focus_distance_m=math.inf)
    fx, fy, cx, cy = cam.intrinsics(1920, 1280)
    assert cam.pixel_pitch_mm(1920) == pytest.approx(36 / 1920)
    assert fx == fy == pytest.approx(50 / (36 / 1920))
    assert (cx, cy) == (959.5, 639.5)
    assert cam.default_resolution(960) == (960, 640)


@pytest.mark.parametrize("kw, words", [
    (dict(f_number=0), "f_number=0 must be > 0"),
    (dict(f_number=-2), "f_number"),
    (dict(f_number=float("nan")), "f_number.*finite"),
    (dict(focus_distance_m=0.05), "beyond the focal length"),
    (dict(focus_distance_m=float("nan")), "focus_distance_m"),
    (dict(iso=0), "iso=0 must be > 0"),
    (dict(shutter_s=0), "shutter_s=0 must be > 0"),
    (dict(transmittance=1.2), "transmittance"),
    (dict(sensor_mm=(36, 0)), "sensor_mm"),
    (dict(luminance_scale=-1), "luminance_scale"),
    (dict(blades=2), "blades"),
    (dict(metering="matrix"), "metering"),
    (dict(lens="zeiss"), "thin:<focal length mm>"),
    (dict(lens="thin:-5"), "focal length must be > 0"),
    (dict(f_number=None, shutter_s=None), "give one"),
])
def test_invalid_values_name_field_and_fix(kw, words):
    with pytest.raises(InputError, match=words):
        Camera(**kw)


def test_extremes_are_valid():
    for n in (0.7, 64):
        for u in (0.06, 2.0, 1e6, math.inf):
            cam = Camera(f_number=n, focus_distance_m=u)
            assert math.isfinite(cam.image_distance_mm) and cam.image_distance_mm >= 50

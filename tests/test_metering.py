"""Auto-exposure: the meter equation, patterns, compensation and limits."""
import math
import warnings

import numpy as np
import pytest

from clpost import Camera, Frame, InputError, Pipeline
from clpost.metering import metered_luminance, metering_weights, resolve
from clpost.photometry import K_REFLECTED, METER_TRANSMITTANCE


def scene(h=40, w=60, value=1.0, centre=None):
    c = np.full((h, w, 3), value, np.float32)
    if centre is not None:
        c[h // 2 - 6: h // 2 + 6, w // 2 - 6: w // 2 + 6] = centre  # 144 px > the 72 px spot
    return Frame(c)


@pytest.mark.parametrize("mode", ["average", "centre", "spot"])
def test_weights_are_normalised_and_symmetric(mode):
    w = metering_weights(mode, 31, 45)
    assert w.sum() == pytest.approx(1.0) and (w >= 0).all()
    np.testing.assert_allclose(w, w[::-1, ::-1], atol=1e-15)


def test_spot_covers_three_percent_and_centre_weights_the_middle():
    w = metering_weights("spot", 200, 300)
    assert np.count_nonzero(w) / w.size == pytest.approx(0.03, rel=0.05)
    c = metering_weights("centre", 200, 300)
    assert c[100, 150] > 10 * c[0, 0]


@pytest.mark.parametrize("focus", [math.inf, 0.5, 0.12])
def test_aperture_priority_lands_a_uniform_scene_at_qK_over_78(focus):
    cam = Camera(f_number=4, shutter_s=None, iso=200, transmittance=0.83,
                 luminance_scale=37.0, focus_distance_m=focus)
    frame = scene(value=1.0)
    out = Pipeline(cam).run(frame)
    # TTL metering compensates the bellows factor, so the result is focus-independent — and the
    # transmittance (it sees through the glass; calibrated for T_m = 0.9), so q = π T_m / 4
    # whatever the lens's T (a meter blind to T would leave a dark lens underexposed).
    np.testing.assert_allclose(out.color, math.pi * METER_TRANSMITTANCE / 4 * K_REFLECTED / 78, rtol=1e-6)


def test_shutter_priority_solves_for_the_f_number():
    cam = Camera(f_number=None, shutter_s=1 / 100, iso=100, luminance_scale=1.0,
                 focus_distance_m=math.inf)
    L = 400.0
    got = resolve(cam, scene(value=L))
    # N^2 / t = L S / K
    assert got.f_number == pytest.approx(math.sqrt(L * 100 * 0.01 / K_REFLECTED), rel=1e-12)


def test_exposure_compensation_doubles_per_ev():
    base = Camera(shutter_s=None, luminance_scale=50.0)
    plus = Camera(shutter_s=None, luminance_scale=50.0, exposure_compensation_ev=1.0)
    f = scene()
    assert resolve(plus, f).shutter_s / resolve(base, f).shutter_s == pytest.approx(2.0, rel=1e-12)


def test_spot_meter_reads_the_centre_only():
    f = scene(value=1.0, centre=1000.0)
    avg = metered_luminance(Camera(shutter_s=None, metering="average", luminance_scale=1.0), f)
    spot = metered_luminance(Camera(shutter_s=None, metering="spot", luminance_scale=1.0), f)
    assert spot == pytest.approx(1000.0, rel=1e-12)
    assert avg == pytest.approx((144 * 1000.0 + (2400 - 144)) / 2400, rel=1e-6)


def test_out_of_range_is_clamped_with_a_warning():
    cam = Camera(shutter_s=None, f_number=16, luminance_scale=1e-6)
    with pytest.warns(UserWarning, match="shutter .* outside"):
        got = resolve(cam, scene())
    assert got.shutter_s == 30.0


def test_black_frame_cannot_be_metered():
    with pytest.raises(InputError, match="black"):
        resolve(Camera(shutter_s=None, luminance_scale=1.0), scene(value=0.0))


def test_manual_camera_is_untouched():
    cam = Camera()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert resolve(cam, scene()) is cam


def test_shutter_priority_stays_in_the_lens_range_and_says_by_how_much():
    frame = Frame(np.ones((8, 8, 3), np.float32))
    cam = Camera(lens="zeiss-planar-50-f1.4", f_number=None, shutter_s=1 / 1000, luminance_scale=100.0)
    with pytest.warns(UserWarning, match=r"f/1\.4.*EV off the meter"):
        got = resolve(cam, frame)
    assert got.f_number == pytest.approx(cam.optics.max_aperture)


def test_metering_reads_luminance_in_the_working_space():
    red = Frame(np.tile(np.array([1.0, 0.0, 0.0], np.float32), (4, 4, 1)))
    y709 = metered_luminance(Camera(shutter_s=None, luminance_scale=1.0), red)
    yaces = metered_luminance(Camera(shutter_s=None, luminance_scale=1.0, working_space="acescg"), red)
    assert y709 == pytest.approx(0.2126, abs=1e-4) and yaces == pytest.approx(0.2722, abs=1e-3)

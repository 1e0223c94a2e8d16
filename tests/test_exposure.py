"""exposure: closed forms (ISO 2720 / ISO 12232), kernel vs float64 reference, extremes."""
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from clpost import Camera, Frame, Pipeline
from clpost.photometry import K_REFLECTED, camera_bellows_factor
from clpost.photometry import exposure_mode
from clpost.stages.exposure import exposure_gain

from conftest import assert_planned


def uniform(L, h=9, w=11):
    """A uniform grey scene of luminance L cd/m² (luminance_scale=1: Y is cd/m²)."""
    return Frame(np.full((h, w, 3), L, np.float32), depth=np.full((h, w), 5.0, np.float32))


def test_gain_matches_the_written_formula():
    cam = Camera(f_number=2.8, shutter_s=1 / 125, iso=400, transmittance=0.8,
                 luminance_scale=250.0, focus_distance_m=math.inf)
    expected = 250.0 * math.pi * 0.8 / (4 * 2.8**2) * (1 / 125) / (78 / 400)
    assert exposure_gain(cam) == pytest.approx(expected, rel=1e-14)


@pytest.mark.parametrize("n, t, s", [(1.4, 1 / 60, 100), (8, 1 / 250, 400), (16, 2.0, 50)])
def test_metered_uniform_scene_lands_at_qK_over_78(n, t, s):
    # ISO 2720: L S / K = N^2 / t  ->  L = K N^2 / (S t)
    T = 0.83
    L = K_REFLECTED * n * n / (s * t)
    cam = Camera(f_number=n, shutter_s=t, iso=s, transmittance=T, luminance_scale=1.0,
                 focus_distance_m=math.inf)
    out = Pipeline(cam).run(uniform(L))
    q = math.pi * T / 4
    assert q * K_REFLECTED / 78 == pytest.approx(0.1045, abs=5e-4)  # the "0.104" of the brief
    np.testing.assert_allclose(out.color, q * K_REFLECTED / 78, rtol=1e-6)


def test_bellows_factor_costs_two_stops_at_one_to_one():
    inf = Camera(focus_distance_m=math.inf, luminance_scale=1.0)
    macro = Camera(focus_distance_m=0.1, luminance_scale=1.0)  # u = 2f: magnification 1, v = 2f
    assert exposure_gain(macro) / exposure_gain(inf) == pytest.approx(0.25, rel=1e-12)


def test_kernel_matches_reference_on_odd_size_random_and_adversarial(rng):
    h, w = 23, 37
    c = (rng.random((h, w, 3)) * 100).astype(np.float32)
    adversarial = np.array([0.0, 1e-6, 1e-38, 1e-45, 1.0, 1e4, 1e8, 3e38 / 1e7], np.float32)
    c.reshape(-1)[: adversarial.size * 5] = np.tile(adversarial, 5)
    frame = Frame(c, depth=np.full((h, w), np.inf, np.float32))
    pipe = Pipeline(Camera(f_number=1.4, shutter_s=1 / 30, iso=800, luminance_scale=1.0))
    assert_planned(pipe, frame, "exposure")
    out = pipe.run(frame)
    ref = pipe.reference(frame)
    assert out.color.dtype == np.float32 and out.color.shape == (h, w, 3)
    assert np.isfinite(out.color).all()
    normal = np.abs(ref) > 1e-30  # below that float32 denormals carry few bits
    rel = np.abs(out.color[normal] - ref[normal]) / np.abs(ref[normal])
    assert rel.max() <= 2e-7, f"worst at flat index {np.argmax(rel)}"
    np.testing.assert_array_equal(out.color[ref == 0], 0)


@given(
    n=st.floats(0.7, 64), t=st.floats(1 / 8000, 30), s=st.floats(25, 102400),
    u=st.one_of(st.just(math.inf), st.floats(0.06, 1e6)),
    lum=st.sampled_from([1e-6, 1e-3, 1.0, 1e3, 1e8]),
)
def test_extremes_stay_finite_and_exact(n, t, s, u, lum):
    cam = Camera(f_number=n, shutter_s=t, iso=s, focus_distance_m=u, luminance_scale=1.0)
    frame = uniform(lum, 3, 5)
    out = _pipe(cam).run(frame)
    ref = lum * exposure_gain(cam)
    assert np.isfinite(out.color).all()
    np.testing.assert_allclose(out.color, ref, rtol=2e-7)


_pipes = {}


def _pipe(cam):
    # One pipeline per test run: scalars change, programs and buffers must not be rebuilt.
    p = _pipes.setdefault("p", Pipeline(cam))
    p.camera = cam
    return p


def test_changing_exposure_never_rebuilds(rng):
    frame = Frame(rng.random((8, 8, 3)).astype(np.float32))
    pipe = Pipeline(Camera(f_number=2, luminance_scale=1.0))
    pipe.run(frame)
    progs = dict(pipe.runtime._programs)
    buf = pipe._buffers
    for n in (1.4, 4, 11):
        pipe.camera = Camera(f_number=n, luminance_scale=1.0)
        pipe.run(frame)
    assert pipe.runtime._programs.keys() == progs.keys()
    assert pipe._buffers is buf


def test_skipped_exactly_when_identity():
    cam = Camera(f_number=1.0, shutter_s=1.0, iso=78.0, transmittance=1.0,
                 focus_distance_m=math.inf, luminance_scale=4 / math.pi)
    assert exposure_gain(cam) == pytest.approx(1.0, rel=1e-15)
    frame = uniform(0.3)
    pipe = Pipeline(cam)
    if exposure_gain(cam) == 1.0:
        assert pipe.plan(frame) == []
        np.testing.assert_array_equal(pipe.run(frame).color, frame.color)
    else:  # rounding left the gain a hair off 1: then it must be planned and exact
        assert pipe.plan(frame) == ["exposure"]
    assert Pipeline(Camera(luminance_scale=1.0)).plan(frame) == ["exposure"]


def test_working_f_number_uses_the_pupil_magnification():
    thin = Camera(focus_distance_m=0.5)
    assert camera_bellows_factor(thin) == pytest.approx(thin.image_distance_mm / thin.focal_length_mm)
    tele = Camera(lens="telephoto-250", focus_distance_m=3.0)
    p = tele.optics.paraxial.pupil_magnification
    m = tele.image_distance_mm / tele.focal_length_mm - 1
    assert p != pytest.approx(1.0, abs=0.05)
    assert camera_bellows_factor(tele) == pytest.approx(1 + m / p, rel=1e-12)


# -- exposure modes -------------------------------------------------------------------

def test_passthrough_by_default_is_gain_exactly_one_and_not_planned(rng):
    cam = Camera()
    assert cam.luminance_scale is None and exposure_mode(cam) == "passthrough"
    assert exposure_gain(cam) == 1.0
    frame = Frame(rng.random((5, 7, 3)).astype(np.float32) * 40)
    pipe = Pipeline(cam)
    assert "exposure" not in pipe.plan(frame)
    np.testing.assert_array_equal(pipe.run(frame).color, frame.color)
    assert pipe.run(frame).metadata["camera"]["clpost.exposureMode"] == "passthrough"
    # f-number, shutter, ISO and T do not rescale a passthrough plate
    assert exposure_gain(Camera(f_number=8, shutter_s=1 / 1000, iso=3200, transmittance=0.5)) == 1.0


@pytest.mark.parametrize("mode_kw", [{}, {"luminance_scale": 37.0}, {"reference_exposure": "f/2,1/50,100"}])
def test_ev_and_nd_are_exact_powers_of_two_in_every_mode(mode_kw):
    base = exposure_gain(Camera(**mode_kw))
    for ev, nd in [(1.0, 0.0), (-2.5, 0.0), (0.0, 3.0), (2.0, 10.0)]:
        got = exposure_gain(Camera(exposure_compensation_ev=ev, nd_stops=nd, **mode_kw))
        assert got / base == pytest.approx(2.0 ** (ev - nd), rel=1e-14)
    if not mode_kw:
        assert exposure_gain(Camera(exposure_compensation_ev=1.0, nd_stops=3.0)) == 0.25  # exact


def test_relative_mode_is_one_at_the_reference_and_photographic_ratios_elsewhere():
    ref = dict(reference_exposure="f/2,1/50,100", focus_distance_m=1.0)
    at_ref = Camera(f_number=2.0, shutter_s=1 / 50, iso=100, **ref)
    assert exposure_mode(at_ref) == "relative" and exposure_gain(at_ref) == 1.0
    assert Pipeline(at_ref).plan(uniform(0.3)) == []
    # one stop each: f/2.8 (−1, to rounding of √2), 1/25 s (+1), ISO 400 (+2), T 0.45 (−1)
    cam = Camera(f_number=2.0 * math.sqrt(2), shutter_s=1 / 25, iso=400, transmittance=0.45, **ref)
    assert exposure_gain(cam) == pytest.approx(2.0, rel=1e-14)
    assert exposure_gain(Camera(f_number=4, shutter_s=1 / 50, iso=100, **ref)) == 0.25
    # a 4th element is the reference transmittance
    assert exposure_gain(Camera(f_number=2, shutter_s=1 / 50, iso=100, transmittance=0.45,
                                reference_exposure=(2, 1 / 50, 100, 0.9))) == 0.5
    # the meter sees the plate at the reference's luminance scale: metering lands at mid-grey
    from clpost.photometry import MID_GREY_SIGNAL

    out = Pipeline(Camera(shutter_s=None, f_number=2.0, **ref)).run(uniform(0.05))
    np.testing.assert_allclose(out.color, MID_GREY_SIGNAL, rtol=1e-6)


def test_physical_mode_is_the_unchanged_formula():
    cam = Camera(f_number=2.8, shutter_s=1 / 125, iso=400, transmittance=0.8, luminance_scale=250.0,
                 focus_distance_m=math.inf)
    assert exposure_mode(cam) == "physical"
    expected = 250.0 * math.pi * 0.8 / (4 * 2.8**2) * (1 / 125) / (78 / 400)
    assert exposure_gain(cam) == pytest.approx(expected, rel=1e-14)
    # the old default camera, now asked for explicitly: 1 cd/m², 1/50 s, f/2, ISO 100, T 0.9, u = 3 m
    old = Camera(luminance_scale=1.0)
    b = old.image_distance_mm / old.focal_length_mm
    assert exposure_gain(old) == pytest.approx(math.pi * 0.9 / (4 * (2 * b) ** 2) * 0.02 * 100 / 78, rel=1e-14)


def test_reference_exposure_and_luminance_scale_are_exclusive_and_parsed():
    from clpost import InputError

    with pytest.raises(InputError, match="both set; give one"):
        Camera(luminance_scale=100.0, reference_exposure="f/2,1/50,100")
    assert Camera(reference_exposure="2,0.02,100,0.8").reference_exposure == (2.0, 0.02, 100.0, 0.8)
    for bad in ("f/2,1/50", "f/0,1/50,100", "f/2,1/50,100,1.5"):
        with pytest.raises(InputError, match="reference_exposure"):
            Camera(reference_exposure=bad)
    assert Camera(reference_exposure="f/2,1/50,100").describe()["clpost.referenceExposure"] == "f/2,0.02,100,0.9"


def test_auto_exposure_needs_a_light_level():
    from clpost import InputError

    with pytest.raises(InputError, match="passthrough camera does not know"):
        Pipeline(Camera(shutter_s=None)).run(uniform(0.2))


def test_nd_makes_the_ttl_meter_choose_a_longer_shutter_for_the_same_image():
    from clpost.metering import resolve

    frame = uniform(0.2)
    plain = Camera(shutter_s=None, luminance_scale=1000.0)
    nd = Camera(shutter_s=None, luminance_scale=1000.0, nd_stops=3.0)
    assert resolve(nd, frame).shutter_s / resolve(plain, frame).shutter_s == pytest.approx(8.0, rel=1e-12)
    a, b = Pipeline(plain).run(frame).color, Pipeline(nd).run(frame).color
    np.testing.assert_allclose(a, b, rtol=1e-6)
    # EC in auto-exposure is the meter's (longer shutter), never applied twice
    ec = Camera(shutter_s=None, luminance_scale=1000.0, exposure_compensation_ev=1.0)
    np.testing.assert_allclose(Pipeline(ec).run(frame).color, 2 * a, rtol=1e-6)


def test_far_from_mid_grey_warns_in_one_line_naming_the_fix():
    from clpost.metering import ExposureWarning

    with pytest.warns(ExposureWarning, match=r"metered 7\.\d EV below mid-grey \(physical exposure\); fix with --ev \+7"):
        Pipeline(Camera(luminance_scale=1.0)).run(uniform(0.18))
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", ExposureWarning)
        Pipeline(Camera(luminance_scale=1.0, shutter_s=0.02 * 2 ** 7.16)).run(uniform(0.18))  # at grey
        Pipeline(Camera()).run(uniform(1e5))  # passthrough: the plate's exposure is the user's

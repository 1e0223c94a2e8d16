"""print: metered grey prints at 18 % neutral; linear inversion is identity on the straight line."""
import math

import numpy as np
import pytest

from clpost import Camera, Frame, Pipeline
from clpost.film_stock import load_stock
from clpost.photometry import K_REFLECTED
from clpost.stages.print import PAPER_RANGE

from conftest import assert_planned


def _cam(stock, mode, **kw):
    return Camera(f_number=4.0, shutter_s=1 / 125, iso=kw.pop("iso", 100), luminance_scale=1.0, film=stock,
                  film_output=mode, grain_amount=0.0, focus_distance_m=math.inf, **kw)


def metered_grey(cam):
    """Luminance that the ISO 2720 meter would expose as mid-grey at these settings."""
    return K_REFLECTED * cam.f_number ** 2 / (cam.iso * cam.shutter_s)


@pytest.mark.parametrize("stock", ["kodak-ektar-100", "kodak-gold-200", "fuji-superia-400", "neutral-100"])
def test_metered_grey_prints_at_18_percent_neutral(stock):
    cam = _cam(stock, "print")
    frame = Frame(np.full((3, 5, 3), metered_grey(cam), np.float32))
    out = Pipeline(cam).run(frame).color
    np.testing.assert_allclose(out, 0.18, rtol=2e-3)


def test_print_is_monotone_and_bounded_by_paper_white_and_dmax(rng):
    cam = _cam("kodak-gold-200", "print")
    lum = np.logspace(-6, 8, 301).astype(np.float32)
    out = Pipeline(cam).run(Frame(np.repeat(lum[None, :, None], 3, 2))).color[0]
    assert np.isfinite(out).all()
    assert np.all(np.diff(out, axis=0) >= -1e-6)
    assert out.min() >= 10 ** -PAPER_RANGE * 0.999 and out.max() <= 1.0


def test_linear_output_is_identity_on_the_straight_line():
    cam = _cam("kodak-ektar-100", "linear")
    s = load_stock("kodak-ektar-100")
    gam, icp = s.straight_line()
    # signals whose exposure lies mid-way along every layer's straight line: 0.3 of the metered grey …
    signal = np.array([0.05, 0.1, 0.3], np.float32)
    frame = Frame(np.repeat(signal[None, :, None], 3, 2))
    pipe = Pipeline(cam, stages=["film", "print"], already_applied=("exposure",))
    out = pipe.run(frame).color[0]
    np.testing.assert_allclose(out, signal[:, None] * np.ones(3), rtol=0.08)
    # … while toe and shoulder are compressed: deep shadows come back lifted, highlights lowered
    ext = Pipeline(cam, stages=["film", "print"], already_applied=("exposure",)).run(Frame(np.array([[[1e-5] * 3, [1e3] * 3]], np.float32))).color[0]
    assert np.all(ext[0] > 1e-5) and np.all(ext[1] < 1e3)


@pytest.mark.parametrize("mode", ["print", "linear"])
def test_kernel_matches_reference_odd_size(rng, mode):
    cam = _cam("fuji-superia-400", mode, iso=400)
    c = (10.0 ** rng.uniform(-6, 8, (23, 37, 3))).astype(np.float32)
    frame = Frame(c)
    pipe = Pipeline(cam)
    assert_planned(pipe, frame, "exposure", "film", "print")
    assert pipe.kernels(frame) == ["exposure__film__print"]  # one fused pass
    out, ref = pipe.run(frame).color, pipe.reference(frame)
    rel = np.abs(out - ref) / ref
    y, x, ch = np.unravel_index(int(rel.argmax()), rel.shape)
    assert rel.max() < 2e-3, f"worst {rel.max():.2e} at (x={x}, y={y}, c={ch})"


def test_negative_output_skips_print():
    cam = _cam("kodak-ektar-100", "negative")
    entries = {e.stage: e for e in Pipeline(cam).explain(Frame(np.ones((2, 2, 3), np.float32)))}
    assert not entries["print"].planned and "negative" in entries["print"].reason


@pytest.mark.parametrize("stock", ["kodak-gold-200", "neutral-100"])
def test_print_depends_on_exposure_only_at_equal_T_times_t(stock, rng):
    # T 0.1 with 9× the shutter vs T 0.9 printed 0.41 vs 0.07 — the printer light was
    # computed from the lens's T; a printer sees only the negative
    lum = (10.0 ** rng.uniform(-1, 3, (5, 7, 3))).astype(np.float32)
    frame = Frame(lum)
    dark = _cam(stock, "print", transmittance=0.1).with_(shutter_s=9 / 125)
    clear = _cam(stock, "print", transmittance=0.9)
    a, b = Pipeline(dark).run(frame).color, Pipeline(clear).run(frame).color
    np.testing.assert_allclose(a, b, rtol=2e-5)
    # and the grey card the meter exposes prints at 18 % through either lens (TTL meter)
    grey = Frame(np.full((3, 5, 3), 50.0, np.float32))
    for T in (0.1, 0.9):
        cam = Camera(f_number=4.0, shutter_s=None, luminance_scale=1.0, film=stock, grain_amount=0.0,
                     transmittance=T, focus_distance_m=math.inf)
        np.testing.assert_allclose(Pipeline(cam).run(grey).color, 0.18, rtol=2e-3)


def test_film_rates_the_camera_at_its_box_speed_unless_iso_is_given():
    assert Camera(film="kodak-gold-200").iso == 200.0
    assert Camera(film="fuji-superia-400").iso == 400.0
    assert Camera(film="kodak-gold-200", iso=800).iso == 800.0
    assert Camera().iso == 100.0
    from clpost.cli import build_parser, camera_from_args

    args = build_parser().parse_args(["process", "in.exr", "-o", "o.exr", "--film", "kodak-gold-200"])
    assert camera_from_args(args).iso == 200.0
    args = build_parser().parse_args(["process", "in.exr", "-o", "o.exr", "--film", "kodak-gold-200", "--iso", "100"])
    assert camera_from_args(args).iso == 100.0

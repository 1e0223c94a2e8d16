"""Focus is where the depth pass says: ``focus_distance_m`` / ``--focus`` is the planar
depth that is sharp, measured from the render's pinhole (a real lens's entrance pupil), for thin
and traced lenses alike; ``focus_scale_m`` / ``--focus-scale`` is the lens-scale distance from the
film; the focused camera's focal length (breathing) matches traced chief rays.

The independent reference is the Kolb-style backward tracer of :mod:`clpost.render.kolb_trace`
(film point → exit-pupil disc → lens → scene), not the unit-focusing solver under test."""
import math

import numpy as np
import pytest

from clpost.camera import Camera
from clpost.errors import InputError
from clpost.optics import get_lens
from clpost.render.ibl_rays import mirrored_table, trace_back
from clpost.render.ibl_warp import lens_to_camera_m
from clpost.render.kolb_trace import axial_blur_px
from clpost.stages.dof import coc_px

W = 1920  # image width the blur is measured at (px); pitch 36 mm / 1920


def traced_blur_px(cam, depth_m, rays=20000):
    return axial_blur_px(cam, depth_m, W, rays=rays)


# (lens, f-number, depth m): centimetres (the fisheye at 8 cm) to far; the achromat and the fisheye
# were held out while the focus solver was written and checked.
CASES = [("zeiss-planar-50-f1.4", 2.0, 0.475), ("zeiss-planar-50-f1.4", 2.8, 3.0),
         ("dgauss-50", 4.0, 0.7), ("telephoto-250", 5.6, 4.0), ("telephoto-250", 5.6, 60.0),
         ("wide-22", 4.0, 0.27), ("thorlabs-lb1471", 8.0, 1.0),
         ("thorlabs-ac254-050-a", 4.0, 0.6), ("thorlabs-ac254-050-a", 4.0, 25.0), ("fisheye-10", 5.6, 0.08)]


@pytest.mark.parametrize("lens, n, depth", CASES)
def test_traced_lens_focused_at_a_depth_makes_that_depth_sharpest(lens, n, depth):
    """An object at depth D with focus_distance_m = D is where the traced blur is least (over
    depths 1 % apart near, 5 % far), the dof stage's CoC there is 0, and it is several times
    sharper than the old reading of the same number as a film distance near (sharper at all beyond)."""
    cam = Camera(lens=lens, f_number=n, focus_distance_m=depth)
    assert cam.focused_depth_m == depth and coc_px(cam, depth, W) == 0.0
    step = 0.01 if depth < 2 else 0.05
    ss = depth * np.exp(step * np.arange(-3, 4))
    blur = [traced_blur_px(cam, s) for s in ss]
    assert int(np.argmin(blur)) == 3, (ss, blur)
    if depth >= get_lens(lens).min_focus_m:  # before, --focus D below the scale's minimum was refused
        old = Camera(lens=lens, f_number=n, focus_scale_m=depth)  # what --focus D meant before
        assert traced_blur_px(old, depth) > blur[3] * (1.5 if depth < 1.5 else 1.0) or depth > 20


@pytest.mark.parametrize("lens, n, depth", CASES[::3])
def test_dof_coc_of_a_traced_lens_matches_the_tracer_off_focus(lens, n, depth):
    """c = (f/N) F (1/u − 1/S) with F the focused camera's focal length: within 3 % of the traced
    blur (spherical aberration and pupil aberrations are the rest) on both sides of focus."""
    cam = Camera(lens=lens, f_number=n, focus_distance_m=depth)
    for s in (0.7 * depth, 1.5 * depth):
        assert 2 * abs(float(coc_px(cam, s, W))) == pytest.approx(traced_blur_px(cam, s), rel=0.03)


@pytest.mark.parametrize("depth", [0.12, 0.5, 3.0, 12.0])
def test_thin_lens_focused_at_a_depth_images_it_sharply(depth):
    """Ideal thin lens traced backwards from the axial film point at v through lens points h
    (slope h/v, bent by −h/f): the footprint at depth S has radius R |1 + S/v − S/f|, zero at D."""
    cam = Camera(lens="thin:50", f_number=2.0, focus_distance_m=depth)
    f, v = 50.0, cam.image_distance_mm
    rng = np.random.default_rng(1)
    h = (f / 4.0) * np.sqrt(rng.random(4000))  # pupil radius f/2N
    for s, want_zero in ((depth, True), (depth * 0.7, False)):
        y = h + s * 1000.0 * (h / v - h / f)
        blur = 2 * np.abs(y).max() * v / (s * 1000.0) / cam.pixel_pitch_mm(W)
        assert (blur < 1e-6) if want_zero else (blur > 1.0)
        assert abs(2 * float(coc_px(cam, s, W))) == pytest.approx(blur, rel=1e-3, abs=1e-6)


@pytest.mark.parametrize("lens", ["thin:35", "zeiss-planar-50-f1.4", "telephoto-250", "fisheye-10"])
def test_focus_scale_names_the_same_internal_state(lens):
    """focus_scale_m L (film → object) converts exactly: the camera it makes has the same depth,
    lens position and scale distance as one given that depth."""
    lo = 0.5 if lens.startswith("thin") else get_lens(lens).min_focus_m
    for scale in (lo * 1.0, lo * 1.7, lo * 10.0, math.inf):
        a = Camera(lens=lens, f_number=5.6, focus_scale_m=scale)
        b = Camera(lens=lens, f_number=5.6, focus_distance_m=a.focus_distance_m)
        assert b.focus_from_film_m == pytest.approx(scale, rel=1e-9)
        assert a.image_distance_mm == b.image_distance_mm
        if a.optics is not None and math.isfinite(scale):
            assert a.focus_state.back_distance_mm == pytest.approx(b.focus_state.back_distance_mm, abs=1e-9)
    thin = Camera(lens="thin:50", focus_scale_m=1.0)
    u = thin.focus_distance_m
    assert u + thin.image_distance_mm / 1000.0 == pytest.approx(1.0, rel=1e-12)  # L = u + v


def test_focus_scale_bad_values_name_the_fix():
    with pytest.raises(InputError, match=r"minimum focus distance 0.45 m.*--focus-scale >= 0.45"):
        Camera(lens="zeiss-planar-50-f1.4", focus_distance_m=0.35)
    with pytest.raises(InputError, match=r"focus_scale_m=0.4 is closer than zeiss-planar-50-f1.4's minimum"):
        Camera(lens="zeiss-planar-50-f1.4", focus_scale_m=0.4)
    with pytest.raises(InputError, match=r"4f = 0.2 m"):
        Camera(lens="thin:50", focus_scale_m=0.15)


def chief_ray_focal_mm(cam, r_mm=0.02):
    """Film height per tan θ of the real chief ray (through the exit-pupil centre) at height r,
    traced backwards; θ seen from the entrance pupil at the focus depth (tan θ = X/D), or the ray's
    direction at infinity focus."""
    lens = cam.optics
    pres = lens.focused(cam.focus_from_film_m * 1000.0, cam.f_number)
    table, zf = mirrored_table(pres, lens.stop_radius_mm(cam.f_number))
    q, d, ok = trace_back(table, zf, np.array([[0.0, r_mm]]), np.array([0.0, 0.0, lens.paraxial.z_exit_pupil_mm]))
    assert ok[0]
    oc = lens_to_camera_m(q, lens.paraxial.z_entrance_pupil_mm)[0] * 1000.0
    dc = np.array([d[0, 0], -d[0, 1], -d[0, 2]])
    if math.isinf(cam.focus_distance_m):
        return r_mm / abs(dc[1] / dc[2])
    depth = cam.focus_distance_m * 1000.0
    x = oc[1] + (depth - oc[2]) / dc[2] * dc[1]
    return r_mm * depth / abs(x)


@pytest.mark.parametrize("lens, n, depth", [("zeiss-planar-50-f1.4", 2.8, 0.475), ("dgauss-50", 4.0, 1.0),
                                            ("telephoto-250", 8.0, 3.5), ("thorlabs-ac254-050-a", 4.0, 0.6)])
def test_breathing_focal_length_matches_traced_chief_rays(lens, n, depth):
    """The focused camera's focal length (intrinsics, FOV) is the traced chief rays' film height
    per tan θ near the axis (to 1e-3: the chief ray is the exit-pupil-centre ray here), and its
    change from infinity focus is the lens's breathing."""
    cam = Camera(lens=lens, f_number=n, focus_distance_m=depth)
    inf = cam.with_(focus_distance_m=math.inf)
    k, k_inf = chief_ray_focal_mm(cam), chief_ray_focal_mm(inf)
    assert cam.render_focal_length_mm == pytest.approx(k, rel=1e-3)
    assert inf.render_focal_length_mm == pytest.approx(k_inf, rel=1e-3)
    assert cam.render_focal_length_mm / inf.render_focal_length_mm == pytest.approx(k / k_inf, rel=1e-3)
    assert abs(k / k_inf - 1) > 0.01  # the lenses breathe measurably at these depths
    assert cam.intrinsics(W, 1280)[0] == cam.render_focal_length_mm / (36.0 / W)
    assert cam.field_of_view_focused_deg == pytest.approx(
        math.degrees(2 * math.atan(18.0 / cam.render_focal_length_mm)), rel=1e-12)


def test_thin_lens_breathing_is_v_over_f():
    cam = Camera(lens="thin:50", focus_distance_m=0.3)
    assert cam.render_focal_length_mm == pytest.approx(50 * 300 / 250, rel=1e-12)
    assert cam.render_focal_length_mm == cam.image_distance_mm


def test_cli_focus_and_focus_scale_are_exclusive_in_one_line(tmp_path, capsys):
    from clpost.cli import main

    for argv in (["process", str(tmp_path / "in.exr"), "-o", str(tmp_path / "o.exr"), "--focus", "1",
                  "--focus-scale", "1"],
                 ["lens", "info", "dgauss-50", "--focus", "1", "--focus-scale", "1"]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("clpost: error:") and "--focus-scale" in err and "\n" not in err
    assert main(["lens", "info", "dgauss-50", "--focus", "0.3"]) == 2
    assert "--focus-scale >= 0.6" in capsys.readouterr().err


def test_cli_lens_info_reports_the_focused_camera(capsys):
    """`clpost lens info --focus D` gives the lens-scale distance and the camera to render with."""
    from clpost.cli import main

    assert main(["lens", "info", "zeiss-planar-50-f1.4", "--focus", "0.475", "--f-number", "2", "--json"]) == 0
    import json

    at = json.loads(capsys.readouterr().out)["at"]
    cam = Camera(lens="zeiss-planar-50-f1.4", f_number=2.0, focus_distance_m=0.475)
    assert at["depth_m"] == pytest.approx(0.475, rel=1e-12)
    assert at["focus_scale_m"] == pytest.approx(cam.focus_from_film_m, rel=1e-12)
    assert at["render_focal_mm"] == pytest.approx(cam.render_focal_length_mm, rel=1e-12)
    assert at["fov_focused_deg"]["horizontal"] == pytest.approx(cam.field_of_view_focused_deg, rel=1e-12)
    assert 1.05 < at["breathing"] < 1.12


# -- a fixed render at the infinity-focus field of view (--plate-fov infinity) ------------------

def test_plate_magnification_is_v_over_f_for_a_thin_lens():
    from clpost.breathing import magnification

    cam = Camera(lens="thin:50", focus_distance_m=0.5, plate_fov="infinity")
    assert magnification(cam) == pytest.approx((50 * 500 / 450) / 50, rel=1e-12)
    assert magnification(cam.with_(plate_fov="focused")) == 1.0


@pytest.mark.parametrize("lens, n, depth", [("zeiss-planar-50-f1.4", 2.8, 0.475), ("telephoto-250", 8.0, 3.5)])
def test_rescaled_plate_puts_a_point_where_the_traced_chief_ray_lands(lens, n, depth):
    """A small blob at angle θ in a plate rendered at the infinity-focus camera (x = c + F∞ tan θ / p)
    lands, after the rescale, where the real chief ray of the lens focused at D does (0.1 px)."""
    from clpost.breathing import rescale_plate
    from clpost.frame import Frame

    w, h = 480, 320
    cam = Camera(lens=lens, f_number=n, focus_distance_m=depth, plate_fov="infinity")
    p = cam.pixel_pitch_mm(w)
    f_inf = cam.with_(focus_distance_m=math.inf).render_focal_length_mm
    c = ((w - 1) / 2, (h - 1) / 2)
    off = 60.0  # plate px from the centre, along +y (down)
    tan_t = off * p / f_inf
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    blob = np.exp(-((xx - c[0]) ** 2 + (yy - c[1] - off) ** 2) / (2 * 1.5 ** 2))
    plate = Frame(np.repeat(blob[..., None], 3, -1).astype(np.float32), depth=np.full((h, w), depth, np.float32))
    out = rescale_plate(plate, cam).color[..., 0].astype(np.float64)
    y_c = float((out * yy).sum() / out.sum())
    x_c = float((out * xx).sum() / out.sum())
    assert x_c == pytest.approx(c[0], abs=1e-6)
    # the traced chief ray's film height for this θ: its focal length at about that height
    k = chief_ray_focal_mm(cam.with_(plate_fov="focused"), r_mm=off * p * cam.render_focal_length_mm / f_inf)
    assert y_c - c[1] == pytest.approx(k * tan_t / p, abs=0.1)
    assert y_c - c[1] == pytest.approx(off * cam.render_focal_length_mm / f_inf, abs=0.02)  # the scale itself
    assert y_c - c[1] > off + 2.0  # magnified: the lens breathes


def test_pipeline_applies_the_plate_rescale_before_the_stages(rng):
    from clpost.breathing import rescale_plate
    from clpost.frame import Frame
    from clpost.pipeline import Pipeline

    h, w = 24, 36
    frame = Frame(rng.random((h, w, 3)).astype(np.float32) + 0.1, depth=np.full((h, w), 2.0, np.float32),
                  velocity=rng.normal(size=(h, w, 2)).astype(np.float32))
    cam = Camera(lens="thin:50", focus_distance_m=0.4, plate_fov="infinity", shutter_s=1 / 50)
    got = Pipeline(cam, stages=["exposure"]).run(frame)
    want = Pipeline(cam.with_(plate_fov="focused"), stages=["exposure"]).run(rescale_plate(frame, cam))
    np.testing.assert_array_equal(got.color, want.color)
    r = rescale_plate(frame, cam)
    s = 400 / 350
    np.testing.assert_allclose(r.velocity[h // 2, w // 2], frame.velocity[h // 2, w // 2] * s, rtol=1e-6)
    assert r.color.min() >= 0 and np.isfinite(r.color).all() and (r.depth == 2.0).all()
    assert cam.describe()["clpost.plateFov"] == "infinity"  # recorded in the output header
    assert "clpost.plateFov" not in cam.with_(plate_fov="focused").describe()  # default: headers unchanged

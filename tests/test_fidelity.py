"""clpost.fidelity: the metrics of docs/fidelity.md on images whose answers are known."""
import math

import numpy as np
import pytest

from clpost import fidelity as fd
from clpost.colorspace import cctf_encode
from clpost.stages.dof import coc_px as clpost_coc_px

SHOT = dict(focal_mm=50.0, sensor_mm=36.0, f_number=1.4, focus_m=2.0, blades=6, rotation_deg=0.0, fps=24.0,
            shutter_frames=0.5)


def test_psnr_srgb_closed_form():
    a = np.full((8, 9, 3), 0.2)
    b = np.full((8, 9, 3), 0.25)
    d = float(cctf_encode(np.array(0.25), "sRGB") - cctf_encode(np.array(0.2), "sRGB"))
    assert fd.psnr_srgb(a, b) == pytest.approx(-20 * math.log10(abs(d)), abs=1e-9)
    assert fd.psnr_srgb(a, a) == math.inf


def test_psnr_srgb_clips_like_a_viewer():
    """Values above white look the same: a saturated disc counts by its shape, not its energy."""
    a = np.full((4, 4, 3), 0.5)
    a[1, 1] = 5.0
    b = a.copy()
    b[1, 1] = 50.0
    assert fd.psnr_srgb(a, b) == math.inf
    assert fd.psnr_srgb(a, b, exposure=0.01) < 60
    with pytest.raises(ValueError, match="shapes differ"):
        fd.psnr_srgb(a, a[:3])


def test_coc_px_closed_form_and_clpost_camera_agrees():
    # f/N = 50/1.4 mm aperture, f_px = 50·480/36, infinity at 2 m focus: (0.05/1.4)·666.67·0.5 px
    assert fd.coc_px(math.inf, 2.0, 50, 1.4, 36, 480) == pytest.approx(0.05 / 1.4 * 50 * 480 / 36 * 0.5)
    cam = fd.cycles_camera(SHOT, 480, 270)
    assert cam.render_focal_length_mm == pytest.approx(50.0, rel=1e-7)  # no breathing, like Cycles
    depths = np.array([0.5, 1.0, 2.0, 3.0, 12.0, 1e10])
    mine = fd.coc_px(depths, 2.0, 50, 1.4, 36, 480)
    assert np.allclose(2 * np.abs(clpost_coc_px(cam, depths, 480)), mine, rtol=1e-6)
    # the naive mapping (thin:50 at f/1.4) breathes: every CoC S/(S − f) larger
    from clpost import Camera

    naive = Camera(lens="thin:50", f_number=1.4, focus_distance_m=2.0, depth_of_field=True)
    assert 2 * abs(clpost_coc_px(naive, 12.0, 480)) / mine[4] == pytest.approx(2.0 / 1.95, rel=1e-6)


def test_cycles_camera_motion_and_blades():
    cam = fd.cycles_camera(dict(SHOT, blades=5, rotation_deg=12.0), 480, 270, dof=False, motion=True)
    assert cam.shutter_s == pytest.approx(1 / 48)
    assert (cam.blades, cam.blade_rotation_deg, cam.depth_of_field) == (5, 12.0, False)
    assert cam.sensor_mm == pytest.approx((36.0, 20.25))


def _disc(shape, x, y, r, value):
    jj, ii = np.mgrid[0:shape[0], 0:shape[1]]
    img = np.zeros(shape + (3,))
    img[np.hypot(ii - x, jj - y) <= r] = value
    return img


def test_saturated_area_counts_pixels_at_or_above_white():
    img = _disc((41, 43), 20, 21, 6.0, 2.0) + _disc((41, 43), 20, 21, 9.0, 0.5)
    n6 = int(np.count_nonzero(_disc((41, 43), 20, 21, 6.0, 1.0)[..., 0]))
    assert fd.saturated_area(img, 20, 21, 12.0) == n6
    assert fd.saturated_area(img, 20, 21, 12.0, level=0.4) > n6
    assert fd.saturated_area(img, 20, 21, 3.0) < n6  # the window limits it


def test_halo_and_energy_on_lamp_only_images():
    lamp = np.zeros((31, 31, 3))
    lamp[15, 15] = 100.0
    halo = lamp.copy()
    halo += _disc((31, 31), 15, 15, 8.0, 0.05)  # a faint disc around it
    assert fd.halo_pixels(lamp, 15, 15, 12.0, level=0.01) == 0
    ring = int(np.count_nonzero(_disc((31, 31), 15, 15, 8.0, 1)[..., 0])) - \
        int(np.count_nonzero(_disc((31, 31), 15, 15, 3.0, 1)[..., 0]))
    assert fd.halo_pixels(halo, 15, 15, 12.0, level=0.01) == ring
    assert fd.window_energy(lamp, 15, 15, 2.0) == pytest.approx(100.0)


def test_emitter_metrics_in_focus_and_defocused():
    h, w = 60, 480  # the CoC scales with the width: 480 px wide as the suite
    truth_lamp = np.zeros((h, w, 3))
    truth_lamp[30, 40] = 100.0
    # 10 % of the lamp's light spread over a 4 px disc: a halo, but inside the 5 px energy window
    spread = truth_lamp * 0.9 + _disc((h, w), 40, 30, 4.0, 10.0 / np.count_nonzero(_disc((h, w), 40, 30, 4.0, 1)[..., 0]))
    sharp = dict(name="a", x_px=40.0, y_px=30.0, depth_m=2.0, diameter_px=1.0)
    m = fd.emitter_metrics(spread, truth_lamp, spread, truth_lamp, sharp, SHOT, white=0.6)
    assert m["in_focus"] and m["halo_truth"] == 0 and m["halo_test"] > 15
    assert m["energy_ratio"] == pytest.approx(1.0)
    wide = truth_lamp * 0.9 + _disc((h, w), 40, 30, 9.0, 10.0 / np.count_nonzero(_disc((h, w), 40, 30, 9.0, 1)[..., 0]))
    assert fd.emitter_metrics(wide, truth_lamp, wide, truth_lamp, sharp, SHOT, 0.6)["energy_ratio"] < 0.95
    far = dict(sharp, depth_m=12.0)  # CoC ≈ 9.5 px: a disc
    c = fd.coc_px(12.0, 2.0, 50, 1.4, 36, w)
    disc_truth = _disc((h, w), 40, 30, c / 2, 3.0)
    disc_big = _disc((h, w), 40, 30, c / 2 * 1.3, 3.0)
    m = fd.emitter_metrics(disc_big, disc_truth, disc_big * 0.5, disc_truth * 0.5, far, SHOT, white=0.6)
    assert not m["in_focus"]
    n_big, n_truth = (int(np.count_nonzero(d[..., 0])) for d in (disc_big, disc_truth))
    assert (m["area_test"], m["area_truth"]) == (n_big, n_truth)  # the window holds the whole disc
    assert m["area_ratio"] > 1.5
    assert m["energy_ratio"] == pytest.approx(m["area_test"] / m["area_truth"])
    hidden = fd.emitter_metrics(disc_big, disc_truth, disc_big, np.zeros_like(disc_truth), far, SHOT, white=0.6)
    assert hidden["energy_ratio"] is None


def test_motion_box_grows_by_the_blur():
    v = np.zeros((50, 60, 2))
    v[20:25, 30:34] = (10.0, 0.0)
    assert fd.motion_box(v, 0.5) == (20 - 9, 25 + 9, 30 - 9, 34 + 9)
    assert fd.motion_box(np.zeros((5, 5, 2)), 0.5) is None

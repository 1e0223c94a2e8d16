"""dof: thin-lens CoC closed forms, kernels vs the float64 reference, energy, bokeh shape and
texture, occlusion (no halo, partial occlusion), extremes and the plan."""
import math

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from clpost import Camera, Frame, Pipeline
from clpost.stages import dof as D

from conftest import assert_planned, odd_frame

CAM = dict(depth_of_field=True, f_number=1.4, focus_distance_m=2.0, shutter_s=1 / 50, sensor_mm=(6.0, 4.0))
"""A small sensor makes CoC of 5–40 px on test images ~100 px wide."""


def run(cam, frame, quality="final"):
    pipe = Pipeline(cam, quality=quality, stages=["dof"])
    return pipe.run(frame).color, pipe


def assert_matches_reference(pipe, frame, out, rtol=2e-4):
    assert_planned(pipe, frame, "dof")
    ref = pipe.reference(frame)
    err = np.abs(out - ref) / (np.abs(ref) + 1e-3 * max(1.0, float(np.abs(ref).max())))
    worst = np.unravel_index(int(np.argmax(err)), err.shape)
    assert err.max() < rtol, f"largest relative error {err.max():.3g} at (y, x, c) = {worst}"


# -- CoC: closed forms -------------------------------------------------------------------------

@pytest.mark.parametrize("f_mm, n, u_m", [(50, 2.0, 3.0), (35, 1.4, 0.5), (85, 8.0, 10.0), (24, 0.7, 0.1)])
def test_coc_is_the_thin_lens_blur_disc(f_mm, n, u_m):
    cam = Camera(lens=f"thin:{f_mm}", f_number=n, focus_distance_m=u_m)
    s_m = np.array([0.06, u_m / 2, u_m, 2 * u_m, 1e3])
    s = s_m * 1e3
    v = f_mm * u_m * 1e3 / (u_m * 1e3 - f_mm)
    v_s = f_mm * s / (s - f_mm)
    a = f_mm / n
    geometric = a * (v - v_s) / v_s  # blur disc where the cone to v_s meets the film at v
    np.testing.assert_allclose(D.coc_mm(cam, s_m), geometric, rtol=1e-9, atol=1e-12)
    # the talk's C = v^2 |S-u| / (u S N) is the same disc with A = v/N: ratio v/f exactly
    talk = v * v * np.abs(s - u_m * 1e3) / (u_m * 1e3 * s * n)
    np.testing.assert_allclose(np.abs(D.coc_mm(cam, s_m)) * v / f_mm, talk, rtol=1e-9)


def test_coc_sign_far_limit_and_pixels():
    cam = Camera(lens="thin:50", f_number=2.0, focus_distance_m=3.0)
    v = cam.image_distance_mm
    assert D.coc_mm(cam, 1.0) < 0 < D.coc_mm(cam, 10.0)
    assert D.coc_mm(cam, np.inf) == pytest.approx(50 * v / (2.0 * 3000.0), rel=1e-12)
    # radius in px = diameter / (2 pitch); 640 px across 36 mm
    assert D.coc_px(cam, np.inf, 640) == pytest.approx(D.coc_mm(cam, np.inf) / (2 * 36 / 640), rel=1e-12)
    # infinity focus: far limit 0, everything else near field
    inf = cam.with_(focus_distance_m=math.inf)
    assert D.coc_px(inf, np.inf, 640) == 0.0 and D.coc_px(inf, 5.0, 640) < 0
    # depth -> 0+ is clamped to the documented maximum
    assert D.coc_px(cam, 1e-9, 640, limit_px=D.max_coc_px("final")) == -64.0


# -- kernels vs the float64 reference ----------------------------------------------------------

@pytest.mark.parametrize("quality", ["final", "preview", "draft"])
@pytest.mark.parametrize("extra", [dict(blades=6), dict(blades=5, blade_rotation_deg=17, aperture_roundness=0.3,
                                                         spherical_aberration=0.6, optical_vignetting=0.8)])
def test_kernel_matches_reference_on_odd_sizes(rng, quality, extra):
    frame = odd_frame(rng)
    depth = frame.depth.copy()
    depth[rng.random(depth.shape) < 0.1] = np.inf
    depth[0, :3] = 1e-4  # CoC far beyond the maximum
    color = frame.color.copy()
    color[5, 7] = 1e8
    color[9, 30] = 1e-6
    frame = Frame(color, depth=depth)
    out, pipe = run(Camera(**CAM, **extra), frame, quality)
    assert out.dtype == np.float32 and np.isfinite(out).all() and (out >= 0).all()
    assert_matches_reference(pipe, frame, out)


@given(st.integers(0, 2**31 - 1), st.sampled_from([0, 3, 6, 8]), st.floats(-1, 1), st.floats(0.7, 8),
       st.sampled_from(["draft", "final"]))
@example(0, 0, 1.0, 1.0, "draft")  # SA texture zeroes the centre tap: no background weight was 0/0 = NaN
@example(0, 0, 1.0, 1.0, "final")  # ... and a light's textured lattice sums to 0 (dof.light_sums)
@example(1500004200, 0, 0.0, 0.7, "draft")  # 2.4e-4 when the working gather had the lights' ¼-px ramp
def test_kernel_matches_reference_random(seed, blades, sa, n, quality):
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(3, 30)), int(rng.integers(3, 30))
    color = (rng.random((h, w, 3)) * 10 ** rng.uniform(-3, 3, (h, w, 1))).astype(np.float32)
    depth = rng.uniform(0.5, 8, (h, w)).astype(np.float32)
    cam = Camera(**{**CAM, "f_number": n}, blades=blades, spherical_aberration=sa)
    frame = Frame(color, depth=depth)
    out, pipe = run(cam, frame, quality)
    assert np.isfinite(out).all()
    if "dof" in pipe.plan(frame):
        assert np.isfinite(pipe.reference(frame)).all()
        # random colours up to 1000× their neighbours: final's full-resolution gather takes many of
        # them as lights (dof.LIGHT_LUMA; 121 draws: max 1.1e-5)
        assert_matches_reference(pipe, frame, out)
    else:  # an all-in-focus draw: skipped, so the output is the input (skipped <=> identity)
        np.testing.assert_array_equal(out, color)


# -- energy, flatness, shape -------------------------------------------------------------------

def point_frame(depth_m, w=121, h=101, value=1000.0, at=None):
    color = np.full((h, w, 3), 0.0, np.float32)
    y, x = at or (h // 2, w // 2)
    color[y, x] = value
    return Frame(color, depth=np.full((h, w), depth_m, np.float32))


@pytest.mark.parametrize("quality, depth_m", [("final", 0.9), ("final", 20.0), ("final", 0.55),
                                              ("draft", 0.9), ("draft", 20.0)])
def test_point_light_keeps_its_energy_and_becomes_a_hexagon(quality, depth_m):
    cam = Camera(**CAM, blades=6, spherical_aberration=0.5)
    frame = point_frame(depth_m)
    out, _ = run(cam, frame, quality)
    assert out.sum() == pytest.approx(3000.0, rel=0.02)
    r = abs(float(D.coc_px(cam, depth_m, 121)))
    assert 5 < r < 40
    lit = out[..., 0] > 1e-3 * out[..., 0].max()
    ys, xs = np.nonzero(lit)
    # hexagon with a corner at the top: vertical extent r, horizontal r cos 30°
    height, width = ys.max() - ys.min() + 1, xs.max() - xs.min() + 1
    tol = 2.5 if quality == "final" else 6.0  # half resolution: bilinear upsampling widens the edge
    # lattice stride s > 1 (blur larger than the level's budget R_b): the tent prefilter of
    # half-width s and the s-px coverage ramp spread each edge by up to 1.5 (s - 1) px (measured
    # +4.6 px at s = 2, +8.4 px at s = 4 on this frame)
    scale, _, budget = D.QUALITY[quality]
    if quality in D.MIXED and D.lattice_stride(r / D.MIXED[quality][0], D.MIXED[quality][2]) >= 2 ** D.MIXED_LEVEL:
        # final's large blurs (0.55 m: r = 24.6 px) take the half-resolution path
        scale, _, budget = D.MIXED[quality]
        tol = 6.0
    s = D.lattice_stride(r / scale, budget)
    tol += 3 * (s - 1) * scale
    assert height == pytest.approx(2 * r, abs=tol)
    assert width == pytest.approx(2 * r * math.cos(math.pi / 6), abs=tol)


def test_round_aperture_gives_a_circle():
    cam = Camera(**CAM, blades=0)
    out, _ = run(cam, point_frame(20.0))
    lit = out[..., 0] > 1e-6
    ys, xs = np.nonzero(lit)
    assert ys.max() - ys.min() == xs.max() - xs.min()
    r = float(D.coc_px(cam, 20.0, 121))
    assert np.count_nonzero(lit) == pytest.approx(math.pi * (r + 0.5) ** 2, rel=0.05)  # 1-px AA edge


def test_odd_blade_count_points_a_corner_up_behind_focus_and_down_in_front():
    cam = Camera(**CAM, blades=3)
    far, _ = run(cam, point_frame(20.0))
    near, _ = run(cam, point_frame(1.2))
    for img, top_is_corner in ((far, True), (near, False)):
        lit = img[..., 0] > 1e-6
        ys, xs = np.nonzero(lit)
        top_row = np.count_nonzero(lit[ys.min()])
        bottom_row = np.count_nonzero(lit[ys.max()])
        assert (top_row < bottom_row) == top_is_corner


@pytest.mark.parametrize("quality", ["final", "preview", "draft"])
def test_defocused_flat_field_stays_flat(rng, quality):
    h, w = 41, 57
    depth = rng.uniform(0.3, 50, (h, w)).astype(np.float32)
    depth[rng.random((h, w)) < 0.2] = np.inf
    frame = Frame(np.full((h, w, 3), 3.0, np.float32), depth=depth)
    out, _ = run(Camera(**CAM, blades=7, spherical_aberration=0.8, optical_vignetting=1.0), frame, quality)
    assert np.abs(out / 3.0 - 1).max() < 0.01


def _edge_spread_px2(out_row):
    """Variance (px²) of the line-spread function (the derivative of a step edge's profile)."""
    lsf = np.diff(np.asarray(out_row, np.float64))
    x = np.arange(lsf.size) + 0.5
    m = (lsf * x).sum() / lsf.sum()
    return float((lsf * (x - m) ** 2).sum() / lsf.sum())


@pytest.mark.parametrize("quality", ["draft", "preview"])
@pytest.mark.parametrize("r_px", [1.0, 1.5, 4.0, 6.0])
def test_half_resolution_path_blurs_an_edge_like_the_disc(quality, r_px):
    """A step edge blurred by a disc of radius r has a line-spread variance of r²/4 (the disc's
    marginal). The half-resolution path's box and upsampling add 1 px² and depend on the edge's
    phase against the 2×2 blocks, so the mean over both phases is compared: within 12 % of r²/4
    (half_radius, half_blend; before them a 1.5 px CoC gave 3.5× the variance)."""
    h, w = 40, 96
    cam = Camera(**CAM)
    k, inv_u = D.coc_coefficients(cam, w)
    depth = np.full((h, w), 1.0 / (inv_u - r_px / k), np.float32)
    spread = []
    for phase in (0, 1):
        col = np.zeros((h, w, 3), np.float32)
        col[:, w // 2 + phase:] = 1.0
        out, _ = run(cam, Frame(col, depth=depth), quality)
        spread.append(_edge_spread_px2(out[h // 2, :, 0]))
    assert np.mean(spread) == pytest.approx(r_px * r_px / 4, rel=0.12)


def test_tile_plan_dilates_only_by_neighbours_that_can_be_in_front():
    """The gather clamps a source behind p to p's own radius, so a farther, blurrier neighbour
    tile must not raise a tile's reach (stride); a nearer one, or one within the front margin,
    must."""
    rw = np.full((16, 48), 2.0)
    rw[:, 32:] = 4.8  # behind the wall: draft (R_b = 3) would need stride 2 for it
    lvl, cnt = D.tile_plan(rw, 16, 3)
    assert lvl[0, 16] == 0 and cnt[0, 16] == cnt[0, 0]  # the wall tile beside the far tile
    assert D.tile_plan(rw, 16, 3, route=True)[0][0, 16] == 1  # final's routing: as before
    assert lvl[0, 32] == 1
    for near in (-4.8, 2.0 + D.FRONT_MARGIN_PX):
        rw[:, 32:] = near if near < 0 else 4.8
        rw[0, 32] = near  # one source in front of (or level with) the wall's farthest pixel
        assert D.tile_plan(rw, 16, 3)[0][0, 16] == (1 if near < 0 else 0)
    rw[0, 32] = -4.8
    assert D.tile_plan(rw, 16, 3)[0][0, 16] == 1
    # the front margin decides (the level case above holds either way: 2 + margin is stride 1): a
    # wall at 3.375 px is stride 1 alone, a source within the margin behind it (3.625 px) reaching
    # it needs stride 2, one beyond the margin is clamped to the wall's radius
    rw = np.full((16, 48), 3.375)
    rw[:, 32:] = 4.8
    assert D.tile_plan(rw, 16, 3)[0][0, 16] == 0
    rw[0, 32] = 3.375 + D.FRONT_MARGIN_PX
    assert D.tile_plan(rw, 16, 3)[0][0, 16] == 1
    rw[0, 32] = 3.375 + 2 * D.FRONT_MARGIN_PX
    assert D.tile_plan(rw, 16, 3)[0][0, 16] == 0


@pytest.mark.parametrize("quality", ["draft", "preview"])
def test_a_farther_blurrier_sky_beside_a_wall_does_not_change_the_walls_blur(rng, quality):
    """A textured wall (r = 5 px) beside the sky (r = 9.8 px, stride 2 at draft): the wall's tile
    next to the sky tile keeps the wall's own stride, so away from the sky edge the wall is
    blurred exactly as a wall alone (before, the sky's larger CoC made it stride 2 at draft: the
    mortar of h_panes' brick wall, docs/fidelity.md)."""
    h, w = 48, 128
    cam = Camera(**CAM, blades=5)
    k, inv_u = D.coc_coefficients(cam, w)
    color = (0.2 + rng.random((h, w, 3))).astype(np.float32)
    wall = np.full((h, w), 1.0 / (inv_u - 5.0 / k), np.float32)
    sky = wall.copy()
    sky[:, 64:] = np.inf
    alone, _ = run(cam, Frame(color, depth=wall), quality)
    beside, pipe = run(cam, Frame(color, depth=sky), quality)
    np.testing.assert_array_equal(beside[:, :52], alone[:, :52])
    assert_matches_reference(pipe, Frame(color, depth=sky), beside)


def test_local_blur_skips_only_pixels_whose_side_weights_are_all_negligible():
    """local_blur leaves a pixel as it is exactly when its own |r| and every nearer neighbour's are
    under LOCAL_MIN_PX (side weights < 1/32): an in-focus pixel beside a blurred background keeps
    its colour, beside a blurred foreground it takes the foreground's spread."""
    col = np.zeros((5, 6, 3))
    col[:, 3:] = 1.0
    coc = np.full((5, 6), 0.2)
    coc[:, 3:] = 5.0  # background behind the in-focus left half
    out = D.local_blur(col, coc)
    assert np.array_equal(out[:, :3], col[:, :3])
    coc[:, 3:] = -5.0  # the same neighbour in front
    out = D.local_blur(col, coc)
    assert out[2, 2, 0] > 0.1 and np.array_equal(out[:, :2], col[:, :2])


@pytest.mark.parametrize("sa, near_rim_brighter", [(0.7, True), (-0.7, False)])
def test_spherical_aberration_textures_near_and_far_oppositely(sa, near_rim_brighter):
    cam = Camera(**CAM, blades=0, spherical_aberration=sa)
    for depth_m, rim_brighter in ((1.1, near_rim_brighter), (20.0, not near_rim_brighter)):
        out, _ = run(cam, point_frame(depth_m))
        r = abs(float(D.coc_px(cam, depth_m, 121)))
        row = out[50, 60:, 0]
        centre, rim = row[0], row[int(0.85 * r)]
        assert (rim > 1.3 * centre) if rim_brighter else (centre > 1.3 * rim)


def test_cats_eye_toward_the_corner():
    cam = Camera(**CAM, blades=0, optical_vignetting=1.0)
    h, w = 101, 161
    centre, _ = run(cam, point_frame(20.0, w=w, h=h, at=(50, 80)))
    corner, _ = run(cam, point_frame(20.0, w=w, h=h, at=(12, 18)))
    assert corner.sum() == pytest.approx(centre.sum(), rel=0.03)
    lit_c = np.count_nonzero(centre[..., 0] > 1e-6)
    lit_k = np.count_nonzero(corner[..., 0] > 1e-6)
    assert lit_k < 0.75 * lit_c  # the barrel clips the pupil
    ys, xs = np.nonzero(corner[..., 0] > 1e-6)
    # the clipped pupil is elongated across the radius (the diagonal towards the centre)
    v = np.stack([xs - xs.mean(), ys - ys.mean()], 1).astype(float)
    radial = np.array([80 - 18, 50 - 12], float)
    radial /= np.linalg.norm(radial)
    tangential = np.array([-radial[1], radial[0]])
    assert np.std(v @ tangential) > 1.3 * np.std(v @ radial)


# -- occlusion ---------------------------------------------------------------------------------

def edge_frame():
    """A sharp dark foreground square at the focus distance over a bright textured background at 30 m."""
    h, w = 61, 81
    yy, xx = np.mgrid[0:h, 0:w]
    color = np.stack([1 + 0.5 * np.sin(xx / 3.0), 1 + 0.5 * np.cos(yy / 4.0), np.ones((h, w))], -1)
    depth = np.full((h, w), 30.0)
    fg = (abs(yy - 30) < 15) & (abs(xx - 40) < 15)
    color[fg] = (0.05, 0.1, 0.2)
    depth[fg] = 2.0
    return Frame(color.astype(np.float32), depth=depth.astype(np.float32)), fg


@pytest.mark.parametrize("quality", ["final", "draft"])
def test_in_focus_foreground_has_no_halo_and_does_not_bleed(quality):
    frame, fg = edge_frame()
    out, _ = run(Camera(**CAM, blades=6), frame, quality)
    # the sharp foreground stays exactly itself: background light does not bleed onto it
    np.testing.assert_allclose(out[fg], frame.color[fg], rtol=1e-5)
    # the background next to it is the blurred background, not darkened by the foreground
    ring = np.zeros_like(fg)
    ring[13:48, 23:58] = True
    ring &= ~fg
    lum = out[..., 2]
    assert lum[ring].min() > 0.97  # background blue channel is 1 everywhere


def test_blurred_foreground_covers_the_in_focus_background():
    h, w = 61, 81
    yy, xx = np.mgrid[0:h, 0:w]
    color = np.zeros((h, w, 3), np.float32)
    color[..., 1] = 1.0                       # green background at the focus distance
    depth = np.full((h, w), 2.0, np.float32)
    fg = (abs(yy - 30) < 8) & (abs(xx - 40) < 8)
    color[fg] = (4.0, 0.0, 0.0)               # red foreground at 0.7 m: CoC ≈ −10 px
    depth[fg] = 0.7
    cam = Camera(**CAM, blades=0)
    out, pipe = run(cam, Frame(color, depth=depth))
    outside = (~fg) & (abs(yy - 30) < 12) & (abs(xx - 40) < 12)
    assert out[outside, 0].max() > 0.5          # red spreads over the sharp green background
    far_bg = (abs(yy - 30) > 25) | (abs(xx - 40) > 30)
    np.testing.assert_allclose(out[far_bg], color[far_bg], atol=1e-6)  # beyond the reach: untouched
    # energy: red spread out, green partially hidden, total red conserved within 2 %
    assert out[..., 0].sum() == pytest.approx(color[..., 0].sum(), rel=0.02)


def test_antialiased_light_edge_takes_the_lights_depth():
    # a small bright light at 20 m whose AA edge pixels carry the sky's depth (+inf)
    h, w = 41, 41
    color = np.full((h, w, 3), 0.1, np.float32)
    depth = np.full((h, w), np.inf, np.float32)
    color[20, 20] = 500.0
    depth[20, 20] = 20.0
    color[20, 21] = 200.0  # edge pixel: half light, sky depth
    cam = Camera(**{**CAM, "focus_distance_m": 20.0})
    eff = D.effective_depth(color.astype(np.float64), depth)
    assert eff[20, 21] == 20.0 and np.isinf(eff[0, 0])
    out, _ = run(cam, Frame(color, depth=depth))
    # both pixels stay in focus (no sky-sized halo of the light's energy)
    assert out[20, 21, 0] == pytest.approx(200.0, rel=1e-3)


def _light_with_fringe(h=41, w=41, light_m=1.0):
    """A 2×2 light (300× the sky) at ``light_m``; the 12 fringe pixels around it are equally
    bright (30× the sky: a tenth covered) and carry the sky's depth — the case where every fringe
    pixel's same-depth neighbours are fringe too (the rule before issue 16 missed it)."""
    color = np.full((h, w, 3), 0.1, np.float32)
    depth = np.full((h, w), np.inf, np.float32)
    color[19:23, 19:23] = 3.0          # fringe ring
    color[20:22, 20:22] = 30.0         # the light
    depth[20:22, 20:22] = light_m
    return color, depth


def test_fringe_of_a_light_takes_the_lights_depth():
    color, depth = _light_with_fringe()
    eff = D.effective_depth(color.astype(np.float64), depth)
    assert (eff[19:23, 19:23] == 1.0).all()        # light and fringe: the light's depth
    assert np.isinf(eff[17, 17]) and np.isinf(eff[19, 17])  # the sky around stays sky
    cam = Camera(**{**CAM, "focus_distance_m": 1.0})  # the light in focus, the sky's CoC 6 px
    for q in ("draft", "preview", "final"):
        out, pipe = run(cam, Frame(color, depth=depth), q)
        assert_matches_reference(pipe, Frame(color, depth=depth), out, rtol=1e-3)
        # in focus: no sky-sized halo (issue 16: pixels above 5 % of white beyond 3 px)
        yy, xx = np.mgrid[0:41, 0:41]
        beyond = np.hypot(yy - 20.5, xx - 20.5) > 3 + 2
        assert np.count_nonzero(out[beyond, 1] - 0.1 > 0.05) == 0, q
        assert out[..., 1].sum() == pytest.approx(color[..., 1].sum(), rel=0.01)  # issue 16: 3 %


def test_fringe_of_a_defocused_light_spreads_with_the_lights_coc():
    # focus at 0.5 m: the light (1 m) and the sky blur differently; the fringe must go with the light
    color, depth = _light_with_fringe()
    cam = Camera(**{**CAM, "focus_distance_m": 0.5})
    r_light = float(D.coc_px(cam, 1.0, 41))
    r_sky = float(D.coc_px(cam, np.inf, 41))
    assert r_sky > r_light + 0.5
    yy, xx = np.mgrid[0:41, 0:41]
    beyond = np.hypot(yy - 20.5, xx - 20.5) > r_light + 3
    # the light's energy beyond its own bokeh (+ the lattice's widening): with the sky's CoC the
    # fringe put 3.4 % (final) / 5.6 % (draft) there
    for q, most in (("final", 0.005), ("draft", 0.03)):
        out, _ = run(cam, Frame(color, depth=depth), q)
        e = out[..., 1] - 0.1
        assert e[beyond].sum() < most * e.sum(), q


def test_light_slightly_nearer_than_the_sky_keeps_its_energy():
    # issue 16 (each lamp's energy within 3 %): a 2x2 light 0.8 px of CoC nearer than the sky
    # (r 3.86 vs 4.66 px) was pooled with the sky and normalised by the pool's weight, which its
    # smaller bokeh inflates: it kept 98.2 % (final) / 95.1 % (draft) of its light with the former
    # 1 px front margin. Lamp-only light = run with the light minus run without it, as
    # clpost.fidelity measures it.
    cam = Camera(**CAM)
    w = h = 61
    k, _ = D.coc_coefficients(cam, w)
    light_m = k / 0.8
    assert float(D.coc_px(cam, np.inf, w) - D.coc_px(cam, light_m, w)) == pytest.approx(0.8)
    color = np.full((h, w, 3), 0.1, np.float32)
    depth = np.full((h, w), np.inf, np.float32)
    depth[30:32, 30:32] = light_m
    dark = Frame(color.copy(), depth=depth)
    color[30:32, 30:32] = 30.0
    lit = Frame(color, depth=depth)
    for q, tol in (("final", 0.01), ("draft", 0.03)):
        pipe = Pipeline(cam, quality=q, stages=["dof"])
        added = (pipe.run(lit).color - pipe.run(dark).color)[..., 1].sum()
        assert added == pytest.approx(4 * 29.9, rel=tol), q


def _in_focus_light_on_a_wall():
    """(camera, wall depth, dark, lit): a 61×61 wall (0.25) at a CoC radius of 2.2 px and a 2×2 light
    at the focus distance, absent (dark) or 100× the wall (lit)."""
    cam = Camera(**CAM)
    w = h = 61
    k, inv_u = D.coc_coefficients(cam, w)
    wall_m = 1.0 / (inv_u - 2.2 / k)
    color = np.full((h, w, 3), 0.25, np.float32)
    depth = np.full((h, w), wall_m, np.float32)
    depth[30:32, 30:32] = cam.focus_distance_m
    dark = Frame(color.copy(), depth=depth)
    color[30:32, 30:32] = 100.0
    return cam, wall_m, dark, Frame(color, depth=depth)



def test_in_focus_light_over_a_slightly_blurred_wall_is_not_counted_twice_at_half_resolution():
    # issue 16 (energy within 3 %): the half-resolution path gathers with the variance-matched
    # radius, 0 for every |r| < 2.31 px, so its depth-aware upsampling saw the in-focus light and a
    # wall at r = 2.2 px as one surface: the wall's pixels took the light's blurred light while the
    # light kept its own (143.8 % of its energy at draft). The upsampling now compares the original
    # CoC.
    cam, wall_m, dark, lit = _in_focus_light_on_a_wall()
    assert float(D.coc_px(cam, wall_m, 61)) == pytest.approx(2.2)
    for q, tol in (("draft", 0.03), ("preview", 0.03), ("final", 0.01)):
        out, pipe = run(cam, lit, q)
        assert_matches_reference(pipe, lit, out, rtol=1e-3)
        added = (out - pipe.run(dark).color)[..., 1].sum()
        assert added == pytest.approx(4 * 99.75, rel=tol), q


@pytest.mark.parametrize("quality", ["draft", "preview"])
def test_in_focus_light_leaves_no_ring_on_a_slightly_blurred_wall_at_half_resolution(quality):
    """The same in-focus 2×2 light (100× the wall) over the wall at r = 2.2 px: its working corner,
    2.2 px of CoC from the wall's pixels, weighed 1/40 of the wall's own corners in the depth-aware
    upsampling and ringed the light with its blurred light (the 12 wall pixels around it gained up
    to 2.3× the wall's level; the transparent scene's in-focus lamp: a 23 px draft halo where Cycles
    has none). With a corner of the wall's own within UPSAMPLE_SAME_PX the light's corner gets no
    weight: no wall pixel gains more than 5 % of the wall's level."""
    cam, wall_m, dark, lit = _in_focus_light_on_a_wall()
    out, pipe = run(cam, lit, quality)
    assert_matches_reference(pipe, lit, out, rtol=1e-3)
    added = (out - pipe.run(dark).color)[..., 1]
    yy, xx = np.mgrid[:61, :61]
    wall = np.maximum(np.abs(yy - 30.5), np.abs(xx - 30.5)) > 1.0
    assert added[wall].max() < 0.05 * 0.25


def test_half_covered_pixel_of_a_dark_pole_takes_the_poles_depth():
    h, w = 21, 21
    color = np.full((h, w, 3), 1.0, np.float32)
    depth = np.full((h, w), np.inf, np.float32)
    color[:, :10] = 0.05; depth[:, :10] = 0.8     # a dark pole
    color[:, 10] = 0.5                            # its anti-aliased edge: half pole, sky's depth
    eff = D.effective_depth(color.astype(np.float64), depth)
    pole = np.float32(0.8)
    assert (eff[:, 10] == pole).all() and np.isinf(eff[:, 11:]).all() and (eff[:, :10] == pole).all()
    color[:, 10] = 0.9                            # a tenth covered: stays with the sky
    assert np.isinf(D.effective_depth(color.astype(np.float64), depth)[:, 10]).all()


def test_despeckle_takes_the_median_where_depth_flips_but_colour_does_not():
    """Stochastic-transparency depth (a pane's depth on 1 pixel in 3, the colour smooth): an
    isolated pane-depth pixel whose luminance lies within its wall neighbours' takes the 3×3
    median; a lamp brighter than its surround and a dark wire keep their depth."""
    h, w = 9, 9
    col = np.full((h, w, 3), 0.5, np.float32)
    col[:, 5:] = 0.8  # a colour edge, unrelated to depth
    depth = np.full((h, w), 3.0, np.float32)
    depth[4, 5] = 1.5  # speckle on the edge: luminance 0.8, within its neighbours' 0.5 … 0.8
    depth[2, 2] = 1.5  # speckle inside the flat part
    out = D.despeckle_depth(col, depth)
    assert out[4, 5] == 3.0 and out[2, 2] == 3.0
    lamp, wire = col.copy(), col.copy()
    lamp[4, 2] = 50.0
    wire[:, 6] = 0.05
    d_lamp, d_wire = depth.copy(), depth.copy()
    d_lamp[4, 2] = 9.0
    d_wire[:, 6] = 1.0
    assert D.despeckle_depth(lamp, d_lamp)[4, 2] == 9.0
    assert np.all(D.despeckle_depth(wire, d_wire)[:, 6] == 1.0)


def _pane_speckle(rng, h=24, w=40):
    """Sky (+inf) seen through a 0.3-opacity pane at 1.5 m: the depth pass is the pane's on about
    3 pixels in 10, the colour smooth (the Cycles transparent scene's left pane)."""
    col = np.full((h, w, 3), 0.5, np.float32)
    depth = np.where(rng.random((h, w)) < 0.3, 1.5, np.inf).astype(np.float32)
    return col, depth


def test_a_light_behind_a_speckled_pane_takes_its_own_depth_not_the_panes(rng):
    """A 2-px lamp at 9 m behind the pane: its brightest pixel's depth sample hit the pane, the
    other's the lamp. Within 1.5× of each other they are one source, and the pane's depth is a
    speckle around it, so the bright pixel takes the lamp's 9 m (it spread as a 3.5 px near-field
    blob before: docs/fidelity.md, "Transparent: stochastic depth"). The fringe rule does not pull
    it back to the pane (the pane's speckle is no brighter than the sky: no mix to explain)."""
    col, depth = _pane_speckle(rng)
    y, x = 12, 20
    depth[y - 2:y + 3, x - 2:x + 3] = np.inf
    depth[y, x - 2], depth[y + 2, x + 1] = 1.5, 1.5   # pane speckle next to the lamp
    depth[y, x], depth[y, x + 1] = 1.5, 9.0
    col[y, x], col[y, x + 1] = 220.0, 180.0
    col[y - 1:y + 2, x - 1:x + 3] += 40.0 * (col[y - 1:y + 2, x - 1:x + 3] < 1)   # fringe at the sky's depth
    assert D.despeckle_depth(col, depth)[y, x] == 9.0
    eff = D.effective_depth(col, depth)
    assert eff[y, x] == 9.0 and eff[y, x + 1] == 9.0
    assert np.all(eff[y - 1:y + 2, x - 1:x + 3] >= 9.0)    # its fringe goes with the lamp, not the pane


def test_a_lamps_own_pixels_keep_its_depth_next_to_a_bright_fringe():
    """The other way round (the Cycles motion scene's lamp): a lamp's depth-hit pixels next to a
    fringe pixel as bright as they are but at the wall's depth keep the lamp's depth — the lamp's
    class is seen only on the lamp; and a lamp on a solid fixture at its own depth (a pole: not a
    speckle) keeps it too."""
    h, w = 12, 12
    col = np.full((h, w, 3), 0.3, np.float32)
    depth = np.full((h, w), 8.9, np.float32)
    depth[5:7, 5] = 6.0
    col[5:7, 5] = 150.0
    col[5:7, 6] = 120.0          # fringe at the wall's depth, within 1.5x
    assert np.all(D.despeckle_depth(col, depth)[5:7, 5] == 6.0)
    assert np.all(D.effective_depth(col, depth)[5:7, 5:7] == 6.0)
    pole = depth.copy()
    pole[7:, 5] = 6.0            # the fixture under the lamp, dim, at the lamp's depth
    assert np.all(D.despeckle_depth(col, pole)[5:7, 5] == 6.0)


def test_an_objects_corner_is_not_a_speckle(rng):
    """A textured block's convex corner has 3 same-depth neighbours in one arc: it keeps its
    depth even though its luminance lies within its background neighbours' range."""
    col = (rng.random((12, 12, 3)) * 0.5).astype(np.float32)
    depth = np.full((12, 12), 9.0, np.float32)
    depth[4:, 4:] = 1.0
    cand = D.speckle_candidates(depth)
    assert not cand[4, 4] and not cand[4, 11] and not cand[11, 4]
    assert np.all(D.despeckle_depth(col, depth) == depth)


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_speckle_and_light_rules_kernel_matches_its_reference(rng, quality):
    """The speckled pane with lamps behind it (pane-depth and lamp-depth pixels of one source), at an
    odd size with 16-pixel groups and edge pixels: dof_despeckle's per-pixel fall-back for groups
    with a source candidate, and the fringe rule's own-surface steps, against the numpy rules."""
    col, depth = _pane_speckle(rng, 29, 53)
    for y, x in ((6, 9), (14, 30), (22, 44), (10, 50)):
        depth[y, x], depth[y, x + 1] = 1.5, 9.0
        col[y, x], col[y, x + 1] = 220.0, 180.0
    cam = Camera(**{**CAM, "focus_distance_m": 4.0})
    frame = Frame(col, depth=depth)
    out, pipe = run(cam, frame, quality)
    assert_matches_reference(pipe, frame, out, rtol=1e-3)


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_fringe_rule_kernel_matches_its_reference_on_random_lights_and_steps(rng, quality):
    """Random depth steps (0.5 m … sky) under random HDR lights with anti-aliased fringes, at an odd
    size whose rows have both the kernel's 16-pixel groups and its per-pixel edge path."""
    h, w = 29, 53
    depth = np.where(rng.random((h, w)) < 0.3, np.inf, rng.choice([0.5, 1.0, 3.0, 9.0], (h, w))).astype(np.float32)
    depth = np.repeat(np.repeat(depth[::3, ::3], 3, 0), 3, 1)[:h, :w].copy()   # 3-px blocks: real steps
    color = (rng.random((h, w, 3)) * 0.5).astype(np.float32)
    for _ in range(12):                                                            # lights and fringes
        y, x = rng.integers(1, h - 1), rng.integers(1, w - 1)
        color[y - 1:y + 2, x - 1:x + 2] += rng.random() * 30
        color[y, x] += rng.random() * 300
    cam = Camera(**{**CAM, "focus_distance_m": 1.0})
    eff = D.effective_depth(color.astype(np.float64), depth)
    assert (eff <= depth).all() and (eff != depth).any()          # only ever nearer, and it fired
    frame = Frame(color, depth=depth)
    out, pipe = run(cam, frame, quality)
    assert_matches_reference(pipe, frame, out, rtol=1e-3)


@pytest.mark.parametrize("space", ["rec709", "acescg"])
def test_highlight_edge_test_uses_the_working_spaces_luminance(space):
    """A reddish edge pixel on a blue sky is 'brighter than its same-depth neighbours' in ACEScg
    (Y weights 0.272 / 0.674 / 0.054) but not in Rec. 709 (0.213 / 0.715 / 0.072): the kernel
    and its reference decide with the camera's working space."""
    h, w = 41, 41
    color = np.zeros((h, w, 3), np.float32)
    color[..., 2] = 1.0
    depth = np.full((h, w), np.inf, np.float32)
    color[20, 20], depth[20, 20] = (500.0, 500.0, 500.0), 1.0   # a defocused lamp (CoC ≈ 6 px)
    color[20, 21] = (0.4, 0.0, 0.0)
    cam = Camera(**{**CAM, "focus_distance_m": 20.0}, working_space=space)
    eff = D.effective_depth(color.astype(np.float64), depth, D.luma_weights(cam))
    assert (eff[20, 21] == 1.0) == (space == "acescg")
    frame = Frame(color, depth=depth)
    out, pipe = run(cam, frame)
    assert_matches_reference(pipe, frame, out)


# -- extremes, plan, determinism ---------------------------------------------------------------

@pytest.mark.parametrize("n", [0.7, 1.4, 64.0])
@pytest.mark.parametrize("u", [0.1, 2.0, 1e6])
def test_extreme_apertures_focus_and_depths_stay_finite(rng, n, u):
    h, w = 23, 37
    depth = np.geomspace(1e-4, 1e4, h * w).reshape(h, w).astype(np.float32)
    depth[::5, ::3] = np.inf
    color = (rng.random((h, w, 3)) * np.geomspace(1e-6, 6e4, w)[None, :, None]).astype(np.float16)
    frame = Frame(color, depth=depth)
    cam = Camera(**{**CAM, "f_number": n, "focus_distance_m": u})
    pipe = Pipeline(cam, quality="draft", stages=["dof"])
    out = pipe.run(frame).color
    assert np.isfinite(out).all() and (out >= 0).all()
    assert_matches_reference(pipe, frame, out, rtol=1e-3)


@pytest.mark.parametrize("quality", ["final", "draft"])
@pytest.mark.parametrize("change", [dict(spherical_aberration=0.9), dict(optical_vignetting=0.9)])
def test_a_pipeline_replanned_for_another_aperture_matches_a_fresh_one(rng, quality, change):
    # the stage (and its cached tables) outlives a plan: a second camera differing only in σ or the
    # cat's eye once kept the first's light/texture sums and arguments (up to 5.5 off at draft)
    frame = odd_frame(rng)
    color = frame.color.copy()
    color[5, 7], color[12, 20] = 200.0, 150.0  # lights: the sum table's taps
    frame = Frame(color, depth=frame.depth)
    first = Camera(**CAM, blades=6, spherical_aberration=0.3, optical_vignetting=0.3)
    second = Camera(**{**CAM, "blades": 6, "spherical_aberration": 0.3, "optical_vignetting": 0.3, **change})
    pipe = Pipeline(first, quality=quality, stages=["dof"])
    pipe.run(frame)
    fresh = Pipeline(second, quality=quality, stages=["dof"]).run(frame).color
    assert np.array_equal(pipe.run(frame, second).color, fresh)


def test_not_planned_when_off_or_all_in_focus():
    frame = point_frame(5.0)
    assert "dof" not in Pipeline(Camera(), stages=["dof"]).plan(frame)
    focused = Camera(**{**CAM, "focus_distance_m": 5.0})
    entry = [e for e in Pipeline(focused).explain(frame) if e.stage == "dof"][0]
    assert not entry.planned and "in focus" in entry.reason
    assert Pipeline(Camera(**CAM)).plan(frame)[0] == "dof"
    # f/64 at 50 mm, focused at infinity: the blur at 5 m is far below half a pixel at 121 px
    assert "dof" not in Pipeline(Camera(**{**CAM, "f_number": 64.0, "focus_distance_m": math.inf})).plan(frame)


def test_needs_depth_when_on():
    from clpost.errors import InputError

    with pytest.raises(InputError, match="needs the frame's depth"):
        Pipeline(Camera(**CAM)).plan(Frame(np.ones((5, 5, 3), np.float32)))


def test_camera_validates_the_dof_fields():
    from clpost.errors import InputError

    for kw in (dict(aperture_roundness=1.5), dict(spherical_aberration=-2), dict(optical_vignetting=float("nan"))):
        with pytest.raises(InputError, match="Camera\\."):
            Camera(**kw)


@pytest.mark.parametrize("vec", ["1", "8", "16"])
@pytest.mark.parametrize("quality", ["final", "draft"])
def test_both_gather_vector_widths_match_the_reference(rng, monkeypatch, vec, quality):
    """The gather runs 8 or 16 pixels per work-item (by the device's native float width), or one
    (CLPOST_DOF_VEC=1, a GPU's form); every width, on a width that leaves partial groups of 8 and
    16 and with every optional term on."""
    monkeypatch.setenv("CLPOST_DOF_VEC", vec)
    frame = odd_frame(rng, w=101, h=29)  # wide enough for every kernel's vector path at half res
    cam = Camera(**CAM, blades=5, spherical_aberration=-0.4, optical_vignetting=0.6)
    out, pipe = run(cam, frame, quality)
    assert_matches_reference(pipe, frame, out)


def test_a_gpu_gets_the_one_pixel_gather(rng, monkeypatch):
    """On a GPU (Runtime.wide false) the gather runs one pixel per work-item without being asked
    (the 8-wide CPU form was 1.2x slower on the H200); its frame is the CLPOST_DOF_VEC=1 frame."""
    from clpost.runtime import Runtime
    from clpost.stages.dof_cl import gather_vector_width

    monkeypatch.delenv("CLPOST_DOF_VEC", raising=False)
    frame = odd_frame(rng, w=101, h=29)
    cam = Camera(**CAM, blades=5)
    with Runtime.forced_width(False):
        gpu, pipe = run(cam, frame, "final")
        assert gather_vector_width(pipe.runtime) == 1
    assert gather_vector_width(pipe.runtime) in (8, 16)
    monkeypatch.setenv("CLPOST_DOF_VEC", "1")
    np.testing.assert_array_equal(gpu, run(cam, frame, "final")[0])


@pytest.mark.parametrize("extra", [dict(blades=6), dict(blades=5, spherical_aberration=0.5, optical_vignetting=0.7)])
def test_final_mixed_resolution_matches_the_reference(rng, extra):
    """Final gathers working tiles of large reach at half resolution and the rest at full
    resolution: a frame whose left part is near focus and right part far behind has both, with
    big tiles next to small ones (the upsampling's corners then read the neighbouring working
    tile's half-resolution gather, which dof_tile_mix must keep)."""
    w, h = 256, 70  # 8 working tiles across
    color = (rng.random((h, w, 3)) * 10).astype(np.float32)
    color[30, 200] = 1e4
    depth = np.full((h, w), 2.1, np.float32)
    depth[:, 150:192] = 3.0  # r = 6.5 px: a blurred working tile (x 64-79) beside a big one
    depth[:, 192:] = np.inf  # r = 19.5 px > 17: half resolution there and in the tile beside it
    depth[20:40, 120:140] = 1.3  # a near block (r = -10.5 px) over the sharp part, full resolution
    frame = Frame(color, depth=depth)
    cam = Camera(**CAM, **extra)
    out, pipe = run(cam, frame, "final")
    coc = D.coc_px(cam, D.effective_depth(color, depth), w, D.max_coc_px("final"))
    mask = D.mixed_mask(D._working(color.astype(np.float64), coc, 2)[1], coc, "final")
    assert 0.2 < mask.mean() < 0.8
    assert np.isfinite(out).all() and (out >= 0).all()
    assert_matches_reference(pipe, frame, out)
    # outside the mixed tiles the output is the full-resolution gather with its small CoCs mixed
    # with the 3x3 blur (D._full_small), exactly as before
    full, alpha = D.gather_reference(color.astype(np.float64), coc, 64, 8, cam.blades, cam.blade_rotation_deg,
                                     cam.aperture_roundness, cam.spherical_aberration, cam.optical_vignetting)
    full = D._full_small(color.astype(np.float64), coc, full, alpha)
    np.testing.assert_allclose(out[~mask], full[~mask], rtol=2e-4, atol=1e-3)


def test_final_mixed_resolution_when_only_the_full_resolution_plan_is_coarse(rng):
    """Far pixels (r = 24.4 px) on every other column among in-focus ones: the working CoC (the
    2x2 min) is in focus, so the half-resolution plan is fine, but the full-resolution plan
    wants stride 4, a level final does not build at full resolution: those tiles must go to the
    half-resolution path too (else the gather would read past its levels)."""
    w, h = 160, 40
    color = (rng.random((h, w, 3)) * 10).astype(np.float32)
    depth = np.full((h, w), 2.0, np.float32)
    depth[:, 96::2] = np.inf
    color[:, 96::2] *= 0.05   # a dark far field behind bright stripes: with colours of one range the
                              # one-pixel stripes read as depth speckle (despeckle_depth) and swap depths
    frame = Frame(color, depth=depth)
    cam = Camera(**{**CAM, "f_number": 0.7}, blades=6)
    out, pipe = run(cam, frame, "final")
    coc = D.coc_px(cam, D.effective_depth(color, depth), w, D.max_coc_px("final"))
    rw = D._working(color.astype(np.float64), coc, 2)[1]
    assert D.tile_plan(rw, 32, 8, route=True)[0].max() < D.MIXED_LEVEL  # the half-resolution plan alone: no tile
    mask = D.mixed_mask(rw, coc, "final")
    assert 0.2 < mask.mean() < 0.8
    assert np.isfinite(out).all()
    assert_matches_reference(pipe, frame, out)


def test_deterministic(rng):
    frame = odd_frame(rng)
    a, _ = run(Camera(**CAM, blades=6), frame)
    b, _ = run(Camera(**CAM, blades=6), frame)
    assert np.array_equal(a, b)


def test_cli_camera_options_reach_the_camera():
    from clpost.cli import build_parser, camera_from_args

    args = build_parser().parse_args(["bench", "--depth-of-field", "on", "--roundness", "0.25",
                                      "--spherical-aberration", "-0.5", "--cats-eye", "0.3"])
    cam = camera_from_args(args)
    assert (cam.depth_of_field, cam.aperture_roundness, cam.spherical_aberration, cam.optical_vignetting) == \
        (True, 0.25, -0.5, 0.3)
    assert camera_from_args(build_parser().parse_args(["bench"])).depth_of_field is False


def test_a_one_pixel_lamp_hit_by_the_depth_in_one_of_its_two_pixels_keeps_its_depth():
    """Held-out h_lamps' lamp01 (docs/fidelity.md, "Held-out scenes"): a 1-px lamp at 3 m straddling
    two pixels (375 and 361× the wall's luminance) before a wall at 5.9 m; the depth pass hit the
    lamp in one. Its bright twin is the only other-depth neighbour as bright as it — outside the
    robust range (2nd-darkest … 2nd-brightest), so not a speckle: it keeps 3 m. A pane's speckle
    next to one bright glint of another depth still is one (its colour is its neighbours')."""
    h, w = 9, 9
    col = np.full((h, w, 3), 0.3, np.float32)
    depth = np.full((h, w), 5.9, np.float32)
    y, x = 4, 3
    col[y, x], col[y, x + 1], col[y, x + 2] = 375.2, 361.2, 5.1
    col[y - 1, x:x + 2], col[y + 1, x:x + 2] = [[51.7] * 3, [37.8] * 3], [[56.6] * 3, [42.6] * 3]
    depth[y, x] = 3.0
    assert D.despeckle_depth(col, depth)[y, x] == 3.0
    pane = np.full((h, w, 3), 0.5, np.float32)
    d_pane = np.full((h, w), 3.0, np.float32)
    d_pane[4, 4] = 1.5                      # a speckle of the pane …
    pane[3, 5] = 5.0                        # … next to one glint at the wall's depth
    assert D.despeckle_depth(pane, d_pane)[4, 4] == 3.0


def _one_pixel_lamp_on_a_wall(h=41, w=41, y=20, x=19, lamp_m=1.0):
    """A 1-px lamp (at ``lamp_m``) straddling two pixels (375 and 361× the wall's luminance, as
    held-out h_lamps' lamp01) before a wall at 5.9 m; the point-sampled depth hit the lamp in the
    left pixel only, so its twin and its anti-aliased fringe (5–57×) carry the wall's depth."""
    col = np.full((h, w, 3), 0.3, np.float32)
    depth = np.full((h, w), 5.9, np.float32)
    col[y, x], col[y, x + 1], col[y, x + 2] = 375.2, 361.2, 5.1
    col[y - 1, x:x + 2], col[y + 1, x:x + 2] = [[51.7] * 3, [37.8] * 3], [[56.6] * 3, [42.6] * 3]
    depth[y, x] = lamp_m
    return col, depth


def _twin_only_frame():
    """:func:`_one_pixel_lamp_on_a_wall` with the pixel right of the twin dimmed to 2× the wall
    (5.1× in h_lamps): two pixels from the lamp's depth sample, beyond the fringe rule's 3×3 reach;
    the light's-tail clause takes it with the lamp (docs/fidelity.md, "Held-out scenes")."""
    col, depth = _one_pixel_lamp_on_a_wall()
    col[20, 21] = 0.6
    return col, depth


def test_a_one_pixel_lamps_fringe_goes_with_the_lamp_past_its_twin():
    """The fringe pixels above and below the lamp had its bright twin (at the wall's depth, within 5 %
    of the lamp) among their own surface, so the fringe rule's "near surface brighter than every
    other pixel of p's own surface" failed and they kept the wall's depth: the in-focus lamp got a
    wall-sized halo (h_lamps lamp01: 65 px at final, Cycles 0). A pixel of p's surface within 1.5×
    of a near source far above p is that source's twin and is left out of the comparison."""
    col, depth = _twin_only_frame()
    eff = D.effective_depth(col.astype(np.float64), depth)
    assert np.all(eff[19:22, 19:21] == 1.0)                  # lamp, twin and fringe: the lamp's depth
    assert eff[20, 21] == 1.0                                # the twin's tail (2 px from the depth sample): the lamp's
    assert eff[17, 19] == np.float32(5.9)                    # the wall: the wall's
    cam = Camera(**{**CAM, "focus_distance_m": 1.0})         # the lamp in focus, the wall's CoC 5 px
    wall = np.full_like(col, 0.3)
    yy, xx = np.mgrid[0:41, 0:41]
    beyond = np.hypot(yy - 20, xx - 19.5) > 3
    for q in ("draft", "final"):
        frame = Frame(col, depth=depth)
        out, pipe = run(cam, frame, q)
        assert_matches_reference(pipe, frame, out, rtol=1e-3)
        lamp = out - run(cam, Frame(wall, depth=depth), q)[0]
        # lamp-only light above 5 % of white beyond 3 px; the rule without the twin clause left
        # 118 (draft) / 110 (final) such pixels
        assert np.count_nonzero(lamp[beyond] @ D.luma_weights() > 0.05) == 0, q


def test_a_textured_pixel_beside_a_white_silhouette_keeps_its_depth():
    """The twin clause is for lights (HDR): a grey texel (0.3) of a far wall beside a white near
    object (1.0), with a white texel of the wall (1.0) in its 3×3, is not a fringe of the object —
    the white texel is the wall's own, not the object's twin. The clause needs the near source's 5 %
    above p's surface's darkest (here 0.05 vs 0.1); without that it took the object's depth (a
    form of this change did: thin, occluder, transparent and held-out pixels moved, ≤ 0.03 dB)."""
    col = np.full((7, 7, 3), 0.1, np.float32)
    depth = np.full((7, 7), 6.0, np.float32)
    col[:, :3], depth[:, :3] = 1.0, 2.0          # the white near object, left
    col[3, 3] = 0.3                               # the texel beside it
    col[2, 4] = 1.0                               # a white texel of the wall
    assert D.effective_depth(col.astype(np.float64), depth)[3, 3] == 6.0
    col[:, :3], col[2, 4], col[3, 3] = 400.0, 400.0, 30.0   # a light, its twin and their fringe: taken
    assert D.effective_depth(col.astype(np.float64), depth)[3, 3] == 2.0


@pytest.mark.parametrize("wall", [0.02, 0.0, -0.01])
def test_a_textured_pixel_beside_a_white_silhouette_on_a_black_wall_keeps_its_depth(wall):
    """The same texel on a near-black wall: the light clause's "5 % of the light above the darkest
    of p's surface" holds for any brighter near pixel when that darkest is ~0 (or negative), so the
    texel took the object's depth (main 46a9c94). A light also covers at most LIGHT_FRINGE (¼) of
    p: the texel is 0.29–0.31 of the object, a 1-px lamp's fringe is 0.10–0.15 of it."""
    col = np.full((7, 7, 3), wall, np.float32)
    depth = np.full((7, 7), 6.0, np.float32)
    col[:, :3], depth[:, :3] = 1.0, 2.0
    col[3, 3], col[2, 4] = 0.3, 1.0
    assert D.effective_depth(col.astype(np.float64), depth)[3, 3] == 6.0
    col[:, :3], col[2, 4], col[3, 3] = 400.0, 400.0, 30.0   # a light, its twin and their fringe: taken
    assert D.effective_depth(col.astype(np.float64), depth)[3, 3] == 2.0


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_black_wall_texels_and_lamp_twins_kernel_matches_its_reference(quality):
    """The black-wall texel (kept) and the 1-px lamp's twin fringe (taken), tiled over an odd-sized
    frame so both land in dof_coc's 16-lane groups and in its per-pixel edge path."""
    h, w = 23, 53
    col = np.full((h, w, 3), 0.01, np.float32)
    depth = np.full((h, w), 6.0, np.float32)
    for y, x in ((3, 1), (3, 20), (3, 45), (15, 8), (15, 30)):     # white objects 3 px wide, texel, white texel
        col[y - 2:y + 3, x - 1:x + 2], depth[y - 2:y + 3, x - 1:x + 2] = 1.0, 2.0
        col[y, x + 2], col[y - 1, x + 3] = 0.3, 1.0
    for y, x in ((10, 3), (10, 25), (19, 49)):                     # 1-px lamps straddling two pixels
        col[y, x], col[y, x + 1] = 375.2, 361.2
        col[y - 1, x:x + 2], col[y + 1, x:x + 2] = [[51.7] * 3, [37.8] * 3], [[56.6] * 3, [42.6] * 3]
        depth[y, x] = 2.0
    eff = D.effective_depth(col.astype(np.float64), depth)
    assert eff[3, 22] == 6.0 and eff[15, 10] == 6.0 and eff[9, 25] == 2.0
    cam = Camera(**{**CAM, "focus_distance_m": 2.0})
    frame = Frame(col, depth=depth)
    out, pipe = run(cam, frame, quality)
    assert_matches_reference(pipe, frame, out, rtol=1e-3)


def _lamp_behind_an_in_focus_pane():
    """Held-out h_panes' lamp00: a 2-px lamp at 6 m seen through a 0.2 pane at 1.2 m over the sky;
    its pixels 124, 201, 234 (depth 6 / 5.99) and 164 (the pane's depth sample), fringe at the
    sky's, the pane's speckle around (luminances and depths as exported by Cycles)."""
    lum = np.array([[0.44, 6.83, 11.94, 3.00, 0.44],
                    [6.83, 124.4, 201.08, 33.67, 0.44],
                    [5.55, 164.02, 234.3, 37.5, 0.44],
                    [0.44, 18.33, 34.94, 1.72, 0.44],
                    [0.44, 0.44, 1.72, 0.44, 0.44]])
    d = np.array([[np.inf] * 5,
                  [1.2, 6.0, 5.99, np.inf, np.inf],
                  [np.inf, 1.2, 5.99, np.inf, np.inf],
                  [np.inf] * 5,
                  [np.inf, 1.2, np.inf, np.inf, np.inf]])
    col = np.full((15, 21, 3), 0.44, np.float32)
    depth = np.full((15, 21), np.inf, np.float32)
    col[5:10, 8:13] = lum[..., None]
    depth[5:10, 8:13] = d
    depth[2, 3] = depth[12, 17] = depth[1, 14] = 1.2            # more of the pane's speckle
    return col, depth


def test_a_lamp_behind_an_in_focus_pane_keeps_its_depth():
    """The light-behind-a-pane rule needs a dim speckle of p's depth class showing the surround
    (≤ 1.5× p's dimmest other-depth neighbour): the lamp's own dimmer pixel (124, far above the sky)
    is not one, so the two brightest lamp pixels keep 6 m (they went to the pane's 1.2 m: a disc
    0.09× Cycles'), and the pane's sample over the lamp takes the lamp's depth."""
    col, depth = _lamp_behind_an_in_focus_pane()
    out = D.despeckle_depth(col, depth)
    assert np.allclose(out[6:8, 9:11], 6.0, rtol=2e-3)


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_robust_range_and_surround_speckle_kernel_matches_its_reference(quality):
    """dof_despeckle (its 16-lane and per-pixel paths) against the numpy rules on the two held-out
    patterns above, tiled over an odd-sized frame so both paths see them."""
    col, depth = _lamp_behind_an_in_focus_pane()
    col = np.tile(col, (2, 3, 1))[:29, :53].copy()
    depth = np.tile(depth, (2, 3))[:29, :53].copy()
    for y, x in ((4, 30), (20, 47), (25, 1)):
        col[y, x], col[y, x + 1], depth[y, x] = 375.0, 361.0, 1.0
    d_np = D.despeckle_depth(col, depth)
    assert (d_np != depth).any() and (d_np[[4, 20, 25], [30, 47, 1]] == 1.0).all()
    cam = Camera(**{**CAM, "focus_distance_m": 4.0})
    frame = Frame(col, depth=depth)
    out, pipe = run(cam, frame, quality)
    assert_matches_reference(pipe, frame, out, rtol=1e-3)


@pytest.mark.parametrize("quality", ["draft", "preview", "final"])
@pytest.mark.parametrize("eta", [0.0, 0.5, 1.0])
def test_cats_eye_point_light_keeps_its_energy(quality, eta):
    """The clipped bokeh keeps its energy (module docstring: the light the barrel removes belongs
    to the vignetting stage), at the centre (an unclipped pupil) and toward a corner. Before the
    front/rear barrel pair and the symmetric weights, the centre kept 1.145 at final, η = 1 (the
    barrel's displaced centroid magnified the blur and the normalisation turned that into light)."""
    cam = Camera(**CAM, blades=0, optical_vignetting=eta)
    for at, tol in [((50, 80), 0.015 + 0.015 * eta), ((12, 18), 0.01)]:
        out, _ = run(cam, point_frame(20.0, w=161, h=101, at=at), quality)
        assert out.sum() / 3000.0 == pytest.approx(1.0, abs=tol), (at, quality, eta)


@pytest.mark.parametrize("r", [0.5, 0.9, 1.2])
def test_final_small_coc_is_at_least_as_accurate_as_draft_on_a_flat_textured_wall(r):
    """A flat textured wall at a CoC radius under √2 px (h_spin's brick wall: 0.9 px): final's
    full-resolution lattice disc with its 1-px coverage ramp blurred it too much (variance 0.31
    px² per axis at r = 0.9 for the disc's 0.20; none at r = 0.5); with the 3×3 blur there
    (_full_small) final is at least as close as draft to the float64 disc-convolved texture, and
    closer than the bare gather (from |r| = 1 px on it ramps back to the gather, which is closer on
    the Cycles truths' sloped surfaces at 1.4-2 px: there only the second holds)."""
    from scipy.special import j1

    n = 64
    g = np.random.default_rng(7)
    f = np.hypot(np.fft.fftfreq(n)[:, None], np.fft.fftfreq(n)[None, :])
    tex = np.real(np.fft.ifft2(np.fft.fft2(g.random((n, n, 3)), axes=(0, 1))
                               * np.exp(-(f / 0.25) ** 2)[..., None], axes=(0, 1))) + 0.2
    x = 2 * np.pi * r * f
    H = np.where(x > 0, 2 * j1(np.maximum(x, 1e-12)) / np.maximum(x, 1e-12), 1.0)  # the disc's transfer
    truth = np.real(np.fft.ifft2(np.fft.fft2(tex, axes=(0, 1)) * H[..., None], axes=(0, 1)))
    coc = np.full((n, n), r)
    cam = Camera(**CAM)
    gathered, alpha = D.gather_reference(tex, coc, 64, 8, 0, 0.0, 0.0, 0.0, 0.0)
    final = D._full_small(tex, coc, gathered, alpha)
    draft = D._half_composite(cam, tex, coc, *D.QUALITY["draft"])[0]
    err = lambda a: np.sqrt(np.mean((a - truth)[16:-16, 16:-16] ** 2))
    if r <= D.SMALL_LO_PX:
        assert err(final) <= err(draft) * 1.001
        assert err(final) < 0.5 * err(gathered)
    assert err(final) < 0.9 * err(gathered)


# -- the half-resolution path's narrow-source layer ---------------------------------------------

def _small_light(r_light, r_back, level=40.0, back=0.1, size=81):
    """(camera, dark, lit): a flat background (``back``) at CoC radius ``r_back`` px and a 2×2 light
    at ``r_light`` px (nearer: smaller), absent (dark) or ``level`` (lit); r_back = inf: the sky."""
    cam = Camera(**CAM, blades=6)
    w = h = size
    k, inv_u = D.coc_coefficients(cam, w)
    depth = np.full((h, w), np.inf if math.isinf(r_back) else 1.0 / (inv_u - r_back / k), np.float32)
    depth[40:42, 40:42] = 1.0 / (inv_u - r_light / k)
    color = np.full((h, w, 3), back, np.float32)
    dark = Frame(color.copy(), depth=depth)
    color[40:42, 40:42] = level
    return cam, dark, Frame(color, depth=depth)


@pytest.mark.parametrize("r_back", [5.0, math.inf])
def test_small_bright_light_at_half_resolution_keeps_its_energy_and_its_disc(r_back):
    # issue 16 (an emitter's saturated disc within 10 % of the truth's area, its energy within
    # 3 %): a 2×2 light 400× its background, 1.5 px of CoC nearer than a wall (h_lamps' lamp10)
    # or at 4 px over the sky (the emitters scene's far lamps). The half-resolution path's disc
    # edge (the 2×2 box, the working coverage ramp, the bilinear upsampling) is ≈ 3 px of ramp,
    # all of it saturated at this level: draft's disc had 1.4–1.6× final's saturated area and the
    # lamp in front of the wall kept 0.8 of its light (its working block's CoC is the light's, the
    # wall's light around it pooled). Now the light is spread at full resolution
    # (dof.narrow_sources): final's disc and energy at draft and preview.
    cam, dark, lit = _small_light(3.5 if math.isinf(r_back) else r_back - 1.5, r_back)
    area, energy = {}, {}
    for q in ("final", "draft", "preview"):
        pipe = Pipeline(cam, quality=q, stages=["dof"])
        out = pipe.run(lit).color
        added = out - pipe.run(dark).color
        energy[q] = float(added[..., 1].sum()) / (4 * 39.9)
        area[q] = int(np.count_nonzero(out[..., 1] >= 1.0))
    assert energy["final"] == pytest.approx(1.0, abs=0.03)
    for q in ("draft", "preview"):
        assert energy[q] == pytest.approx(1.0, abs=0.03), (q, energy)
        assert area[q] == pytest.approx(area["final"], rel=0.10), (q, area)


def test_small_coc_light_over_a_larger_coc_sky_keeps_final_s_disc_and_energy_at_half_resolution():
    # issue 16: a light of CoC radius 1.2 px (in focus for the half-resolution path: its pixels take
    # the full-resolution 3×3 blur whole) over a sky at 2.6 px (taking the half-resolution blur
    # whole). Its excess leaves the working image (dof.NARROW_FOCUS_PX), so the 3×3's share of it
    # that the sky pixels around it would take was lost: 0.67 of its light and a quarter of
    # final's saturated disc at draft. Now that share is added back (dof.small_layer). Final spreads
    # such a light with the same 3×3 weights (dof.LIGHT_SMALL_PX): it kept 1.090 of its light (the
    # 1-px ramp's lattice sum in the sky's front layer, and _full_small's lerp on its own pixels);
    # with the lights' ¼-px disc instead, 1.029 and 12 saturated px where the 2×2 square's
    # continuous convolution with the r = 1.2 px hexagon saturates 16, as the 3×3 does.
    cam, dark, lit = _small_light(1.2, 2.6, level=60.0)
    area, energy = {}, {}
    for q in ("final", "draft", "preview"):
        out, pipe = run(cam, lit, q)
        assert_matches_reference(pipe, lit, out, rtol=1e-3)
        energy[q] = float((out - pipe.run(dark).color)[..., 1].sum()) / (4 * 59.9)
        area[q] = int(np.count_nonzero(out[..., 1] >= 1.0))
    assert energy["final"] == pytest.approx(1.0, abs=0.005) and area["final"] == 16, (energy, area)
    for q in ("draft", "preview"):
        assert energy[q] == pytest.approx(1.0, abs=0.03), (q, energy)
        assert area[q] == pytest.approx(area["final"], rel=0.10), (q, area)


@pytest.mark.parametrize("sa", [0.6, -0.6])
@pytest.mark.parametrize("r_light, r_back", [(2.68, 2.68), (2.68, 4.2), (3.5, math.inf), (-3.0, 2.0)])
def test_final_light_keeps_its_energy_with_spherical_aberration(sa, r_light, r_back):
    # final's lights (dof.LIGHT_RAMP_PX) have their ¼-px weights rescaled by their lattice sums;
    # without the texture in those sums (dof.light_sums) a 2×2 light kept 0.980 / 1.019 of its light
    # over a wall at its own CoC (σ = ±0.6) and 0.971 / 1.031 before a wall at 4.2 px; with it
    # 1.000 (the near light before a far wall: 1.017 / 0.970, the 1-px ramp's 1.010 / 0.977, until
    # the wall's taps behind it took the light's texture: 1.000)
    cam, dark, lit = _small_light(r_light, r_back)
    cam = cam.with_(spherical_aberration=sa)
    out, pipe = run(cam, lit, "final")
    energy = float((out - pipe.run(dark).color)[..., 1].sum()) / (4 * 39.9)
    assert energy == pytest.approx(1.0, abs=0.005), energy


@pytest.mark.parametrize("r_light, r_back", [(-2.5, 3.0), (-4.0, 3.0), (3.5, math.inf), (2.68, 4.2)])
def test_light_keeps_its_energy_under_the_texture_at_every_quality(r_light, r_back):
    # issue 16: each emitter's energy within 3 %, with the spherical-aberration texture too. A tap
    # behind p is clamped to p's radius (the background clamp); it took its own layer's texture, so
    # a near light's own pixel was normalised against the far wall's opposite-signed texture: at
    # final the light before a wall at 3 px kept 0.937 / 1.040 of its light (σ = −0.6 / +0.6). Now
    # such a tap takes p's texture (dof.gather_reference): 1.000 at every quality and σ.
    for sa in (-0.6, 0.0, 0.6):
        cam, dark, lit = _small_light(r_light, r_back)
        cam = cam.with_(spherical_aberration=sa)
        for q in ("draft", "preview", "final"):
            out, pipe = run(cam, lit, q)
            energy = float((out - pipe.run(dark).color)[..., 1].sum()) / (4 * 39.9)
            assert energy == pytest.approx(1.0, abs=0.03), (sa, q, energy)


def test_near_light_in_the_working_image_keeps_its_energy_under_the_texture():
    # a near light (r = −3 px) over a wall at 2 px is not a narrow source (the wall's |CoC| is just
    # under dof.NARROW_MIN_PX), so draft and preview blur it at half resolution (working r 0.96
    # px). There the texture changed its energy to 0.649 / 1.429 (σ = −0.6 / +0.6) of the
    # untextured 1.039: its own pixel normalised against the wall's opposite texture (above), and
    # the small disc's textured lattice sum (the rim value fills the coverage ramp: 1.225 / 0.937
    # of the plain disc's 1.081, dof.texture_sums) in the wall's unnormalised front layer. Now the
    # texture moves it by under 2 % (1.018 / 1.055; the untextured 4 % is the path's own). Since
    # near lights over walls sharper than 2 px are split too (the next test's cases) this one is
    # a narrow source: the layer normalises its textured disc, 1.000 at every σ.
    cam, dark, lit = _small_light(-3.0, 2.0)
    energy = {}
    for sa in (-0.6, 0.0, 0.6):
        c = cam.with_(spherical_aberration=sa)
        for q in ("draft", "preview"):
            out, pipe = run(c, lit, q)
            if sa and q == "draft":
                assert_matches_reference(pipe, lit, out)
            energy[q, sa] = float((out - pipe.run(dark).color)[..., 1].sum()) / (4 * 39.9)
    for q in ("draft", "preview"):
        assert energy[q, 0.0] == pytest.approx(1.0, abs=0.05), energy
        for sa in (-0.6, 0.6):
            assert energy[q, sa] == pytest.approx(energy[q, 0.0], rel=0.03), energy


def _light_over_wall(r_light, r_back, n, off):
    """(camera, dark, lit): an n×n light at 40 (CoC ``r_light`` px) at (40 + off, 40 + off) over a
    0.1 wall at ``r_back`` px (inf: the sky), 81×81 (:func:`_small_light`'s camera)."""
    cam = Camera(**CAM, blades=6)
    k, inv_u = D.coc_coefficients(cam, 81)
    depth = np.full((81, 81), np.inf if math.isinf(r_back) else 1.0 / (inv_u - r_back / k), np.float32)
    depth[40 + off:40 + off + n, 40 + off:40 + off + n] = 1.0 / (inv_u - r_light / k)
    color = np.full((81, 81, 3), 0.1, np.float32)
    dark = Frame(color.copy(), depth=depth)
    color[40 + off:40 + off + n, 40 + off:40 + off + n] = 40.0
    return cam, dark, Frame(color, depth=depth)


@pytest.mark.parametrize("r_light, r_back, n, off", [
    (-2.5, 1.2, 1, 0), (-4.0, 1.8, 3, 1), (-6.0, 1.0, 2, 1), (-1.7, 3.0, 2, 0), (-3.0, 1.5, 2, 1)])
def test_near_light_over_a_sharp_wall_keeps_final_s_energy_and_disc_at_half_resolution(r_light, r_back, n, off):
    # issue 16 (each emitter's energy within 3 %): a near light over a wall sharper than 2 px was
    # not split off (every |CoC| of its 3×3 had to be ≥ dof.NARROW_MIN_PX), and the composite's
    # per-pixel lerp(3×3, half blur, max(b, α)) took b of the light's front layer and 1 − b of its
    # 3×3 share on the wall: these kept 0.99 / 0.82 / 0.51 / 0.76 / 0.61 of their light at draft
    # and preview, as a centre spike (peak 4.5 / 1.3 / 3.7 / 1.7 / 0.95× final's; L1 distance from
    # final's excess 0.98 / 0.34 / 0.98 / 0.86 / 0.43 of the light). Now the light is split (the
    # layer: final's disc) and the 3×3 reads the colour without its excess.
    cam, dark, lit = _light_over_wall(r_light, r_back, n, off)
    ex = {}
    for q in ("draft", "preview", "final"):
        out, pipe = run(cam, lit, q)
        if q == "draft":
            assert_matches_reference(pipe, lit, out, rtol=1e-3)
        ex[q] = (out - pipe.run(dark).color)[..., 1] / (n * n * 39.9)
    for q in ("draft", "preview"):
        assert float(ex[q].sum()) == pytest.approx(1.0, abs=0.03), (q, float(ex[q].sum()))
        assert float(ex[q].max()) <= 1.1 * float(ex["final"].max()), (q, float(ex[q].max()), float(ex["final"].max()))
        assert float(np.abs(ex[q] - ex["final"]).sum()) < 0.1, q


def test_small_coc_light_behind_a_few_nearer_pixels_leaves_the_working_image():
    # the transparent scene's lamp behind the pane (CoC radius 1.16 px over the sky's 2.08) had
    # 1.46× Cycles' disc and 1.05 of its light at draft: a few pixels around it carry the pane's
    # depth (stochastic transparency; clumps the depth despeckle keeps), so the in-focus lights'
    # front test ("nothing nearer in the 5×5 working pixels") kept it in the working image, whose
    # blur the sky pixels around it take whole. Up to dof.NARROW_FRONT_MAX nearer pixels of the
    # 10×10 are now a surface's stochastic depth, not a foreground's soft edge (a light beside a
    # blurred bar has 20: test_in_focus_light_behind_a_blurred_foreground_stays_...).
    cam, dark, lit = _small_light(1.2, 2.6, level=60.0)
    k, inv_u = D.coc_coefficients(cam, 81)
    for f in (dark, lit):  # two 2×2 clumps of a pane's depth with the sky's colour: 8 of 100
        f.depth[36:38, 37:39] = f.depth[43:45, 42:44] = 1.0 / (inv_u + 3.5 / k)
    color64, depth64 = lit.color.astype(np.float64), lit.depth.astype(np.float64)
    coc = D.coc_px(cam, D.effective_depth(color64, depth64), 81, limit_px=64)
    assert np.count_nonzero(coc[36:46, 36:46] < 0) == 8
    _, base = D.narrow_sources(color64, coc, 2)
    assert (base[40:42, 40:42] < 1.0).all()
    for q in ("draft", "preview"):
        out, pipe = run(cam, lit, q)
        assert_matches_reference(pipe, lit, out, rtol=1e-3)


@pytest.mark.parametrize("quality, sa", [("draft", 0.4), ("preview", 0.4), ("draft", 0.0)])
def test_narrow_source_layer_matches_the_reference(quality, sa):
    # the layer's kernels (dof_narrow.cl, dof_upsample) against dof.narrow_sources/narrow_layer: an
    # odd-sized textured frame with lights over the sky, before and behind a slanted wall, on cell
    # borders (x, y = 63, 64), at the edge (not split), behind a blurred foreground bar, one above
    # NARROW_SUM_PX (normalised by its integral), with and without texture (without it the kernel
    # takes the disc's constant weight where a whole group of 16 is inside), rotated round-ish
    # blades; and a cell with more than NARROW_MAX light pixels (none split)
    cam = Camera(**CAM, blades=5, blade_rotation_deg=17.0, aperture_roundness=0.3, spherical_aberration=sa)
    h, w = 141, 203
    yy, xx = np.mgrid[0:h, 0:w]
    k, inv_u = D.coc_coefficients(cam, w)

    def at(r):
        return 1.0 / (inv_u - r / k)

    color = np.stack([0.3 + 0.1 * np.sin(xx / 5.0), 0.25 + 0.1 * np.cos(yy / 7.0), np.full((h, w), 0.4)], -1)
    depth = np.full((h, w), np.inf)
    wall = xx > 120
    depth[wall] = at(3.0 + 0.02 * (xx[wall] - 120))
    bar = (yy > 90) & (yy < 100)
    depth[bar] = at(-6.0)
    color[bar] = (0.05, 0.05, 0.08)
    lights = [(30, 30, 2.5), (63, 40, 3.0), (64, 64, 4.5), (150, 30, 2.6), (170, 60, 14.0), (1, 20, 3.0),
              (80, 104, 4.0), (100, 20, 0.0)]
    for x, y, r in lights:
        color[y:y + 2, x:x + 2] = (60.0, 40.0, 20.0)
        depth[y:y + 2, x:x + 2] = at(r) if r else cam.focus_distance_m
    for i in range(40):  # a starfield in one cell: > NARROW_MAX light pixels
        x, y = 130 + 6 * (i % 10), 100 + 6 * (i // 10) % 36
        color[y, x:x + 2] = 30.0
    frame = Frame(color.astype(np.float32), depth=depth.astype(np.float32))
    src, _ = D.narrow_sources(color, D.coc_px(cam, D.effective_depth(color, depth), w, limit_px=64), 2)
    assert len(src) >= 20  # the layer is exercised (4 pixels of each light split)
    out, pipe = run(cam, frame, quality)
    assert_matches_reference(pipe, frame, out, rtol=1e-3)


def _in_focus_light_over_the_sky(h=105, w=105, y=51, x=51):
    """(camera, dark, lit): a 2×2 light 100× white in focus over a defocused sky (0.5; CoC radius
    8.0 px at f/1.4 on this sensor: draft gathers it at lattice stride 2), absent (dark) or lit."""
    cam = Camera(**CAM, blades=6)
    depth = np.full((h, w), np.inf, np.float32)
    depth[y:y + 2, x:x + 2] = cam.focus_distance_m
    color = np.full((h, w, 3), 0.5, np.float32)
    dark = Frame(color.copy(), depth=depth)
    color[y:y + 2, x:x + 2] = 100.0
    return cam, dark, Frame(color, depth=depth)


@pytest.mark.parametrize("quality", ["draft", "preview"])
def test_in_focus_light_over_a_defocused_sky_has_no_halo_at_half_resolution(quality):
    # issue 16 (an in-focus emitter's pixels above 5 % of white beyond 3 px ≤ 2× the truth's, here
    # 0): h_lamps' lamp00 (2 px in focus over the sky) had a 68 px halo at draft. The light's
    # working block fed the prefiltered levels, whose tent (half-width = the lattice stride, 4–8
    # working px) reached it from the sky pixels beside it, and the gather's centre tap blends a
    # pixel toward its level's colour: the sky around took the lamp's light, blurred, while the
    # lamp kept its own from the full-resolution 3×3 blur. An in-focus light's excess now leaves
    # the working image (dof.NARROW_FOCUS_PX): its light stays on its pixels, and is not lost.
    cam, dark, lit = _in_focus_light_over_the_sky()
    assert float(D.coc_px(cam, np.float32(np.inf), 105)) == pytest.approx(8.0, abs=0.05)
    out, pipe = run(cam, lit, quality)
    assert_matches_reference(pipe, lit, out, rtol=1e-3)
    added = (out - pipe.run(dark).color)[..., 1]
    yy, xx = np.mgrid[:105, :105]
    beyond = np.hypot(yy - 51.5, xx - 51.5) > 3.0
    assert np.count_nonzero(added[beyond] > 0.05) == 0, np.count_nonzero(added[beyond] > 0.05)
    assert added.sum() == pytest.approx(4 * 99.5, rel=0.03)


def test_in_focus_light_behind_a_blurred_foreground_stays_in_the_half_resolution_image():
    # the in-focus light's excess leaves the working image only with nothing in front of it in the
    # 5×5 working pixels around its block: beside a blurred foreground it is the background seen
    # through the foreground's soft edge (the occluder scene's sharp corners behind the blurred bar
    # lost 0.14 dB at draft without that test). Kernel = reference on both cases, side by side.
    cam = Camera(**CAM, blades=6)
    h, w = 61, 97
    k, inv_u = D.coc_coefficients(cam, w)
    depth = np.full((h, w), np.inf, np.float32)
    color = np.full((h, w, 3), 0.5, np.float32)
    depth[20:40, 60:70] = 1.0 / (inv_u + 6.0 / k)  # a blurred foreground bar (r = -6 px)
    color[20:40, 60:70] = 0.05
    for x in (20, 72):  # one light free, one right beside the bar
        depth[30:32, x:x + 2] = cam.focus_distance_m
        color[30:32, x:x + 2] = 100.0
    color64, depth64 = color.astype(np.float64), depth.astype(np.float64)
    coc = D.coc_px(cam, D.effective_depth(color64, depth64), w, limit_px=64)
    src, base = D.narrow_sources(color64, coc, 2)
    assert len(src) == 0
    assert (base[30:32, 20:22] < 1.0).all() and (base[30:32, 72:74] == 100.0).all()
    frame = Frame(color, depth=depth)
    out, pipe = run(cam, frame, "draft")
    assert_matches_reference(pipe, frame, out, rtol=1e-3)


HIGHLIGHTS_LAMP00 = np.array([[0.14, 2.95, 1.07, 0.14, 0.14],
                              [27.31, 129.44, 61.04, 1.07, 0.14],
                              [60.1, 220.32, 128.5, 2.95, 0.14],
                              [9.51, 63.85, 27.31, 1.07, 0.14],
                              [0.14, 1.07, 1.07, 0.14, 0.14]])
"""The Cycles suite's highlights lamp00 (2 px, in focus at 2.5 m over buildings at 40 m) as exported:
luminance of its 5×5 from (185, 66); the depth pass hit it at (1, 1), (2, 1), (2, 2). The two 1.07
pixels of the bottom row are single samples of the pixel filter's tail (the lamp's radiance / 256 spp),
two rows below the depth hits."""


def _tail_frame(h=23, w=53, texture=False):
    """HIGHLIGHTS_LAMP00 tiled so lamps land in dof_coc_tail's 16-lane groups and in its per-pixel
    edge groups, before a far surface (0.14 at 40 m); ``texture``: the tail row and the one below are
    the surface's own band of 0.3 texels (bright texels of a textured surface, not tail samples: more
    than two own neighbours as bright)."""
    col = np.full((h, w, 3), 0.14, np.float32)
    depth = np.full((h, w), 40.0, np.float32)
    spots = ((2, 0), (2, 24), (14, 48), (14, 9))
    for y, x in spots:
        col[y:y + 5, x:x + 5] = HIGHLIGHTS_LAMP00[..., None]
        depth[y + 1, x + 1] = depth[y + 2, x + 1] = depth[y + 2, x + 2] = 2.5
        if texture:
            col[y + 4:y + 6, :] = 0.3
    return col, depth, spots


def test_a_lights_tail_two_pixels_from_its_depth_sample_goes_with_the_light():
    """Issue 16: an in-focus lamp's filter-tail samples two pixels from its depth hits kept the far
    surface's depth (the fringe rule's 3×3 reach) and spread as a halo (highlights: 13–25 px per lamp
    at final, Cycles 0). The light's tail clause gives them the light's depth; a texel band of the
    surface there keeps the surface's."""
    col, depth, spots = _tail_frame()
    eff = D.effective_depth(col.astype(np.float64), depth)
    for y, x in spots:
        assert np.all(eff[y + 4, x + 1:x + 3] == 2.5), (y, x)     # the tail samples: the lamp's
        assert eff[y + 4, x + 3] == 40.0 and eff[y + 5, x + 1] == 40.0  # the surface around: its own
    tex, d_tex, _ = _tail_frame(texture=True)
    eff_tex = D.effective_depth(tex.astype(np.float64), d_tex)
    for y, x in spots:
        assert np.all(eff_tex[y + 4, x + 1:x + 3] == 40.0), (y, x)
    cam = Camera(**{**CAM, "focus_distance_m": 2.5})               # the surface's CoC ≈ 7 px
    surface = np.full_like(col, 0.14)
    yy, xx = np.mgrid[0:col.shape[0], 0:col.shape[1]]
    for q in ("draft", "final"):
        for c, d in ((col, depth), (tex, d_tex)):
            frame = Frame(c, depth=d)
            out, pipe = run(cam, frame, q)
            assert_matches_reference(pipe, frame, out, rtol=1e-3)
        lamp = run(cam, Frame(col, depth=depth), q)[0] - run(cam, Frame(surface, depth=depth), q)[0]
        far = np.ones(col.shape[:2], bool)
        for y, x in spots:
            far &= np.hypot(yy - (y + 2), xx - (x + 1.5)) > 3.5
        # lamp-only light above 5 % of the lamp's 220 / 256 spp beyond 3.5 px: the rule without the
        # tail clause left such pixels around every lamp
        assert np.count_nonzero(lamp[far] @ D.luma_weights() > 0.05) == 0, q

"""motion_blur: kernel vs float64 reference, invariants, closed forms, plan and bad input."""
import numpy as np
import pytest
from hypothesis import given, strategies as st

from clpost import Camera, Frame, Pipeline
from clpost.errors import InputError
from clpost.stages.motion_blur import (DENSITY, SAMPLES, SAMPLES_MAX, TILE, MotionBlur, half_vectors, jitter,
                                       reference_blur, reference_layers, shutter_fraction, shutter_from_angle, tap_cap,
                                       tap_records, taps, tile_max)

from conftest import assert_planned

CAM = Camera(frame_rate_fps=24.0, shutter_s=1 / 48)   # 180° shutter: fraction 0.5


def _run(cam, frame, quality="final"):
    pipe = Pipeline(cam, quality=quality, stages=["motion_blur"])
    return pipe, pipe.run(frame).color


def _compare(cam, frame, quality="final", tol=1e-5):
    pipe, out = _run(cam, frame, quality)
    assert_planned(pipe, frame, "motion_blur")
    assert pipe.plan(frame) == ["motion_blur"]
    ref = pipe.reference(frame)
    assert out.dtype == np.float32 and np.isfinite(out).all()
    err = np.abs(out - ref).max(axis=2) / np.maximum(np.abs(ref).max(axis=2), 1.0)
    y, x = np.unravel_index(int(np.argmax(err)), err.shape)
    assert err.max() < tol, f"largest error {err.max():.3g} at (x={x}, y={y}): kernel {out[y, x]} ref {ref[y, x]}"
    return out, ref


def _frame(rng, w=37, h=23, speed=15.0, sky_rows=5):
    color = (rng.random((h, w, 3)) * 10).astype(np.float32)
    vel = (rng.normal(size=(h, w, 2)) * speed).astype(np.float32)
    depth = rng.uniform(0.5, 50, (h, w)).astype(np.float32)
    depth[:sky_rows] = np.inf
    return Frame(color, depth=depth, velocity=vel, metadata={"frame_index": 7})


@pytest.mark.parametrize("quality", list(SAMPLES))
def test_kernel_matches_reference_on_odd_size(rng, quality):
    _compare(CAM, _frame(rng), quality)


def test_tap_count_follows_the_neighbourhood_speed():
    # S = min(S_q, 2 ceil(DENSITY |v_N|) + 1): odd, strata at most 1/DENSITY px apart on the path 2|v_N|
    ln = np.array([0.0, 0.5, 0.8, 1.0, 2.0, 4.0, 20.0], np.float32)
    for s_q in SAMPLES.values():
        s = taps(ln, s_q)
        assert (s % 2 == 1).all() and (s <= s_q).all() and s[-1] == s_q
        dense = s < s_q
        assert (2 * ln[dense] / s[dense] <= 1.0 / DENSITY).all()
    assert DENSITY == 1.5   # the values below: 2 ceil(1.5 |v_N|) + 1
    np.testing.assert_array_equal(taps(ln, 23), [1, 3, 5, 5, 7, 13, 23])


def test_tap_cap_spends_the_still_tiles_budget_within_bounds():
    # C = S_q x tiles / moving tiles, rounded down to odd, in [S_q, S_max]
    nmax = np.zeros((4, 6, 2))
    assert tap_cap(nmax, 5, 11) == 5                      # nothing moves: S_q
    nmax[0, 0] = (0.6, 0.0)                               # 1 of 24 tiles: 120 -> 11
    assert tap_cap(nmax, 5, 11) == 11
    nmax[:2, :] = (0.0, 0.6)                              # 12 of 24: 10 -> 9 (odd)
    assert tap_cap(nmax, 5, 11) == 9
    nmax[:2, :] = (0.0, 0.5)                              # |v_N| = 0.5 does not run the gather
    assert tap_cap(nmax, 5, 11) == 5
    nmax[:] = (3.0, 4.0)                                  # everything moves: S_q
    assert tap_cap(nmax, 23, 23) == 23 and tap_cap(nmax, 5, 11) == 5
    assert all(SAMPLES_MAX[q] >= SAMPLES[q] and SAMPLES_MAX[q] % 2 == 1 for q in SAMPLES)


@pytest.mark.parametrize("quality", list(SAMPLES))
def test_sparse_motion_takes_more_taps_in_both_forms(rng, monkeypatch, quality):
    """A mover in 2 of 24 tiles: the frame's cap rises to S_max (draft 5 -> 19); the kernel matches
    the reference and the one-pixel form the 16-wide one."""
    from clpost.runtime import Runtime

    h, w = 4 * TILE, 6 * TILE
    color = (rng.random((h, w, 3)) * 10).astype(np.float32)
    vel = np.zeros((h, w, 2), np.float32)
    vel[5:15, 3:17] = (60.0, 10.0)                        # |h| 15 px: S_max taps where it reaches
    depth = rng.uniform(1.0, 30.0, (h, w)).astype(np.float32)
    frame = Frame(color, depth=depth, velocity=vel, metadata={"frame_index": 4})
    _, nm = tile_max(half_vectors(vel, 0.25, True))
    assert tap_cap(nm, SAMPLES[quality], SAMPLES_MAX[quality]) == SAMPLES_MAX[quality]
    want, _ = _compare(CAM, frame, quality, tol=2e-4)
    monkeypatch.setattr(Runtime, "wide", property(lambda self: False))
    got, _ = _compare(CAM, frame, quality, tol=2e-4)
    np.testing.assert_allclose(got, want, rtol=2e-6, atol=2e-6)
    if SAMPLES_MAX[quality] > SAMPLES[quality]:         # and it differs from S_q taps
        from clpost.stages.motion_blur import reference_blur
        old = reference_blur(color.astype(np.float64), vel, depth, 0.5, SAMPLES[quality], 4)
        assert np.abs(old - want).max() > 0.1


@pytest.mark.parametrize("quality", list(SAMPLES))
def test_kernel_matches_reference_where_tiles_take_different_tap_counts(rng, quality):
    # tiles of slow, medium and fast motion side by side, 16-pixel groups straddling tile edges
    # whose lanes take different S (the float16 gather masks the lanes past their own S)
    h, w = 2 * TILE + 3, 5 * TILE + 7
    color = (rng.random((h, w, 3)) * 10).astype(np.float32)
    vel = np.zeros((h, w, 2), np.float32)
    for i, speed in enumerate([0.0, 1.5, 5.0, 0.0, 12.0, 40.0]):
        vel[:, i * TILE:(i + 1) * TILE, 0] = speed * (1 + 0.2 * rng.random((h, min(TILE, max(w - i * TILE, 0)))))
    vel[..., 1] = rng.normal(size=(h, w)) * 0.7
    depth = rng.uniform(1.0, 30.0, (h, w)).astype(np.float32)
    frame = Frame(color, depth=depth, velocity=vel, metadata={"frame_index": 3})
    _compare(CAM, frame, quality)


@pytest.mark.parametrize("quality", list(SAMPLES))
@pytest.mark.parametrize("w,h", [(5 * TILE + 7, 2 * TILE + 3), (1, 1), (37, 23)])
def test_one_pixel_per_work_item_form_matches_the_sixteen_wide_one(rng, monkeypatch, quality, w, h):
    """The prep's and the gather's one-pixel form (a GPU's, Runtime.wide False) gives the 16-wide
    form's image (the same operations per pixel; tap counts differing within a row and tile
    edges) and the float64 reference."""
    from clpost.runtime import Runtime

    color = (rng.random((h, w, 3)) * 10).astype(np.float32)
    vel = np.zeros((h, w, 2), np.float32)
    for i, speed in enumerate([0.0, 1.5, 5.0, 0.0, 12.0, 40.0]):
        x0, x1 = min(i * TILE, w), min((i + 1) * TILE, w)
        vel[:, x0:x1, 0] = speed * (1 + 0.2 * rng.random((h, x1 - x0)))
    vel[..., 1] = rng.normal(size=(h, w)) * 0.7
    vel[h // 2:, ::5] = rng.normal(size=vel[h // 2:, ::5].shape) * 20.0
    depth = rng.uniform(1.0, 30.0, (h, w)).astype(np.float32)
    depth[:2] = np.inf
    frame = Frame(color, depth=depth, velocity=vel, metadata={"frame_index": 5})
    pipe = Pipeline(CAM, quality=quality, stages=["motion_blur"])
    assert MotionBlur.lanes(pipe.runtime) == 16
    want = pipe.run(frame).color
    monkeypatch.setattr(Runtime, "wide", property(lambda self: False))
    pipe = Pipeline(CAM, quality=quality, stages=["motion_blur"])
    assert MotionBlur.lanes(pipe.runtime) == 1
    # every fifth column of the lower half has random 20 px/frame vectors: float32 weights at cylinder
    # edges round apart from the float64 reference's by up to ~1e-4 (in either form, they are equal)
    got, ref = _compare(CAM, frame, quality, tol=2e-4)
    np.testing.assert_allclose(got, want, rtol=2e-6, atol=2e-6)


def test_adversarial_velocities_and_depths(rng):
    f = _frame(rng, 41, 29)
    vel = f.velocity.copy()
    vel[0:3] = 3e38                 # near FLT_MAX: clamped, never inf/NaN
    vel[3:6] = -1e30
    vel[6:9, :, 0] = 0.0            # purely vertical
    vel[9:12] = 0.0                 # static rows
    vel[12:14] = 1e-30              # denormal-ish speeds
    depth = f.depth.copy()
    depth[14:18] = 1e-6             # almost at the lens
    depth[18:] = 1e8
    color = f.color.copy()
    color[20:, ::3] = 1e8           # extreme luminance next to 1e-6
    color[20:, 1::3] = 1e-6
    frame = Frame(color, depth=depth, velocity=vel)
    out, _ = _compare(CAM, frame, tol=2e-5)
    assert out.min() >= color.min() - 1e-6 and out.max() <= color.max() * (1 + 1e-6)


@given(speed=st.floats(0.0, 200.0), fraction=st.floats(0.05, 1.0), seed=st.integers(0, 2**16))
def test_kernel_matches_reference_hypothesis(speed, fraction, seed):
    rng = np.random.default_rng(seed)
    f = _frame(rng, 23, 19, speed=speed, sky_rows=2)
    cam = Camera(frame_rate_fps=25.0, shutter_s=fraction / 25.0)
    if MotionBlur().skip_reason(cam, f) is None:
        _compare(cam, f, "draft")


def test_constant_image_stays_constant(rng):
    f = _frame(rng, 45, 31, speed=40)
    flat = Frame(np.full_like(f.color, 3.25), depth=f.depth, velocity=f.velocity)
    _, out = _run(CAM, flat)
    np.testing.assert_allclose(out, 3.25, rtol=1e-6)


def test_energy_of_a_dot_with_uniform_motion_is_conserved():
    h, w = 61, 81
    color = np.zeros((h, w, 3), np.float32)
    color[30, 40] = 1000.0
    vel = np.zeros((h, w, 2), np.float32)
    vel[..., 0] = 24.0              # 24 px per frame, 180° shutter: a 12 px streak
    frame = Frame(color, depth=np.full((h, w), 5.0, np.float32), velocity=vel)
    pipe, out = _run(CAM, frame)
    # a gather normalises per output pixel, so a lone dot keeps its energy only on average over
    # the jitter (one frame index: σ ≈ 10 % with these 19 taps): the mean over 16 frame indices
    totals = [pipe.run(Frame(color, depth=frame.depth, velocity=vel, metadata={"frame_index": k})).color.sum(axis=(0, 1))
              for k in range(16)]
    np.testing.assert_allclose(np.mean(totals, axis=0), 1000.0, rtol=0.05)
    row = out[30, :, 0]
    assert np.count_nonzero(out[:, :, 0].sum(axis=1)) == 1          # stays on its row
    xs = np.arange(w)
    mean = (row * xs).sum() / row.sum()
    var = (row * (xs - mean) ** 2).sum() / row.sum()
    assert abs(mean - 40) < 0.5
    # the true streak is a box of length L = v·s = 12 px: variance L²/12 = 12 px². The coverage
    # weights give a box up to the taps' rounding to pixels: measured 10.7 px² (McGuire's cones
    # gave 8.7, between the box and a triangle of the same extent, L²/24 = 6 px²)
    assert 9.0 < var < 14.0, var


@pytest.mark.parametrize("quality", list(SAMPLES))
def test_energy_of_a_texture_with_uniform_motion_is_conserved(rng, quality):
    h, w = 47, 121
    color = (rng.random((h, w, 3)) ** 4 * 100).astype(np.float32)
    color[:, :25] = color[:, -25:] = 1.0         # flat margins: no energy leaves the image
    vel = np.zeros((h, w, 2), np.float32)
    vel[..., 0], vel[..., 1] = 31.0, -7.0
    frame = Frame(color, depth=np.full((h, w), 5.0, np.float32), velocity=vel)
    pipe, out = _run(CAM, frame, quality)
    sl = (slice(4, -4), slice(None))              # rows whose vertical smear stays inside
    # jitter noise (where a pixel's own-surface taps cover less than the shutter, the pixel itself
    # fills in): one frame index keeps the total to ~3 % at 5 taps (draft), ~2 % at 11 (preview),
    # ~1 % at 23 (final); the mean over 8 frame indices measured within 0.8 % at every level
    rtol = {5: 5e-2, 11: 2e-2}.get(SAMPLES[quality], 1.2e-2)
    np.testing.assert_allclose(out[sl].sum(axis=(0, 1)), color[sl].sum(axis=(0, 1)), rtol=rtol)
    sums = [pipe.run(Frame(color, depth=frame.depth, velocity=vel, metadata={"frame_index": k})).color[sl].sum(axis=(0, 1))
            for k in range(8)]
    np.testing.assert_allclose(np.mean(sums, axis=0), color[sl].sum(axis=(0, 1)), rtol=1e-2)


@pytest.mark.parametrize("cap", [5, 11, 19, 23])
def test_a_uniformly_moving_surface_covers_itself_all_shutter(rng, cap):
    """Inside a surface that moves as one (one velocity, one depth), X's own surface covers X for
    the whole shutter: the own layer's coverage is the share co / ca of X's path, 1 up to the tap
    record's rounding, so no background shows through it. The absolute sum co scatters
    (0.87-1.07 at 5 taps; 0.89-0.98 at 11, always short) and, as the coverage, let the
    background estimate through wherever it fell below 1."""
    h, w = 60, 100
    color = rng.random((h, w, 3))
    vel = np.zeros((h, w, 2), np.float32)
    vel[..., 0], vel[..., 1] = 27.0, 9.0                      # |h| = 7.1 px at a 180° shutter
    depth = np.full((h, w), 4.0, np.float32)
    inner = (slice(20, -20), slice(20, -20))                  # paths stay inside the image
    for k in range(3):
        L = reference_layers(color, vel, depth, 0.5, cap, k, samples_max=cap)
        share = (L["co"] / L["ca"])[inner]
        assert np.abs(share - 1).max() < 1e-3
        assert np.abs(L["co"][inner] - 1).max() > 0.02         # the sum alone is not the coverage
        out = reference_blur(color, vel, depth, 0.5, cap, k, samples_max=cap)
        cf = np.minimum(L["cf"], 1.0)[..., None]                # level taps off X's path (module docstring)
        front = L["sf"] / np.where(L["cf"] > 0, L["cf"], 1.0)[..., None]
        no_background = cf * front + (1.0 - cf) * L["so"] / L["co"][..., None]
        np.testing.assert_allclose(out[inner], no_background[inner], rtol=1e-6)
    for quality in SAMPLES:                                   # and the kernels (cap = S_q: everything moves)
        _compare(CAM, Frame(color.astype(np.float32), depth=depth, velocity=vel), quality)


def test_far_static_region_is_bit_identical_and_moving_object_smears_over_background(rng):
    h, w = 60, 120
    color = (rng.random((h, w, 3)) + 0.5).astype(np.float32)
    color[20:40, 20:30] = 50.0          # a bright moving block near 2 m over a 20 m wall
    vel = np.zeros((h, w, 2), np.float32)
    vel[20:40, 20:30, 0] = 30.0
    depth = np.full((h, w), 20.0, np.float32)
    depth[20:40, 20:30] = 2.0
    frame = Frame(color, depth=depth, velocity=vel)
    _, out = _run(CAM, frame)
    # tiles more than one tile away from any motion see NeighborMax = 0: untouched bits
    np.testing.assert_array_equal(out[:, 3 * TILE:], color[:, 3 * TILE:])
    # the static background just right of the block receives its smear (foreground over background)
    # (half-length 7.5 px: a ramp from the edge to ~7 px out, as the cone weight prescribes)
    smear = out[30, 30:38, 0]
    assert smear[:4].min() > 5.0 and np.all(np.diff(smear) < 0) and smear[-1] < 2.0, smear
    # and the block's interior gets transparent at its ends: the trailing edge mixes in background
    assert out[30, 20, 0] < 45.0


def test_deterministic_and_jitter_depends_on_frame_index(rng):
    f = _frame(rng)
    _, a = _run(CAM, f)
    _, b = _run(CAM, f)
    np.testing.assert_array_equal(a, b)
    g = f.replace(metadata={"frame_index": 8})
    _, c = _run(CAM, g)
    assert not np.array_equal(a, c)
    xs, ys = np.meshgrid(np.arange(64), np.arange(64))
    j = jitter(1, 2, xs, ys)
    assert j.dtype == np.float32 and -0.5 <= j.min() and j.max() < 0.5 and abs(j.mean()) < 0.02


def test_jitter_spreads_neighbouring_pixels_over_the_strata():
    # the R2 lattice: any 8 consecutive pixels of a row, and any 3x3 block, leave no gap in [-1/2, 1/2)
    # (circular) wider than 0.25 / 0.2 — independent uniform draws leave gaps of 0.7 and more here
    ys, xs = np.mgrid[0:64, 0:64]
    for frame in (0, 5):
        j = jitter(1, frame, xs, ys)

        def gap(v):
            v = np.sort(v)
            return np.diff(np.concatenate([v, v[:1] + 1.0])).max()

        assert max(gap(j[y, x:x + 8]) for y in range(64) for x in range(56)) < 0.25
        assert max(gap(j[y:y + 3, x:x + 3].ravel()) for y in range(62) for x in range(62)) < 0.2


def test_front_surface_reaches_only_pixels_on_its_own_motion_line(rng):
    # a bar sliding right (|h| 5 px) above a static wall, and a faster diagonal mover in the same tile
    # neighbourhood, so v_N is diagonal: taps of a wall pixel 3 rows below the bar run diagonally into
    # the bar within its half-length (4.2 px). The bar never passes over that pixel (3 px off the
    # bar's motion line, beyond LINE + 1/2): no smear (without the line test: up to 1.1 here).
    h, w = 60, 60
    color = np.full((h, w, 3), 0.2, np.float32)
    vel = np.zeros((h, w, 2), np.float32)
    depth = np.full((h, w), 10.0, np.float32)
    color[20:24, 20:30] = 5.0
    vel[20:24, 20:30] = (20.0, 0.0)        # 180°: |h| = 5 px
    depth[20:24, 20:30] = 2.0
    vel[40:44, 40:44] = (30.0, 30.0)       # the neighbourhood's fastest: v_N diagonal
    depth[40:44, 40:44] = 2.0
    frame = Frame(color, depth=depth, velocity=vel, metadata={"frame_index": 2})
    out, ref = _compare(CAM, frame, "final")
    assert np.abs(out[26, 18:32, 0] - 0.2).max() < 1e-3, out[26, 18:32, 0]


@pytest.mark.parametrize("wide", [True, False])
def test_a_still_pixel_sees_a_second_mover_that_its_neighbourhood_maximum_hides(rng, monkeypatch, wide):
    # a bright bar sliding right (|h| 5 px, depth 4) over a static wall (depth 10), and a faster dark
    # mover going down-left (|h| 10.6 px, depth 2) in the next tile, so the wall ahead of the bar has
    # the diagonal as v_N and no tap along the bar: its leading streak stopped at the edge (x 36-39:
    # 0.33 / 0.2 / 0.2 / 0.2 where the frame without the diagonal mover gives 0.85 / 0.66 / 0.47 / 0.29).
    # The neighbourhood's second direction (another surface: depth 4 vs 2) sends a still pixel's odd
    # taps along the bar; the streak matches the frame without the diagonal mover.
    from clpost.runtime import Runtime

    if not wide:
        monkeypatch.setattr(Runtime, "wide", property(lambda self: False))
    h, w = 60, 80

    def frame(diagonal):
        color = np.full((h, w, 3), 0.2, np.float32)
        vel = np.zeros((h, w, 2), np.float32)
        depth = np.full((h, w), 10.0, np.float32)
        color[20:30, 20:35], vel[20:30, 20:35], depth[20:30, 20:35] = 2.0, (20.0, 0.0), 4.0
        if diagonal:
            color[36:40, 40:44], vel[36:40, 40:44], depth[36:40, 40:44] = 0.0, (-30.0, 30.0), 2.0
        return Frame(color, depth=depth, velocity=vel, metadata={"frame_index": 1})

    alone, _ = _compare(CAM, frame(False), "final")
    both, _ = _compare(CAM, frame(True), "final")
    ahead = (slice(22, 28), slice(36, 40), 0)
    assert alone[ahead].mean(axis=0).min() > 0.25                    # the bar's streak reaches x = 39
    np.testing.assert_allclose(both[ahead].mean(axis=0), alone[ahead].mean(axis=0), atol=0.1)


def test_clamp_keeps_direction_and_caps_length():
    v = np.array([[[3e38, -3e38], [0.0, 0.0], [3.0, 4.0]]], np.float32)
    hv = half_vectors(v, 0.25)
    assert np.isclose(np.hypot(*hv[0, 0]), TILE) and np.isclose(hv[0, 0, 0], -hv[0, 0, 1])
    assert (hv[0, 1] == 0).all()
    np.testing.assert_allclose(hv[0, 2], [0.75, 1.0])


def test_tap_record_keeps_length_to_2e_10_and_direction_to_a_step(rng):
    # what a tap reads of Y (one word): max(|h|, 0.5) to a relative 2^-10, the unit direction to 1/127
    # per component (< 0.2 px off Y's motion line at the 21 px a tap reaches)
    v = np.concatenate([rng.normal(size=(2000, 2)) * 10.0, rng.normal(size=(200, 2)) * 1e-3,
                        [[0.0, 0.0], [3e38, -3e38], [0.0, -5.0], [80.0, 0.0]]]).astype(np.float32)[None]
    l, e = tap_records(v, 0.25)
    hv = half_vectors(v, 0.25)[0]
    length = np.hypot(hv[:, 0], hv[:, 1])
    want = np.maximum(length, 0.5)
    assert (np.abs(l[0] - want) <= want * 2.0 ** -11 * 1.0001).all()
    moving = length > 0
    unit = hv[moving] / length[moving, None]
    assert (np.abs(e[0][moving] / 127.0 - unit) <= 0.5 / 127.0 + 1e-6).all()
    assert (e[0][~moving] == 0).all() and (np.abs(e[0]) <= 127).all()
    assert l[0, -1] == 20.0 and l[0, -4] == 0.5 and (e[0, -2] == (0, -127)).all()


@pytest.mark.parametrize("wide", [True, False])
def test_prep_writes_the_tap_records_of_the_reference_bit_for_bit(rng, monkeypatch, wide):
    # the record plane motion_blur_prep packs (both forms: 16-pixel rows with edge groups one by one,
    # or one pixel per work-item) is tap_records' word exactly, and h and the key half_vectors32's:
    # the image tests compare through tolerances that a changed rounding of |h_Y| or of e_Y may pass
    import pyopencl as cl

    from clpost.runtime import Runtime
    from clpost.stages.motion_blur import effective_velocity, half_vectors32

    monkeypatch.setattr(Runtime, "wide", property(lambda self: wide))
    h, w = 7, 53
    vel = (rng.normal(size=(h, w, 2)) * 10.0 ** rng.uniform(-3, 2, (h, w, 1))).astype(np.float32)
    vel[0, :6] = [[0, 0], [1e-45, 0], [3e38, -3e38], [-3.4e38, 3.4e38], [0, -1e-40], [80, 0]]
    vel[1, ::3] = 0.0
    a = np.arange(w) * 0.7                          # every direction byte, halfway cases included
    vel[2] = np.stack([7 * np.cos(a), 7 * np.sin(a)], axis=-1)
    vel[3, :, 0], vel[3, :, 1] = np.linspace(-90, 90, w), 0.5
    depth = rng.uniform(1.0, 20.0, (h, w)).astype(np.float32)
    frame = Frame(np.zeros((h, w, 3), np.float32), depth=depth, velocity=vel)
    pipe = Pipeline(CAM, quality="draft", stages=["motion_blur"])
    stage, rt = pipe.plan_for(frame, pipe.camera_for(frame)).stages[0], pipe.runtime
    assert MotionBlur.lanes(rt) == (16 if wide else 1)
    k = np.float32(shutter_fraction(CAM) / 2.0)
    mf = cl.mem_flags
    vb, db = (cl.Buffer(rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(x))
              for x in (vel, depth))
    hv = np.zeros((4, h, w), np.float32)
    hb, ib = cl.Buffer(rt.context, mf.READ_WRITE, hv.nbytes), cl.Buffer(rt.context, mf.READ_WRITE, hv.nbytes // 4)
    knl = stage._kernel(rt, CAM, "motion_blur_prep")
    rt.launch(knl, *stage._row_launch(rt, w, h), vb, db, hb, ib, np.int32(w), np.int32(h), k)
    cl.enqueue_copy(rt.queue, hv, hb)
    ve, _ = effective_velocity(vel, depth)
    lq, q = tap_records(ve, k)
    qi = q.astype(np.int32).astype(np.uint32)
    want = (((lq.view(np.uint32) - np.uint32(0x3F000000)) >> np.uint32(13))
            | ((qi[..., 0] & np.uint32(0xFF)) << np.uint32(16)) | (qi[..., 1] << np.uint32(24)))
    got = hv[3].view(np.uint32)
    bad = np.argwhere(got != want)
    assert not bad.size, f"{len(bad)} records differ, first at (y, x) = {tuple(bad[0])}: {got[tuple(bad[0])]:#x} " \
                         f"vs {want[tuple(bad[0])]:#x}"
    np.testing.assert_array_equal(np.moveaxis(hv[:3], 0, -1), half_vectors32(ve, k))


def test_rolling_shutter_matches_reference_and_slants_a_moving_bar():
    h, w = 41, 51
    color = np.zeros((h, w, 3), np.float32)
    color[:, 24:27] = 1.0
    vel = np.zeros((h, w, 2), np.float32)
    vel[..., 0] = 10.0
    frame = Frame(color, depth=np.full((h, w), 3.0, np.float32), velocity=vel)
    # tiny shutter: no blur, only the readout skew (readout 1/24 s at 24 fps = one frame)
    cam = Camera(frame_rate_fps=24.0, shutter_s=1e-4, readout_time_s=1 / 24)
    out, _ = _compare(cam, frame)
    xs = np.arange(w)
    for y in (0, 20, 40):
        cx = (out[y, :, 0] * xs).sum() / out[y, :, 0].sum()
        assert abs(cx - (25 + 10 * (y / 40 - 0.5))) < 0.05, (y, cx)


def test_skipped_without_frame_rate_or_motion(rng):
    f = _frame(rng)
    assert Pipeline(Camera(), stages=["motion_blur"]).plan(f) == []
    assert "frame rate" in MotionBlur().skip_reason(Camera(), f)
    still = f.replace(velocity=np.zeros_like(f.velocity))
    assert "no blur" in MotionBlur().skip_reason(CAM, still)
    # largest half-length 0.3 px: the filter would leave every pixel as it is, so it is not planned
    slow = f.replace(velocity=np.full_like(f.velocity, 0.3 / np.sqrt(2) * 4 / 2))
    assert MotionBlur().skip_reason(CAM, slow) is not None
    # the default camera's plan is unchanged by the new fields
    assert Camera().frame_rate_fps is None and Camera().readout_time_s == 0.0


def test_needs_velocity_when_planned(rng):
    f = Frame(np.ones((5, 7, 3), np.float32), depth=np.ones((5, 7), np.float32))
    with pytest.raises(InputError, match="velocity"):
        Pipeline(CAM, stages=["motion_blur"]).plan(f)


def test_shutter_angle_and_fraction():
    assert shutter_from_angle(180, 24) == pytest.approx(1 / 48)
    assert shutter_fraction(Camera(frame_rate_fps=24, shutter_s=shutter_from_angle(180, 24))) == pytest.approx(0.5)
    with pytest.raises(InputError, match="shutter-angle"):
        shutter_from_angle(0, 24)
    with pytest.raises(InputError, match="fps"):
        shutter_from_angle(180, -1)


@pytest.mark.parametrize("kw, match", [
    (dict(frame_rate_fps=0.0), "frame_rate_fps"),
    (dict(frame_rate_fps=float("nan")), "frame_rate_fps"),
    (dict(frame_rate_fps=24, readout_time_s=-1e-3), "readout_time_s"),
    (dict(readout_time_s=0.01), "frame_rate_fps"),
])
def test_camera_rejects_bad_motion_parameters(kw, match):
    with pytest.raises(InputError, match=match):
        Camera(**kw)


def test_nan_velocity_rejected_at_the_frame():
    v = np.zeros((3, 4, 2), np.float32)
    v[1, 2, 0] = np.nan
    with pytest.raises(InputError, match="velocity"):
        Frame(np.ones((3, 4, 3), np.float32), velocity=v)


def test_a_shutter_longer_than_the_frame_interval_is_refused():
    with pytest.raises(InputError, match="longer than one frame interval at 24 fps"):
        Camera(frame_rate_fps=24.0, shutter_s=1 / 5)
    Camera(frame_rate_fps=24.0, shutter_s=1 / 24)  # 360° is the longest a frame can be exposed


def _aa_lamp_frame():
    """A 3 px bright lamp moving 24 px/frame right over a dark static wall, as a renderer exports
    it: colour and velocity averaged over the pixel filter (the edge pixels carry a fraction of
    both), depth point-sampled (the edge pixels carry the wall's)."""
    h, w = 21, 81
    cover = np.zeros(w)
    cover[38:41] = 1.0
    cover[37], cover[41] = 0.4, 0.15              # partial coverage of the anti-aliased edges
    color = np.full((h, w, 3), 0.05, np.float32)
    vel = np.zeros((h, w, 2), np.float32)
    depth = np.full((h, w), 9.0, np.float32)
    for y in range(8, 13):
        color[y, :, :] = (0.05 * (1 - cover) + 100.0 * cover)[:, None]
        vel[y, :, 0] = 24.0 * cover
        depth[y, cover >= 0.5] = 6.0
    return Frame(color, depth=depth, velocity=vel), cover


def _box_streak(cover, v=24.0, fraction=0.5, background=0.05, lamp=100.0):
    """The exact exposure of the lamp row: each pixel's lamp coverage moved along a centred box
    of length v·fraction (closed form, supersampled)."""
    w = cover.size
    out = np.zeros(w)
    taus = (np.arange(400) + 0.5) / 400 - 0.5
    xs = np.arange(w)
    for tau in taus:
        shift = v * fraction * tau
        moved = np.interp(xs - shift, xs, cover, left=0, right=0)
        out += background * (1 - moved) + lamp * moved
    return out / taus.size


@pytest.mark.parametrize("quality", list(SAMPLES))
def test_anti_aliased_moving_lamp_is_a_box_streak(quality):
    """Renderer fringe (issue 16): the lamp's edge pixels carry part of its velocity and the wall's
    depth. The streak must be the flat box of length 12 px convolved with the lamp (what Cycles
    renders), not a peak with tapered wings. Measured (draft / preview / final): before the
    coverage gather and the fringe rule energy 1.31 / 1.52 / 1.41×, peak 3.0 / 3.0 / 2.6× the box
    level, L1 error 0.75 / 0.84 / 0.74 of the energy; after 0.94 / 0.96 / 0.94, 1.35 / 1.09 /
    1.04×, 0.32 / 0.13 / 0.09 (frame index 0). With the pixel footprint and the nearest-weighted
    background (docs/motion_blur.md), means over 24 frame indices: energy 1.03 / 1.01 / 1.02 (before
    0.97 / 0.96 / 0.99), peak 1.41 / 1.17 / 1.14×, L1 0.26 / 0.15 / 0.07 (before 0.24 / 0.13 / 0.09);
    one frame index's energy varies by σ 8 / 4 / 1.5 %, so the bounds apply to the mean of 8."""
    frame, cover = _aa_lamp_frame()
    pipe = Pipeline(CAM, quality=quality, stages=["motion_blur"])
    assert_planned(pipe, frame, "motion_blur")
    rows = np.array([pipe.run(Frame(frame.color, depth=frame.depth, velocity=frame.velocity,
                                    metadata={"frame_index": k})).color[10, :, 0] for k in range(8)], np.float64)
    truth = _box_streak(cover)
    np.testing.assert_allclose(rows.sum(axis=1).mean(), truth.sum(), rtol=0.08)
    # inside the plateau (x 33..45) the truth is flat at ~100·3.55/12 ≈ 30: no central peak
    plateau = slice(33, 46)
    peaks = rows[:, plateau].max(axis=1)
    assert peaks.mean() < 1.5 * truth[plateau].max(), (peaks, truth[plateau])
    l1 = np.abs(rows - truth).sum(axis=1) / truth.sum()
    assert l1.mean() < 0.4, l1


def test_kernel_constants_come_from_the_stage_defines_only():
    # every MOTION_BLUR_* name the kernels use is a define of the stage (one place: the .py), or a
    # kernel-internal #define (the rounding trick, the lane count); each float literal is the .py's float32
    import re

    from clpost.runtime import kernel_source
    from clpost.stages import motion_blur as mb

    defines = MotionBlur("final").defines(CAM)
    src = re.sub(r"/\*.*?\*/", "", "".join(kernel_source(k) for k in ("motion_blur_pixels", "motion_blur")),
                 flags=re.S)   # the code, not its comments
    own = set(re.findall(r"#define (MOTION_BLUR_\w+)", src))
    assert own == {"MOTION_BLUR_RINT_MAGIC", "MOTION_BLUR_LANES"}
    assert set(re.findall(r"\bMOTION_BLUR_[A-Z0-9_]+\b", src)) - own - {"MOTION_BLUR_LANES"} <= set(defines)
    expect = {"SOFT_Z": mb.SOFT_Z, "FOOT": mb.FOOT, "AGREE0": mb.AGREE0, "AGREE1": mb.AGREE1,
              "DIFFER2": mb.AGREE0 ** 2, "DIR": mb.DIR, "LINE": mb.LINE, "FRINGE2": mb.FRINGE ** 2,
              "R2X": mb.JITTER_R2[0], "R2Y": mb.JITTER_R2[1], "DENSITY": DENSITY}
    for name, value in expect.items():
        literal = defines[f"MOTION_BLUR_{name}"]
        assert literal.endswith("f") and np.float32(float(literal[:-1])) == np.float32(value), name

"""coma: planning, kernel vs float64 reference, comet geometry of a point source, energy,
sign, stability, the traced lens's coma."""
import numpy as np
import pytest

from clpost import Camera, Frame, InputError, Pipeline
from clpost.stages import _field as fld
from clpost.stages import coma

from conftest import assert_planned, assert_stage_runs, odd_frame

FLAGSHIP = "zeiss-planar-50-f1.4"


def test_not_planned_without_coma_and_identity_when_skipped(rng):
    frame = odd_frame(rng)
    for cam in (Camera(), Camera(coma_mm=0.0), Camera(lens=FLAGSHIP, f_number=2.0, coma_mm=0.0)):
        pipe = Pipeline(cam, stages=["coma"])
        assert pipe.plan(frame) == []
        assert np.array_equal(pipe.run(frame).color, frame.color)
    assert "coma" in Pipeline(Camera(lens=FLAGSHIP, f_number=1.4)).plan(frame)


@pytest.mark.parametrize("w,h,kw", [(37, 23, dict(coma_mm=0.9)), (23, 37, dict(coma_mm=-40.0)),
                                    (41, 29, dict(lens=FLAGSHIP, f_number=1.4)),
                                    (133, 77, dict(coma_mm=0.1)), (131, 85, dict(coma_mm=-0.15)),
                                    (160, 90, dict(lens=FLAGSHIP, f_number=2.0))])
def test_kernel_matches_reference(rng, w, h, kw):
    frame = odd_frame(rng, w=w, h=h, scale=10.0)
    color = frame.color.copy()
    color[0, 0] = 1e8  # adversarial: a highlight in the corner, zeros beside it
    color[1, :4] = 0.0
    frame = Frame(color)
    pipe = Pipeline(Camera(**kw), stages=["coma"])
    assert_planned(pipe, frame, "coma")
    out = pipe.run(frame).color
    ref = pipe.reference(frame)
    err = np.abs(out - ref) / np.maximum(np.abs(ref), 10.0)
    j = np.unravel_index(int(np.argmax(err)), err.shape)
    assert err.max() < 2e-4, f"max rel error {err.max():.3g} at (x={j[1]}, y={j[0]}, c={j[2]})"
    assert np.all(np.isfinite(out)) and out.dtype == np.float32


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_point_source_comet_length_width_and_centroid(sign):
    w, h = 301, 201
    cam = Camera(coma_mm=sign * 1.2)  # comet 3C = 1.2 mm at the corner
    cx, cy = (w - 1) / 2, (h - 1) / 2
    x0 = 250
    r_mm = (x0 - cx) * fld.pitch_mm(cam, w)
    g = coma.comet_geometry_px(cam, r_mm, w)
    c = sign * 1.2 / 3 / (np.hypot(36, 24) / 2) * r_mm / (36 / w)   # closed form, px
    assert g["centroid"] == pytest.approx(c, rel=1e-12)
    color = np.zeros((h, w, 3), np.float32)
    color[int(cy), x0] = 1.0
    out = Pipeline(cam, stages=["coma"]).run(Frame(color)).color[..., 0].astype(np.float64)
    assert out.sum() == pytest.approx(1.0, abs=3e-3)  # energy: Jacobian-weighted taps (bilinear ripple left)
    ys, xs = np.mgrid[0:h, 0:w]
    m = out / out.sum()
    taps = coma.comet_offsets(fld.vogel_disc(64).astype(np.float64))
    mean_r = taps[:, 1].mean()  # ⟨p_x² + 3 p_y²⟩ = 1 for the continuous pupil
    assert mean_r == pytest.approx(1.0, abs=0.01)
    # centroid: C radially (+x here), none sideways
    assert (m * xs).sum() - x0 == pytest.approx(c * mean_r, abs=0.03 * abs(c) + 0.02)
    assert (m * ys).sum() - cy == pytest.approx(0.0, abs=0.01 * abs(c) + 0.01)  # Vogel taps: ⟨t_s⟩ ≈ 0
    # extent: the tail reaches 3C, the comet is 2C wide (±1 px of bilinear spread)
    lit = out > 1e-6
    span_x = xs[lit] - x0
    tip = span_x.max() if sign > 0 else -span_x.min()
    assert abs(tip - g["length"] * sign) <= 1.0 and (span_x.min() >= -1 if sign > 0 else span_x.max() <= 1)
    assert abs((ys[lit].max() - ys[lit].min()) - g["width"]) <= 2.0


def test_uniform_field_dims_by_the_mean_jacobian_and_huge_coma_is_capped():
    """Linear coma C = k r moves each comet's centroid outward like a magnification: a uniform
    field becomes ⟨J⟩ = ⟨(1 − k t_r)² + k² t_s²⟩ (closed form of the tap Jacobian)."""
    w, h = 45, 31
    frame = Frame(np.full((h, w, 3), 3.0, np.float32))
    cam = Camera(coma_mm=0.9)
    k = 0.9 / 3 / (np.hypot(36, 24) / 2)
    t = coma.comet_offsets(fld.vogel_disc(64).astype(np.float64))
    want = 3.0 * np.mean((1 - k * t[:, 1]) ** 2 + k * k * t[:, 0] ** 2)
    out = Pipeline(cam, stages=["coma"]).run(frame).color
    inner = out[8:-8, 8:-8]  # away from the border's edge-continued padding
    np.testing.assert_allclose(inner, want, rtol=2e-5)
    np.testing.assert_allclose(Pipeline(Camera(coma_mm=1e-9), stages=["coma"]).run(frame).color, 3.0, rtol=1e-6)
    for big in (1e6, -1e6):
        out = Pipeline(Camera(coma_mm=big), stages=["coma"]).run(frame).color
        assert np.all(np.isfinite(out)) and out.min() >= 0
    c, _, _, _, _ = coma.Coma().c_px(Camera(coma_mm=1e6), w, h)
    assert np.abs(c).max() == pytest.approx(coma.MAX_TAIL_PX / 3)


def test_traced_coma_grows_with_field_and_with_aperture():
    wide = coma.coma_curve(Camera(lens=FLAGSHIP, f_number=1.4))
    f4 = coma.coma_curve(Camera(lens=FLAGSHIP, f_number=4.0))
    r = np.linspace(0.0, 19.0, 20)
    cw = wide(r)
    assert cw[0] == 0.0 and np.all(np.diff(cw) > 0)
    assert abs(f4(19.0)) < 0.25 * abs(cw[-1])  # Seidel coma ∝ aperture²: (4/1.4)² ≈ 8
    g = coma.comet_geometry_px(Camera(lens=FLAGSHIP, f_number=1.4), 16.5, 1280)
    assert 2.0 < g["length"] <= coma.MAX_TAIL_PX  # a visible comet in the corners wide open


def test_bad_coefficient():
    with pytest.raises(InputError, match="coma_mm"):
        Camera(coma_mm=float("inf"))


def test_tile_windows_hold_the_per_pixel_comet():
    """The kernel reads each tap from a 3 × 3 window placed by the tile centre's comet; it is exact
    while the pixel's own landing point stays within ½ px of the tile's (Coma.shape_error_px)."""
    cam = Camera(lens=FLAGSHIP, f_number=1.4, focus_distance_m=3.0)
    for w, h in ((1280, 720), (1920, 1080)):
        err, where = coma.Coma().shape_error_px(cam, w, h)
        assert 0.0 < err < 0.5, (w, h, err, where)
    err, where = coma.Coma().shape_error_px(Camera(coma_mm=1.2), 301, 201)  # the point-source test's
    assert err < 0.5, (err, where)


def test_uniform_tiles_bound_the_per_pixel_landing_points():
    """Tiles whose landing points stay within UNIFORM_PX of the tile centre's take the tile's
    comet (the fast kernel); the bound holds against the per-pixel landing points
    (shape_error_px over those tiles), and the benchmark's coma uses it everywhere."""
    st = coma.Coma("draft")
    # a linear coma is an affine comet field: every tile deviates alike (all or none uniform)
    assert st.tile_uniform(Camera(coma_mm=0.1), 133, 77).all()
    assert not st.tile_uniform(Camera(coma_mm=-0.15), 131, 85).any()
    for cam, w, h in ((Camera(coma_mm=0.1), 133, 77), (Camera(coma_mm=0.087), 1280, 720)):
        uni = st.tile_uniform(cam, w, h)
        c, _, _, ex, ey = st.c_px(cam, w, h)
        t = fld.per_pixel(st.tile_axes_px(cam, w, h), w, h)
        mask = fld.per_pixel(uni, w, h)
        worst = 0.0
        for ts, tr in coma.comet_offsets(fld.vogel_disc(st.uniform_taps).astype(np.float64)):
            d = np.hypot(c * (ts * ey - tr * ex) - (t[..., 0] * ts + t[..., 2] * tr),
                         c * (-ts * ex - tr * ey) - (t[..., 1] * ts + t[..., 3] * tr))
            worst = max(worst, float(d[mask].max()))
        assert worst <= coma.UNIFORM_PX, (w, h, worst)
    assert st.tile_uniform(Camera(coma_mm=0.087), 1920, 1080).all()


def test_device_comet_is_recomputed_when_the_camera_changes(rng):
    """The per-pixel comet stays on the device between frames (it depends on the camera and the
    size only): a new coefficient or frame size must not reuse it."""
    frame = Frame(odd_frame(rng, w=67, h=45, scale=10.0).color)
    pipe = Pipeline(Camera(coma_mm=0.9), stages=["coma"])
    for cam, f in ((Camera(coma_mm=0.9), frame), (Camera(coma_mm=-2.0), frame),
                   (Camera(coma_mm=-2.0), Frame(odd_frame(rng, w=45, h=67, scale=10.0).color))):
        pipe.camera = cam
        assert_planned(pipe, f, "coma")
        out, ref = pipe.run(f).color, pipe.reference(f)
        assert np.abs(out - ref).max() < 2e-3 * np.abs(ref).max(), cam.coma_mm


def _apply_stencils(st, cam, color):
    """float64 numpy application of Coma.uniform_stencils (what coma_s<S> computes)."""
    h, w = color.shape[:2]
    _, dc, q, _, _ = st.c_px(cam, w, h)
    a, b = dc + q, dc * q
    ntx, _ = fld.tiles(w, h)
    out = np.full_like(color, np.nan)
    for size, _, ids, dx, dy, wts in st.uniform_stencils(cam, w, h):
        assert size in coma.STENCIL_SIZES and dx.shape == (ids.size, size) and wts.shape == (ids.size, size, 4)
        for t, sx, sy, sw in zip(ids, dx, dy, wts):
            x0, y0 = (t % ntx) * fld.TILE_W, (t // ntx) * fld.TILE_H
            ys, xs = np.mgrid[y0:min(y0 + fld.TILE_H, h), x0:min(x0 + fld.TILE_W, w)].astype(np.float64)
            blk = (slice(y0, y0 + fld.TILE_H), slice(x0, x0 + fld.TILE_W))
            acc = 0.0
            for ox, oy, (w0, w1, w2, w3) in zip(sx, sy, sw):
                assert w3 == 0.0
                acc = acc + (w0 - a[blk] * w1 + b[blk] * w2)[..., None] * fld.bilinear_padded(color, xs + ox, ys + oy)
            out[blk] = acc
    return out


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_uniform_stencils_regroup_the_taps_exactly(rng, quality):
    """The uniform tiles' stencils (taps merged per integer offset, the Jacobian through three
    tap moments, or folded into W0 where the tile has one) give the reference's tap-by-tap sum to
    float64 rounding, with per-pixel Jacobians (traced lens) and folded ones (linear coma); a
    folded W0 sums to the mean Jacobian; at most 4N offsets, and short comets need few."""
    st = coma.Coma(quality)
    for cam, w, h in ((Camera(coma_mm=0.1), 133, 77), (Camera(lens=FLAGSHIP, f_number=2.0), 160, 90)):
        uni = st.tile_uniform(cam, w, h)
        const = st.tile_jacobian(cam, w, h)[2]
        assert uni.all() and const.all() if cam.coma_mm else uni.any() and not const[uni].any()
        color = rng.uniform(0.0, 10.0, (h, w, 3))
        color[5, 7] = 1e8
        assert_stage_runs(st, cam, Frame(color.astype(np.float32)))
        ref = st.reference(cam, Frame(color.astype(np.float32)), color)
        mask = fld.per_pixel(uni, w, h)[..., None]
        got = np.where(mask, _apply_stencils(st, cam, color), ref)  # the window tiles are not stencils
        err = np.abs(got - ref) / np.maximum(np.abs(ref), 1.0)
        j = np.unravel_index(int(np.argmax(err)), err.shape)
        assert err.max() < 1e-9, f"max rel error {err.max():.3g} at (x={j[1]}, y={j[0]}, c={j[2]})"
    sizes = {}
    for size, const, ids, dx, dy, wts in st.uniform_stencils(Camera(coma_mm=0.087), 640, 360):
        assert const  # a linear coefficient: one Jacobian per tile (a = 2k, b = k²), folded into W0
        k = 0.087 / 3 / (np.hypot(36, 24) / 2)
        t = coma.comet_offsets(fld.vogel_disc(st.uniform_taps).astype(np.float64))
        mean_jac = np.mean(1 - 2 * k * t[:, 1] + k * k * (t * t).sum(1))
        np.testing.assert_allclose(wts[..., 0].sum(1), mean_jac, rtol=1e-12)
        n_used = (wts[..., 0] > 0).sum(1)
        assert n_used.max() <= min(size, 4 * st.uniform_taps)
        sizes[size] = ids.size
    # the benchmark's comets (<= 1.5 px at 640 px wide) need at most 16 offsets, whatever N
    assert max(sizes) <= 16 and min(sizes) == 4, sizes


def test_uniform_tiles_never_clamp_the_jacobian():
    """The stencil is exact only where no tap's Jacobian reaches its clamp at 0: on every tile
    tile_uniform accepts, the unclamped J of every tap and pixel is >= 0 (steep coefficients and
    the traced lens; a huge coma is capped and takes the window kernel)."""
    for cam, w, h in ((Camera(coma_mm=0.1), 133, 77), (Camera(coma_mm=-40.0), 23, 37),
                      (Camera(coma_mm=3.0), 61, 41), (Camera(lens=FLAGSHIP, f_number=2.0), 320, 180)):
        st = coma.Coma("final")
        uni = fld.per_pixel(st.tile_uniform(cam, w, h), w, h)
        _, dc, q, _, _ = st.c_px(cam, w, h)
        for ts, tr in coma.comet_offsets(fld.vogel_disc(st.taps).astype(np.float64)):
            jac = (1.0 - dc * tr) * (1.0 - q * tr) + q * dc * ts * ts
            assert jac[uni].min(initial=1.0) >= 0.0, (cam.coma_mm, w, h)
    assert not coma.Coma("final").tile_uniform(Camera(coma_mm=-40.0), 23, 37).any()


def test_inner_tiles_read_the_source_and_the_pad_fills_only_the_ring(rng):
    """Uniform tiles whose reads stay inside the frame read the source; coma_pad then leaves the
    padded copy's inside unwritten (stale from the previous frame): a second, different frame
    must still match the reference everywhere (odd size, so partial tiles border the ring)."""
    w, h = 197, 121
    st = coma.Coma("final")
    cam = Camera(coma_mm=0.1)
    inner = st.inner_tiles(w, h)
    assert st.tile_uniform(cam, w, h).all() and 0.2 < inner.mean() < 0.8
    pipe = Pipeline(cam, stages=["coma"])
    for scale in (1e4, 3.0):  # a bright frame first: stale values would show in the second
        frame = Frame(odd_frame(rng, w=w, h=h, scale=scale).color)
        assert_planned(pipe, frame, "coma")
        out, ref = pipe.run(frame).color, pipe.reference(frame)
        err = np.abs(out - ref) / np.maximum(np.abs(ref), 1.0)
        j = np.unravel_index(int(np.argmax(err)), err.shape)
        assert err.max() < 2e-4, f"max rel error {err.max():.3g} at (x={j[1]}, y={j[0]}, c={j[2]})"


def test_program_has_one_stencil_kernel_pair_per_stencil_size():
    """The kernel list is generated from STENCIL_SIZES: every size the planner can pick builds."""
    from clpost.runtime import get_runtime
    from clpost.stages.coma import Coma
    from clpost.stages.coma import STENCIL_SIZES
    from clpost.stages.coma_cl import program_source

    st = Coma("draft")
    rt = get_runtime()
    prog = rt.program(program_source(st.taps), "coma", {**st.defines(Camera(coma_mm=0.01)), "COMA_WHOLE_TILES": 0})
    names = {k.function_name for k in prog.all_kernels()}
    want = {f"coma_{kind}{s}" for kind in "sc" for s in STENCIL_SIZES} | {"coma", "coma_pad", "coma_shape"}
    assert want <= names


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_huge_finite_colour_stays_finite(rng, quality):
    """A frame × 2^119 (values up to ~1e37, a hot pixel at 3.3e38; FLT_MAX = 3.4e38): the window
    gather scales each tap's weight by 1/COMA_TAPS instead of the sum at the end, where 64 taps of
    ~1e37 overflowed to inf (430 pixels of this frame at final on main). Power-of-two scaling is
    exact: the output is the unscaled frame's, scaled."""
    w, h = 161, 91
    color = odd_frame(rng, w=w, h=h, scale=10.0).color.copy()
    color[40, 100] = 500.0
    k = 2.0 ** 119
    assert 3e38 < color.max() * k < np.finfo(np.float32).max
    pipe = Pipeline(Camera(coma_mm=1.2), stages=["coma"], quality=quality)
    small = pipe.run(Frame(color)).color
    huge = pipe.run(Frame(color * np.float32(k))).color
    assert np.isfinite(huge).all(), np.argwhere(~np.isfinite(huge))[:3]
    np.testing.assert_allclose(huge, small.astype(np.float64) * k, rtol=1e-6, atol=0)

"""lateral_color: wavelengths from colour-science, partial dispersion, kernel vs reference,
closed-form fringe of a point, flux per channel, planning."""
import numpy as np
import pytest

from clpost import Camera, Frame, InputError, Pipeline
from clpost.optics.prescription import LAMBDA_C_NM, LAMBDA_D_NM, LAMBDA_F_NM
from clpost.stages import _field as fld
from clpost.stages import lateral_color as lc

from conftest import assert_planned, odd_frame

FLAGSHIP = "zeiss-planar-50-f1.4"


def test_channel_wavelengths_and_partial_dispersion():
    assert lc.channel_wavelengths_nm() == (611.0, 549.0, 464.0)  # Rec.709 primaries from D65
    p = lc.partial_dispersion([LAMBDA_F_NM, LAMBDA_D_NM, LAMBDA_C_NM])
    assert p[1] == 0.0 and p[0] - p[2] == pytest.approx(1.0, rel=1e-12)
    assert p[0] == pytest.approx(0.699, abs=0.002)  # P_F,d of normal glass (N-BK7: 0.6923)


def test_not_planned_without_lateral_color_and_identity_when_skipped(rng):
    frame = odd_frame(rng)
    for cam in (Camera(), Camera(lateral_color_mm=0.0), Camera(lens=FLAGSHIP, lateral_color_mm=0.0)):
        pipe = Pipeline(cam, stages=["lateral_color"])
        assert pipe.plan(frame) == []
        assert np.array_equal(pipe.run(frame).color, frame.color)
    assert "lateral_color" in Pipeline(Camera(lens=FLAGSHIP, f_number=1.4)).plan(frame)


@pytest.mark.parametrize("w,h,kw", [(37, 23, dict(lateral_color_mm=0.5)), (23, 37, dict(lateral_color_mm=-30.0)),
                                    (41, 29, dict(lens=FLAGSHIP, f_number=1.4)),
                                    (133, 77, dict(lateral_color_mm=0.5)), (131, 83, dict(lateral_color_mm=-0.9))])
def test_kernel_matches_reference(rng, w, h, kw):
    frame = odd_frame(rng, w=w, h=h, scale=10.0)
    pipe = Pipeline(Camera(**kw), stages=["lateral_color"])
    assert_planned(pipe, frame, "lateral_color")
    out = pipe.run(frame).color
    ref = pipe.reference(frame)
    err = np.abs(out - ref)
    j = np.unravel_index(int(np.argmax(err)), err.shape)
    assert err.max() < 1e-3, f"max abs error {err.max():.3g} (values 0–10) at (x={j[1]}, y={j[0]}, c={j[2]})"
    assert np.all(np.isfinite(out)) and out.dtype == np.float32


def test_point_fringe_matches_closed_form_and_flux_is_conserved():
    w, h = 301, 201
    cam = Camera(lateral_color_mm=0.3)
    cx, cy = (w - 1) / 2, (h - 1) / 2
    x0 = 240.0
    r_mm = (x0 - cx) * fld.pitch_mm(cam, w)
    want = lc.fringe_px(cam, r_mm, w)
    # closed form: P_c · L(r) / pitch with L linear to the corner
    p = lc.partial_dispersion(lc.channel_wavelengths_nm())
    assert want == pytest.approx(p * 0.3 * r_mm / (np.hypot(36, 24) / 2) / (36 / w), rel=1e-12)
    ys, xs = np.mgrid[0:h, 0:w]
    spot = np.exp(-((xs - x0) ** 2 + (ys - cy) ** 2) / (2 * 1.5 ** 2))
    frame = Frame(np.repeat(spot[..., None], 3, -1).astype(np.float32))
    out = Pipeline(cam, stages=["lateral_color"]).run(frame).color.astype(np.float64)
    for c in range(3):
        m = out[..., c]
        # flux: the Jacobian makes it exact in the continuum; bilinear resampling's partition-of-
        # unity ripple leaves ≤ |1 − r/ρ|/4 (0.3 % for blue here, 1e-5 for real lenses)
        assert m.sum() == pytest.approx(spot.sum(), rel=0.004)
        shift = (m * xs).sum() / m.sum() - x0
        assert shift == pytest.approx(want[c], abs=0.02), (c, shift, want[c])
        assert (m * ys).sum() / m.sum() == pytest.approx(cy, abs=1e-3)
    assert want[2] - want[0] > 1.0  # a visible fringe: blue outside red by > 1 px


def test_flagship_fringe_is_sub_pixel_at_1280():
    cam = Camera(lens=FLAGSHIP, f_number=1.4)
    f = lc.fringe_px(cam, 16.5, 1280)
    assert 0.1 < abs(f[2] - f[0]) < 1.0  # a well-corrected Planar: ~0.26 px of R–B at 16.5 mm
    assert np.all(lc.fringe_px(cam, 0.0, 1280) == 0.0)


def test_bad_coefficient():
    with pytest.raises(InputError, match="lateral_color_mm"):
        Camera(lateral_color_mm=float("nan"))


def test_tile_model_matches_the_exact_map_and_most_tiles_are_fast():
    """The per-tile affine model (the vectorised path) against the exact per-pixel map: a linear L
    is a pure scale (affine to rounding); a traced lens within the tolerances at 1080p."""
    st = lc.LateralColor()
    for cam, w, h in ((Camera(lateral_color_mm=0.007), 960, 540), (Camera(lens=FLAGSHIP, f_number=1.4), 960, 540),
                      (Camera(lateral_color_mm=0.5), 133, 77)):
        pos, jac, where = st.model_error_px(cam, w, h)
        assert pos <= 2 * lc.AFFINE_TOL_PX, (pos, where)
        assert jac <= 2 * lc.AFFINE_TOL_JAC, (jac, where)
    for cam, w, h, fast_min in ((Camera(lateral_color_mm=0.007), 1920, 1080, 0.95),
                                (Camera(lens=FLAGSHIP, f_number=1.4), 1920, 1080, 0.9),
                                (Camera(lateral_color_mm=0.5), 133, 77, 0.3)):
        assert st.tile_plan(cam, w, h)["fast"].mean() >= fast_min
    # strong lateral colour: no tile fits one bilinear cell, all take the per-pixel map
    assert not st.tile_plan(Camera(lateral_color_mm=-30.0), 64, 48)["fast"].any()


def test_hdr_points_and_lines_leave_no_dark_ring():
    """HDR-safe resampling (issue 16): lateral colour resamples bilinearly (weights ≥ 0 on the
    2×2 cell), so HDR spots and one-pixel lines on a dim background never pull a pixel below what
    the background alone gives there (the channel's Jacobian included), and each channel keeps its
    flux."""
    w, h = 161, 121
    rng = np.random.default_rng(16)
    img = np.full((h, w), 0.1)
    for _ in range(12):
        img[rng.integers(10, h - 10), rng.integers(10, w - 10)] = 1e3
    img[h // 4, 10:w - 10] = img[10:h - 10, w // 4] = 1e3  # lines stopping short of the edges: all flux stays
    pipe = Pipeline(Camera(lateral_color_mm=0.6), stages=["lateral_color"])
    out = pipe.run(Frame(np.repeat(img[..., None], 3, -1).astype(np.float32))).color.astype(np.float64)
    floor = pipe.run(Frame(np.full((h, w, 3), 0.1, np.float32))).color.astype(np.float64)
    assert np.all(out >= floor * (1 - 1e-5)), float((floor - out).max())
    for c in range(3):
        assert out[..., c].sum() == pytest.approx(floor[..., c].sum() + (img - 0.1).sum(), rel=0.01)

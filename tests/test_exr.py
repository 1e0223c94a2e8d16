"""EXR I/O: round trips per layout, files written the way each tool writes them, windows, errors."""
from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import OpenEXR
import pytest

from clpost import exr
from clpost.errors import InputError, OutputError
from clpost.frame import Frame

H, W = 6, 9
FOCAL_PX = 12.0


def _win(x0: int, y0: int, x1: int, y1: int) -> tuple[np.ndarray, np.ndarray]:
    return np.array([x0, y0], dtype=np.int32), np.array([x1, y1], dtype=np.int32)


def _write_raw(path: Path, channels: dict, **header) -> Path:
    """A single-part file written straight through the bindings, not through clpost."""
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, **header},
                 channels).write(str(path))
    return path


def _frame(alpha: bool = True, depth: bool = True, velocity: bool = True) -> Frame:
    rng = np.random.default_rng(7)
    color = rng.uniform(0, 4, (H, W, 3)).astype(np.float32)
    d = rng.uniform(0.3, 50, (H, W)).astype(np.float32)
    d[0, :3] = np.inf
    d[-1, -1] = np.inf
    v = rng.uniform(-20, 20, (H, W, 2)).astype(np.float32)
    return Frame(color=color,
                 depth=d if depth else None,
                 velocity=v if velocity else None,
                 alpha=rng.uniform(0, 1, (H, W)).astype(np.float32) if alpha else None)


# ---------------------------------------------------------------------------------------------
# Round trips
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("half", [False, True], ids=["float", "half"])
@pytest.mark.parametrize("layout", exr.LAYOUTS)
def test_round_trip_every_layout(tmp_path, layout, half):
    src = _frame()
    path = tmp_path / f"rt_{layout}.exr"
    exr.write_frame(path, src, {"clpost.lens": "thin:50"}, half=half, layout=layout, focal_px=FOCAL_PX)
    got = exr.read_frame(path, focal_px=FOCAL_PX)

    assert got.metadata["layout"] == layout  # auto-detected
    assert got.metadata["path"] == str(path)
    assert got.metadata["header"]["clpost.lens"] == "thin:50"
    assert got.metadata["depth_kind"] == "planar"
    for buf in (got.color, got.alpha, got.depth, got.velocity):
        assert buf.dtype == np.float32
    tol = dict(rtol=1e-3, atol=1e-3) if half else dict(rtol=0, atol=0)
    np.testing.assert_allclose(got.color, src.color, **tol)
    np.testing.assert_allclose(got.alpha, src.alpha, **tol)
    np.testing.assert_allclose(got.velocity, src.velocity, rtol=1e-3 if half else 0, atol=1e-2 if half else 0)
    # Depth is float32 even in half files; 1/z (nuke) and radial (arnold) cost an ulp or two.
    assert np.array_equal(np.isinf(got.depth), np.isinf(src.depth))
    fin = np.isfinite(src.depth)
    np.testing.assert_allclose(got.depth[fin], src.depth[fin], rtol=1e-6, atol=0)


def test_half_file_keeps_depth_float_and_inf(tmp_path):
    path = tmp_path / "half.exr"
    exr.write_frame(path, _frame(), half=True)
    f = OpenEXR.File(str(path), separate_channels=True)
    types = {n: c.type() for n, c in f.channels().items()}
    assert types["R"] == OpenEXR.HALF and types["velocity.X"] == OpenEXR.HALF
    assert types["Z"] == OpenEXR.FLOAT
    assert f.header()["compression"] == OpenEXR.ZIP_COMPRESSION
    assert np.isinf(exr.read_frame(path).depth[0, 0])


def test_half_depth_written_by_another_tool_is_read(tmp_path):
    z = np.full((H, W), 2.5, np.float16)
    z[1, 1] = np.inf
    c = np.ones((H, W), np.float16)
    path = _write_raw(tmp_path / "hz.exr", {"R": c, "G": c, "B": c, "Z": z})
    got = exr.read_frame(path)
    assert got.depth.dtype == np.float32 and np.isinf(got.depth[1, 1]) and got.depth[0, 0] == 2.5


def test_optional_buffers_absent(tmp_path):
    path = tmp_path / "rgb.exr"
    exr.write_frame(path, _frame(alpha=False, depth=False, velocity=False))
    assert set(OpenEXR.File(str(path), separate_channels=True).channels()) == {"R", "G", "B"}
    got = exr.read_frame(path)
    assert got.alpha is None and got.depth is None and got.velocity is None


# ---------------------------------------------------------------------------------------------
# Files written the way each tool writes them
# ---------------------------------------------------------------------------------------------

def _blender_file(path: Path, layer: str = "ViewLayer") -> Path:
    """One part per pass, half Combined, float Depth with 1e10 sky, y-up vectors (Blender 5.x)."""
    rgba = {f"{layer}.Combined.{c}": np.full((H, W), v, np.float16) for c, v in zip("RGBA", (0.5, 0.25, 0.125, 1.0))}
    depth = np.full((H, W), 4.0, np.float32)
    depth[0, :] = 1e10  # sky
    vec = {f"{layer}.Vector.{c}": np.zeros((H, W), np.float32) for c in "XYZW"}
    # Pixel (x=4, y=2) moves 3 px right and 2 px down per frame. y up: down is −2, so
    # XY = previous − current = (−3, +2) and ZW = current − next = (−3, +2).
    for c, val in zip("XYZW", (-3.0, 2.0, -3.0, 2.0)):
        vec[f"{layer}.Vector.{c}"][2, 4] = val
    head = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    parts = [OpenEXR.Part(dict(head), rgba, f"{layer}.Combined"),
             OpenEXR.Part(dict(head), {f"{layer}.Depth.Z": depth}, f"{layer}.Depth"),
             OpenEXR.Part(dict(head), vec, f"{layer}.Vector")]
    OpenEXR.File(parts).write(str(path))
    return path


@pytest.mark.parametrize("layer", ["ViewLayer", "RenderLayer.001"])
def test_blender_multipart_file_converts_to_our_conventions(tmp_path, layer):
    got = exr.read_frame(_blender_file(tmp_path / "blender.exr", layer))
    assert got.metadata["layout"] == "blender"
    np.testing.assert_array_equal(got.velocity[2, 4], [3.0, 2.0])  # right and down
    assert np.count_nonzero(got.velocity) == 2
    assert np.all(np.isinf(got.depth[0])) and np.all(got.depth[1:] == 4.0)
    np.testing.assert_array_equal(got.color[0, 0], [0.5, 0.25, 0.125])
    assert np.all(got.alpha == 1.0)


def test_blender_backward_pair_only(tmp_path):
    path = _blender_file(tmp_path / "b.exr")
    f = OpenEXR.File(str(path), separate_channels=True)
    vec = {n: c.pixels for n, c in f.parts[2].channels.items() if n.endswith((".X", ".Y"))}
    parts = [f.parts[0], OpenEXR.Part({"type": OpenEXR.scanlineimage}, vec, "ViewLayer.Vector")]
    OpenEXR.File(parts).write(str(tmp_path / "xy.exr"))
    np.testing.assert_array_equal(exr.read_frame(tmp_path / "xy.exr").velocity[2, 4], [3.0, 2.0])


def test_blender_writer_writes_like_blender(tmp_path):
    v = np.zeros((H, W, 2), np.float32)
    v[2, 4] = (3.0, 2.0)
    d = np.full((H, W), 4.0, np.float32)
    d[0] = np.inf
    exr.write_frame(tmp_path / "w.exr", Frame(np.ones((H, W, 3), np.float32), d, v), layout="blender")
    f = OpenEXR.File(str(tmp_path / "w.exr"), separate_channels=True)
    assert [p.name() for p in f.parts] == ["ViewLayer.Combined", "ViewLayer.Depth", "ViewLayer.Vector"]
    assert set(f.parts[0].channels) == {f"ViewLayer.Combined.{c}" for c in "RGBA"}
    assert np.all(f.parts[0].channels["ViewLayer.Combined.A"].pixels == 1.0)  # no alpha → opaque
    z = f.parts[1].channels["ViewLayer.Depth.Z"].pixels
    assert z.dtype == np.float32 and np.all(z[0] == 1e10) and np.all(z[1:] == 4.0)
    vec = {n.rsplit(".", 1)[1]: c.pixels[2, 4] for n, c in f.parts[2].channels.items()}
    assert vec == {"X": -3.0, "Y": 2.0, "Z": -3.0, "W": 2.0}


def test_nuke_file_conventions(tmp_path):
    c = np.ones((H, W), np.float32)
    inv = np.full((H, W), 0.25, np.float32)  # 1/z: z = 4 m
    inv[0, 0] = 0.0  # no hit
    fu, fv = np.zeros((H, W), np.float32), np.zeros((H, W), np.float32)
    fu[2, 4], fv[2, 4] = 3.0, -2.0  # right 3, down 2 in Nuke's y-up space
    path = _write_raw(tmp_path / "nuke.exr", {"R": c, "G": c, "B": c, "depth.Z": inv, "forward.u": fu, "forward.v": fv})
    got = exr.read_frame(path)
    assert got.metadata["layout"] == "nuke"
    assert np.isinf(got.depth[0, 0]) and got.depth[1, 1] == 4.0
    np.testing.assert_array_equal(got.velocity[2, 4], [3.0, 2.0])
    # A depth.Z holding metres (not 1/z) is read with the override.
    metres = _write_raw(tmp_path / "nuke_m.exr", {"R": c, "G": c, "B": c, "depth.Z": np.full((H, W), 0.25, np.float32)})
    assert np.all(exr.read_frame(metres, depth="planar").depth == 0.25)


def test_nuke_backward_vectors_are_negated(tmp_path):
    c = np.ones((H, W), np.float32)
    bu, bv = np.zeros((H, W), np.float32), np.zeros((H, W), np.float32)
    bu[2, 4], bv[2, 4] = -3.0, 2.0  # to the previous frame: left 3, up 2 (y up)
    path = _write_raw(tmp_path / "nb.exr", {"R": c, "G": c, "B": c, "backward.u": bu, "backward.v": bv})
    got = exr.read_frame(path)
    assert got.metadata["layout"] == "nuke"
    np.testing.assert_array_equal(got.velocity[2, 4], [3.0, 2.0])


def test_arnold_file_conventions(tmp_path):
    c = np.ones((H, W), np.float32)
    planar = np.full((H, W), 5.0, np.float32)
    radial = exr.planar_to_radial(planar, FOCAL_PX)
    assert radial[0, 0] > 5.0 and radial.min() >= 5.0
    mr, mg = np.zeros((H, W), np.float32), np.zeros((H, W), np.float32)
    mr[2, 4], mg[2, 4] = 3.0, -2.0
    path = _write_raw(tmp_path / "arnold.exr",
                      {"R": c, "G": c, "B": c, "Z": radial, "motionvector.R": mr, "motionvector.G": mg,
                       "motionvector.B": np.zeros_like(mr)})
    got = exr.read_frame(path, focal_px=FOCAL_PX)
    assert got.metadata["layout"] == "arnold" and got.metadata["depth_kind"] == "planar"
    np.testing.assert_allclose(got.depth, 5.0, rtol=1e-6)
    np.testing.assert_array_equal(got.velocity[2, 4], [3.0, 2.0])
    # Unverified conventions can be overridden, and without a focal length the reader says so.
    assert exr.read_frame(path, focal_px=FOCAL_PX, velocity_y_up=False).velocity[2, 4, 1] == -2.0
    with pytest.warns(exr.DepthConventionWarning, match="arnold.exr.*radial.*focal_px"):
        raw = exr.read_frame(path)
    assert raw.metadata["depth_kind"] == "radial"
    np.testing.assert_array_equal(raw.depth, radial)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert exr.read_frame(path, depth="planar").metadata["depth_kind"] == "planar"


def test_radial_planar_inverse_and_centre():
    d = np.full((5, 7), 2.0, np.float32)
    r = exr.planar_to_radial(d, (10.0, 20.0))
    assert r[2, 3] == 2.0  # principal point at the centre pixel of an odd image
    np.testing.assert_allclose(r[2, 0], 2.0 * np.hypot(1, 3 / 10), rtol=1e-6)
    np.testing.assert_allclose(exr.radial_to_planar(r, (10.0, 20.0)), d, rtol=1e-6)
    with pytest.raises(InputError, match="focal_px"):
        exr.radial_to_planar(d, 0.0)


# ---------------------------------------------------------------------------------------------
# Layout detection
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("names, layout", [
    (["R", "G", "B"], "clpost"),
    (["R", "G", "B", "A", "Z", "velocity.X", "velocity.Y"], "clpost"),
    (["ViewLayer.Combined.R", "ViewLayer.Combined.G", "ViewLayer.Combined.B", "ViewLayer.Depth.Z"], "blender"),
    (["Shot.Combined.R", "Shot.Combined.G", "Shot.Combined.B"], "blender"),
    (["R", "G", "B", "depth.Z"], "nuke"),
    (["R", "G", "B", "forward.u", "forward.v"], "nuke"),
    (["R", "G", "B", "Z", "motionvector.R", "motionvector.G", "motionvector.B"], "arnold"),
])
def test_detect_layout(names, layout):
    assert exr.detect_layout(names) == layout


def test_detect_layout_names_the_channels_found():
    with pytest.raises(InputError, match=r"Y, depth\.Z") as e:
        exr.detect_layout(["Y", "depth.Z"])
    assert "clpost" in str(e.value) and "\n" not in str(e.value)


def test_explicit_layout_overrides_detection(tmp_path):
    path = tmp_path / "plain.exr"
    exr.write_frame(path, _frame(velocity=False))
    with pytest.warns(exr.DepthConventionWarning):
        assert exr.read_frame(path, layout="arnold").metadata["layout"] == "arnold"
    with pytest.raises(InputError, match=r"plain\.exr.*'blender'.*ViewLayer\.Combined\.R"):
        exr.read_frame(path, layout="blender")
    with pytest.raises(InputError, match="unknown.*clpost, blender, nuke, arnold"):
        exr.read_frame(path, layout="maya")


# ---------------------------------------------------------------------------------------------
# Windows
# ---------------------------------------------------------------------------------------------

def test_data_window_inside_display_window_is_padded(tmp_path):
    h, w = 3, 4  # data window (2,1)-(5,3) inside display (0,0)-(7,5)
    c = np.full((h, w), 0.5, np.float32)
    z = np.full((h, w), 3.0, np.float32)
    vx = np.full((h, w), 1.5, np.float32)
    path = _write_raw(tmp_path / "dw.exr", {"R": c, "G": c, "B": c, "Z": z, "velocity.X": vx, "velocity.Y": vx},
                      dataWindow=_win(2, 1, 5, 3), displayWindow=_win(0, 0, 7, 5))
    got = exr.read_frame(path)
    assert got.size == (8, 6)
    inside = np.zeros((6, 8), bool)
    inside[1:4, 2:6] = True
    assert np.all(got.color[inside] == 0.5) and np.all(got.color[~inside] == 0)
    assert np.all(got.alpha[inside] == 1) and np.all(got.alpha[~inside] == 0)
    assert np.all(got.depth[inside] == 3.0) and np.all(np.isinf(got.depth[~inside]))
    assert np.all(got.velocity[inside] == 1.5) and np.all(got.velocity[~inside] == 0)


def test_display_window_with_offset_origin(tmp_path):
    c = np.arange(12, dtype=np.float32).reshape(3, 4)
    path = _write_raw(tmp_path / "off.exr", {"R": c, "G": c, "B": c, "A": np.ones_like(c)},
                      dataWindow=_win(11, 20, 14, 22), displayWindow=_win(10, 20, 15, 23))
    got = exr.read_frame(path)
    assert got.size == (6, 4)
    np.testing.assert_array_equal(got.color[0:3, 1:5, 0], c)
    assert got.alpha[3].sum() == 0 and got.alpha[:, 0].sum() == 0


def test_overscan_is_read_and_written_back(tmp_path):
    # the data window reaches 2 px beyond the display window on the left and top, 2 right, 2 bottom
    c = np.arange(10 * 12, dtype=np.float32).reshape(10, 12)
    path = _write_raw(tmp_path / "overscan.exr", {"R": c, "G": c + 1, "B": c + 2},
                      dataWindow=_win(-2, -2, 9, 7), displayWindow=_win(0, 0, 7, 5))
    got = exr.read_frame(path)
    assert got.size == (12, 10)  # the arrays cover the data window, which holds the display window
    w = got.windows
    assert w.data == ((-2, -2), (9, 7)) and w.display == ((0, 0), (7, 5))
    assert w.display_offset == (2, 2) and w.display_size == (8, 6) and w.overscan == (2, 2, 2, 2)
    np.testing.assert_array_equal(got.color[..., 0], c)
    assert got.alpha is None  # every array pixel has data
    exr.write_frame(tmp_path / "out.exr", got)
    head = exr.read_header(tmp_path / "out.exr")[0]
    assert head.data_window == ((-2, -2), (9, 7)) and head.display_window == ((0, 0), (7, 5))
    np.testing.assert_array_equal(exr.read_frame(tmp_path / "out.exr").color, got.color)


def test_disjoint_windows_keep_both(tmp_path):
    # data window right of the display window, not touching it (the OpenEXR DisplayWindow t09 case)
    c = np.full((3, 4), 0.25, np.float32)
    path = _write_raw(tmp_path / "apart.exr", {"R": c, "G": c, "B": c},
                      dataWindow=_win(6, 0, 9, 2), displayWindow=_win(0, 0, 3, 2))
    got = exr.read_frame(path)
    assert got.size == (10, 3) and got.windows.origin == (0, 0)
    assert np.all(got.color[:, 6:] == 0.25) and np.all(got.color[:, :6] == 0)
    assert np.all(got.alpha[:, 6:] == 1) and np.all(got.alpha[:, :6] == 0)
    exr.write_frame(tmp_path / "out.exr", got)
    head = exr.read_header(tmp_path / "out.exr")[0]
    assert (head.data_window, head.display_window) == (((6, 0), (9, 2)), ((0, 0), (3, 2)))


def test_parts_with_different_data_windows_are_placed(tmp_path):
    # OpenEXR makes parts share the display window; their data windows may differ (each pass's
    # bounding box): each is placed at its own offset, "no data" elsewhere
    head = {"type": OpenEXR.scanlineimage, "displayWindow": _win(0, 0, W - 1, H - 1)}
    c = np.ones((H, W), np.float32)
    parts = [OpenEXR.Part({**head, "dataWindow": _win(0, 0, W - 1, H - 1)}, {"R": c, "G": c, "B": c}, "rgba"),
             OpenEXR.Part({**head, "dataWindow": _win(2, 1, 5, 3)}, {"Z": np.full((3, 4), 2.0, np.float32)}, "depth")]
    OpenEXR.File(parts).write(str(tmp_path / "sizes.exr"))
    got = exr.read_frame(tmp_path / "sizes.exr")
    assert got.size == (W, H)
    inside = np.zeros((H, W), bool)
    inside[1:4, 2:6] = True
    assert np.all(got.depth[inside] == 2.0) and np.all(np.isinf(got.depth[~inside]))


# ---------------------------------------------------------------------------------------------
# Errors
# ---------------------------------------------------------------------------------------------

def test_missing_file(tmp_path):
    with pytest.raises(InputError, match=r"nope\.exr: no such file"):
        exr.read_frame(tmp_path / "nope.exr")


def test_not_an_exr(tmp_path):
    (tmp_path / "text.exr").write_text("hello")
    with pytest.raises(InputError, match=r"text\.exr: not an OpenEXR file"):
        exr.read_frame(tmp_path / "text.exr")


@pytest.mark.parametrize("keep", [0.1, 0.5, 0.9])
def test_truncated_file(tmp_path, keep):
    rng = np.random.default_rng(1)
    c = rng.random((64, 64)).astype(np.float32)  # random data: ZIP cannot shrink it to one chunk
    good = _write_raw(tmp_path / "good.exr", {"R": c, "G": c, "B": c})
    data = good.read_bytes()
    bad = tmp_path / "trunc.exr"
    bad.write_bytes(data[:int(len(data) * keep)])
    with pytest.raises(InputError, match=r"trunc\.exr.*(corrupt|truncated)"):
        exr.read_frame(bad)


def test_missing_color_channel(tmp_path):
    c = np.ones((H, W), np.float32)
    path = _write_raw(tmp_path / "rg.exr", {"R": c, "G": c, "Z": c})
    with pytest.raises(InputError, match=r"rg\.exr.*needs color channels R, G, B; missing B"):
        exr.read_frame(path, layout="clpost")
    with pytest.raises(InputError, match=r"rg\.exr.*no known channel layout.*G, R, Z"):
        exr.read_frame(path)


def test_partial_velocity_is_refused(tmp_path):
    c = np.ones((H, W), np.float32)
    path = _write_raw(tmp_path / "v.exr", {"R": c, "G": c, "B": c, "velocity.X": c})
    with pytest.raises(InputError, match=r"v\.exr.*velocity.*missing velocity\.Y"):
        exr.read_frame(path)


def test_integer_color_is_refused(tmp_path):
    c = np.ones((H, W), np.float32)
    path = _write_raw(tmp_path / "u.exr", {"R": np.ones((H, W), np.uint32), "G": c, "B": c})
    with pytest.raises(InputError, match=r"u\.exr.*'R'.*integer"):
        exr.read_frame(path)


def test_invalid_pixels_name_the_file(tmp_path):
    c = np.ones((H, W), np.float32)
    c[1, 2] = np.nan
    path = _write_raw(tmp_path / "nan.exr", {"R": c, "G": c, "B": c})
    with pytest.raises(InputError, match=r"nan\.exr.*NaN.*x=2, y=1"):
        exr.read_frame(path)


def test_alpha_filter_overshoot_is_clipped_but_garbage_is_not(tmp_path):
    c = np.ones((H, W), np.float32)
    a = np.ones((H, W), np.float32)
    a[0, 0] = 1.0004
    exr.read_frame(_write_raw(tmp_path / "a1.exr", {"R": c, "G": c, "B": c, "A": a}))
    a[0, 0] = 1.5
    with pytest.raises(InputError, match=r"a2\.exr.*alpha"):
        exr.read_frame(_write_raw(tmp_path / "a2.exr", {"R": c, "G": c, "B": c, "A": a}))


def test_write_header_and_half_errors(tmp_path):
    f = _frame()
    with pytest.raises(InputError, match=r"h\.exr.*'compression'.*managed by OpenEXR"):
        exr.write_frame(tmp_path / "h.exr", f, {"compression": "none"})
    with pytest.raises(InputError, match=r"h\.exr.*'clpost.f'.*str"):
        exr.write_frame(tmp_path / "h.exr", f, {"clpost.f": 2.0})
    hot = f.replace(color=np.full((H, W, 3), 1e6, np.float32))
    with pytest.raises(InputError, match=r"h\.exr.*color.*float16.*half=False"):
        exr.write_frame(tmp_path / "h.exr", hot, half=True)
    assert list(tmp_path.iterdir()) == []
    exr.write_frame(tmp_path / "new_dir" / "h.exr", f)  # output directories are created
    assert [p.name for p in (tmp_path / "new_dir").iterdir()] == ["h.exr"]


# ---------------------------------------------------------------------------------------------
# Atomic writes
# ---------------------------------------------------------------------------------------------

def test_write_is_atomic_on_failure(tmp_path, monkeypatch):
    path = tmp_path / "out.exr"
    exr.write_frame(path, _frame())
    before = path.read_bytes()

    def half_written_then_fail(exr_file, tmp):
        Path(tmp).write_bytes(b"\x76\x2f\x31\x01 partial")
        raise RuntimeError("disk full")

    monkeypatch.setattr(exr.io, "_write_exr", half_written_then_fail)
    with pytest.raises(OutputError, match=r"out\.exr: cannot write EXR \(disk full\)"):
        exr.write_frame(path, _frame(alpha=False))
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.exr"]


def test_write_is_atomic_on_interrupt(tmp_path, monkeypatch):
    def interrupted(exr_file, tmp):
        raise KeyboardInterrupt

    monkeypatch.setattr(exr.io, "_write_exr", interrupted)
    with pytest.raises(KeyboardInterrupt):
        exr.write_frame(tmp_path / "out.exr", _frame())
    assert list(tmp_path.iterdir()) == []


def test_write_replaces_existing_file_and_respects_umask(tmp_path):
    path = tmp_path / "out.exr"
    exr.write_frame(path, _frame())
    exr.write_frame(path, _frame(velocity=False))
    assert exr.read_frame(path).velocity is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.exr"]
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask


# ---------------------------------------------------------------------------------------------
# info
# ---------------------------------------------------------------------------------------------

def test_info_numbers(tmp_path):
    d = np.full((H, W), 2.0, np.float32)
    d[0, 0], d[1, 1], d[2, 2] = 0.5, 9.0, np.inf
    v = np.zeros((H, W, 2), np.float32)
    v[3, 3] = (3.0, -4.0)
    v[4, 4] = (-1.0, 2.0)
    path = tmp_path / "info.exr"
    exr.write_frame(path, Frame(np.ones((H, W, 3), np.float32), d, v), layout="blender")
    i = exr.info(path)
    assert i["layout"] == "blender" and i["size"] == (W, H) and len(i["parts"]) == 3
    assert ("ViewLayer.Depth.Z", "float") in i["parts"][1]["channels"]
    assert i["parts"][0]["data_window"] == ((0, 0), (W - 1, H - 1))
    assert i["depth"] == {"min": 0.5, "max": 9.0, "inf_count": 1}
    assert i["velocity"] == {"x": (-1.0, 3.0), "y": (-4.0, 2.0), "max_magnitude": 5.0}
    assert i["problems"] == []
    text = exr.format_info(i)
    assert "layout blender" in text and "+inf (sky) 1 px" in text and "max |v| 5" in text


def test_info_reports_problems_instead_of_failing(tmp_path):
    c = np.ones((H, W), np.float32)
    i = exr.info(_write_raw(tmp_path / "odd.exr", {"mask.Q": c}))  # (a lone Y reads as grey)
    assert i["layout"] is None and i["depth"] is None
    assert "no known channel layout" in i["problems"][0]
    assert "problem:" in exr.format_info(i)
    i = exr.info(_write_raw(tmp_path / "arn.exr", {"R": c, "G": c, "B": c, "Z": c, "motionvector.R": c, "motionvector.G": c}))
    assert i["layout"] == "arnold" and i["depth_kind"] == "radial" and "focal_px" in i["problems"][0]


def test_write_onto_a_directory_fails_cleanly(tmp_path):
    (tmp_path / "out.exr").mkdir()
    with pytest.raises(OutputError, match=r"out\.exr: cannot replace it.*not a directory"):
        exr.write_frame(tmp_path / "out.exr", _frame())
    assert [p.name for p in tmp_path.iterdir()] == ["out.exr"]


@pytest.mark.parametrize("compression", ["zip", "zips", "piz", "rle", "none"])
def test_every_offered_compression_is_lossless(tmp_path, compression):
    f = _frame()
    exr.write_frame(tmp_path / "c.exr", f, compression=compression)
    g = exr.read_frame(tmp_path / "c.exr")
    np.testing.assert_array_equal(g.color, f.color)
    np.testing.assert_array_equal(g.depth, f.depth)


def test_unknown_compression_is_refused(tmp_path):
    with pytest.raises(InputError, match="compression 'dwaa' is unknown"):
        exr.write_frame(tmp_path / "c.exr", _frame(), compression="dwaa")
    assert not list(tmp_path.iterdir())

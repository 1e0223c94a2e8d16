"""The EXR fast paths of issue 20: colour read and written interleaved by OpenEXR's bindings, velocity
and depth without extra copies, a sequence reusing written images — each equal to the plane-by-plane
path, and each falling back where the bindings would get it wrong."""
import numpy as np
import OpenEXR
import pytest

import clpost.exr.io as io
from clpost import Camera, Frame, Pipeline, exr
from clpost.errors import InputError
from clpost.exr.layouts import depth_to_planar


def _frame(rng, h=6, w=9, alpha=False):
    depth = rng.uniform(1, 9, (h, w)).astype(np.float32)
    depth[0, 0] = np.inf
    return Frame(rng.uniform(0, 4, (h, w, 3)).astype(np.float32), depth=depth,
                 velocity=rng.normal(size=(h, w, 2)).astype(np.float32),
                 alpha=rng.uniform(0, 1, (h, w)).astype(np.float32) if alpha else None)


@pytest.mark.parametrize("layout", ["clpost", "blender", "nuke", "arnold"])
@pytest.mark.parametrize("half", [False, True])
@pytest.mark.parametrize("alpha", [False, True])
def test_interleaved_read_equals_plane_by_plane(tmp_path, monkeypatch, layout, half, alpha):
    p = tmp_path / "x.exr"
    focal = 20.0 if layout == "arnold" else None
    exr.write_frame(p, _frame(np.random.default_rng(1), alpha=alpha), layout=layout, half=half, focal_px=focal)
    assert io._can_interleave(exr.read_header(p))
    fast = exr.read_frame(p, focal_px=focal)
    monkeypatch.setattr(io, "_can_interleave", lambda headers: False)
    slow = exr.read_frame(p, focal_px=focal)
    for name in ("color", "alpha", "depth", "velocity"):
        a, b = getattr(fast, name), getattr(slow, name)
        assert (a is None) == (b is None) and (a is None or np.array_equal(a, b)), name
    assert fast.color.flags.c_contiguous and fast.velocity.flags.c_contiguous


def test_colour_is_the_array_openexr_read(tmp_path):
    """No stack: the frame's colour is the bindings' interleaved array itself."""
    p = tmp_path / "x.exr"
    exr.write_frame(p, _frame(np.random.default_rng(2)))
    parts = io._load(p)
    rgb = io._interleaved([parts[0].planes[c] for c in "RGB"])
    assert rgb is not None and rgb.shape == (6, 9, 3)
    f = io._frame_from_parts(p, parts, None, None, None, None)
    assert f.color is rgb


def _write_raw(path, channels):
    # (the bindings replace the dict's arrays by their Channel objects: hand them a copy)
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 dict(channels)).write(str(path))


def test_a_layer_of_mixed_pixel_types_is_read_plane_by_plane(tmp_path):
    """The bindings would read R (half) into G's float array; such files are read a plane at a time."""
    rng = np.random.default_rng(3)
    r = rng.uniform(0, 1, (5, 7)).astype(np.float16)
    g, b = (rng.uniform(0, 1, (5, 7)).astype(np.float32) for _ in range(2))
    p = tmp_path / "mixed.exr"
    _write_raw(p, {"R": r, "G": g, "B": b})
    assert not io._can_interleave(exr.read_header(p))
    f = exr.read_frame(p)
    np.testing.assert_array_equal(f.color, np.stack([r.astype(np.float32), g, b], axis=-1))


def test_a_channel_named_like_a_layer_key_keeps_planes(tmp_path):
    rng = np.random.default_rng(4)
    ch = {c: rng.uniform(0, 1, (4, 5)).astype(np.float32) for c in ("R", "G", "B", "RGB")}
    p = tmp_path / "odd.exr"
    _write_raw(p, ch)
    assert not io._can_interleave(exr.read_header(p))
    f = exr.read_frame(p, labels="all")
    np.testing.assert_array_equal(f.color, np.stack([ch["R"], ch["G"], ch["B"]], axis=-1))
    np.testing.assert_array_equal(f.labels["RGB"], ch["RGB"])


def test_writable_groups_rgb_in_order_and_makes_other_planes_contiguous(tmp_path):
    rng = np.random.default_rng(5)
    c = rng.uniform(0, 1, (4, 6, 3)).astype(np.float32)
    v = rng.normal(size=(4, 6, 2)).astype(np.float32)
    out = io._writable({"R": c[..., 0], "G": c[..., 1], "B": c[..., 2], "velocity.X": v[..., 0],
                        "L.R": c[..., 2], "L.G": c[..., 1], "L.B": c[..., 0]})
    assert out["RGB"] is c and "R" not in out
    assert {"L.R", "L.G", "L.B"} <= out.keys()  # reversed channels: not one interleaved array
    assert all(a.flags.c_contiguous for k, a in out.items())
    # the bindings ignore a plane's strides: what _writable hands them reads back exactly
    p = tmp_path / "w.exr"
    _write_raw(p, out)
    with OpenEXR.File(str(p), separate_channels=True) as f:
        got = {k: ch.pixels for k, ch in f.channels().items()}
    for i, k in enumerate("RGB"):
        np.testing.assert_array_equal(got[k], c[..., i])
        np.testing.assert_array_equal(got["L." + k], c[..., 2 - i])
    np.testing.assert_array_equal(got["velocity.X"], v[..., 0])


def test_a_label_cannot_hide_behind_the_grouped_colour(tmp_path):
    """Clashes are checked on channel names before colour is grouped under 'RGB'."""
    f = Frame(np.ones((3, 4, 3), np.float32), labels={"R": np.zeros((3, 4), np.uint32)})
    with pytest.raises(InputError, match="label channel 'R' clashes"):
        exr.write_frame(tmp_path / "x.exr", f)
    assert not (tmp_path / "x.exr").exists()


def test_depth_to_planar_touches_its_input_only_in_place():
    raw = np.array([[1.0, 2e10], [3.0, np.inf]], np.float32)
    keep = raw.copy()
    d, kind = depth_to_planar(None, raw, "planar", None)
    assert kind == "planar" and d is not raw and np.array_equal(raw, keep)
    assert np.array_equal(d, [[1.0, np.inf], [3.0, np.inf]])
    d2, _ = depth_to_planar(None, raw, "planar", None, in_place=True)
    assert d2 is raw and np.array_equal(raw, d)


def test_display_size_reads_the_header_only(tmp_path):
    p = tmp_path / "x.exr"
    exr.write_frame(p, _frame(np.random.default_rng(6), h=7, w=11))
    assert exr.display_size(p) == (11, 7) == exr.info(p)["size"]
    with pytest.raises(InputError, match="no such file"):
        exr.display_size(tmp_path / "missing.exr")


def test_pipeline_downloads_into_out_when_it_fits():
    f = _frame(np.random.default_rng(7))
    pipe = Pipeline(Camera(luminance_scale=1.0, vignetting="natural"))
    ref = pipe.run(f).color
    out = np.full((6, 9, 3), -1, np.float32)
    got = pipe.run(f, out=out)
    assert got.color is out and np.array_equal(out, ref)
    wrong = np.zeros((6, 8, 3), np.float32)
    assert pipe.run(f, out=wrong).color is not wrong and not wrong.any()


@pytest.mark.filterwarnings("ignore::clpost.metering.ExposureWarning")
def test_a_sequence_reuses_written_images(tmp_path, monkeypatch):
    from clpost.batch import FrameJob, process_sequence

    rng = np.random.default_rng(8)
    jobs = []
    for k in range(5):
        src = tmp_path / f"in.{k}.exr"
        exr.write_frame(src, _frame(rng))
        jobs.append(FrameJob(k, src, tmp_path / f"out.{k}.exr"))
    pipe = Pipeline(Camera(luminance_scale=1.0, vignetting="natural"))
    real, given = pipe.run, []

    def run(frame, camera=None, out=None):
        given.append(out)
        return real(frame, camera, out)

    monkeypatch.setattr(pipe, "run", run)
    process_sequence(pipe, jobs)
    # frames 0 and 1 have nothing written yet; later frames get an image already on disk
    assert given[:2] == [None, None] and all(g is not None for g in given[2:])
    for job in jobs:
        np.testing.assert_array_equal(exr.read_frame(job.dst).color,
                                      Pipeline(pipe.camera).run(exr.read_frame(job.src)).color)

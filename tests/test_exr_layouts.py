"""The Layout objects of clpost.exr: one per renderer convention, each recognising what it writes."""
import numpy as np
import pytest

from clpost import Frame, exr
from clpost.errors import InputError
from clpost.exr.io import read_header


@pytest.mark.parametrize("name", exr.LAYOUTS)
def test_each_layout_detects_what_it_writes_and_round_trips(tmp_path, name):
    lay = exr.REGISTRY[name]
    assert isinstance(lay, exr.Layout) and lay.name == name
    rng = np.random.default_rng(3)
    f = Frame(rng.random((5, 7, 3)).astype(np.float32), depth=rng.uniform(1, 9, (5, 7)).astype(np.float32),
              velocity=rng.normal(size=(5, 7, 2)).astype(np.float32))
    p = tmp_path / f"{name}.exr"
    exr.write_frame(p, f, layout=name, focal_px=20.0 if name == "arnold" else None)
    headers = read_header(p)
    names = {c for h in headers for c in h.channels}
    assert exr.detect_layout(names) == name
    assert len(headers) == (3 if name == "blender" else 1)
    g = exr.read_frame(p, focal_px=20.0 if name == "arnold" else None)
    assert g.metadata["layout"] == name
    np.testing.assert_array_equal(g.color, f.color)
    np.testing.assert_allclose(g.depth, f.depth, rtol=2e-6)
    np.testing.assert_array_equal(g.velocity, f.velocity)


def test_unknown_layout_names_the_known_ones(tmp_path):
    with pytest.raises(InputError, match="layout 'maya' is unknown; use one of clpost, blender, nuke, arnold"):
        exr.get_layout(tmp_path / "x.exr", "maya")


def test_header_check_refuses_before_allocating(tmp_path):
    p = tmp_path / "x.exr"
    exr.write_frame(p, Frame(np.zeros((8, 8, 3), np.float32)))
    (h,) = read_header(p)
    h.display_window = ((0, 0), (59999, 59999))
    with pytest.raises(InputError, match=r"x\.exr: reading it needs .* GiB \(60000x60000 display window"):
        exr.check_header(p, [h])
    h.display_window = ((0, 0), (7, 7))
    exr.check_header(p, [h])


def test_header_check_compares_the_read_with_available_memory(tmp_path, monkeypatch):
    import clpost.exr.io as io

    p = tmp_path / "x.exr"
    exr.write_frame(p, Frame(np.zeros((64, 64, 3), np.float32)))
    headers = read_header(p)
    exr.check_header(p, headers)
    monkeypatch.setattr(io, "_limit_bytes", lambda: 64 * 64 * 4)  # less than 3 float planes of 64²
    with pytest.raises(InputError, match=r"x\.exr: reading it needs .* more than the 0\.0 GiB available"):
        exr.check_header(p, headers)


def test_header_longer_than_the_first_read_is_parsed(tmp_path):
    p = tmp_path / "x.exr"
    exr.write_frame(p, Frame(np.zeros((4, 4, 3), np.float32)), header={f"clpost.k{i}": "x" * 1000 for i in range(200)})
    assert p.stat().st_size > 1 << 17
    (h,) = read_header(p)
    assert set(h.channels) == {"R", "G", "B"} and h.data_window == ((0, 0), (3, 3))
    assert exr.read_frame(p).metadata["header"]["clpost.k199"] == "x" * 1000

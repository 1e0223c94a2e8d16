"""Frame patterns (####, @, %0Nd) and frame ranges (fileseq FrameSet syntax)."""
from __future__ import annotations

import numpy as np
import pytest

from clpost.errors import InputError
from clpost.sequence import expand, find_frames, has_pattern, parse_frames, parse_pattern


@pytest.mark.parametrize("pattern, frame, path", [
    ("shot/render.####.exr", 7, "shot/render.0007.exr"),
    ("render.#.exr", 7, "render.7.exr"),
    ("render.##.exr", 123, "render.123.exr"),  # padding is a minimum width
    ("render.%04d.exr", 42, "render.0042.exr"),
    ("render.%d.exr", 42, "render.42.exr"),
    ("render_@@@_beauty.exr", 5, "render_005_beauty.exr"),  # token in the middle of the name
    ("frame####", 12345, "frame12345"),
    ("render.####.exr", -5, "render.-005.exr"),  # printf %04d: the sign counts toward the width
    ("/abs/dir.v2/img.%03d.exr", np.int64(9), "/abs/dir.v2/img.009.exr"),
    ("still.exr", 3, "still.exr"),  # no token: the path itself
])
def test_expand(pattern, frame, path):
    assert expand(pattern, frame) == path


def test_hash_means_one_digit_not_fileseq_default_four():
    assert parse_pattern("a.#.exr").width == 1
    assert parse_pattern("a.####.exr").width == 4
    assert parse_pattern("a.@@.exr").width == 2


def test_has_pattern():
    assert has_pattern("a.####.exr") and has_pattern("a.%04d.exr") and has_pattern("a.@.exr")
    assert not has_pattern("a.0001.exr") and not has_pattern("a.exr")
    assert not has_pattern("shot#1/a.exr")  # the directory part is literal


@pytest.mark.parametrize("pattern, match", [
    ("a.%4d.exr", r"'a\.%4d\.exr'.*spaces.*'%04d'"),
    ("a.##.v#.exr", r"'a\.##\.v#\.exr' has 2 frame tokens"),
    ("a.exr", r"'a\.exr' has no frame token"),
    ("", "empty"),
])
def test_bad_patterns(pattern, match):
    with pytest.raises(InputError, match=match) as e:
        parse_pattern(pattern)
    assert "render.####.exr" in str(e.value)  # an example of a good one


def test_expand_rejects_non_integer_frames():
    for bad in (1.5, "7", True):
        with pytest.raises(InputError, match="must be an integer"):
            expand("a.####.exr", bad)


@pytest.mark.parametrize("spec, frames", [
    ("1-5", [1, 2, 3, 4, 5]),
    ("1-10x3", [1, 4, 7, 10]),
    ("1-100x25", [1, 26, 51, 76]),
    ("1,3,5-7", [1, 3, 5, 6, 7]),
    ("10-8", [10, 9, 8]),
    ("1-6y3", [2, 3, 5, 6]),
    ("42", [42]),
    (" 3,1 ", [3, 1]),  # order as written
    ("-2-1", [-2, -1, 0, 1]),
])
def test_parse_frames(spec, frames):
    assert parse_frames(spec) == frames


@pytest.mark.parametrize("spec", ["abc", "1-10x0", "1-10x-2", "", "  ", "1.5-3", "1-100000000"])
def test_bad_frame_ranges(spec):
    with pytest.raises(InputError) as e:
        parse_frames(spec)
    msg = str(e.value)
    assert repr(spec) in msg and "1-100x2" in msg and "\n" not in msg


def _touch(d, *names):
    for n in names:
        (d / n).write_bytes(b"")


def test_find_frames_hash(tmp_path):
    _touch(tmp_path, "img.0001.exr", "img.0003.exr", "img.10000.exr", "img.7.exr", "img.0002.exr.bak",
           "other.0002.exr", "img.000x.exr", "img.-001.exr")
    (tmp_path / "img.0005.exr").mkdir()  # a directory is not a frame
    assert find_frames(str(tmp_path / "img.####.exr")) == [-1, 1, 3, 10000]
    assert find_frames(str(tmp_path / "img.%04d.exr")) == [-1, 1, 3, 10000]
    assert find_frames(str(tmp_path / "img.#.exr")) == [7, 10000]


def test_find_frames_at_and_relative(tmp_path, monkeypatch):
    _touch(tmp_path, "b_01_v2.exr", "b_12_v2.exr", "b_1_v2.exr")
    monkeypatch.chdir(tmp_path)
    assert find_frames("b_@@_v2.exr") == [1, 12]


def test_find_frames_errors(tmp_path):
    with pytest.raises(InputError, match=r"matches no files.*'img\.0001\.exr'"):
        find_frames(str(tmp_path / "img.####.exr"))
    with pytest.raises(InputError, match=r"directory .*missing.* does not exist"):
        find_frames(str(tmp_path / "missing" / "img.####.exr"))
    with pytest.raises(InputError, match="no frame token"):
        find_frames(str(tmp_path / "img.exr"))

"""Camera track files (--camera-track): formats, names, interpolation, end holds, bad files."""
import json

import pytest

from clpost import Camera, InputError
from clpost.camera_track import load_track
from clpost.cli import main


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_json_linear_and_step_with_end_holds(tmp_path):
    p = _write(tmp_path, "t.json", json.dumps({
        "interpolation": {"f-number": "step"},
        "keys": [{"frame": 10, "focus": 1.0, "f-number": 2.0},
                 {"frame": 20, "focus": 3.0},
                 {"frame": 30, "f-number": 8}]}))
    t = load_track(p)
    assert set(t.names) == {"focus_distance_m", "f_number"}
    v = t.values_at
    assert v(10)["focus_distance_m"] == 1.0 and v(15)["focus_distance_m"] == pytest.approx(2.0)
    assert v(12)["focus_distance_m"] == pytest.approx(1.4)
    assert v(0)["focus_distance_m"] == 1.0 and v(99)["focus_distance_m"] == 3.0  # holds the ends
    assert v(29)["f_number"] == 2.0 and v(30)["f_number"] == 8.0  # step: last key at or before
    assert v(5)["f_number"] == 2.0 and v(31)["f_number"] == 8.0


def test_csv_with_field_and_flag_names_empty_cells_and_comments(tmp_path):
    p = _write(tmp_path, "t.csv", "# a focus pull\nframe,focus_distance_m,--iso,blades:step\n"
                                  "1,1.0,100,5\n5,,400,\n9,2.0,,7\n")
    t = load_track(p)
    v = t.values_at
    assert v(5)["focus_distance_m"] == pytest.approx(1.5)  # empty cell: no key at 5
    assert v(3)["iso"] == pytest.approx(250.0) and v(9)["iso"] == 400.0
    assert v(8)["blades"] == 5 and v(9)["blades"] == 7 and isinstance(v(9)["blades"], int)


def test_text_values_read_as_the_flag_reads_them(tmp_path):
    p = _write(tmp_path, "t.json", json.dumps([{"frame": 1, "shutter": "1/50", "lens": "thin:35"},
                                               {"frame": 2, "shutter": "1/25", "lens": "thin:85"}]))
    t = load_track(p)
    assert t.values_at(1)["shutter_s"] == pytest.approx(0.02)
    assert t.values_at(2)["lens"] == "thin:85" and t.values_at(1)["lens"] == "thin:35"  # structural: step


def test_default_interpolations():
    from clpost.camera_track import default_interpolation

    by = {s.name: s for s in Camera.param_specs()}
    assert default_interpolation(by["focus_distance_m"]) == "linear"
    assert default_interpolation(by["f_number"]) == "linear"
    assert default_interpolation(by["noise_seed"]) == "step"  # whole numbers
    assert default_interpolation(by["lens"]) == "step"  # structural
    assert default_interpolation(by["spherical_aberration"]) == "step"  # structural float


BAD = [
    ("t.json", '{"keys": [{"frame": 1, "focus": 2.0},\n {"frame": 2 "focus": 1}]}', r"t\.json: line 2, column 14: not valid JSON"),
    ("t.json", '{"keys": [{"frame": 1, "focsu": 2.0}]}', r"t\.json: keys\[0\] 'focsu': unknown camera parameter"),
    ("t.json", '{"keys": [{"frame": 1.5, "focus": 2.0}]}', r"keys\[0\] 'frame': 1\.5 is not a whole frame number"),
    ("t.json", '{"keys": [{"focus": 2.0}]}', r"keys\[0\]: a keyframe without 'frame'"),
    ("t.json", '{"keys": []}', r"key 'keys': must be a non-empty list"),
    ("t.json", '{"keys": [{"frame": 1, "f-number": -2}]}', r"keys\[0\] 'f_number': Camera\.f_number=-2 must be > 0"),
    ("t.json", '{"interpolation": {"lens": "linear"}, "keys": [{"frame": 1, "lens": "thin:50"}]}',
     r"lens cannot be interpolated linearly \(structural.*use 'step'"),
    ("t.json", '{"interpolation": {"focus": "cubic"}, "keys": [{"frame": 1, "focus": 2}]}',
     r"interpolation 'cubic' is unknown; use 'linear' or 'step'"),
    ("t.csv", "frame,focus\n1,2.0\n2,abc\n", r"t\.csv: line 3 'focus_distance_m': 'abc' is not a value of --focus"),
    ("t.csv", "frame,focus\n1,2.0,3\n", r"t\.csv: line 2: 3 cells but the header has 2 columns"),
    ("t.csv", "focus,frame\n1,2\n", r"t\.csv: line 1: the header row must start with 'frame'"),
    ("t.csv", "frame,focus\n", r"line 1: a header but no keyframe rows"),
    ("t.csv", "frame,focus\n1,2\n1,3\n", r"line 3 'focus': frame 1 has two keys"),
    ("t.txt", "frame,focus\n1,2\n", r"unknown extension '\.txt'; name it \.json or \.csv"),
]


@pytest.mark.parametrize("name,text,match", BAD, ids=[b[2][:40] for b in BAD])
def test_bad_track_files_are_one_line_naming_file_and_place(tmp_path, name, text, match):
    p = _write(tmp_path, name, text)
    with pytest.raises(InputError, match=match) as exc:
        load_track(p)
    assert "\n" not in str(exc.value)


def test_bad_track_on_the_command_line_exits_2_with_one_line(tmp_path, capsys):
    from clpost import Frame, exr
    import numpy as np

    exr.write_frame(tmp_path / "in.exr", Frame(np.ones((4, 4, 3), np.float32)))
    p = _write(tmp_path, "t.csv", "frame,focus\n1,2.0\n2,far\n")
    rc = main(["process", str(tmp_path / "in.exr"), "-o", str(tmp_path / "out.exr"), "--camera-track", str(p)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1
    assert "t.csv: line 3" in err and "docs/camera-tracks.md" in err
    assert not (tmp_path / "out.exr").exists()
    rc = main(["process", str(tmp_path / "in.exr"), "-o", str(tmp_path / "out.exr"),
               "--camera-track", str(tmp_path / "missing.json")])
    assert rc == 2 and "missing.json: no such file" in capsys.readouterr().err


def test_the_examples_in_docs_load_and_agree(tmp_path):
    import re
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[1] / "docs" / "camera-tracks.md").read_text()
    js = re.search(r"```json\n(.*?)```", doc, re.S).group(1)
    csv_text = re.search(r"```\n(# focus pull.*?)```", doc, re.S).group(1)
    a = load_track(_write(tmp_path, "a.json", js))
    b = load_track(_write(tmp_path, "b.csv", csv_text))
    for t in (a, b):
        assert t.values_at(101)["focus_distance_m"] == 1.2 and t.values_at(124)["focus_distance_m"] == 3.5
        assert t.values_at(112)["f_number"] == 2.8  # stepped
    assert b.values_at(113)["f_number"] == 4.0 and a.values_at(130)["f_number"] == 4.0

"""clpost bench: bytes/taps accounting, scenes with missing stages, JSON schema and the markdown
section (no timing assertions: timings on a shared machine are not testable)."""
import json

import numpy as np
import pytest

from clpost import bench
from clpost.camera import Camera
from clpost.cli import main
from clpost.pipeline import Pipeline


def test_launch_bytes_counts_each_buffer_once():
    cam = Camera(vignetting="natural", luminance_scale=1.0)
    f = bench.synthetic_frame(37, 23, velocity_px=4.0)
    pipe = Pipeline(cam)
    (L,) = bench.launches(pipe, f, pipe.camera_for(f))
    assert L["kernel"] == "vignetting__exposure" and L["kind"] == "pointwise"
    assert L["bytes"] == 37 * 23 * (12 + 12 + 4)  # RGB in + RGB out + the RI plane, no aux buffer


def test_launch_bytes_with_aux_and_taps():
    cam = Camera(frame_rate_fps=24.0)
    f = bench.synthetic_frame(37, 23, velocity_px=8.0)
    pipe = Pipeline(cam, stages=["motion_blur"], quality="draft")
    ls = bench.launches(pipe, f, pipe.camera_for(f))
    assert [L["kind"] for L in ls] == ["convert", "gather", "convert"]
    mb = ls[1]
    n = 37 * 23
    assert mb["bytes"] == n * (12 + 12 + 4 + 8)  # colour in/out + depth + velocity
    st = pipe._stages[[s.name for s in pipe._stages].index("motion_blur")]
    assert mb["taps_per_pixel"] == 3 * (st.samples + 1)


def test_distortion_taps_per_quality():
    from clpost.stages.distortion import Distortion

    assert Distortion("final").taps_per_pixel(None, None) == 3 * 16
    assert Distortion("draft").taps_per_pixel(None, None) == 3 * 4


def test_scene_reports_missing_stages_and_fields():
    sc = bench.Scene("t", "test", wants=("exposure", "no_such_stage"),
                     camera_fields=dict(f_number=4.0, luminance_scale=1.0, no_such_field=1))
    row = bench.bench_case(sc, 32, 16, repeats=1, warmup=0)
    assert row["not_available"]["no_such_stage"] == "stage not in this build"
    assert "Camera.no_such_field" in row["not_available"]
    assert row["plan"] == ["exposure"]


@pytest.mark.slow
def test_json_schema_and_markdown(tmp_path, capsys):
    md = tmp_path / "benchmarks.md"
    md.write_text("# Benchmarks\n\nhand-written DoF section\n")
    assert main(["bench", "--sizes", "48x32", "--repeats", "1", "--warmup", "0", "--scenes",
                 "worst,full", "--qualities", "draft", "--json", "--markdown", str(md)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["schema"] == bench.SCHEMA_VERSION and doc["device"]
    assert [(r["scene"], r["quality"]) for r in doc["rows"]] == [("worst", "draft"), ("full", "draft")]
    for r in doc["rows"]:
        for key in ("width", "height", "plan", "not_available", "kernels", "copy_kernel_gbps", "device_ms",
                    "wall_ms", "wall_fps", "upload_ms", "download_ms", "numpy_ms", "speedup_vs_numpy",
                    "cv2_remap_ms", "talk_hd4000_fps", "target_ms"):
            assert key in r, key
        assert r["device_ms"] == sum(k["ms"] for k in r["kernels"])
        for k in r["kernels"]:
            # a plan's kernel reads and writes the colour at least; a companion kernel building a
            # table (vignetting_plane: 8 B a pixel) moves its own planes, never nothing
            assert k["bytes"] >= (48 * 32 * 8 if k["kind"] == "aux" else 2 * 12 * 48 * 32), k["kernel"]
            if k["ms"] > 0:
                assert np.isclose(k["gbps"], k["bytes"] / k["ms"] / 1e6)
                assert np.isclose(k["percent_of_copy"], 100 * k["gbps"] / r["copy_kernel_gbps"])
    full = doc["rows"][1]
    assert "motion_blur" in full["plan"] and "grain" in full["plan"] and "distortion" in full["plan"]
    assert "dof" in doc["rows"][0]["not_available"] or "dof" in doc["rows"][0]["plan"]
    text = md.read_text()
    assert "hand-written DoF section" in text and text.count(bench.MARK_BEGIN) == 1
    # regenerating replaces the section, keeps the rest
    assert main(["bench", "--sizes", "48x32", "--repeats", "1", "--warmup", "0", "--scenes", "worst",
                 "--qualities", "draft", "--markdown", str(md)]) == 0
    text2 = md.read_text()
    assert text2.count(bench.MARK_BEGIN) == 1 and "hand-written DoF section" in text2
    assert "| full |" not in text2


@pytest.mark.slow
def test_talk_rows():
    sc = bench.SCENES["no_defocus"]
    row = bench.bench_case(sc, 1280, 720, repeats=1, warmup=0, numpy_max_pixels=0,
                           frame=bench.synthetic_frame(1280, 720))
    assert row["talk_hd4000_fps"] == 60.0 and row["numpy_ms"] is None
    assert "HD 4000" in bench.format_markdown({"device": "x", "time": "t", "load_average": [1.0],
                                               "rows": [row]}, "clpost bench")

"""CLI end to end on small sequences: output equals the library call; errors are one line."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clpost import Camera, Frame, Pipeline, exr
from clpost.cli import main

CAM_ARGS = ["--f-number", "2.8", "--shutter", "1/60", "--iso", "200", "--luminance-scale", "50"]
CAM = Camera(f_number=2.8, shutter_s=1 / 60, iso=200, luminance_scale=50.0)


def make_blender_sequence(folder: Path, n=3, w=33, h=21, seed=0):
    """Frames written the way Blender 5.x writes a multilayer EXR (one part per pass)."""
    rng = np.random.default_rng(seed)
    frames = []
    for i in range(1, n + 1):
        f = Frame(rng.random((h, w, 3)).astype(np.float32) * 4,
                  depth=rng.uniform(0.5, 30, (h, w)).astype(np.float32),
                  velocity=rng.normal(size=(h, w, 2)).astype(np.float32))
        exr.write_frame(folder / f"shot.{i:04d}.exr", f, layout="blender")
        frames.append(f)
    return frames


def run_cli(*args):
    return main([str(a) for a in args])


def test_process_blender_sequence_equals_library_call(tmp_path, capsys):
    make_blender_sequence(tmp_path)
    out = tmp_path / "out"
    assert run_cli("process", tmp_path / "shot.####.exr", "-o", out / "cam.####.exr", "--quiet", *CAM_ARGS) == 0
    assert "processed 3 frame(s)" in capsys.readouterr().out
    pipe = Pipeline(CAM)
    for i in (1, 2, 3):
        got = exr.read_frame(out / f"cam.{i:04d}.exr")
        src = exr.read_frame(tmp_path / f"shot.{i:04d}.exr")
        np.testing.assert_array_equal(got.color, pipe.run(src).color)
        np.testing.assert_array_equal(got.depth, src.depth)
        hdr = got.metadata["header"]
        assert hdr["clpost.fNumber"] == "2.8" and hdr["clpost.plan"] == "exposure"


def test_frame_range_patterns_and_skip_existing(tmp_path, capsys):
    make_blender_sequence(tmp_path, n=4)
    out = tmp_path / "o"
    assert run_cli("process", tmp_path / "shot.%04d.exr", "-o", out / "x.@@@@.exr", "--frames", "1-4x2",
                   "--quiet", *CAM_ARGS) == 0
    assert sorted(p.name for p in out.iterdir()) == ["x.0001.exr", "x.0003.exr"]
    before = (out / "x.0001.exr").stat().st_mtime_ns
    assert run_cli("process", tmp_path / "shot.####.exr", "-o", out / "x.####.exr", "--quiet", *CAM_ARGS) == 0
    assert "skipped 2 existing" in capsys.readouterr().out
    assert (out / "x.0001.exr").stat().st_mtime_ns == before
    assert run_cli("process", tmp_path / "shot.####.exr", "-o", out / "x.####.exr", "--quiet", "--overwrite",
                   *CAM_ARGS) == 0
    assert (out / "x.0001.exr").stat().st_mtime_ns != before


def test_explain_prints_plan_and_reasons(tmp_path, capsys):
    make_blender_sequence(tmp_path, n=1)
    assert run_cli("process", tmp_path / "shot.####.exr", "-o", tmp_path / "o.####.exr", "--explain",
                   "--shutter", "auto", "--luminance-scale", "1") == 0
    text = capsys.readouterr().out
    assert "+ exposure" in text and "kernels: exposure" in text and "auto-exposure: f/2" in text
    assert not list(tmp_path.glob("o.*"))
    assert run_cli("process", tmp_path / "shot.####.exr", "-o", tmp_path / "o.####.exr", "--explain",
                   "--stages", "") == 0
    assert "not selected by --stages" in capsys.readouterr().out


def one_line_error(capsys, *args, code=2):
    assert run_cli(*args) == code
    # warnings are their own one-line messages (e.g. an exposure far from mid-grey)
    err = "\n".join(ln for ln in capsys.readouterr().err.splitlines()
                    if not ln.startswith("clpost: warning: ")).strip()
    assert err.startswith("clpost: error:") and "Traceback" not in err
    return err


def test_bad_inputs_give_one_line_and_exit_2(tmp_path, capsys):
    make_blender_sequence(tmp_path, n=2)
    out = tmp_path / "o.####.exr"
    seq = tmp_path / "shot.####.exr"
    assert "f_number" in one_line_error(capsys, "process", seq, "-o", out, "--f-number", "0")
    assert "unknown stage" in one_line_error(capsys, "process", seq, "-o", out, "--stages", "bokeh")
    err = one_line_error(capsys, "process", tmp_path / "missing.exr", "-o", tmp_path / "m.exr")
    assert "missing.exr" in err
    assert "frame pattern" in one_line_error(capsys, "process", seq, "-o", tmp_path / "single.exr")
    (tmp_path / "bad.exr").write_bytes(b"not an exr at all")
    assert "bad.exr" in one_line_error(capsys, "process", tmp_path / "bad.exr", "-o", tmp_path / "b.exr")
    assert not (tmp_path / "b.exr").exists()


def test_size_mismatch_stops_with_the_frame_named_and_nothing_partial(tmp_path, capsys):
    make_blender_sequence(tmp_path, n=2)
    odd = Frame(np.ones((10, 12, 3), np.float32), depth=np.ones((10, 12), np.float32))
    exr.write_frame(tmp_path / "shot.0003.exr", odd, layout="blender")
    out = tmp_path / "o"
    err = one_line_error(capsys, "process", tmp_path / "shot.####.exr", "-o", out / "o.####.exr", "--quiet")
    assert "shot.0003.exr" in err and "12x10" in err
    assert sorted(p.name for p in out.iterdir()) == ["o.0001.exr", "o.0002.exr"]  # complete ones only
    for p in out.iterdir():
        exr.read_frame(p)


def test_info_reports_ranges(tmp_path, capsys):
    make_blender_sequence(tmp_path, n=1)
    assert run_cli("info", tmp_path / "shot.0001.exr", "--json") == 0
    d = json.loads(capsys.readouterr().out)
    assert d["layout"] == "blender"


@pytest.mark.slow
def test_bench_json(capsys, tmp_path):
    # the demo scene renders its frame once into --cache (EXR) and reads it back after
    assert run_cli("bench", "--sizes", "48x32", "--repeats", "2", "--scenes", "demo", "--cache",
                   str(tmp_path), "--json") == 0
    d = json.loads(capsys.readouterr().out)
    row = d["rows"][0]
    assert (tmp_path / "demo_48x32.exr").is_file()
    assert "exposure" in row["plan"] and row["wall_ms"] > 0 and row["copy_kernel_gbps"] > 0


@pytest.mark.slow
def test_console_script_is_installed_and_errors_cleanly(tmp_path):
    exe = Path(sys.executable).with_name("clpost")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "clpost.cli"]
    r = subprocess.run(cmd + ["process", str(tmp_path / "nope.exr"), "-o", str(tmp_path / "x.exr")],
                       capture_output=True, text=True, env=dict(os.environ))
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "nope.exr" in r.stderr


def test_arnold_radial_depth_is_made_planar_with_the_camera(tmp_path, capsys):
    from clpost.exr import planar_to_radial

    h, w = 20, 30
    planar = np.full((h, w), 4.0, np.float32)
    fx = CAM.intrinsics(w, h)[0]
    f = Frame(np.ones((h, w, 3), np.float32), depth=planar_to_radial(planar, fx),
              velocity=np.zeros((h, w, 2), np.float32))
    exr.write_frame(tmp_path / "a.exr", f, layout="arnold")  # focal_px omitted: Z stored as given
    assert run_cli("process", tmp_path / "a.exr", "-o", tmp_path / "o.exr", "--quiet", *CAM_ARGS) == 0
    assert capsys.readouterr().err == ""
    got = exr.read_frame(tmp_path / "o.exr")
    np.testing.assert_allclose(got.depth, planar, rtol=1e-6)


@pytest.mark.slow
def test_demo_writes_exrs_and_visibly_exposed_pngs(tmp_path, capsys):
    from PIL import Image

    out = tmp_path / "demo"
    assert run_cli("demo", out, "--size", "96x64", "--frames", "2") == 0
    text = capsys.readouterr().out
    assert "+ exposure" in text and "wrote" in text
    for i in (1, 2):
        src = exr.read_frame(out / "render" / f"demo.{i:04d}.exr")
        assert src.depth is not None and src.velocity is not None and src.color.max() >= 100  # lamps
        got = exr.read_frame(out / f"clpost.{i:04d}.exr")
        assert got.metadata["header"]["clpost.shutter_s"] != "auto"  # the meter's choice is recorded
        png = np.asarray(Image.open(out / "preview" / f"clpost.{i:04d}.png"))
        assert png.shape == (64, 96, 3) and 40 < png.mean() < 200  # exposed, neither black nor blown
    assert "exists" in one_line_error(capsys, "demo", out, "--size", "96x64", "--frames", "2")


def test_film_and_sensor_options_reach_the_camera(tmp_path, capsys):
    make_blender_sequence(tmp_path, n=1)
    src = tmp_path / "shot.0001.exr"
    assert run_cli("process", src, "-o", tmp_path / "f.exr", "--explain", "--film", "kodak-gold-200",
                   "--film-output", "linear", *CAM_ARGS) == 0
    out = capsys.readouterr().out
    # the camera's grain is white at this size: fused with film and print into one kernel
    assert "Kodak Gold 200" in out and "kernels: exposure__film__grain__print" in out
    assert "fused with the pointwise stages beside it" in out
    assert run_cli("process", src, "-o", tmp_path / "s.exr", "--quiet", "--sensor-preset", "smartphone",
                   "--noise-seed", "3", *CAM_ARGS) == 0
    got = exr.read_frame(tmp_path / "s.exr")
    cam = CAM.with_(sensor_preset="smartphone", noise_seed=3)
    frame = exr.read_frame(src)
    want = Pipeline(cam).run(frame.replace(metadata=dict(frame.metadata, frame_index=0))).color
    np.testing.assert_array_equal(got.color, want)
    assert got.metadata["header"]["clpost.sensorPreset"] == "smartphone"
    assert run_cli("process", src, "-o", tmp_path / "x.exr", "--film", "kodak-gold-200",
                   "--sensor-preset", "smartphone", *CAM_ARGS) == 2
    assert "one medium" in capsys.readouterr().err


def test_meter_options_without_auto_exposure_are_an_error(tmp_path, capsys):
    exr.write_frame(tmp_path / "a.exr", Frame(np.ones((4, 6, 3), np.float32)))
    # --ev acts in every exposure mode; only --metering needs auto-exposure
    assert main(["process", str(tmp_path / "a.exr"), "-o", str(tmp_path / "b.exr"), "--metering", "spot"]) == 2
    assert "only in auto-exposure" in capsys.readouterr().err
    assert main(["process", str(tmp_path / "a.exr"), "-o", str(tmp_path / "b.exr"), "--ev", "2",
                 "--shutter", "auto", "--luminance-scale", "1", "--explain"]) == 0
    with pytest.raises(SystemExit) as exc:
        main(["demo", str(tmp_path / "d"), "--depth-of-field", "enabled"])
    assert exc.value.code == 2
    assert "is not on/off" in capsys.readouterr().err

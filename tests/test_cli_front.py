"""``clpost process --front``: a foreground rendered as its own layer, read per frame into
``Frame.front``; the output equals the library's two-layer run; each bad front is one line, exit 2,
nothing written."""
import json
from pathlib import Path

import numpy as np
import pytest

from clpost import Camera, Frame, Pipeline, exr
from clpost import fidelity as fd
from clpost.batch import FrameJob
from clpost.cli import build_parser, camera_from_args, main
from clpost.frame import front_layer

DATA = Path(__file__).parent / "data" / "cycles"


def run_cli(*args):
    return main([str(a) for a in args])


def one_line_error(capsys, *args):
    assert run_cli(*args) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if not ln.startswith("clpost: warning: ")]
    assert len(err) == 1 and err[0].startswith("clpost: error:"), err
    return err[0]


def cycles_flags(entry: dict) -> list[str]:
    """The ``clpost process`` flags of :func:`clpost.fidelity.cycles_camera` (the Cycles thin lens)."""
    w, h = entry["size"]
    cam = fd.cycles_camera(entry["shot"], w, h)
    return ["--lens", cam.lens, "--f-number", repr(cam.f_number), "--focus", repr(cam.focus_distance_m),
            "--sensor", f"{cam.sensor_mm[0]!r}x{cam.sensor_mm[1]!r}", "--depth-of-field", "on",
            "--blades", str(cam.blades), "--blade-rotation", repr(cam.blade_rotation_deg)]


@pytest.fixture(scope="module")
def occluder():
    return json.loads((DATA / "manifest.json").read_text())["scenes"]["occluder"]


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_front_layer_run_equals_the_library_two_layer_run(occluder, quality, tmp_path):
    w, h = occluder["size"]
    args = build_parser().parse_args(["process", "bg.exr", "-o", "o.exr", *cycles_flags(occluder)])
    assert camera_from_args(args) == fd.cycles_camera(occluder["shot"], w, h)
    out = tmp_path / "two.exr"
    assert run_cli("process", DATA / "occluder" / "bg.exr", "-o", out, "--front", DATA / "occluder" / "fg.exr",
                   "--stages", "dof,front_layer", "--quality", quality, "--quiet", *cycles_flags(occluder)) == 0
    got = exr.read_frame(out)
    assert got.metadata["header"]["clpost.plan"] == "dof,front_layer"
    want = fd.cycles_pipeline(occluder, "dof", quality, front=True).run(fd.cycles_layers(DATA, occluder))
    np.testing.assert_allclose(got.color, want.color, rtol=1e-5, atol=1e-6)
    # the front layer made a difference: the background's dof alone is another image
    alone = fd.cycles_pipeline(occluder, "dof", quality).run(exr.read_frame(DATA / "occluder" / "bg.exr"))
    assert np.abs(alone.color - got.color).max() > 0.1


W, H = 33, 21
CAM_ARGS = ["--depth-of-field", "on", "--f-number", "1.4", "--focus", "1"]
CAM = Camera(depth_of_field=True, f_number=1.4, focus_distance_m=1.0)


def make_layers(folder: Path, n=2, fg_layout="clpost", seed=0, fg_size=(W, H), alpha=True, depth=True):
    """``bg.####.exr`` (Blender multilayer) and ``fg.####.exr`` (``fg_layout``): a near square over a
    transparent film, premultiplied, with depth where it covers (+inf elsewhere)."""
    rng = np.random.default_rng(seed)
    for i in range(1, n + 1):
        bg = Frame(rng.random((H, W, 3)).astype(np.float32), depth=rng.uniform(2, 20, (H, W)).astype(np.float32))
        exr.write_frame(folder / f"bg.{i:04d}.exr", bg, layout="blender")
        w, h = fg_size
        a = np.zeros((h, w), np.float32)
        a[5:14, 8 + i:20 + i] = 1.0
        a[4, 8 + i:20 + i] = 0.5  # a partly covered edge
        color = rng.random((h, w, 3)).astype(np.float32) * 3 * a[..., None]
        d = np.where(a > 0, np.float32(0.4), np.float32(np.inf)).astype(np.float32)
        fg = Frame(color, depth=d if depth else None, alpha=a if alpha else None)
        exr.write_frame(folder / f"fg.{i:04d}.exr", fg, layout=fg_layout)


def test_sequence_pattern_each_frame_gets_its_own_front_and_the_default_plan_has_front_layer(tmp_path, capsys):
    make_layers(tmp_path)
    out = tmp_path / "out"
    assert run_cli("process", tmp_path / "bg.####.exr", "-o", out / "cam.####.exr", "--front",
                   tmp_path / "fg.%04d.exr", "--quiet", *CAM_ARGS) == 0
    assert "processed 2 frame(s)" in capsys.readouterr().out
    pipe = Pipeline(CAM)
    for i in (1, 2):
        bg, fg = (exr.read_frame(tmp_path / f"{k}.{i:04d}.exr") for k in ("bg", "fg"))
        assert fg.metadata["layout"] == "clpost" and bg.metadata["layout"] == "blender"  # each its own detection
        want = pipe.run(Frame(bg.color, depth=bg.depth, alpha=bg.alpha,
                              front=front_layer(fg.color, fg.alpha, fg.depth)))
        got = exr.read_frame(out / f"cam.{i:04d}.exr")
        assert got.metadata["header"]["clpost.plan"] == "dof,front_layer"  # no --stages: a candidate
        np.testing.assert_allclose(got.color, want.color, rtol=1e-5, atol=1e-6)
    # frame 2's front is its own, not frame 1's: the square moved by a pixel
    one, two = (exr.read_frame(out / f"cam.{i:04d}.exr").color for i in (1, 2))
    assert not np.allclose(one, two)


def test_explain_shows_the_front_file_and_the_front_layer_stage(tmp_path, capsys):
    make_layers(tmp_path, n=1)
    assert run_cli("process", tmp_path / "bg.####.exr", "-o", tmp_path / "o.####.exr", "--front",
                   tmp_path / "fg.####.exr", "--explain", *CAM_ARGS) == 0
    text = capsys.readouterr().out
    assert f"front layer: {tmp_path / 'fg.0001.exr'}" in text and "premultiplied" in text
    assert "+ front_layer" in text and "kernels:" in text and "front_layer" in text.split("kernels:")[1]
    assert not list(tmp_path.glob("o.*"))


def test_a_still_front_serves_every_frame(tmp_path, capsys):
    make_layers(tmp_path, n=2)
    out = tmp_path / "out"
    assert run_cli("process", tmp_path / "bg.####.exr", "-o", out / "c.####.exr", "--front",
                   tmp_path / "fg.0001.exr", "--quiet", *CAM_ARGS) == 0
    assert sorted(p.name for p in out.iterdir()) == ["c.0001.exr", "c.0002.exr"]


def snapshot(folder: Path) -> dict:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.mark.parametrize("case", ["missing", "size", "no_alpha", "no_depth", "is_input", "is_output",
                                  "stages_without_front_layer", "stages_without_dof", "pattern_for_one_file"])
def test_bad_front_is_one_line_exit_2_and_nothing_written(case, tmp_path, capsys):
    kw = {"size": dict(fg_size=(W, H - 1)), "no_alpha": dict(alpha=False), "no_depth": dict(depth=False)}
    make_layers(tmp_path, **kw.get(case, {}))
    seq, front, out = tmp_path / "bg.####.exr", tmp_path / "fg.####.exr", tmp_path / "out" / "c.####.exr"
    extra = []
    if case == "missing":
        (tmp_path / "fg.0002.exr").unlink()
    elif case == "is_input":
        front = seq
    elif case == "is_output":
        front = out
    elif case == "stages_without_front_layer":
        extra = ["--stages", "dof"]
    elif case == "stages_without_dof":
        extra = ["--stages", "front_layer"]
    elif case == "pattern_for_one_file":
        seq, out = tmp_path / "bg.0001.exr", tmp_path / "out" / "c.exr"
    before = snapshot(tmp_path)
    err = one_line_error(capsys, "process", seq, "-o", out, "--front", front, *CAM_ARGS, *extra)
    expect = {"missing": ["fg.0002.exr", "does not exist", "frame 2"], "size": ["33x20", "33x21", "fg.0001.exr"],
              "no_alpha": ["no alpha channel", "Transparent", "fg.0001.exr"],
              "no_depth": ["no depth channel", "fg.0001.exr"],
              "is_input": ["is the input", "bg.0001.exr"], "is_output": ["is the output", "c.0001.exr"],
              "stages_without_front_layer": ["add front_layer to --stages"],
              "stages_without_dof": ["--stages dof,front_layer"],
              "pattern_for_one_file": ["frame pattern", "bg.0001.exr"]}[case]
    assert all(e in err for e in expect), err
    assert not (tmp_path / "out").exists()  # nothing written, not even the output folder
    assert snapshot(tmp_path) == before  # the inputs are untouched


def test_the_job_carries_its_front_to_a_dask_worker(tmp_path):
    """What a worker runs (:func:`clpost.distributed.process_frame_task`) on a pickled job: the
    front travels with the job and is read there."""
    import pickle

    from clpost.distributed import PipelineSpec, process_frame_task

    make_layers(tmp_path, n=1)
    cam = CAM
    job = FrameJob(1, tmp_path / "bg.0001.exr", tmp_path / "w.0001.exr", front=tmp_path / "fg.0001.exr")
    res = process_frame_task(PipelineSpec(cam), pickle.loads(pickle.dumps(job)), None, False, "zip", False, (W, H))
    assert "error" not in res, res
    got = exr.read_frame(tmp_path / "w.0001.exr")
    assert got.metadata["header"]["clpost.plan"] == "dof,front_layer"
    bg, fg = (exr.read_frame(tmp_path / f"{k}.0001.exr") for k in ("bg", "fg"))
    want = Pipeline(cam).run(Frame(bg.color, depth=bg.depth, alpha=bg.alpha,
                                   front=front_layer(fg.color, fg.alpha, fg.depth)))
    np.testing.assert_allclose(got.color, want.color, rtol=1e-5, atol=1e-6)


@pytest.mark.slow
def test_workers_run_equals_the_serial_run(tmp_path, capsys):
    make_layers(tmp_path)
    args = [tmp_path / "bg.####.exr", "--front", tmp_path / "fg.####.exr", "--quiet", *CAM_ARGS]
    assert run_cli("process", *args, "-o", tmp_path / "s" / "c.####.exr") == 0
    assert run_cli("process", *args, "-o", tmp_path / "d" / "c.####.exr", "--workers", "1") == 0
    for i in (1, 2):
        np.testing.assert_array_equal(exr.read_frame(tmp_path / "d" / f"c.{i:04d}.exr").color,
                                      exr.read_frame(tmp_path / "s" / f"c.{i:04d}.exr").color)


def test_info_says_a_layer_with_alpha_and_depth_can_be_a_front(tmp_path, capsys):
    make_layers(tmp_path, n=1)
    assert run_cli("info", tmp_path / "fg.0001.exr", tmp_path / "bg.0001.exr") == 0
    fg_text, bg_text = capsys.readouterr().out.split(str(tmp_path / "bg.0001.exr"))
    assert "usable as a front layer (process --front)" in fg_text
    assert "alpha: covers" in bg_text and "usable as a front layer" not in bg_text  # opaque everywhere


def test_a_front_with_other_windows_is_refused_before_anything_is_written(tmp_path, capsys):
    """Same display size but the input has overscan and the front does not: the pixels would not line up."""
    from clpost.frame import Windows

    make_layers(tmp_path, n=1)
    rng = np.random.default_rng(1)
    win = Windows(((-2, -2), (W + 1, H + 1)), ((0, 0), (W - 1, H - 1)))
    bg = Frame(rng.random((H + 4, W + 4, 3)).astype(np.float32), depth=np.full((H + 4, W + 4), 5, np.float32),
               metadata={"windows": win})
    exr.write_frame(tmp_path / "bg.0001.exr", bg, layout="blender")
    err = one_line_error(capsys, "process", tmp_path / "bg.####.exr", "-o", tmp_path / "out" / "c.####.exr",
                         "--front", tmp_path / "fg.####.exr", *CAM_ARGS)
    assert "fg.0001.exr" in err and "differs from the input's" in err and "data (-2,-2)-(34,22)" in err
    assert not (tmp_path / "out").exists()


def test_a_front_cropped_by_its_data_window_without_alpha_is_refused(tmp_path, capsys):
    """The reader gives a cropped file alpha 1 inside its data window; that is no coverage: the
    front needs its own alpha channel."""
    from clpost.frame import Windows

    make_layers(tmp_path, n=1)
    win = Windows(((4, 3), (W - 5, H - 4)), ((0, 0), (W - 1, H - 1)))
    fg = Frame(np.ones((H, W, 3), np.float32), depth=np.ones((H, W), np.float32), metadata={"windows": win})
    exr.write_frame(tmp_path / "fg.0001.exr", fg, layout="clpost")
    assert exr.read_frame(tmp_path / "fg.0001.exr").alpha is not None  # made from the data window
    err = one_line_error(capsys, "process", tmp_path / "bg.0001.exr", "-o", tmp_path / "out" / "c.exr",
                         "--front", tmp_path / "fg.0001.exr", *CAM_ARGS)
    assert "no alpha channel" in err
    # with its alpha, a front cropped to where it covers is fine: outside its data window is alpha 0
    a = np.zeros((H, W), np.float32)
    a[6:12, 8:20] = 1
    exr.write_frame(tmp_path / "fg.0001.exr", fg.replace(color=fg.color * a[..., None], alpha=a), layout="clpost")
    assert run_cli("process", tmp_path / "bg.0001.exr", "-o", tmp_path / "c.exr", "--front", tmp_path / "fg.0001.exr",
                   "--quiet", *CAM_ARGS) == 0
    bg, fr = (exr.read_frame(tmp_path / f"{k}.0001.exr") for k in ("bg", "fg"))
    assert fr.windows.data != fr.windows.display
    want = Pipeline(CAM).run(Frame(bg.color, depth=bg.depth, alpha=bg.alpha,
                                   front=front_layer(fr.color, fr.alpha, fr.depth)))
    np.testing.assert_allclose(exr.read_frame(tmp_path / "c.exr").color, want.color, rtol=1e-5, atol=1e-6)


def test_an_opaque_front_warns_that_the_input_never_shows(tmp_path, capsys):
    make_layers(tmp_path, n=1)
    fg = Frame(np.ones((H, W, 3), np.float32), depth=np.ones((H, W), np.float32), alpha=np.ones((H, W), np.float32))
    exr.write_frame(tmp_path / "fg.0001.exr", fg, layout="blender")
    assert run_cli("process", tmp_path / "bg.0001.exr", "-o", tmp_path / "c.exr", "--front", tmp_path / "fg.0001.exr",
                   "--quiet", *CAM_ARGS) == 0
    warn = [ln for ln in capsys.readouterr().err.splitlines() if "alpha is 1 everywhere" in ln]
    assert len(warn) == 1 and "Film > Transparent" in warn[0]

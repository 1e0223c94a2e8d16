"""Issue 18 "done when": a five-frame focus pull driven by the inputs' OpenEXR ``focus``
attributes puts each plane's sharp frame where the thin lens says, and costs no rebuilds."""
import numpy as np
import pytest

from clpost import Camera, Pipeline, exr
from clpost.cli import main
from clpost.focus_pull import bench, coc_px, contact_sheet, planes_scene, sharpness, strip_slices, write_pull

DEPTHS = (1.0, 2.0, 4.0)  # m: three planes
FOCUS = (1.0, 1.5, 2.0, 3.0, 4.0)  # m: the pull, one value per frame (EXR attribute)
W, H, N = 480, 96, 1.4  # px, px, f-number; thin:50 on a 36 mm sensor: 0.075 mm pixels
PITCH = 36.0 / W


def _process_pull(tmp_path, *extra):
    src = write_pull(tmp_path / "in", planes_scene(W, H, DEPTHS), FOCUS)
    rc = main(["process", src, "-o", str(tmp_path / "out" / "o.####.exr"), "--depth-of-field", "on",
               "--f-number", str(N), "--quiet", *extra])
    assert rc == 0
    return [exr.read_frame(tmp_path / "out" / f"o.{i:04d}.exr") for i in range(1, len(FOCUS) + 1)]


def test_exr_focus_pull_puts_the_sharp_frame_where_the_thin_lens_says(tmp_path):
    outs = _process_pull(tmp_path)
    ref = planes_scene(W, H, DEPTHS).color
    max_r = max(coc_px(d, u, 50.0, N, PITCH) for d in DEPTHS for u in FOCUS) / 2
    cols = strip_slices(W, len(DEPTHS), int(max_r) + 4)
    for d, c in zip(DEPTHS, cols):
        s = [sharpness(o.color, ref, c) for o in outs]
        coc = [coc_px(d, u, 50.0, N, PITCH) for u in FOCUS]
        sharp = FOCUS.index(d)
        assert int(np.argmin(coc)) == sharp and coc[sharp] == 0
        assert int(np.argmax(s)) == sharp, (d, s, coc)
        assert s[sharp] > 0.97, (d, s)  # in focus: the texture is untouched
        for i, (si, ci) in enumerate(zip(s, coc)):
            if ci > 2.0:  # a blur circle of 2+ px wipes out most of a 1-px texture's gradients
                assert si < 0.5, (d, i, s, coc)
        # more blur, less sharpness: the order over frames follows the predicted CoC
        order = np.argsort(coc)
        assert all(s[order[k]] >= s[order[k + 1]] - 0.02 for k in range(len(order) - 1)), (d, s, coc)
    # each output records the focus it used, under the OpenEXR name and the clpost key
    for o, u in zip(outs, FOCUS):
        assert o.metadata["attributes"]["focus"] == pytest.approx(u)
        assert float(o.metadata["header"]["clpost.focusDistance_m"]) == u


def test_exr_driven_frame_equals_the_same_focus_given_as_a_flag(tmp_path):
    outs = _process_pull(tmp_path)
    src = tmp_path / "in" / "pull.0002.exr"
    assert main(["process", str(src), "-o", str(tmp_path / "flag.exr"), "--depth-of-field", "on",
                 "--f-number", str(N), "--focus", str(FOCUS[1]), "--quiet"]) == 0
    np.testing.assert_array_equal(exr.read_frame(tmp_path / "flag.exr").color, outs[1].color)


def test_focus_pull_builds_no_new_plan_or_program():
    frame = planes_scene(160, 48, DEPTHS)
    cam = Camera(f_number=N, depth_of_field=True, focus_distance_m=FOCUS[0])
    pipe = Pipeline(cam)
    pipe.run(frame, cam)
    plans, programs = len(pipe._plans), len(pipe.runtime._programs)
    for u in FOCUS:
        pipe.run(frame, cam.with_(focus_distance_m=u))
    assert len(pipe._plans) == plans == 1
    assert len(pipe.runtime._programs) == programs
    b = bench(cam, frame, FOCUS, repeats=1)
    assert b["pull_plans"] == b["pull_plans_after_warmup"] == 1
    assert b["programs_built_after_warmup"] == 0 and b["frames"] == len(FOCUS)


def test_contact_sheet_stacks_frames():
    a, b = np.zeros((2, 3, 3), np.float32), np.ones((2, 3, 3), np.float32)
    sheet = contact_sheet([a, b], gap=1)
    assert sheet.shape == (5, 3, 3) and sheet[3:].min() == 1 and sheet[:3].max() == 0

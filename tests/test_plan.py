"""The public Plan: built once per camera structure and size, run per frame with per-frame scalars."""
import math

import numpy as np
import pytest

from clpost import Camera, Frame, Pipeline
from clpost.errors import InputError
from clpost.plan import Plan


def scene(rng, w=37, h=23):
    color = rng.uniform(0.05, 2.0, size=(h, w, 3)).astype(np.float32)
    depth = np.where(np.arange(w)[None, :] < w // 2, 0.8, 6.0).repeat(h, 0).astype(np.float32)
    depth[0, 0] = np.inf
    return Frame(color, depth=depth)


def test_a_focus_pull_reuses_the_plan_and_matches_a_fresh_pipeline(rng):
    frame = scene(rng, w=160, h=40)
    cam = Camera(f_number=2.0, depth_of_field=True, blades=6, focus_distance_m=0.8)
    pipe = Pipeline(cam, quality="draft")
    plan = pipe.plan_for(frame)
    assert isinstance(plan, Plan) and plan.stage_names[0] == "dof"
    plan.run(frame)
    programs = len(pipe.runtime._programs)
    for focus, f_number in ((1.5, 2.0), (4.0, 2.8), (6.0, 1.4)):
        cam_k = cam.with_(focus_distance_m=focus, f_number=f_number)
        assert pipe.plan_for(frame, cam_k) is plan  # scalars: the same plan, no rebuild
        out = plan.run(frame, cam_k).color
        assert len(pipe.runtime._programs) == programs
        fresh = Pipeline(cam_k, quality="draft").run(frame).color
        np.testing.assert_array_equal(out, fresh)
        assert plan.last_timings["dof"] > 0 and plan.last_host_ms >= 0


def test_a_structural_change_makes_a_new_plan_and_plan_run_refuses_it(rng):
    frame = scene(rng)
    cam = Camera(f_number=2.0, depth_of_field=True, blades=6, focus_distance_m=0.8)
    pipe = Pipeline(cam, quality="draft")
    plan = pipe.plan_for(frame)
    other = cam.with_(blades=5)
    assert pipe.plan_for(frame, other) is not plan
    with pytest.raises(InputError, match="Pipeline.run"):
        plan.run(frame, other)
    with pytest.raises(InputError, match="built for 37x23"):
        plan.run(scene(rng, w=16, h=9), cam)
    with pytest.raises(InputError, match="clpost.Frame"):
        pipe.run(frame.color)


def test_launches_carry_the_sizes_a_resampling_stage_changes(rng):
    from clpost.calibration import OpenCVModel, required_render

    model = OpenCVModel(width=40, height=30, fx=38.0, fy=38.0, cx=19.5, cy=14.5, k1=-0.2)
    spec = required_render(model)
    frame = Frame(rng.uniform(0, 1, (spec.height, spec.width, 3)).astype(np.float32))
    plan = Pipeline(Camera(lens="thin:12", distortion=model, vignetting="natural")).plan_for(frame)
    kinds = [(L.kind, L.in_size, L.out_size) for L in plan.launches]
    assert ("gather", (spec.width, spec.height), (40, 30)) in kinds
    assert plan.output_size == (40, 30) and plan.kernel_names[-1].startswith("vignetting")
    assert plan.run(frame).color.shape == (30, 40, 3)


def test_depth_range_is_nearest_farthest_finite_and_sky():
    d = np.array([[0.5, 3.0], [np.inf, 2.0]], np.float32)
    assert Frame(np.zeros((2, 2, 3), np.float32), depth=d).depth_range == (0.5, 3.0, True)
    sky = Frame(np.zeros((2, 2, 3), np.float32), depth=np.full((2, 2), np.inf, np.float32))
    near, far, has_sky = sky.depth_range
    assert math.isinf(near) and math.isinf(far) and has_sky
    assert Frame(np.zeros((2, 2, 3), np.float32)).depth_range is None


# -- recorded launches (clpost.runtime_record) --------------------------------------------------

def _count_argument_sets(monkeypatch):
    """Count every kernel argument set through pyopencl (set_args: one per argument)."""
    import pyopencl as cl

    counts = {"args": 0}
    set_args, set_arg = cl.Kernel.set_args, cl.Kernel.set_arg

    def counting_set_args(self, *a):
        counts["args"] += len(a)
        return set_args(self, *a)

    def counting_set_arg(self, i, v):
        counts["args"] += 1
        return set_arg(self, i, v)

    monkeypatch.setattr(cl.Kernel, "set_args", counting_set_args)
    monkeypatch.setattr(cl.Kernel, "set_arg", counting_set_arg)
    return counts


def _worst_case(rng, w=48, h=32):
    """The bench's worst case at a small size: dof, astigmatism, distortion (extended-frustum
    render), vignetting, exposure — with a velocity buffer the distortion resamples."""
    from clpost.calibration import OpenCVModel, required_render

    model = OpenCVModel(width=w, height=h, fx=0.9 * w, fy=0.9 * w, cx=(w - 1) / 2, cy=(h - 1) / 2, k1=-0.1)
    spec = required_render(model)
    depth = np.tile(np.geomspace(0.5, 30.0, spec.width).astype(np.float32), (spec.height, 1))
    velocity = rng.uniform(-2, 2, (spec.height, spec.width, 2)).astype(np.float32)
    frame = Frame(rng.uniform(0.05, 2.0, (spec.height, spec.width, 3)).astype(np.float32), depth=depth,
                  velocity=velocity)
    cam = Camera(lens="thin:20", sensor_mm=(20.0 / 0.9, 20.0 / 0.9 * h / w), f_number=1.4, depth_of_field=True,
                 focus_distance_m=2.0, distortion=model, vignetting="natural", astigmatism_mm=0.2,
                 field_curvature_mm=0.1, exposure_compensation_ev=0.5)
    stages = ["dof", "astigmatism", "distortion", "vignetting", "exposure"]
    return Pipeline(cam, quality="final", stages=stages), frame, cam, stages


def test_a_replayed_frame_sets_no_kernel_argument(rng, monkeypatch):
    """The second frame of a plan replays the recorded launches: no stage code runs, no argument
    is set, and the image is the first frame's."""
    pipe, frame, cam, stages = _worst_case(rng)
    first = pipe.run(frame)
    plan = pipe.last_plan
    assert plan.stage_names == stages
    counts = _count_argument_sets(monkeypatch)
    recorded = []
    monkeypatch.setattr(plan, "_record", lambda *a: recorded.append(a) or Plan._record(plan, *a))
    again = pipe.run(frame)
    assert pipe.last_plan is plan and not recorded
    assert counts["args"] == 0 and plan.last_patched == []
    np.testing.assert_array_equal(again.color, first.color)
    np.testing.assert_array_equal(again.depth, first.depth)
    np.testing.assert_array_equal(again.velocity, first.velocity)
    assert set(plan.last_timings) >= {"dof", "astigmatism", "distortion", "distortion_aux", "upload", "download"}


def test_changed_scalars_set_only_the_arguments_that_changed(rng, monkeypatch):
    """A focus pull and an exposure change through one plan: only the arguments whose values
    changed are set (by index), and the image is a fresh pipeline's."""
    pipe, frame, cam, stages = _worst_case(rng)
    pipe.run(frame)
    plan = pipe.last_plan
    counts = _count_argument_sets(monkeypatch)
    focused = cam.with_(focus_distance_m=3.5)
    out = pipe.run(frame, focused)
    assert pipe.last_plan is plan
    patched = plan.last_patched
    assert counts["args"] == len(patched) > 0
    # the focus moves the CoC (dof) and the astigmatic foci (astigmatism); the distortion's
    # map and the pointwise kernel (vignetting, exposure) do not depend on it
    assert {name.split("[")[0] for name, _ in patched} == {"dof", "astigmatism"}
    assert len(patched) <= 6
    fresh = Pipeline(focused, quality="final", stages=stages).run(frame)
    np.testing.assert_array_equal(out.color, fresh.color)

    counts["args"] = 0
    brighter = focused.with_(exposure_compensation_ev=1.5)
    out = pipe.run(frame, brighter)
    assert plan.last_patched == [("vignetting__exposure", len(plan.nodes[-1].args) - 1)]
    assert counts["args"] == 1
    np.testing.assert_array_equal(out.color, Pipeline(brighter, quality="final", stages=stages).run(frame).color)


@pytest.mark.parametrize("stages, cam", [
    (["motion_blur"], Camera(shutter_s=1 / 48, frame_rate_fps=24.0)),
    (["sensor"], Camera(sensor_preset="smartphone")),
])
def test_a_frame_index_reaches_the_stages_that_hash_it(rng, stages, cam):
    """Motion blur (gather) and the sensor's noise (pointwise) hash the frame index: a replay must
    not keep the recorded index (Stage.replay_key)."""
    w, h = 40, 24
    velocity = np.zeros((h, w, 2), np.float32)
    velocity[..., 0] = np.linspace(0, 9, w)[None, :]
    color = rng.uniform(0, 1, (h, w, 3)).astype(np.float32)
    frames = [Frame(color, depth=np.full((h, w), 3.0, np.float32), velocity=velocity, metadata={"frame_index": i})
              for i in (0, 1)]
    pipe = Pipeline(cam, stages=["exposure", *stages])  # sensor requires exposure (an identity here)
    assert pipe.plan(frames[0]) == stages
    a, b = (pipe.run(f).color for f in frames)
    assert np.any(a != b)  # the noise changes with the index
    np.testing.assert_array_equal(b, Pipeline(cam, stages=["exposure", *stages]).run(frames[1]).color)


def test_plans_that_share_a_stage_take_turns(rng):
    """Two plans of one pipeline (two field curvatures, same size) share the stages' scratch
    state (the astigmatism's focal offsets are computed once per camera and size): running one
    plan after the other re-records rather than replaying over the other's state."""
    frame = scene(rng, w=64, h=32)
    cams = [Camera(f_number=2.0, astigmatism_mm=0.3, field_curvature_mm=fc, depth_of_field=False)
            for fc in (0.2, -0.3)]
    pipe = Pipeline(cams[0], stages=["astigmatism"])
    first = [pipe.run(frame, c).color for c in cams]
    assert pipe.plan_for(frame, cams[0]) is not pipe.plan_for(frame, cams[1])
    for c, want in zip(cams, first):
        np.testing.assert_array_equal(pipe.run(frame, c).color, want)
    np.testing.assert_array_equal(first[0], Pipeline(cams[0], stages=["astigmatism"]).run(frame).color)


def test_a_recorded_stage_cannot_read_the_device_back(rng):
    from clpost.runtime_record import Recorder

    pipe = Pipeline(Camera())
    rt = pipe.runtime
    rec = Recorder(rt, scene(rng), key=None)
    buf = rt.empty((4,))
    with pytest.raises(RuntimeError, match="reads nothing back"):
        rec.copy(np.empty(4, np.float32), buf, blocking=True)


def test_pointwise_tables_shared_between_plans_are_not_replayed_stale(rng):
    """Two plans of one pipeline and size share the pointwise tables' buffers (vignetting's RI
    plane): a plan whose arguments are unchanged still re-uploads its table after the other plan
    wrote the buffer."""
    frame = scene(rng, w=64, h=32)
    cams = [Camera(vignetting="natural", lens=lens, depth_of_field=False) for lens in ("thin:24", "thin:85")]
    pipe = Pipeline(cams[0], stages=["vignetting"])
    first = [pipe.run(frame, c).color for c in cams]
    assert pipe.plan_for(frame, cams[0]) is not pipe.plan_for(frame, cams[1]) and np.any(first[0] != first[1])
    for c, want in zip(cams, first):
        np.testing.assert_array_equal(pipe.run(frame, c).color, want)


def test_plan_run_downloads_into_a_pinned_out_array_from_pinned_inputs(rng):
    """Frames whose arrays live in page-locked memory (Runtime.pinned_empty) and an ``out=``
    array give the image of ordinary arrays; ``out`` is the returned colour; a wrong ``out`` is
    refused with one line naming the shape it must have."""
    frame = scene(rng, w=64, h=24)
    cam = Camera(f_number=2.0, depth_of_field=True, blades=6, focus_distance_m=0.8)
    pipe = Pipeline(cam, quality="draft")
    plan = pipe.plan_for(frame)
    want = plan.run(frame).color
    rt = pipe.runtime
    color, depth = rt.pinned_empty(frame.color.shape), rt.pinned_empty(frame.depth.shape)
    color[...], depth[...] = frame.color, frame.depth
    out = rt.pinned_empty(want.shape)
    got = plan.run(frame.replace(color=color, depth=depth), out=out)
    assert got.color is out
    np.testing.assert_array_equal(out, want)
    with pytest.raises(InputError, match=r"out= must be .*\(24, 64, 3\)"):
        plan.run(frame, out=np.empty((24, 63, 3), np.float32))

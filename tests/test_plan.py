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

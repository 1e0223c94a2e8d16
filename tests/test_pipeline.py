"""Planner: registry and names, planning and explain, fusion, buffer/program reuse."""
import re
from pathlib import Path

import numpy as np
import pytest

import clpost.pipeline as pipeline_mod
from clpost import Camera, Frame, InputError, Pipeline
from clpost.codegen import fused_source
from clpost.runtime import kernels_dir
from clpost.stages import GatherStage, PointwiseStage, registry
from clpost.stages.exposure import Exposure, exposure_gain

from conftest import assert_planned, odd_frame

TESTS = Path(__file__).parent


def test_stage_names_match_kernel_files_functions_and_tests():
    assert list(registry())[0:1] and "exposure" in registry()
    for name, cls in registry().items():
        assert re.fullmatch(r"[a-z_]+", name)
        src = kernels_dir() / f"{name}.cl"
        text = src.read_text()
        if issubclass(cls, PointwiseStage):
            assert re.search(rf"\b{name}_apply\s*\(", text), f"{src} must define {name}_apply"
            kname, fused = fused_source([cls()], "interleaved", "interleaved")
            assert kname == name and f"__kernel void {name}(" in fused
        else:
            assert re.search(rf"__kernel\s+void\s+{name}\s*\(", text), f"{src} must define __kernel {name}"
        assert (TESTS / f"test_{name}.py").is_file(), f"stage {name} needs tests/test_{name}.py"


def test_unknown_stage_and_quality_are_refused():
    with pytest.raises(InputError, match="unknown stage.*bokeh.*known: .*exposure"):
        Pipeline(Camera(luminance_scale=1.0), stages=["bokeh"])
    with pytest.raises(InputError, match="quality 'ultra'"):
        Pipeline(Camera(luminance_scale=1.0), quality="ultra")


def test_explain_lists_every_stage_with_a_reason(rng):
    frame = odd_frame(rng)
    lines = Pipeline(Camera(luminance_scale=1.0), stages=[]).explain(frame)
    assert [e.stage for e in lines] == list(registry())
    assert all(not e.planned and "--stages" in e.reason for e in lines)
    assert Pipeline(Camera(luminance_scale=1.0), stages=[]).run(frame).color is frame.color


class Tint(PointwiseStage):
    """A test-only second pointwise stage: per-channel gain depending on x (exercises PixelCtx)."""

    name = "tint"
    order = 75.0
    args = (("float", "k"), ("__global const float *", "lut"))

    def source(self):
        return """
inline void tint_apply(CLP_F *r, CLP_F *g, CLP_F *b, const CLP_CTX p, const float k, __global const float *lut) {
    *r = *r * lut[0] + k * CLP_X(p);
    *g = *g * lut[1] + k * CLP_X(p);
    *b = *b * lut[2] + k * CLP_X(p);
}"""

    def skip_reason(self, camera, frame):
        return None

    def values(self, camera, frame):
        return (np.float32(0.5), np.array([1.0, 2.0, 3.0], np.float32))

    def reference(self, camera, frame, color):
        x = np.arange(frame.width)[None, :, None]
        return color * np.array([1.0, 2.0, 3.0]) + 0.5 * x


def test_consecutive_pointwise_stages_fuse_into_one_kernel(rng, monkeypatch):
    reg = {"exposure": Exposure, "tint": Tint}
    monkeypatch.setattr(pipeline_mod, "registry", lambda: reg)
    frame = odd_frame(rng)
    pipe = Pipeline(Camera(luminance_scale=1.0))
    assert pipe.plan(frame) == ["exposure", "tint"]
    assert pipe.kernels(frame) == ["exposure__tint"]
    out = pipe.run(frame)
    assert set(pipe.last_timings) == {"upload", "exposure__tint", "download"}
    np.testing.assert_allclose(out.color, pipe.reference(frame), rtol=1e-6, atol=1e-6)
    # restricting to one stage gives that stage alone
    only = Pipeline(Camera(luminance_scale=1.0), stages=["tint"])
    assert_planned(only, frame, "tint")
    np.testing.assert_allclose(only.run(frame).color, Tint().reference(None, frame, frame.color.astype(float)),
                               rtol=1e-6, atol=1e-6)


def test_buffers_are_reused_per_resolution(rng):
    pipe = Pipeline(Camera(luminance_scale=1.0))
    a, b = odd_frame(rng), odd_frame(rng)
    pipe.run(a)
    bufs = pipe._buffers
    pipe.run(b)
    assert pipe._buffers is bufs
    pipe.run(odd_frame(rng, w=16, h=9))
    assert pipe._buffers is not bufs and pipe._buffers.size == (16, 9)


def test_depth_and_velocity_pass_through_untouched(rng):
    frame = odd_frame(rng).replace(velocity=rng.normal(size=(23, 37, 2)))
    out = Pipeline(Camera(luminance_scale=1.0)).run(frame)
    assert out.depth is frame.depth and out.velocity is frame.velocity
    assert out.metadata["plan"] == ["exposure"]
    assert out.metadata["camera"]["clpost.fNumber"] == "2"


def test_auto_exposure_changes_only_scalars(rng):
    pipe = Pipeline(Camera(luminance_scale=1.0, shutter_s=None))
    f1 = odd_frame(rng, scale=1.0)
    f2 = odd_frame(rng, scale=100.0)
    o1, o2 = pipe.run(f1), pipe.run(f2)
    assert len(pipe._plans) == 1  # per-frame scalars: one plan, no rebuild
    # the meter brings both to the same mean exposure level
    assert o1.color.mean() == pytest.approx(o2.color.mean(), rel=0.05)
    assert exposure_gain(pipe.camera_for(f1)) == pytest.approx(100 * exposure_gain(pipe.camera_for(f2)), rel=0.1)


def test_a_stage_needing_a_missing_buffer_says_so(rng, monkeypatch):
    class NeedsDepth(Tint):
        name = "needs_depth"
        reads = ("depth",)

    monkeypatch.setattr(pipeline_mod, "registry", lambda: {"needs_depth": NeedsDepth})
    frame = odd_frame(rng, depth=False)
    with pytest.raises(InputError, match="needs_depth' needs the frame's depth buffer"):
        Pipeline(Camera(luminance_scale=1.0)).plan(frame)


def test_half_float_input_runs(rng):
    c = (rng.random((23, 37, 3)) * 1000).astype(np.float16)
    frame = Frame(c, depth=np.full((23, 37), np.inf, np.float16))
    pipe = Pipeline(Camera(luminance_scale=1.0))
    assert_planned(pipe, frame, "exposure")
    np.testing.assert_allclose(pipe.run(frame).color, pipe.reference(frame), rtol=2e-7)


class BoxBlur(GatherStage):
    """A test-only gather: 3×3 box blur (edge-clamped) scaled by min(depth, 1) — exercises the
    planar layout, layout conversions around gathers, and the depth upload."""

    name = "boxblur"
    order = 10.0
    reads = ("depth",)
    SRC = """
__kernel void boxblur(__global const float *src, __global float *dst, const int width,
                      const int height, __global const float *depth) {
    const int x = get_global_id(0), y = get_global_id(1);
    const size_t n = (size_t)width * height, i = (size_t)y * width + x;
    for (int c = 0; c < 3; ++c) {
        float acc = 0.0f;
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
                const int xx = clamp(x + dx, 0, width - 1), yy = clamp(y + dy, 0, height - 1);
                acc += src[c * n + (size_t)yy * width + xx];
            }
        dst[c * n + i] = acc / 9.0f * fmin(depth[i], 1.0f);
    }
}"""

    def skip_reason(self, camera, frame):
        return None

    def enqueue(self, rt, camera, frame, src, dst, aux):
        import pyopencl as cl

        k = cl.Kernel(rt.program(self.SRC, "boxblur"), "boxblur")
        k.set_args(src, dst, np.int32(frame.width), np.int32(frame.height), aux["depth"])
        return [cl.enqueue_nd_range_kernel(rt.queue, k, (frame.width, frame.height), None)]

    def reference(self, camera, frame, color):
        p = np.pad(color, ((1, 1), (1, 1), (0, 0)), mode="edge")
        h, w = frame.height, frame.width
        acc = sum(p[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3)) / 9.0
        return acc * np.minimum(frame.depth, 1.0)[..., None]


class DepthTint(Tint):
    """Pointwise stage reading depth: c * depth."""

    name = "depthtint"
    order = 80.0
    reads = ("depth",)
    args = ()

    def source(self):
        return """
inline void depthtint_apply(CLP_F *r, CLP_F *g, CLP_F *b, const CLP_CTX p, __global const float *depth) {
    const CLP_F z = CLP_PLANE(depth, p);
    *r *= z;
    *g *= z;
    *b *= z;
}"""

    def values(self, camera, frame):
        return ()

    def reference(self, camera, frame, color):
        return color * frame.depth[..., None]


@pytest.mark.parametrize("names, kernels", [
    (["boxblur"], ["convert_interleaved_to_planar", "boxblur", "convert_planar_to_interleaved"]),
    (["boxblur", "exposure"], ["convert_interleaved_to_planar", "boxblur", "exposure"]),
    (["boxblur", "exposure", "depthtint"], ["convert_interleaved_to_planar", "boxblur", "exposure__depthtint"]),
    (["exposure", "depthtint"], ["exposure__depthtint"]),
])
def test_gathers_get_planar_buffers_and_aux_uploads(rng, monkeypatch, names, kernels):
    reg = {"boxblur": BoxBlur, "exposure": Exposure, "depthtint": DepthTint}
    monkeypatch.setattr(pipeline_mod, "registry", lambda: reg)
    frame = odd_frame(rng)
    frame = frame.replace(depth=np.where(rng.random((23, 37)) < 0.1, np.inf, frame.depth))
    frame = frame.replace(depth=np.minimum(frame.depth, 3.0))  # keep the depth tint finite
    pipe = Pipeline(Camera(luminance_scale=1.0), stages=names)
    assert pipe.kernels(frame) == kernels
    out = pipe.run(frame)
    np.testing.assert_allclose(out.color, pipe.reference(frame), rtol=2e-6, atol=1e-7)
    assert set(kernels) <= set(pipe.last_timings)


VECTOR_GROUPS = {
    "vignetting+exposure": (dict(f_number=2.0, vignetting="natural"), ["vignetting", "exposure"]),
    "exposure+film+print": (dict(f_number=2.0, film="fuji-superia-400", grain_amount=0.0),
                            ["exposure", "film", "print"]),
    "film+linear print": (dict(film="kodak-ektar-100", film_output="linear", grain_amount=0.0), ["film", "print"]),
    "exposure+sensor": (dict(f_number=2.0, sensor_preset="smartphone", iso=800), ["exposure", "sensor"]),
    # white grain (the default camera's grain is far under a pixel): GrainWhite, a stage with
    # per-work-item state, 32 pixels per work-item as two 16-lane calls
    "film+white grain+print": (dict(film="kodak-ektar-100"), ["film", "grain", "print"]),
}
# every other pointwise stage of the registry, alone, with the camera its class declares as an
# example (Stage.example): a new stage is covered without editing this file
VECTOR_GROUPS.update({
    name: (dict(cls.example), [name]) for name, cls in registry().items()
    if issubclass(cls, PointwiseStage) and not any(name in names for _, names in VECTOR_GROUPS.values())})


def test_vector_groups_cover_every_pointwise_stage():
    covered = {n for _, names in VECTOR_GROUPS.values() for n in names}
    pointwise = {n for n, cls in registry().items() if issubclass(cls, PointwiseStage)}
    assert pointwise <= covered  # (each group's camera planning its stages is checked below)


_LAYOUTS = [("interleaved", "interleaved"), ("planar", "planar"), ("planar", "interleaved"), ("interleaved", "planar")]


# every width and layout pair for the first group (a row of one single 16-lane vector, a work-item
# and pixels one by one, two work-items, three and a tail); the other groups at one width with a
# work-item and a tail (37 = 32 + 5), white grain's also at 100 = 3·32 + 4 and at 53 = 32 + 16 + 5
# (a row's last whole vector, which prepares its own state), in two layout pairs
@pytest.mark.parametrize("group, w, layouts",
                         [("vignetting+exposure", w, lay) for w in (16, 37, 64, 100) for lay in _LAYOUTS]
                         + [(g, 37, lay) for g in list(VECTOR_GROUPS)[1:] for lay in _LAYOUTS[::3]]
                         + [("film+white grain+print", w, lay) for w in (100, 53) for lay in _LAYOUTS[::3]])
def test_sixteen_pixel_vector_path_equals_the_one_pixel_path(rng, w, layouts, group):
    """Every pointwise stage runs as 16-lane vectors, several per work-item (a row's last pixels as
    single vectors, then one by one), from its one width-generic source; the result is bit for bit
    the one-pixel kernel's, for every layout pair (white grain's state shared by a pair of vectors
    included)."""
    import pyopencl as cl

    from clpost.codegen import ITEM_VECTORS, VECTOR_PIXELS, global_size, item_pixels, vector_path

    h = 5
    kw, names = VECTOR_GROUPS[group]
    frame = odd_frame(rng, w=w, h=h, scale=50.0)
    # signals from deep shadow (sensor: Poisson lanes) to highlights (normal lanes), and zeros
    frame = frame.replace(color=(frame.color * np.float32(10.0) ** rng.uniform(-4, 1, (h, w, 1))).astype(np.float32))
    frame.color[0, :3] = 0.0
    pipe = Pipeline(Camera(luminance_scale=1.0, **kw), stages=names, already_applied=() if "exposure" in names else ("exposure",))
    pipe.run(frame)
    cam = pipe.camera_for(frame)
    plan = pipe.plan_for(frame, cam)
    stages = plan.stages
    assert [s.name for s in stages] == names
    k = ITEM_VECTORS * VECTOR_PIXELS  # 16-lane vectors per work-item
    assert vector_path(stages) and item_pixels(stages) == k and global_size(stages, *layouts, w, h) == ((w + k - 1) // k, h)
    rt, bufs = pipe.runtime, plan.buffers
    cl.enqueue_copy(rt.queue, bufs.color_in, np.ascontiguousarray(frame.color))
    defines = {k: v for s in stages for k, v in s.defines(cam).items()}
    args = [np.int32(w), np.int32(h)] + [a for s in stages for a in plan.arg_values(s, cam, frame)]
    outs = []
    for vec, gsize in ((False, (w, h)), (True, ((w + k - 1) // k, h))):
        name, src = fused_source(stages, *layouts, vector=vec)
        kern = cl.Kernel(rt.program(src, name, defines), name)
        dst = rt.empty((h, w, 3))
        kern.set_args(bufs.color_in, dst, *args)
        cl.enqueue_nd_range_kernel(rt.queue, kern, gsize, None)
        out = np.empty((h, w, 3), np.float32)
        cl.enqueue_copy(rt.queue, out, dst)
        outs.append(out)
    assert np.array_equal(outs[0], outs[1])
    assert np.isfinite(outs[0]).all()


def test_static_tables_are_uploaded_once_and_changed_ones_again(rng, monkeypatch):
    """vignetting's per-pixel RI plane is built on the device from the LUT and kept: the second
    frame copies neither again; a camera with another curve (focus moves the exit pupil)
    uploads its new LUT — not a plane: no host pass over the pixels — and the image follows it."""
    import pyopencl as cl

    frame = odd_frame(rng, w=37, h=23)
    pipe = Pipeline(Camera(luminance_scale=1.0, vignetting="natural"), stages=["vignetting", "exposure"])
    pipe.run(frame)
    plane_bytes = 37 * 23 * 4
    copies = []
    real = cl.enqueue_copy

    def spy(queue, dst, src, **kw):
        copies.append(getattr(src, "nbytes", None))
        return real(queue, dst, src, **kw)

    monkeypatch.setattr(cl, "enqueue_copy", spy)
    first = pipe.run(frame).color
    lut_bytes = 1024 * 4  # vignetting.LUT_SIZE float32
    assert plane_bytes not in copies and lut_bytes not in copies  # colour in/out (37·23·12 bytes) only
    pipe2 = Pipeline(Camera(luminance_scale=1.0, vignetting="natural", focus_distance_m=0.3), stages=["vignetting", "exposure"])
    pipe2._buffers = pipe._buffers  # same device buffers, new curve
    copies.clear()
    second = pipe2.run(frame).color
    assert lut_bytes in copies and plane_bytes not in copies and not np.array_equal(first, second)
    assert_planned(pipe2, frame, "vignetting", "exposure")
    np.testing.assert_allclose(second, pipe2.reference(frame), rtol=2e-5)


def test_a_gpu_runtime_plans_one_pixel_per_work_item(rng, monkeypatch):
    """On a device that does not want wide work-items (a GPU: coalesced loads) the plan builds the
    one-pixel fused kernel over the whole frame; the image is the wide kernel's, bit for bit."""
    from clpost.runtime import Runtime

    kw, names = VECTOR_GROUPS["vignetting+exposure"]
    frame = odd_frame(rng, w=37, h=5, scale=50.0)
    cam = Camera(luminance_scale=1.0, **kw)
    wide = Pipeline(cam, stages=names).run(frame).color
    monkeypatch.setattr(Runtime, "wide", property(lambda self: False))
    pipe = Pipeline(cam, stages=names)
    narrow = pipe.run(frame).color
    plan = pipe.plan_for(frame, pipe.camera_for(frame))
    node = next(n for n in plan.nodes if not n.gather and n.stages)
    assert node.size == (37, 5)
    assert np.array_equal(wide, narrow)

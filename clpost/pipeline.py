"""Plan and run a chain of stages on frames: build kernels once, run many frames.

Plan time vs call time (after reikna): :meth:`Pipeline.plan` decides which stages change the
image for this camera and frame (a stage that is an identity is not planned — "model only what the
scene requires"); consecutive pointwise stages are fused into **one generated kernel** (one pass
over memory); programs are built once per (stages, defines) and device buffers are allocated once
per resolution, then reused for every frame. Per-frame scalars (exposure gain …) are kernel
arguments, so changing them never rebuilds anything.

Device layouts: the host frame (H, W, 3) is uploaded as is ("interleaved"); gathers work on
planar buffers. The first and last fused kernels convert between the two as part of their single
pass; a plan that starts or ends with a gather gets a conversion kernel there.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from .camera import Camera
from .errors import InputError
from .frame import Frame
from . import metering
from .runtime import kernel_source
from .stages import QUALITIES, GatherStage, PointwiseStage, Stage, registry

INTERLEAVED, PLANAR = "interleaved", "planar"


@dataclass(frozen=True)
class PlanEntry:
    """One line of ``--explain``: a stage, whether it runs, and why."""

    stage: str
    planned: bool
    reason: str

    def __str__(self) -> str:
        return f"{'+' if self.planned else '-'} {self.stage:<14} {self.reason}"


AUX_BUFFERS = {
    # Frame buffer → OpenCL parameter of a fused kernel (uploaded once per frame when a planned
    # stage reads it). Layouts: depth H×W float32 (+inf sky); velocity H×W×2 float32 interleaved.
    "depth": "__global const float *restrict depth",
    "velocity": "__global const float *restrict velocity",
}


VECTOR_PIXELS = 16
"""Pixels per work-item of a fused kernel whose stages all have an explicit-vector form
(``PointwiseStage.vector``: ``<name>_apply16`` on float16 channels of 16 pixels of a row). PoCL
does not vectorise the one-pixel-per-work-item form of the fused stage code (its vectoriser
remarks: float3 values, library calls, selects), and explicit float16 is what it compiles to
AVX-512 (the dof and astigmatism gathers found the same)."""


def vector_path(stages: list[PointwiseStage]) -> bool:
    """Whether :func:`fused_source` generates the :data:`VECTOR_PIXELS`-wide kernel for ``stages``
    (every stage has the vector form and none reads depth or velocity)."""
    return bool(stages) and all(getattr(s, "vector", False) and not s.reads for s in stages)


def _lanes(vec: str, first: int) -> str:
    """``(float16)(vec[first], vec[first + 3], …)`` from three float16 ``vec0..vec2`` holding 48
    consecutive interleaved floats: channel ``first`` of 16 pixels."""
    comps = [f"{vec}{(first + 3 * k) // 16}.s{(first + 3 * k) % 16:x}" for k in range(16)]
    return f"(float16)({', '.join(comps)})"


def _interleave(part: int) -> str:
    """The float16 holding interleaved floats 16·part … 16·part + 15 of channels r, g, b."""
    comps = [f"{'rgb'[f % 3]}.s{f // 3:x}" for f in range(16 * part, 16 * part + 16)]
    return f"(float16)({', '.join(comps)})"


def fused_source(stages: list[PointwiseStage], src_layout: str, dst_layout: str,
                 vector: bool | None = None) -> tuple[str, str]:
    """Generate one OpenCL kernel applying ``stages`` in order to each pixel.

    Returns ``(kernel_name, source)``. The kernel is named after its stages joined by ``__``
    (a single stage's kernel is named like the stage); with no stages it only converts layouts.
    Parameters: ``src, dst, width, height``, then ``depth`` / ``velocity`` if any stage reads
    them, then each stage's ``args`` prefixed ``<stage>_``. A stage that reads depth or velocity
    receives those pointers right after ``p``, in that order.
    """
    name = "__".join(s.name for s in stages) or f"convert_{src_layout}_to_{dst_layout}"
    params = ["__global const float *restrict src", "__global float *restrict dst",
              "const int width", "const int height"]
    aux = [b for b in AUX_BUFFERS if any(b in s.reads for s in stages)]
    params += [AUX_BUFFERS[b] for b in aux]
    body = []
    for s in stages:
        call_args = ["c", "p"] + [b for b in AUX_BUFFERS if b in s.reads]
        for cl_type, arg in s.args:
            params.append(f"{'const ' if '*' not in cl_type else ''}{cl_type} {s.name}_{arg}")
            call_args.append(f"{s.name}_{arg}")
        body.append(f"    c = {s.name}_apply({', '.join(call_args)});")
    if not stages and src_layout != dst_layout:
        return name, kernel_source("common") + _convert_source(name, src_layout)
    load = "load_interleaved(src, i)" if src_layout == INTERLEAVED else "load_planar(src, i, n)"
    store = ("store_interleaved(dst, i, c);" if dst_layout == INTERLEAVED
             else "store_planar(dst, i, n, c);")
    parts = [kernel_source("common")] + [s.source() for s in stages]
    nl = "\n"
    if vector_path(stages) if vector is None else vector:
        calls16 = []
        for s in stages:
            extra = "".join(f", {s.name}_{arg}" for _, arg in s.args)
            calls16.append(f"        {s.name}_apply16(&r, &g, &b, p16{extra});")
        if src_layout == INTERLEAVED:
            load16 = ("const float16 v0 = vload16(0, src + 3 * i), v1 = vload16(1, src + 3 * i), "
                      "v2 = vload16(2, src + 3 * i);\n"
                      f"        float16 r = {_lanes('v', 0)};\n        float16 g = {_lanes('v', 1)};\n"
                      f"        float16 b = {_lanes('v', 2)};")
        else:
            load16 = "float16 r = vload16(0, src + i), g = vload16(0, src + n + i), b = vload16(0, src + 2 * n + i);"
        if dst_layout == INTERLEAVED:
            store16 = "\n".join(f"        vstore16({_interleave(k)}, {k}, dst + 3 * i);" for k in range(3))
        else:
            store16 = ("        vstore16(r, 0, dst + i);\n        vstore16(g, 0, dst + n + i);\n"
                       "        vstore16(b, 0, dst + 2 * n + i);")
        tail = "\n".join("    " + line for line in body)
        parts.append(f"""
__kernel void {name}({", ".join(params)})
{{
    const int x0 = get_global_id(0) * {VECTOR_PIXELS};
    const int y = get_global_id(1);
    if (x0 >= width || y >= height) return;
    const size_t n = (size_t)width * (size_t)height;
    const size_t i0 = (size_t)y * (size_t)width + (size_t)x0;
    (void)n;
    if (x0 + {VECTOR_PIXELS} <= width) {{
        const size_t i = i0;
        const PixelCtx16 p16 = {{x0, y, width, height, i0}};
        {load16}
{nl.join(calls16)}
{store16}
    }} else {{  /* the row's last 1–15 pixels, one by one */
        for (int x = x0; x < width; ++x) {{
            const size_t i = i0 + (size_t)(x - x0);
            const PixelCtx p = {{x, y, width, height, i}};
            float3 c = {load};
{tail}
            {store}
        }}
    }}
}}
""")
        return name, "\n".join(parts)
    parts.append(f"""
__kernel void {name}({", ".join(params)})
{{
    const int x = get_global_id(0);
    const int y = get_global_id(1);
    if (x >= width || y >= height) return;
    const size_t n = (size_t)width * (size_t)height;
    const size_t i = (size_t)y * (size_t)width + (size_t)x;
    const PixelCtx p = {{x, y, width, height, i}};
    (void)n; (void)p;
    float3 c = {load};
{nl.join(body)}
    {store}
}}
""")
    return name, "\n".join(parts)


CONVERT_PIXELS = 4
"""Pixels per work-item of a plain layout conversion: three ``vload4`` of 4 interleaved pixels
and one ``vstore4`` per plane (or the reverse). Measured at 1080p on the 2-core PoCL CPU (same
run, best of 17): 1.8 ms vs 6.2 ms for one pixel per work-item with scalar loads, whose stride-3
access PoCL does not vectorise."""


def global_size(stages: list[PointwiseStage], src_layout: str, dst_layout: str, w: int, h: int) -> tuple[int, int]:
    """NDRange of the kernel :func:`fused_source` generates for this group at ``w`` × ``h``."""
    if not stages and src_layout != dst_layout:
        return (w + CONVERT_PIXELS - 1) // CONVERT_PIXELS, h
    if vector_path(stages):
        return (w + VECTOR_PIXELS - 1) // VECTOR_PIXELS, h
    return w, h


def _convert_source(name: str, src_layout: str) -> str:
    """Interleaved ↔ planar, :data:`CONVERT_PIXELS` pixels per work-item (a row's last 1–3 pixels
    one by one)."""
    if src_layout == INTERLEAVED:
        whole = """const float4 a = vload4(0, src + 3 * i), b = vload4(1, src + 3 * i), c = vload4(2, src + 3 * i);
        vstore4((float4)(a.x, a.w, b.z, c.y), 0, dst + i);
        vstore4((float4)(a.y, b.x, b.w, c.z), 0, dst + n + i);
        vstore4((float4)(a.z, b.y, c.x, c.w), 0, dst + 2 * n + i);"""
        one = "store_planar(dst, j, n, load_interleaved(src, j));"
    else:
        whole = """const float4 r = vload4(0, src + i), g = vload4(0, src + n + i), b = vload4(0, src + 2 * n + i);
        vstore4((float4)(r.x, g.x, b.x, r.y), 0, dst + 3 * i);
        vstore4((float4)(g.y, b.y, r.z, g.z), 0, dst + 3 * i + 4);
        vstore4((float4)(b.z, r.w, g.w, b.w), 0, dst + 3 * i + 8);"""
        one = "store_interleaved(dst, j, load_planar(src, j, n));"
    return f"""
__kernel void {name}(__global const float *restrict src, __global float *restrict dst,
                     const int width, const int height)
{{
    const int x = get_global_id(0) * {CONVERT_PIXELS};
    const int y = get_global_id(1);
    if (x >= width || y >= height) return;
    const size_t n = (size_t)width * (size_t)height;
    const size_t i = (size_t)y * (size_t)width + (size_t)x;
    if (x + {CONVERT_PIXELS} <= width) {{
        {whole}
    }} else {{
        for (size_t j = i; j < i + (size_t)(width - x); ++j)
            {one}
    }}
}}
"""


def _check_calibration_focal(cam: Camera) -> None:
    """Warn when a calibration's focal length disagrees with the camera's lens and sensor: the
    distortion stage uses the calibration, while vignetting, dof and the aberrations use the
    camera's f / pixel pitch."""
    model = cam.distortion
    if model is None:
        return
    f_cam = cam.intrinsics(model.width, model.height)[0]
    if abs(model.fx - f_cam) > 0.01 * f_cam:
        warnings.warn(f"calibration{model._where()} has f_x = {model.fx:.6g} px but the camera "
                      f"({cam.lens}, {cam.sensor_mm[0]:g} mm wide) gives {f_cam:.6g} px at "
                      f"{model.width} px: vignetting, dof and aberrations follow the camera; set "
                      "--lens/--sensor to match the calibration", stacklevel=3)


def resized_view(frame: Frame, size: tuple[int, int], host: dict, by: str) -> Frame:
    """The frame as stages after a resampling stage ``by`` see it: ``size`` (width, height), the
    resampler's depth/velocity/alpha (``host``), and no host color (stages read color on the
    device; a zero-stride placeholder keeps shapes right without allocating)."""
    w, h = size
    placeholder = np.broadcast_to(np.zeros((1, 1, 3), np.float32), (h, w, 3))
    meta = dict(frame.metadata, resampled_by=by)
    meta.pop("intrinsics", None)  # the render's pinhole intrinsics no longer describe these pixels
    return frame.replace(color=placeholder, depth=host.get("depth"), velocity=host.get("velocity"),
                         alpha=host.get("alpha"), metadata=meta, validate=False)


@dataclass
class _Node:
    """One kernel launch of a plan: a fused pointwise group or a gather stage."""

    stages: list[Stage]
    src_layout: str
    dst_layout: str
    kernel: object = None

    @property
    def name(self) -> str:
        return "__".join(s.name for s in self.stages) or f"convert_{self.src_layout}_to_{self.dst_layout}"


@dataclass
class _Buffers:
    size: tuple[int, int]
    color_in: object
    color_out: object
    planar: list = field(default_factory=list)
    aux: dict = field(default_factory=dict)
    args: dict = field(default_factory=dict)
    uploaded: dict = field(default_factory=dict)
    """(stage, arg) → the read-only host array last copied into its buffer (not copied again)."""


class Pipeline:
    """A camera's chain of stages, planned per frame and run with OpenCL.

    ``stages`` restricts the candidates to the named stages (compositors often want one effect);
    ``device`` is a substring of an OpenCL platform/device name (see :mod:`clpost.runtime`).
    """

    def __init__(self, camera: Camera, quality: str = "final", stages: list[str] | None = None,
                 device: str | None = None) -> None:
        if not isinstance(camera, Camera):
            raise InputError(f"Pipeline: camera must be a clpost.Camera, not {type(camera).__name__}")
        if quality not in QUALITIES:
            raise InputError(f"quality {quality!r} is unknown: use one of {', '.join(QUALITIES)}")
        known = registry()
        if stages is not None:
            unknown = [s for s in stages if s not in known]
            if unknown:
                raise InputError(f"--stages: unknown stage(s) {', '.join(unknown)}; known: {', '.join(known)}")
        self.camera = camera
        self.quality = quality
        self.device = device
        self._selected = None if stages is None else set(stages)
        self._stages = [cls(quality) for cls in known.values()]
        self._runtime = None
        self._nodes: dict[tuple, list[_Node]] = {}
        self._buffers: _Buffers | None = None
        self.last_timings: dict[str, float] = {}
        """Device milliseconds of the last :meth:`run`, per kernel and for upload/download."""

    # -- planning -----------------------------------------------------------------------------
    @property
    def runtime(self):
        if self._runtime is None:
            from .runtime import get_runtime

            self._runtime = get_runtime(self.device)
        return self._runtime

    def camera_for(self, frame: Frame) -> Camera:
        """The camera resolved for this frame: auto-exposure metered, and a lens_data lens without
        a calibration given its traced distortion at the frame's size."""
        cam = metering.resolve(self.camera, frame)
        if self.camera.distortion is not None:
            _check_calibration_focal(cam)
        if cam.distortion is None and cam.optics is not None and cam.lens_distortion:
            from .calibration import lens_distortion_model

            model = lens_distortion_model(cam, frame.size)
            if model is not None:
                cam = cam.with_(distortion=model)
        return cam

    def explain(self, frame: Frame, camera: Camera | None = None, reasons: bool = True) -> list[PlanEntry]:
        """Every known stage, in physical order, with whether it runs and why (``reasons=False``:
        a planned stage's reason is left empty — some cost a pass over the frame on the host,
        e.g. dof's CoC range, and running a frame does not need them)."""
        cam = camera or self.camera_for(frame)
        out = []
        for st in self._stages:
            if self._selected is not None and st.name not in self._selected:
                out.append(PlanEntry(st.name, False, "not selected by --stages"))
                continue
            why = st.skip_reason(cam, frame)
            if why is None:
                missing = [b for b in st.reads if getattr(frame, b) is None]
                if missing:
                    raise InputError(
                        f"stage '{st.name}' needs the frame's {' and '.join(missing)} buffer; "
                        f"provide it or leave the stage out with --stages"
                    )
                out.append(PlanEntry(st.name, True, st.reason_needed(cam, frame) if reasons else ""))
            else:
                out.append(PlanEntry(st.name, False, why))
        return out

    def plan(self, frame: Frame) -> list[str]:
        """Names of the stages that run for this frame, in order."""
        return [e.stage for e in self.explain(frame) if e.planned]

    def _planned(self, frame: Frame, cam: Camera) -> list[Stage]:
        names = {e.stage for e in self.explain(frame, cam, reasons=False) if e.planned}
        return [s for s in self._stages if s.name in names]

    def kernels(self, frame: Frame) -> list[str]:
        """The kernel launches of this frame's plan (fused groups joined by ``__``)."""
        cam = self.camera_for(frame)
        return [n.name for n in self._build_nodes(self._planned(frame, cam), cam, build=False)]

    def _build_nodes(self, planned: list[Stage], cam: Camera, build: bool = True) -> list[_Node]:
        """Group the plan into kernel launches; build each fused group's program once.

        Each group's program key is its stages plus *their* ``defines`` (structural
        parameters), so a structural change of one stage rebuilds only its own group.
        """
        key = tuple((s.name, tuple(sorted(s.defines(cam).items()))) for s in planned)
        if build and key in self._nodes:
            return self._nodes[key]
        groups: list[list[Stage]] = []
        for s in planned:
            if isinstance(s, PointwiseStage) and groups and groups[-1] and isinstance(groups[-1][0], PointwiseStage):
                groups[-1].append(s)
            else:
                groups.append([s])
        if groups and isinstance(groups[0][0], GatherStage):
            groups.insert(0, [])
        if groups and groups[-1] and isinstance(groups[-1][0], GatherStage):
            groups.append([])
        nodes = []
        for i, g in enumerate(groups):
            gather = bool(g) and isinstance(g[0], GatherStage)
            src = PLANAR if gather or i > 0 else INTERLEAVED
            dst = PLANAR if gather or i < len(groups) - 1 else INTERLEAVED
            nodes.append(_Node(g, src, dst))
        if build:
            import pyopencl as cl

            rt = self.runtime
            for node in nodes:
                if node.stages and isinstance(node.stages[0], GatherStage):
                    continue
                defines: dict = {}
                for s in node.stages:
                    defines.update(s.defines(cam))
                kname, src = fused_source(node.stages, node.src_layout, node.dst_layout)
                prog = rt.program(src, kname, defines)
                node.kernel = cl.Kernel(prog, kname)
            self._nodes[key] = nodes
        return nodes

    # -- running ------------------------------------------------------------------------------
    def _buffers_for(self, w: int, h: int) -> _Buffers:
        if self._buffers is None or self._buffers.size != (w, h):
            rt = self.runtime
            self._buffers = _Buffers((w, h), rt.empty((h, w, 3)), rt.empty((h, w, 3)))
        return self._buffers

    def _planar(self, bufs: _Buffers, k: int, size: tuple[int, int] | None = None):
        if size is not None and size != bufs.size:
            # a resampling gather (distortion) changed the size: later buffers at the new size
            key = ("planar", size, k)
            if key not in bufs.args:
                bufs.args[key] = self.runtime.empty((3, size[1], size[0]))
            return bufs.args[key]
        while len(bufs.planar) <= k:
            w, h = bufs.size
            bufs.planar.append(self.runtime.empty((3, h, w)))
        return bufs.planar[k]

    def _color_out(self, bufs: _Buffers, size: tuple[int, int]):
        if size == bufs.size:
            return bufs.color_out
        key = ("color_out", size)
        if key not in bufs.args:
            bufs.args[key] = self.runtime.empty((size[1], size[0], 3))
        return bufs.args[key]

    def _arg_values(self, stage: PointwiseStage, cam: Camera, frame: Frame, bufs: _Buffers) -> list:
        import pyopencl as cl

        vals = []
        for (cl_type, arg), v in zip(stage.args, stage.values(cam, frame)):
            if "*" in cl_type:
                a = np.ascontiguousarray(v)
                key = (stage.name, arg)
                buf = bufs.args.get(key)
                if buf is None or buf.size != max(a.nbytes, 4):
                    buf = bufs.args[key] = self.runtime.empty(a.shape, a.dtype)
                    bufs.uploaded.pop(key, None)
                # a stage's static table (read-only, the same object) is uploaded once
                if not (bufs.uploaded.get(key) is a and not a.flags.writeable):
                    cl.enqueue_copy(self.runtime.queue, buf, a)
                    bufs.uploaded[key] = a
                vals.append(buf)
            else:
                vals.append(v)
        return vals

    def run(self, frame: Frame) -> Frame:
        """Process one frame; returns a new Frame whose color is the camera's output
        (normalised sensor signal; later stages: the film/sensor's recorded values)."""
        import pyopencl as cl

        from .runtime import event_ms

        cam = self.camera_for(frame)
        planned = self._planned(frame, cam)
        meta = dict(frame.metadata, camera=cam.describe(), plan=[s.name for s in planned])
        self.last_timings = {}
        if not planned:
            return frame.replace(metadata=meta, validate=False)
        nodes = self._build_nodes(planned, cam)
        rt, q = self.runtime, self.runtime.queue
        w, h = frame.width, frame.height
        bufs = self._buffers_for(w, h)
        events = [("upload", cl.enqueue_copy(q, bufs.color_in, frame.color, is_blocking=False))]
        for name in AUX_BUFFERS:
            if any(name in s.reads for s in planned):
                host = getattr(frame, name)
                buf = bufs.aux.get(name)
                if buf is None:
                    buf = bufs.aux[name] = rt.empty(host.shape)
                events.append(("upload", cl.enqueue_copy(q, buf, host, is_blocking=False)))
        src, planar_k = bufs.color_in, 0
        size, host_out, aux = (w, h), {}, bufs.aux
        view = frame  # the frame as the next stage sees it: resampling stages change its size
        for k, node in enumerate(nodes):
            gather = node.kernel is None
            out_size = node.stages[0].output_size(cam, view) if gather else size
            if node.dst_layout == INTERLEAVED:
                dst = self._color_out(bufs, out_size)
            else:
                dst = self._planar(bufs, planar_k, out_size)
                planar_k ^= 1
            if gather:
                stage = node.stages[0]
                for ev in stage.enqueue(rt, cam, view, src, dst, aux):
                    events.append((stage.name, ev))
                host_out.update(stage.host_buffers(cam, view))
                if out_size != size:
                    view = resized_view(frame, out_size, host_out, stage.name)
                    later = [s for n in nodes[k + 1:] for s in n.stages]
                    aux, evs = self._upload_aux(bufs, view, later, out_size)
                    events += evs
                size = out_size
            else:
                w, h = size
                args = [src, dst, np.int32(w), np.int32(h)]
                args += [aux[b] for b in AUX_BUFFERS if any(b in s.reads for s in node.stages)]
                for s in node.stages:
                    args += self._arg_values(s, cam, view, bufs)
                node.kernel.set_args(*args)
                gsize = global_size(node.stages, node.src_layout, node.dst_layout, w, h)
                events.append((node.name, cl.enqueue_nd_range_kernel(q, node.kernel, gsize, None)))
            src = dst
        w, h = size
        out = np.empty((h, w, 3), np.float32)
        events.append(("download", cl.enqueue_copy(q, out, self._color_out(bufs, size), is_blocking=True)))
        for name, ev in events:
            self.last_timings[name] = self.last_timings.get(name, 0.0) + event_ms(ev)
        return frame.replace(color=out, metadata=meta, validate=False, **host_out)

    def reference(self, frame: Frame) -> np.ndarray:
        """The same plan through each stage's float64 numpy reference; returns (H, W, 3) float64."""
        cam = self.camera_for(frame)
        color = frame.color.astype(np.float64)
        view, host = frame, {}
        for s in self._planned(frame, cam):
            color = s.reference(cam, view, color)
            if color.shape[:2] != (view.height, view.width):
                host.update(s.host_buffers(cam, view))
                view = resized_view(frame, (color.shape[1], color.shape[0]), host, s.name)
        return color

    def _upload_aux(self, bufs: _Buffers, view: Frame, later: list[Stage], size: tuple[int, int]):
        """Device depth/velocity at a resampled size for the stages after the resampling one."""
        import pyopencl as cl

        aux, events = {}, []
        for name in AUX_BUFFERS:
            readers = [s.name for s in later if name in s.reads]
            if not readers:
                continue
            host = getattr(view, name)
            if host is None:
                raise InputError(f"stage '{readers[0]}' needs {name} after a resampling stage that "
                                 f"provides none; leave one of them out with --stages")
            key = ("aux", size, name)
            if key not in bufs.args:
                bufs.args[key] = self.runtime.empty(host.shape)
            aux[name] = bufs.args[key]
            events.append(("upload", cl.enqueue_copy(self.runtime.queue, aux[name],
                                                     np.ascontiguousarray(host), is_blocking=False)))
        return aux, events

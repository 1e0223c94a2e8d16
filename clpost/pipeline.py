"""Plan and run a chain of stages on frames: build kernels once, run many frames.

Plan time vs call time (after reikna): :meth:`Pipeline.plan` decides which stages change the
image for this camera and frame (a stage that is an identity is not planned — "model only what the
scene requires"); consecutive pointwise stages are fused into **one generated kernel** (one pass
over memory); programs are built once per (stages, defines) and device buffers are allocated once
per resolution, then reused for every frame. Per-frame scalars (exposure gain …) are kernel
arguments, so changing them never rebuilds anything.

Kernel code generation and device layouts: :mod:`clpost.codegen`.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from .camera import Camera
from .errors import InputError
from .frame import Frame
from . import metering
from .codegen import AUX_BUFFERS, INTERLEAVED, PLANAR, fused_source, global_size
from .stages import QUALITIES, GatherStage, PointwiseStage, Stage, registry



@dataclass(frozen=True)
class PlanEntry:
    """One line of ``--explain``: a stage, whether it runs, and why."""

    stage: str
    planned: bool
    reason: str

    def __str__(self) -> str:
        return f"{'+' if self.planned else '-'} {self.stage:<14} {self.reason}"


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


def check_prerequisites(stages: list[Stage], entries: list[PlanEntry], selected: set[str] | None,
                        already_applied: frozenset[str], cam: Camera, frame: Frame) -> None:
    """Refuse a plan in which a stage runs without a stage it ``requires``: one the selection
    (``--stages``) leaves out although it would change this frame (it is not an identity) and
    that the input does not already carry (``already_applied``). Its output is the planned
    stage's input domain (grain on film densities, not on scene light), so the result would be
    nonsense, not an approximation."""
    if selected is None:
        return  # every stage is a candidate: a needed prerequisite is planned
    by_name = {st.name: st for st in stages}

    def missing(name):  # the needed prerequisites of ``name`` left out, nearest first
        return [r for r in by_name[name].requires if r not in selected and r not in already_applied
                and by_name[r].skip_reason(cam, frame) is None]  # else an identity here

    for name in (e.stage for e in entries if e.planned):
        first = missing(name)
        if not first:
            continue
        add, todo = set(), list(first)
        while todo:  # and what those need in turn, so the fix is complete
            r = todo.pop()
            if r not in add:
                add.add(r)
                todo.extend(missing(r))
        fixed = [st.name for st in stages if st.name in selected or st.name in add]
        raise InputError(f"--stages: stage '{name}' works on the output of the '{first[0]}' stage, which is "
                         f"not selected; add the missing stage(s): --stages {','.join(fixed)}")


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
    ``already_applied`` names stages whose effect the input already carries (e.g. film densities
    from an earlier run): the stages that ``require`` them may then run without them.
    """

    def __init__(self, camera: Camera, quality: str = "final", stages: list[str] | None = None,
                 device: str | None = None, already_applied: tuple[str, ...] = ()) -> None:
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
        unknown = [s for s in already_applied if s not in known]
        if unknown:
            raise InputError(f"already_applied: unknown stage(s) {', '.join(unknown)}; known: {', '.join(known)}")
        self._already_applied = frozenset(already_applied)
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
        check_prerequisites(self._stages, out, self._selected, self._already_applied, cam, frame)
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

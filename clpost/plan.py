"""A :class:`Plan`: what runs for one camera structure, frame size, quality and stage selection.

Plan time vs call time (after reikna's ``Computation``): building a plan decides the kernel
launches — consecutive pointwise stages fused into one generated kernel (:mod:`clpost.codegen`),
each gather stage with its own kernels — builds their programs, allocates the device buffers for
the frame size and records each stage's reason (``--explain``) and each launch's sizes
(``clpost bench``). :meth:`Plan.run` does only per-frame work: upload, per-frame scalars as kernel
arguments, enqueue, download. A camera whose scalar parameters change from frame to frame (an
animated focus, f-number, shutter or exposure) runs through the same plan; nothing is rebuilt.

Plans are made by :meth:`clpost.pipeline.Pipeline.plan_for`, which caches them by
(camera structure, frame size, planned stages and their ``defines``).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .codegen import AUX_BUFFERS, INTERLEAVED, PLANAR, fused_source, global_size
from .errors import InputError
from .frame import Frame
from .stages import GatherStage, PointwiseStage, Stage


@dataclass(frozen=True)
class PlanEntry:
    """One line of ``--explain``: a stage, whether it runs, and why."""

    stage: str
    planned: bool
    reason: str

    def __str__(self) -> str:
        return f"{'+' if self.planned else '-'} {self.stage:<14} {self.reason}"


@dataclass(frozen=True)
class Launch:
    """One kernel launch of a plan, in order: a fused pointwise group, a gather stage, or a
    layout conversion (``kind``), with the frame size it reads and writes."""

    name: str
    stages: tuple[str, ...]
    kind: str
    in_size: tuple[int, int]
    out_size: tuple[int, int]


def resized_view(frame: Frame, size: tuple[int, int], host: dict, by: str) -> Frame:
    """The frame as stages after a resampling stage ``by`` see it: ``size`` (width, height), the
    resampler's depth/velocity/alpha/labels (``host``), and no host color (stages read color on the
    device; a zero-stride placeholder keeps shapes right without allocating)."""
    w, h = size
    placeholder = np.broadcast_to(np.zeros((1, 1, 3), np.float32), (h, w, 3))
    meta = dict(frame.metadata, resampled_by=by)
    meta.pop("intrinsics", None)  # the render's pinhole intrinsics no longer describe these pixels
    return frame.replace(color=placeholder, depth=host.get("depth"), velocity=host.get("velocity"),
                         alpha=host.get("alpha"), labels=host.get("labels", {}), metadata=meta, front=None,
                         validate=False)


@dataclass
class _Node:
    """One kernel launch of a plan: a fused pointwise group or a gather stage."""

    stages: list[Stage]
    src_layout: str
    dst_layout: str
    kernel: object = None
    args: list | None = None
    """A pointwise launch's argument values as set on ``kernel`` (only changed ones are set again)."""
    key: tuple | None = None
    """What a pointwise launch's arguments were computed from (buffers, the stages' replay keys)."""
    size: tuple | None = None
    tables: list = field(default_factory=list)
    """(buffer key, host array) of the tables a pointwise launch's arguments point to."""
    recording: object = None
    """A gather launch's :class:`clpost.runtime_record.Recording` (its commands, replayed)."""

    @property
    def name(self) -> str:
        return "__".join(s.name for s in self.stages) or f"convert_{self.src_layout}_to_{self.dst_layout}"

    @property
    def gather(self) -> bool:
        return bool(self.stages) and isinstance(self.stages[0], GatherStage)


@dataclass
class Buffers:
    """Device buffers of a plan's frame size, reused for every frame (and by every plan of the
    same pipeline and size)."""

    size: tuple[int, int]
    color_in: object
    color_out: object
    planar: list = field(default_factory=list)
    aux: dict = field(default_factory=dict)
    args: dict = field(default_factory=dict)
    uploaded: dict = field(default_factory=dict)
    """(stage, arg) → the read-only host array last copied into its buffer (not copied again)."""
    stream: object = None
    """The :class:`clpost.stream.Stream` of :meth:`Plan.submit`'s frames in flight (made on first use)."""


def group_nodes(stages: list[Stage]) -> list[_Node]:
    """Consecutive pointwise stages → one fused launch; each gather its own launch on planar
    buffers; a conversion launch where the plan starts or ends with a gather."""
    groups: list[list[Stage]] = []
    for s in stages:
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
    return nodes


def structure_key(camera) -> object:
    """What of a camera decides programs and buffers: its structural parameters
    (:meth:`clpost.camera.Camera.structure_key`); per-frame scalars (focus, f-number, shutter,
    exposure …) are not in it."""
    return camera.structure_key()


class Plan:
    """The launches of one (camera structure, frame size, quality, stages); see the module
    docstring. ``entries`` is every known stage with whether it runs and why (reasons filled in by
    :meth:`clpost.pipeline.Pipeline.explain`, which may cost a pass over the frame)."""

    def __init__(self, runtime, camera, frame: Frame, stages: list[Stage], quality: str,
                 buffers: Buffers | None = None, build: bool = True) -> None:
        self.runtime = runtime
        self.camera = camera
        self.quality = quality
        self.size = frame.size
        self.stages = list(stages)
        self.structure = structure_key(camera)
        from .stages._field import field_centre_px

        self.principal_point = field_centre_px(camera, frame)
        """The optical axis (px) in the plan's input frame: the one definition every stage uses."""
        self.nodes = group_nodes(self.stages)
        self._aux_names = [b for b in AUX_BUFFERS if any(b in s.reads for s in self.stages)]
        self.launches = self._launches(camera, frame)
        self._aux_reread = any(L.out_size != L.in_size and any(b in s.reads for n in self.nodes[k + 1:]
                                                                for s in n.stages for b in AUX_BUFFERS)
                               for k, L in enumerate(self.launches))
        """Whether a stage after a resampling one reads depth or velocity (uploaded again from
        the resampled host arrays, so :meth:`submit` downloads those in the compute queue's order)."""
        self.buffers = buffers
        self._events: list = []
        self._timings: dict[str, float] = {}
        self._camera_seen = None  # the camera of the last run (its scalars are what is recorded)
        self.last_patched: list[tuple[str, int]] = []
        """(launch, argument index) of every kernel argument set in the last :meth:`run` because its
        value changed (a per-frame scalar; every argument, the first time a launch is recorded
        or a pointwise kernel runs)."""
        self.pipelined = runtime is not None and runtime.discrete
        """Whether :meth:`submit` keeps frames in flight (transfers on their own queues, see
        :mod:`clpost.stream`) or runs each at once; default: on a discrete GPU
        (:attr:`clpost.runtime.Runtime.discrete`). Tests set it on a CPU device."""
        self.in_flight = 2
        """At most this many submitted frames in flight (:meth:`submit`)."""
        self.closed = False
        """Whether :meth:`close` was called (``run`` and ``submit`` then refuse frames)."""
        self.last_host_ms = 0.0
        """CPU time of the calling thread in the last :meth:`run` (host work: planning checks,
        tables, argument setting, enqueueing; the device's threads and waits are not in it)."""
        if build:
            self._build(camera)

    # -- plan time ----------------------------------------------------------------------------
    def _build(self, cam) -> None:
        import pyopencl as cl

        from .runtime import typed_kernel

        rt = self.runtime
        for node in self.nodes:
            if node.gather:
                continue
            defines: dict = {}
            for s in node.stages:
                defines.update(s.defines(cam))
            kname, src = fused_source(node.stages, node.src_layout, node.dst_layout, wide=rt.wide)
            node.kernel = typed_kernel(cl.Kernel(rt.program(src, kname, defines), kname))
        if self.buffers is None or self.buffers.size != self.size:
            w, h = self.size
            self.buffers = Buffers((w, h), rt.empty((h, w, 3)), rt.empty((h, w, 3)))

    def _launches(self, cam, frame: Frame) -> list[Launch]:
        size, out, view = frame.size, [], frame
        for node in self.nodes:
            out_size = tuple(node.stages[0].output_size(cam, view)) if node.gather else size
            kind = "gather" if node.gather else ("pointwise" if node.stages else "convert")
            out.append(Launch(node.name, tuple(s.name for s in node.stages), kind, tuple(size), out_size))
            if out_size != size:
                view = resized_view(frame, out_size, {}, node.name)
            size = out_size
        return out

    @property
    def stage_names(self) -> list[str]:
        return [s.name for s in self.stages]

    @property
    def kernel_names(self) -> list[str]:
        return [n.name for n in self.nodes]

    @property
    def output_size(self) -> tuple[int, int]:
        return self.launches[-1].out_size if self.launches else self.size

    # -- device buffers -----------------------------------------------------------------------
    def _scratch(self, key, shape):
        bufs = self.buffers
        if key not in bufs.args:
            bufs.args[key] = self.runtime.empty(shape)
        return bufs.args[key]

    def _planar(self, k: int, size: tuple[int, int]):
        bufs = self.buffers
        if size != bufs.size:  # a resampling gather (distortion) changed the size
            return self._scratch(("planar", size, k), (3, size[1], size[0]))
        while len(bufs.planar) <= k:
            w, h = bufs.size
            bufs.planar.append(self.runtime.empty((3, h, w)))
        return bufs.planar[k]

    def _color_out(self, size: tuple[int, int]):
        if size == self.buffers.size:
            return self.buffers.color_out
        return self._scratch(("color_out", size), (size[1], size[0], 3))

    def arg_values(self, stage: PointwiseStage, cam, frame: Frame, upload=None, events=None) -> list:
        """The kernel arguments of a pointwise stage for this frame: scalars as they are, host
        arrays in device buffers (a read-only array that is the same object as last time is not
        copied again — a stage's static table), a :class:`~clpost.stages.base.DeviceTable` filled
        on the device when its key changes (its launches' events added to ``events``).
        ``upload(buffer, host)``: how a table is copied (:meth:`_enqueue_nodes`'s, which does not
        block); default a blocking copy on the queue."""
        import pyopencl as cl

        from .stages.base import DeviceTable

        if upload is None:
            def upload(buf, host):
                return cl.enqueue_copy(self.runtime.queue, buf, host, is_blocking=True)
        bufs, vals = self.buffers, []
        for (cl_type, arg), v in zip(stage.args, stage.values(cam, frame)):
            if "*" in cl_type:
                a = v if isinstance(v, DeviceTable) else np.ascontiguousarray(v)
                key = (stage.name, arg)
                buf = bufs.args.get(key)
                if buf is None or buf.size != max(a.nbytes, 4):
                    buf = bufs.args[key] = self.runtime.empty(a.shape, a.dtype)
                    bufs.uploaded.pop(key, None)
                if isinstance(a, DeviceTable):
                    last = bufs.uploaded.get(key)
                    if not (isinstance(last, DeviceTable) and last.key == a.key):
                        evs = a.fill(self.runtime, buf, upload)
                        if events is not None:
                            events += evs
                        bufs.uploaded[key] = a
                elif not (bufs.uploaded.get(key) is a and not a.flags.writeable):
                    # copied without blocking: a table the stage might change later goes as a copy
                    upload(buf, a if not a.flags.writeable else a.copy())
                    bufs.uploaded[key] = a
                vals.append(buf)
            else:
                vals.append(v)
        return vals

    def _upload_aux(self, view: Frame, later: list[Stage], size: tuple[int, int]):
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
            buf = self._scratch(("aux", size, name), host.shape)
            aux[name] = buf
            events.append(("upload", cl.enqueue_copy(self.runtime.queue, buf, np.ascontiguousarray(host),
                                                     is_blocking=False)))
        return aux, events

    # -- call time ----------------------------------------------------------------------------
    def check(self, frame: Frame, camera) -> None:
        """Refuse a frame or camera this plan was not built for (one line naming the fix)."""
        if not isinstance(frame, Frame):
            raise InputError(f"Plan.run takes a clpost.Frame, not {type(frame).__name__}; wrap arrays "
                             "with clpost.Frame(color=...)")
        if frame.size != self.size:
            raise InputError(f"Plan.run: the frame is {frame.width}x{frame.height} but the plan was built "
                             f"for {self.size[0]}x{self.size[1]}; use Pipeline.run, which plans per size")
        if camera is not self.camera and camera is not self._camera_seen and structure_key(camera) != self.structure:
            raise InputError("Plan.run: the camera differs from the plan's in more than its per-frame "
                             "scalars (lens, blades, stock …); use Pipeline.run, which re-plans")
        missing = [n for n in self._aux_names if getattr(frame, n) is None]
        if missing:
            readers = [s.name for s in self.stages if missing[0] in s.reads]
            raise InputError(f"Plan.run: stage '{readers[0]}' needs the frame's {missing[0]} buffer, which "
                             f"this frame lacks; give every frame of the plan its {missing[0]}")

    def run(self, frame: Frame, camera=None, out: np.ndarray | None = None) -> Frame:
        """Process one frame with this plan. ``camera``: this frame's camera (same structure as the
        plan's; its scalars — focus, f-number, shutter, exposure … — may differ per frame).
        ``out``: a C-contiguous float32 (H, W, 3) array of the output size to download the image
        into (e.g. :meth:`~clpost.runtime.Runtime.pinned_empty`'s, which a discrete GPU reads and
        writes ~4× faster than pageable memory); default a new array. Or a dict of such arrays
        by name: ``color``, and ``depth`` (H, W) and ``velocity`` (H, W, 2) where the plan
        resamples them (distortion makes the output frame's depth and velocity at the output
        size; without an array for them, new ones each frame).
        Returns a new Frame whose color is the camera's output."""
        t0 = time.thread_time()
        try:
            self._check_open("run")
            return self._run(frame, self.camera if camera is None else camera, out)
        finally:
            self.last_host_ms = (time.thread_time() - t0) * 1e3

    def _run(self, frame: Frame, cam, out: np.ndarray | None = None) -> Frame:
        import pyopencl as cl

        self.check(frame, cam)
        meta = dict(frame.metadata, camera=cam.describe(), plan=self.stage_names)
        if not self.stages:
            self._camera_seen = cam
            self._events, self._timings, self.last_patched = [], {}, []
            return frame.replace(metadata=meta, validate=False)
        out, outs = self._outputs(out, frame)
        rt, q, bufs = self.runtime, self.runtime.queue, self.buffers
        events = [("upload", cl.enqueue_copy(q, bufs.color_in, frame.color, is_blocking=False))]
        for name in self._aux_names:
            events.append(("upload", cl.enqueue_copy(q, self._aux_buffer(name, frame), getattr(frame, name),
                                                     is_blocking=False)))
        evs, host_out, size = self._enqueue_launches(frame, cam, outs=outs)
        events += evs
        events.append(("download", cl.enqueue_copy(q, out, self._color_out(size), is_blocking=True)))
        # The queue is in order, so every command is complete: let the transfers' events drop their
        # host arrays now (NannyEvent.wait), or the previous frame's arrays would be freed — and
        # counted — in the next run, when these events are replaced.
        for _, ev in events:
            if isinstance(ev, cl.NannyEvent):
                ev.wait()
        self._events = events  # read into last_timings only when asked (profiling queries cost host time)
        return frame.replace(color=out, metadata=meta, validate=False, front=None, **host_out)

    def submit(self, frame: Frame, camera=None, out: np.ndarray | None = None):
        """Enqueue one frame and return at once with a :class:`clpost.stream.PendingFrame`, whose
        ``result()`` is what :meth:`run` returns; up to :attr:`in_flight` frames run at a time,
        each frame's upload and download on queues of their own beside the other frames'
        kernels (:mod:`clpost.stream`), so that a sequence costs about the slowest of upload,
        kernels, download and host work per frame instead of their sum. Arguments as
        :meth:`run`'s; the frame's arrays and ``out`` belong to the frame until ``result()``
        (page-locked ones, :meth:`~clpost.runtime.Runtime.pinned_empty`, are what a GPU copies
        asynchronously; a Frame keeps them only when made with ``copy=False``). Where :attr:`pipelined` is False (a CPU device) the frame runs at once
        and the returned frame is complete. A frame or ``out`` this plan refuses raises
        :class:`~clpost.errors.InputError` before anything is enqueued."""
        t0 = time.thread_time()
        try:
            self._check_open("submit")
            cam = self.camera if camera is None else camera
            if not (self.pipelined and self.stages):
                from .stream import PendingFrame

                return PendingFrame(self._run(frame, cam, out))
            return self._submit(frame, cam, out)
        finally:
            self.last_host_ms = (time.thread_time() - t0) * 1e3

    def drain(self) -> None:
        """Wait for every frame :meth:`submit` has in flight."""
        if self.buffers is not None and self.buffers.stream is not None:
            self.buffers.stream.drain()

    def close(self) -> None:
        """Wait for every frame in flight, then stop the thread that downloads submitted frames
        (:meth:`clpost.stream.Stream.close`); ``run`` and ``submit`` then refuse frames with one
        :class:`~clpost.errors.InputError` line. Idempotent; ``with plan:`` closes at the end
        of the block. The pipeline's other plans of this size share the stream: their next
        ``submit`` starts the thread again. Without it the thread ends with the plan's buffers
        or the interpreter (a daemon, never waited for at exit)."""
        self.closed = True
        if self.buffers is not None and self.buffers.stream is not None:
            self.buffers.stream.close()

    def __enter__(self) -> "Plan":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _check_open(self, call: str) -> None:
        if self.closed:
            raise InputError(f"Plan.{call}: this plan was closed (Plan.close or Pipeline.close); "
                             "get a new one from Pipeline.plan_for")

    def _submit(self, frame: Frame, cam, out: np.ndarray | None):
        import pyopencl as cl

        from .stream import PendingFrame, Stream

        self.check(frame, cam)
        if isinstance(self.in_flight, bool) or not isinstance(self.in_flight, (int, np.integer)) or self.in_flight < 1:
            raise InputError(f"Plan.in_flight must be a whole number of frames >= 1, not {self.in_flight!r}; "
                             "set it to 1 for one frame at a time")
        rt, q, bufs = self.runtime, self.runtime.queue, self.buffers
        if bufs.stream is None:
            bufs.stream = Stream(self.in_flight)
        bufs.stream.resize(self.in_flight)
        stream = bufs.stream
        given = isinstance(out, np.ndarray) or (isinstance(out, dict) and out.get("color") is not None)
        out, outs = self._outputs(out, frame, stream.upcoming)
        callers = [*outs.values(), *([out] if given else [])]  # downloaded into directly: no bounce
        meta = dict(frame.metadata, camera=cam.describe(), plan=self.stage_names)
        slot = stream.reserve()  # waits for the frame that used it last
        uq, dq = rt.transfer_queues()
        names = ["color", *self._aux_names]
        copies: list = []  # (host array, slot buffer, event of the copy into it): the downloads

        def download(host: np.ndarray, buf):
            """A download of the frame's: copied into the slot on the compute queue now, to the
            host by the download worker (Stream.download) once that copy is done — through the
            slot's page-locked bounce array unless ``host`` is one of the caller's arrays."""
            key = len(copies)
            staging = slot.output(rt, key, host.nbytes)
            ev = cl.enqueue_copy(q, staging, buf, byte_count=host.nbytes)
            mine = not any(host is a for a in callers)
            copies.append((host, staging, ev, slot.bounce(rt, key, host, uq) if mine else None))
            return ev

        uploads: list = []  # ("upload", event) of the tables and arrays the stages copy mid-frame
        staged_in: set = set()

        def upload(buf, host: np.ndarray):
            """A host array a stage copies to the device mid-frame (a changed table: a focus pull's
            vignetting; a gather stage's uploads): on the upload queue into the slot's own staging
            buffer, then device-to-device into ``buf`` on the compute queue once that upload is
            done — after the earlier frames' launches that read ``buf``, and waiting for no other
            frame's upload."""
            staging = slot.table(rt, len(uploads), host.nbytes)
            up = cl.enqueue_copy(uq, staging, host, is_blocking=False)
            uq.flush()  # the compute queue waits for it: submit it to the device now
            uploads.append(("upload", up))
            ev = cl.enqueue_copy(q, buf, staging, byte_count=host.nbytes, wait_for=[up])
            staged_in.add(id(ev))
            return ev

        try:
            events = [("upload", cl.enqueue_copy(uq, slot.input(rt, n, getattr(frame, n)), getattr(frame, n),
                                                 is_blocking=False)) for n in names]
            uq.flush()  # another queue waits for these: submit them to the device now
            for n, (_, up) in zip(names, list(events)):
                dst = bufs.color_in if n == "color" else self._aux_buffer(n, frame)
                events.append(("stage_in", cl.enqueue_copy(q, dst, slot.inputs[n], wait_for=[up])))
            # a resampling stage's host depth/velocity that a later stage reads back (uploaded again
            # from the host, _upload_aux) must be downloaded in the compute queue's order
            evs, host_out, size = self._enqueue_launches(frame, cam, None if self._aux_reread else download, upload,
                                                         outs)
            staged = {id(c[2]) for c in copies}
            events += uploads
            events += [("stage_out" if id(ev) in staged else "stage_in" if id(ev) in staged_in else label, ev)
                       for label, ev in evs]
            download(out, self._color_out(size))
            events.append(("stage_out", copies[-1][2]))
            q.flush()
        except BaseException:
            # nothing half-done: whatever was enqueued completes before the error is raised (the
            # slot stays free; nothing is downloaded: the worker gets the frame's copies last)
            for queue in (uq, q):
                queue.finish()
            raise
        pending = PendingFrame(frame.replace(color=out, metadata=meta, validate=False, front=None, **host_out), events,
                               bufs.stream.download(dq, copies), self, [out, *outs.values()])
        bufs.stream.commit(slot, pending)
        return pending

    def _outputs(self, out, frame: Frame, free=None) -> tuple[np.ndarray, dict]:
        """``out`` (an image array, a dict of arrays by name, or None) checked: the image array
        (:meth:`_out_array`) and the caller's arrays for the resampled host buffers by name —
        one line naming what is wrong, before anything is enqueued."""
        if out is None or isinstance(out, np.ndarray):
            return self._out_array(out, free), {}
        if not isinstance(out, dict):
            raise InputError(f"Plan.run: out= must be a float32 image array or a dict of arrays by name "
                             f"('color', 'depth', 'velocity'), not {type(out).__name__}")
        unknown = sorted(set(out) - {"color", "depth", "velocity"})
        if unknown:
            raise InputError(f"Plan.run: out= names {unknown}; the arrays a plan downloads into are "
                             "'color', 'depth' and 'velocity'")
        w, h = self.output_size
        resamples = any(isinstance(s, GatherStage) and type(s).host_buffers is not GatherStage.host_buffers
                        for s in self.stages)
        outs = {}
        for name, shape in (("depth", (h, w)), ("velocity", (h, w, 2))):
            a = out.get(name)
            if a is None:
                continue
            if not resamples or getattr(frame, name) is None:
                raise InputError(f"Plan.run: out['{name}'] given, but this plan makes no new {name} (only a "
                                 f"resampling stage such as distortion does, from the frame's {name}); leave it out")
            if not isinstance(a, np.ndarray) or a.shape != shape or a.dtype != np.float32 or not a.flags.c_contiguous:
                raise InputError(f"Plan.run: out['{name}'] must be a C-contiguous float32 array of shape {shape} "
                                 f"(the plan's output size), not {getattr(a, 'dtype', type(a).__name__)} "
                                 f"{getattr(a, 'shape', '')}")
            self._check_not_in_flight(a, f"out['{name}']", free)
            outs[name] = a
        return self._out_array(out.get("color"), free), outs

    def _check_not_in_flight(self, a: np.ndarray, what: str, free=None) -> None:
        """Refuse ``a`` where a submitted frame whose ``result()`` was not taken (other than slot
        ``free``'s, which :meth:`submit` waits for first) may still download into it."""
        stream = self.buffers.stream if self.buffers is not None else None
        if stream is not None and any(s is not free and s.pending is not None and s.pending.holds(a)
                                      for s in stream.slots):
            raise InputError(f"Plan.run: {what} is an array of a submitted frame still in flight (its "
                             "download would overwrite this frame's); take that frame's result() first, "
                             "or give another array")

    def _out_array(self, out: np.ndarray | None, free=None) -> np.ndarray:
        """``out`` checked against the plan's output (one line naming the shape it must have) and
        against the frames in flight (it must not be the image array of one whose ``result()`` was
        not taken, except the frame of slot ``free``, which :meth:`submit` waits for first), or a
        new array; before anything is enqueued, so a wrong one leaves nothing half-done."""
        w, h = self.output_size
        if out is None:
            return np.empty((h, w, 3), np.float32)
        if out.shape != (h, w, 3) or out.dtype != np.float32 or not out.flags.c_contiguous:
            raise InputError(f"Plan.run: out= must be a C-contiguous float32 array of shape {(h, w, 3)} "
                             f"(the plan's output), not {out.dtype} {out.shape}")
        self._check_not_in_flight(out, "out=", free)
        return out

    def _aux_buffer(self, name: str, frame: Frame):
        """The plan's device buffer of the frame's ``name`` (depth, velocity) at the input size."""
        bufs = self.buffers
        buf = bufs.aux.get(name)
        if buf is None:
            buf = bufs.aux[name] = self.runtime.empty(getattr(frame, name).shape)
        return buf

    def _enqueue_launches(self, frame: Frame, cam, download=None, upload=None, outs=None) -> tuple[list, dict, tuple[int, int]]:
        """Enqueue the plan's launches for one frame on the runtime's queue, reading the frame from
        ``buffers.color_in`` and ``buffers.aux`` (enqueued before) and leaving the image in
        :meth:`_color_out`; per-frame scalars set as kernel arguments (OpenCL takes an argument's
        value when the launch is enqueued, so the next frame may set its own at once). Returns
        [(label, event)], the host buffers of resampling stages (fresh arrays, downloaded
        without blocking: on the queue, or by ``download(host, buffer) -> event``) and the output
        size. Host arrays the stages copy to the device (a pointwise stage's changed table, a
        gather stage's uploads) go without blocking: on the queue, or by ``upload(buffer, host)
        -> event`` (the event on the queue after which the buffer holds them). ``outs``: the
        caller's arrays for the host buffers by name (:meth:`_outputs`), used instead of fresh ones."""
        same_camera = cam is self._camera_seen or cam == self._camera_seen
        self._camera_seen = cam
        self._events, self._timings = [], {}
        try:
            return self._enqueue_nodes(frame, cam, same_camera, download, upload, outs or {})
        except BaseException:
            self._forget()
            raise

    def _forget(self) -> None:
        """After an error part-way through a frame's launches: drop what the next frame would
        otherwise trust — the recordings (a re-recording that stopped may have set some of its
        kernel objects' arguments, which it shares with the previous recording, to values that
        recording does not list) and the pointwise launches' arguments — so the next frame runs
        every stage's code and sets every argument again."""
        self._camera_seen = None
        for node in self.nodes:
            node.recording, node.args, node.key = None, None, None

    def _enqueue_nodes(self, frame: Frame, cam, same_camera: bool, download, upload, outs) -> tuple[list, dict, tuple[int, int]]:
        import pyopencl as cl

        patched = self.last_patched = []
        rt, q, bufs = self.runtime, self.runtime.queue, self.buffers
        events: list = []

        def table(buf, host):
            """A pointwise stage's changed table, in the queue's order after the launches before
            that read its buffer; not blocking (its event keeps ``host`` alive)."""
            ev = upload(buf, host) if upload is not None else cl.enqueue_copy(q, buf, host, is_blocking=False)
            events.append(("upload", ev))
            return ev
        src, planar_k = bufs.color_in, 0
        size, host_out, aux = self.size, {}, bufs.aux
        view = frame  # the frame as the next stage sees it: resampling stages change its size
        for k, (node, launch) in enumerate(zip(self.nodes, self.launches)):
            out_size = launch.out_size
            if node.dst_layout == INTERLEAVED:
                dst = self._color_out(out_size)
            else:
                dst = self._planar(planar_k, out_size)
                planar_k ^= 1
            if node.gather:
                stage = node.stages[0]
                rec = node.recording
                key = stage.replay_key(cam, view)
                io = (src, dst, *aux.values())
                if (rec is not None and same_camera and key is not None and key == rec.key and rec.io == io
                        and stage.__dict__.get("_replayed") is rec):
                    evs, host = rec.replay(q, view, download, upload, outs)
                else:  # first frame, or what the launches depend on changed: run the stage's code
                    rec, evs, host = self._record(node, stage, cam, view, src, dst, aux, key, download, upload,
                                                  outs)
                    rec.io = io
                    patched += [(f"{stage.name}[{i}]", j) for i, j in rec.patched]
                events += evs
                host_out.update(host)
                if out_size != size:
                    view = resized_view(frame, out_size, host_out, stage.name)
                    later = [s for n in self.nodes[k + 1:] for s in n.stages]
                    aux, evs = self._upload_aux(view, later, out_size)
                    events += evs
                size = out_size
            else:
                w, h = size
                keys = [s.replay_key(cam, view) for s in node.stages]
                key = None if None in keys else (src, dst, *aux.values(), *keys)
                if not (same_camera and key is not None and key == node.key
                        and all(bufs.uploaded.get(k) is a for k, a in node.tables)):  # else: as set last frame
                    args = [src, dst, np.int32(w), np.int32(h)]
                    args += [aux[b] for b in AUX_BUFFERS if any(b in s.reads for s in node.stages)]
                    for s in node.stages:
                        args += self.arg_values(s, cam, view, table, events)
                    self._set_changed(node, args, patched)
                    node.key = key
                    # the tables in the buffers (shared by the pipeline's plans of this size) now
                    node.tables = [(k, bufs.uploaded.get(k)) for s in node.stages
                                   for k in ((s.name, arg) for t, arg in s.args if "*" in t)]
                    node.size = global_size(node.stages, node.src_layout, node.dst_layout, w, h,
                                            rt.wide)
                events.append((node.name, cl.enqueue_nd_range_kernel(q, node.kernel, node.size, None)))
            src = dst
        return events, host_out, size

    def _record(self, node: _Node, stage: GatherStage, cam, view: Frame, src, dst, aux, key, download=None,
                upload=None, outs=None):
        """Run a gather stage's code through a :class:`~clpost.runtime_record.Recorder` (its
        commands are enqueued and recorded; the node's previous recording lends its kernel
        objects, so only changed arguments are set); the recording replaces the node's."""
        from .runtime_record import Recorder

        recorder = Recorder(self.runtime, view, key, node.recording, download, upload, outs)
        returned = [(stage.name, ev) for ev in stage.enqueue(recorder, cam, view, src, dst, aux)]
        host, evs = stage.enqueue_host_buffers(recorder, cam, view, aux)
        returned += evs
        rec = recorder.finish(returned, stage.name, host)
        node.recording = rec
        stage.__dict__["_replayed"] = rec  # the stage's scratch state is this recording's now
        return rec, returned, host

    @staticmethod
    def _set_changed(node: _Node, args: list, patched: list) -> None:
        """Set the pointwise kernel's arguments whose values differ from those set last time."""
        from .runtime_record import _same, _typed

        old, knl = node.args, node.kernel
        if old is None or len(old) != len(args):
            knl.set_args(*args)
            patched += [(node.name, j) for j in range(len(args))]
        else:
            for j, (a, b) in enumerate(zip(old, args)):
                if not _same(a, b):
                    knl.set_arg(j, _typed(knl, j, b))
                    patched.append((node.name, j))
        node.args = args

    @property
    def last_timings(self) -> dict[str, float]:
        """Device milliseconds of the last :meth:`run` (or submitted frame whose ``result()`` was
        taken last), per kernel and for upload/download (and a submitted frame's device-to-device
        copies through its slot: stage_in, stage_out)."""
        if self._events:
            from .runtime import event_ms

            t: dict[str, float] = {}
            for name, ev in self._events:
                t[name] = t.get(name, 0.0) + event_ms(ev)
            self._timings, self._events = t, []
        return self._timings

    def reference(self, frame: Frame, camera=None) -> np.ndarray:
        """The same plan through each stage's float64 numpy reference; (H, W, 3) float64."""
        cam = self.camera if camera is None else camera
        color = frame.color.astype(np.float64)
        view, host = frame, {}
        for s in self.stages:
            color = s.reference(cam, view, color)
            if color.shape[:2] != (view.height, view.width):
                host.update(s.host_buffers(cam, view))
                view = resized_view(frame, (color.shape[1], color.shape[0]), host, s.name)
        return color

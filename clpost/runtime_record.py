"""Recorded launches: a gather stage's per-frame commands captured once, then replayed.

A plan (:class:`clpost.plan.Plan`) runs a gather stage's ``enqueue`` (and
``enqueue_host_buffers``) through a :class:`Recorder` in place of the runtime. The Recorder has
the runtime's toolkit (``kernel``, ``kernels``, ``constant``, ``scratch``, ``cached``,
``launch``, ``launch_once``, ``copy``); every ``launch`` and ``copy`` is enqueued at once as
usual AND kept as a command — a launch with its own ``cl.Kernel`` object whose arguments are set
then (:func:`clpost.runtime.private_kernel`). The next frames replay the commands: one
``enqueue_nd_range_kernel`` per launch, no Python of the stage, no argument set.

When what the stage's launches depend on changes (the camera's per-frame scalars — an animated
focus, f-number, shutter —, or the frame index for a stage that draws noise from it:
``GatherStage.replay_key``), the stage's code runs again through a Recorder given the previous
recording: a launch of the same kernel and sizes at the same place keeps its kernel object and
only the arguments whose values changed are set, by index (``Recording.patched`` lists them).

What a recording can replay: launches and copies whose sizes and arguments follow from the
camera, the frame's size and the stage's ``replay_key`` — never from pixel data read back to the
host (so no stage reads the device back mid-frame). A copy from the frame's own arrays
(``frame.depth`` …) is replayed from the next frame's array; a download into a host array gives a
new array each frame (the host buffers a resampling stage returns).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from .runtime import Captured, launch_sizes, private_kernel

FRAME_ARRAYS = ("color", "depth", "velocity", "alpha")


@dataclass
class Launch:
    """A recorded kernel launch: its own kernel object (arguments set), sizes, argument values."""

    source: "cl.Kernel"
    kernel: "cl.Kernel"
    global_size: tuple
    local_size: tuple | None
    args: list

    def enqueue(self, queue, frame):
        return cl.enqueue_nd_range_kernel(queue, self.kernel, self.global_size, self.local_size)


@dataclass
class Copy:
    """A recorded copy. ``src``/``dst``: a buffer or host array, or the name of one of the frame's
    arrays (``frame_src``); ``fresh``: (shape, dtype) of a host destination made new each frame."""

    dst: object
    src: object
    frame_src: str | None = None
    fresh: tuple | None = None

    @property
    def uploads(self) -> bool:
        """Whether it copies a host array (the frame's, or a stage's table) into a buffer."""
        return (self.frame_src is not None or isinstance(self.src, np.ndarray)) and isinstance(
            self.dst, cl.MemoryObjectHolder)

    def enqueue(self, queue, frame, dst=None):
        src = getattr(frame, self.frame_src) if self.frame_src else self.src
        if dst is None:
            dst = np.empty(*self.fresh) if self.fresh else self.dst
        return cl.enqueue_copy(queue, dst, src, is_blocking=False), dst


def _same(a, b) -> bool:
    """Is argument value ``b`` the one already set (``a``)? Buffers by identity, scalars by type and
    value."""
    if a is b:
        return True
    if isinstance(a, (cl.MemoryObjectHolder, cl.LocalMemory)) or a is None or b is None:
        return False
    return type(a) is type(b) and bool(a == b)


def _typed(kernel, index: int, value):
    dtypes = getattr(kernel, "_clpost_dtypes", None)
    dt = dtypes[index] if dtypes is not None and index < len(dtypes) else None
    return value if dt is None else np.dtype(dt).type(value)


@dataclass
class Recording:
    """The commands of one gather stage for one ``key``, in order, with their timing labels; the
    host buffers the stage returned (``host``: name → array, or the index of the download command
    whose fresh array it is)."""

    key: object
    commands: list = field(default_factory=list)
    labels: list = field(default_factory=list)
    host: dict = field(default_factory=dict)
    io: tuple = ()
    """The plan's buffers the stage read and wrote (src, dst, aux …) when recorded."""
    patched: list = field(default_factory=list)
    """(command index, argument index) set when this recording was made from the previous one."""

    def replay(self, queue, frame, download=None, upload=None, outs=None) -> tuple[list, dict]:
        """Enqueue every command again (``frame``: the frame whose arrays the uploads read);
        returns [(label, event)] and the host buffers. ``download(host, buffer) -> event``: how a
        download into a fresh host array is enqueued instead of on ``queue``; ``upload(buffer,
        host) -> event``: how a copy of a host array into a buffer is (``Recorder``'s);
        ``outs``: the caller's arrays for host buffers by name, downloaded into instead of new
        ones."""
        events, fresh = [], {}
        given = {v: outs[k] for k, v in self.host.items() if type(v) is int and k in outs} if outs else {}
        for i, (cmd, label) in enumerate(zip(self.commands, self.labels)):
            if type(cmd) is Launch:
                events.append((label, cl.enqueue_nd_range_kernel(queue, cmd.kernel, cmd.global_size,
                                                                 cmd.local_size)))
            elif cmd.fresh and download is not None:
                dst = given[i] if i in given else np.empty(*cmd.fresh)
                events.append((label, download(dst, cmd.src)))
                fresh[i] = dst
            elif upload is not None and cmd.uploads:
                events.append((label, upload(cmd.dst, getattr(frame, cmd.frame_src) if cmd.frame_src else cmd.src)))
            else:
                ev, dst = cmd.enqueue(queue, frame, given.get(i))
                events.append((label, ev))
                if cmd.fresh:
                    fresh[i] = dst
        host = {k: (fresh[v] if type(v) is int else v) for k, v in self.host.items()} if self.host else {}
        return events, host


class Recorder:
    """The runtime as a gather stage sees it while a plan records it (module docstring).
    ``previous``: the stage's last recording, whose kernel objects are reused where the same
    kernel is launched with the same sizes at the same place. ``download(host, buffer) -> event``:
    how a download into a host array is enqueued instead of on the runtime's queue (recorded the
    same; :meth:`clpost.plan.Plan.submit` moves a frame's downloads off the compute queue);
    ``upload(buffer, host) -> event``: likewise for a copy of a host array into a buffer (the
    returned event is the one after which the buffer holds it). ``outs``: the caller's arrays for
    the output frame's host buffers by name (:meth:`host_array`)."""

    def __init__(self, rt, frame, key, previous: Recording | None = None, download=None, upload=None,
                 outs=None) -> None:
        self.rt = rt
        self.frame = frame
        self._download = download
        self._upload = upload
        self._outs = outs or {}
        self.recording = Recording(key)
        self._events: list = []
        self._old = previous.commands if previous is not None else []

    def __getattr__(self, name):  # program, constant, scratch, empty, device, context, queue, name …
        return getattr(self.rt, name)

    def host_array(self, name: str, shape, dtype=np.float32) -> np.ndarray:
        """The caller's array for the output frame's buffer ``name`` where it gave one (checked
        by the plan before anything is enqueued), else a new one (:meth:`Runtime.host_array`)."""
        given = self._outs.get(name)
        return given if given is not None else self.rt.host_array(name, shape, dtype)

    # -- kernels: captured, so that their arguments are known --------------------------------
    def kernel(self, source, name, defines=None, program=None) -> Captured:
        return Captured(self.rt.kernel(source, name, defines, program))

    def kernels(self, source, program, defines=None) -> dict:
        return {k: Captured(v) for k, v in self.rt.kernels(source, program, defines).items()}

    # -- commands ------------------------------------------------------------------------------
    def launch(self, kernel, global_size, local_size=None, *args) -> "cl.Event":
        cap = kernel if isinstance(kernel, Captured) else Captured(kernel)
        if args:
            cap.set_args(*args)
        glob, local_size = launch_sizes(global_size, local_size)
        rec, i = self.recording, len(self.recording.commands)
        old = self._old[i] if i < len(self._old) else None
        new_args = list(cap.args)
        if (type(old) is Launch and old.source is cap.kernel and old.global_size == glob
                and old.local_size == local_size and len(old.args) == len(new_args)):
            knl = old.kernel
            for j, (a, b) in enumerate(zip(old.args, new_args)):
                if not _same(a, b):
                    knl.set_arg(j, _typed(knl, j, b))
                    rec.patched.append((i, j))
        else:
            knl = private_kernel(cap.kernel)
            knl.set_args(*new_args)
        cmd = Launch(cap.kernel, knl, glob, local_size, new_args)
        ev = cl.enqueue_nd_range_kernel(self.rt.queue, knl, glob, local_size)
        rec.commands.append(cmd)
        self._events.append(ev)
        return ev

    def launch_once(self, kernel, global_size, local_size=None, *args) -> "cl.Event":
        """Plan-time work: enqueued now, not recorded."""
        if isinstance(kernel, Captured):
            args, kernel = (args or tuple(kernel.args)), kernel.kernel
        return self.rt.launch(kernel, global_size, local_size, *args)

    def copy(self, dst, src, blocking: bool = False) -> "cl.Event":
        if blocking:
            raise RuntimeError("a recorded stage reads nothing back mid-frame (its launches would "
                               "depend on the data); see clpost.runtime_record")
        name = next((n for n in FRAME_ARRAYS if src is getattr(self.frame, n, None)), None)
        fresh = (dst.shape, dst.dtype) if isinstance(dst, np.ndarray) else None
        cmd = Copy(dst, None if name else src, name, fresh)
        if fresh and self._download is not None and isinstance(src, cl.MemoryObjectHolder):
            ev = self._download(dst, src)
        elif self._upload is not None and isinstance(src, np.ndarray) and isinstance(dst, cl.MemoryObjectHolder):
            ev = self._upload(dst, src)
        else:
            ev = cl.enqueue_copy(self.rt.queue, dst, src, is_blocking=False)
        self.recording.commands.append(cmd)
        self._events.append(ev)
        return ev

    # -- the result ----------------------------------------------------------------------------
    def finish(self, returned, label: str, host: dict | None = None) -> Recording:
        """Label the commands (by the (label, event) pairs or events the stage ``returned``; the
        others: ``label`` for launches, upload/download for copies) and note the ``host``
        buffers."""
        rec = self.recording
        named = {}
        for item in returned:
            if isinstance(item, tuple):
                named[id(item[1])] = item[0]
        rec.labels = []
        for cmd, ev in zip(rec.commands, self._events):
            default = label if type(cmd) is Launch else ("download" if cmd.fresh or isinstance(cmd.dst, np.ndarray)
                                                          else "upload" if not isinstance(cmd.src, cl.MemoryObjectHolder)
                                                          else label)
            rec.labels.append(named.get(id(ev), default))
        if host:
            where = {id(cmd.dst): i for i, (cmd, ev) in enumerate(zip(rec.commands, self._events))
                     if type(cmd) is Copy and cmd.fresh}
            for ev_cmd in rec.commands:
                if type(ev_cmd) is Copy and ev_cmd.fresh:
                    ev_cmd.dst = None  # the first frame's array belongs to that frame's output
            rec.host = {k: where.get(id(v), v) for k, v in host.items()}
        else:
            for cmd in rec.commands:
                if type(cmd) is Copy and cmd.fresh:
                    cmd.dst = None
        return rec

"""Frames in flight (:meth:`clpost.plan.Plan.submit`): each frame's transfers on queues of their
own, so that on a discrete GPU frame i+1's upload and frame i−1's download run while frame i's
kernels do.

How a submitted frame flows (``docs/architecture.md``, "Frames in flight"):

1. **upload queue**: the frame's host arrays (colour, and depth/velocity where a stage reads
   them) → this frame's *slot*: device staging buffers of its own; so do the host arrays the
   stages copy mid-frame (a table a focus pull changes, a gather stage's uploads), each copied
   device-to-device into its plan buffer on the compute queue once its upload is done;
2. **compute queue** (the runtime's, in order, as :meth:`Plan.run` uses it): the slot's buffers
   copied device-to-device into the plan's fixed input buffers (each copy waits for its upload's
   event), the plan's launches, the output (and a resampling stage's depth/velocity, through
   the plan's download hook, ``runtime_record``) copied device-to-device into the slot;
3. **download thread** (:meth:`Stream.download`), on the download queue: the slot's copies → the
   frame's ``out`` and fresh host arrays, each waiting for its copy's event — a thread, so that
   a driver that downloads into pageable memory synchronously blocks it and not the caller.
   :meth:`Stream.close` (``Plan.close``) ends it; it is a daemon with a finalizer, so neither a
   forgotten close nor a frame that never completes holds the interpreter's exit.

Why the device-to-device copies: every command that reads or writes a buffer the plan's launches
use stays on the one in-order compute queue, so frames cannot race on them, and the gather
stages' recordings — which replay only while their input and output buffers are the ones they
were recorded with — keep replaying. A slot is reused only after its last frame's download has
completed (waited for on the host; that frame's copy out of the staging inputs came before it on
the compute queue), so at most ``len(slots)`` frames are in flight. The copies cost device
bandwidth (a 1080p frame's float colour and depth in and colour out: ≈ 58 MB, read and written
once more — tens of µs at a discrete GPU's memory bandwidth); on a CPU device or an integrated
GPU they would cost as much as the transfers themselves, so there ``Plan.submit`` runs the frame
at once (:attr:`clpost.runtime.Runtime.discrete`).
"""
from __future__ import annotations

import threading
import weakref
from concurrent.futures import Future
from dataclasses import dataclass, field
from queue import SimpleQueue

import numpy as np

from .frame import Frame


class PendingFrame:
    """A submitted frame: :meth:`result` waits for it and returns the processed :class:`Frame`
    (what :meth:`clpost.plan.Plan.run` returns); :meth:`done` asks without waiting. Its events
    keep the frame's host arrays alive until their transfers complete; the arrays must not be
    changed before :meth:`result` (the upload reads them while other frames run)."""

    def __init__(self, frame: Frame, events: list | None = None, downloads=None, plan=None,
                 writes: list | None = None) -> None:
        self._frame = frame
        self._writes = writes if writes is not None else [frame.color]
        """The host arrays the frame's downloads write (its image, the caller's depth/velocity)."""
        self._events = events or []
        self._downloads = downloads
        """The future of the frame's downloads (:meth:`Stream.download`); None: complete."""
        self._plan = plan
        self._waited = downloads is None
        self._error: BaseException | None = None

    def holds(self, array: np.ndarray) -> bool:
        """Whether ``array`` shares memory with an array the frame's downloads write (its image,
        the caller's depth/velocity) and ``result()`` has not been taken: the download may still
        write it."""
        return not self._waited and any(np.may_share_memory(a, array) for a in self._writes)

    def done(self) -> bool:
        """Whether the frame's downloads have completed (its image is in ``out``)."""
        return self._waited or self._downloads.done()

    def wait(self) -> None:
        """Block until every command of the frame has completed, then let its transfers' events
        drop their host arrays (``NannyEvent.wait``). A download that failed raises here, each
        time (the frame's commands complete first, so its slot is free either way)."""
        if self._waited:
            if self._error is not None:
                raise self._error
            return
        import pyopencl as cl

        try:
            self._events += self._downloads.result()
        except Exception as e:  # the download failed (an interrupt of this wait is not: it still runs)
            self._error = e
        try:
            if self._events:
                cl.wait_for_events([ev for _, ev in self._events])
            for _, ev in self._events:
                if isinstance(ev, cl.NannyEvent):
                    ev.wait()
        finally:
            self._waited = True
        if self._error is not None:
            raise self._error

    def result(self) -> Frame:
        """The processed frame, after :meth:`wait`; its device times become the plan's
        ``last_timings``."""
        self.wait()
        if self._plan is not None and self._events:
            self._plan._events, self._plan._timings = list(self._events), {}
        return self._frame


@dataclass
class Slot:
    """Device staging buffers of one frame in flight: its inputs by name (at the plan's input
    size), the tables and arrays its stages copy to the device mid-frame (``tables``, by their
    order in the frame) and its downloads (the image, a resampling stage's depth and velocity) by
    key. A slot's buffers are written only by its own frame, so a frame's upload never
    overwrites what another frame in flight still reads."""

    inputs: dict = field(default_factory=dict)
    tables: dict = field(default_factory=dict)
    outputs: dict = field(default_factory=dict)
    bounces: dict = field(default_factory=dict)
    """Page-locked host arrays by download key: what the downloads into arrays the plan makes
    itself (a resampling stage's depth and velocity, the image without ``out``) land in first."""
    pending: PendingFrame | None = None
    """The last frame that used this slot (waited for before the slot is used again)."""

    def input(self, rt, name: str, host: np.ndarray):
        return _staging(self.inputs, rt, name, host.nbytes)

    def table(self, rt, key, nbytes: int):
        return _staging(self.tables, rt, key, nbytes)

    def output(self, rt, key, nbytes: int):
        return _staging(self.outputs, rt, key, nbytes)

    def bounce(self, rt, key, host: np.ndarray, queue) -> np.ndarray:
        """A page-locked array of ``host``'s shape and type, this slot's for download ``key``
        (made by a map on ``queue``, the upload queue, whose commands wait for nothing on the
        device: not behind the compute queue's work, nor behind downloads waiting for it)."""
        arr = self.bounces.get(key)
        if arr is None or arr.shape != host.shape or arr.dtype != host.dtype:
            arr = self.bounces[key] = rt.pinned_empty(host.shape, host.dtype, queue)
        return arr


def _staging(buffers: dict, rt, key, nbytes: int):
    """``buffers[key]``, made anew when missing or of another size."""
    buf = buffers.get(key)
    if buf is None or buf.size != max(nbytes, 4):
        buf = buffers[key] = rt.empty((max(nbytes, 4),), np.uint8)
    return buf


def _download(queue, copies: list) -> list:
    """The download worker's job: each (host array, slot buffer, event of the copy into it,
    page-locked bounce array or None) copied into its host array once that event completes.
    None of the copies is a blocking read: NVIDIA's driver holds every other thread's enqueue
    for as long as a blocking read into pageable memory runs (H200: the submitting thread
    stopped for each frame's depth download, so frames ran one after another — docs/
    benchmarks.md, "Frames in flight"), so a download into an array the plan made itself goes by
    DMA into the slot's page-locked bounce array and from there by a host copy (NumPy's, which
    releases the GIL); a caller's ``out`` is copied into directly (page-locked, it is DMA)."""
    import pyopencl as cl

    events = [(cl.enqueue_copy(queue, host if bounce is None else bounce, buf, wait_for=[staged],
                               is_blocking=False), host, bounce) for host, buf, staged, bounce in copies]
    queue.flush()
    for ev, host, bounce in events:
        ev.wait()
        if bounce is not None:
            np.copyto(host, bounce)
    return [("download", ev) for ev, _, _ in events]


class Stream:
    """The slots of one :class:`clpost.plan.Buffers` (shared by the plans of a pipeline and size,
    which share its device buffers and the compute queue), used round robin, and the thread
    that enqueues their frames' downloads, in order.

    The thread is started by the first download and stopped by :meth:`close` (after the frames in
    flight complete; a later download starts it again). It is a daemon thread, and a
    ``weakref.finalize`` stops it when the stream is collected or the interpreter exits, without
    waiting: a download that never completes (a device that hangs) cannot hold the exit."""

    def __init__(self, depth: int) -> None:
        self.slots = [Slot() for _ in range(depth)]
        self.next = 0
        self._jobs = None
        self._thread = None
        self._finalizer = None

    def resize(self, depth: int) -> None:
        """``depth`` slots (frames in flight); the frames in flight complete first."""
        if depth != len(self.slots):
            self.drain()
            self.slots = [Slot() for _ in range(depth)]
            self.next = 0

    @property
    def upcoming(self) -> Slot:
        """The slot the next frame takes (:meth:`reserve` waits for its last frame)."""
        return self.slots[self.next % len(self.slots)]

    def reserve(self) -> Slot:
        """The next slot, once the frame that used it last is complete."""
        slot = self.upcoming
        _complete(slot)
        return slot

    def download(self, queue, copies: list) -> Future:
        """Hand a frame's downloads (:func:`_download`) to the worker thread; their future."""
        if self._thread is None:
            self._jobs = SimpleQueue()
            self._thread = threading.Thread(target=_serve, args=(self._jobs,), name="clpost-download",
                                            daemon=True)
            self._thread.start()
            # references the queue and thread only (not the stream), so the stream can be collected
            self._finalizer = weakref.finalize(self, _stop, self._jobs, self._thread, 0.0)
        future = Future()
        self._jobs.put((future, _download, (queue, copies)))
        return future

    def commit(self, slot: Slot, pending: PendingFrame) -> None:
        slot.pending = pending
        self.next += 1

    def drain(self) -> None:
        """Wait for every frame in flight."""
        for slot in self.slots:
            _complete(slot)

    def close(self) -> None:
        """Wait for every frame in flight, then stop the download thread and wait for it to end.
        Idempotent; a later download starts a new thread."""
        self.drain()
        if self._thread is not None:
            self._finalizer.detach()
            _stop(self._jobs, self._thread, None)
            self._jobs = self._thread = self._finalizer = None


def _serve(jobs: SimpleQueue) -> None:
    """The download thread: run each (future, function, arguments) of ``jobs`` in order, its
    result or exception into its future, until a None."""
    while True:
        job = jobs.get()
        if job is None:
            return
        future, fn, args = job
        if not future.set_running_or_notify_cancel():
            continue
        try:
            future.set_result(fn(*args))
        except BaseException as e:  # the frame's error (its result() raises it), not the thread's end
            future.set_exception(e)


def _stop(jobs: SimpleQueue, thread: threading.Thread, timeout: float | None) -> None:
    """Ask the download thread to end after the downloads handed to it; wait ``timeout`` s for it
    (None: until it ends; 0: not at all — the finalizer's, at exit)."""
    jobs.put(None)
    if timeout != 0.0 and thread is not threading.current_thread():
        thread.join(timeout)


def _complete(slot: Slot) -> None:
    """Wait for the last frame that used ``slot``; a download of its that failed is that frame's
    error (its ``result()`` raises it), not the caller's, and leaves the slot free."""
    pending = slot.pending
    if pending is not None:
        try:
            pending.wait()
        except Exception:
            pass
        slot.pending = None  # not on an interrupt of the wait: the frame may still be in flight

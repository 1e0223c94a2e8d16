"""Plan.submit: frames in flight (transfers on their own queues, staged into the plan's buffers) give
what Plan.run gives frame by frame. On PoCL (a CPU device) submit runs each frame at once unless
the plan is told to pipeline (``plan.pipelined = True``), which these tests do to exercise the GPU
path's queues, events and slots on the CPU; on a GPU (``CLPOST_DEVICE=nvidia``) they check the
same against the driver's real concurrency."""
import gc

import numpy as np
import pyopencl as cl
import pytest

from clpost import Camera, Frame, Pipeline
from clpost.errors import InputError
from test_plan import _worst_case, scene


def _frames(frame, n):
    """``n`` frames of different content (scaled colour, depth and velocity), fresh arrays each."""
    vel = frame.velocity
    return [frame.replace(color=(frame.color * (1.0 + 0.37 * i)).astype(np.float32),
                          depth=(frame.depth * (1.0 + 0.1 * i)).astype(np.float32),
                          velocity=None if vel is None else (vel * (1.0 - 0.2 * i)).astype(np.float32),
                          metadata=dict(frame.metadata, frame_index=i)) for i in range(n)]


@pytest.fixture(scope="module")
def worst():
    rng = np.random.default_rng(20)
    pipe, frame, cam, stages = _worst_case(rng)
    plan = pipe.plan_for(frame)
    assert plan.stage_names == stages
    return plan, frame, cam


@pytest.mark.parametrize("in_flight", [1, 2, 3])
def test_frames_in_flight_with_a_focus_pull_match_plan_run_frame_by_frame(worst, in_flight):
    """The worst case (dof, astigmatism, distortion resampling depth and velocity, vignetting,
    exposure): five frames of different content and focus submitted back to back, results taken
    out of order, are bit for bit Plan.run's — image and the distortion's host buffers."""
    plan, frame, cam = worst
    cams = [cam.with_(focus_distance_m=f) for f in (2.0, 3.5, 1.0, 1.0, 6.0)]
    frames = _frames(frame, len(cams))
    plan.pipelined = False
    want = [plan.run(f, c) for f, c in zip(frames, cams)]
    assert not np.array_equal(want[0].color, want[1].color)
    assert not np.array_equal(want[0].depth, want[1].depth) and not np.array_equal(want[0].velocity, want[1].velocity)
    plan.pipelined, plan.in_flight = True, in_flight
    try:
        pending = [plan.submit(f, c) for f, c in zip(frames, cams)]
        got = [pending[i].result() for i in (4, 0, 3, 1, 2)]
        got = [got[i] for i in (1, 3, 4, 2, 0)]
    finally:
        plan.pipelined = False
    for w, g in zip(want, got):
        np.testing.assert_array_equal(g.color, w.color)
        np.testing.assert_array_equal(g.depth, w.depth)
        np.testing.assert_array_equal(g.velocity, w.velocity)
        assert g.metadata["camera"] == w.metadata["camera"]
    assert len(plan.buffers.stream.slots) == in_flight


def test_submitted_frames_transfer_on_their_own_queues_and_keep_their_arrays_alive(worst):
    """Uploads and downloads run on the runtime's transfer queues, the staging copies and kernels
    on the compute queue; a frame whose arrays nobody else holds still uploads them (the events
    keep them alive); a slot is reused only once its last frame is complete."""
    plan, frame, cam = worst
    want = [plan.run(f, cam).color for f in _frames(frame, 3)]
    plan.pipelined, plan.in_flight = True, 2
    try:
        pending = [plan.submit(f, cam) for f in _frames(frame, 3)]  # the frames live only in the events
        gc.collect()
        assert pending[0].done()  # the third submit reused the first frame's slot: it waited for it
        got = [p.result().color for p in pending]
    finally:
        plan.pipelined = False
    for w, g in zip(want, got):
        np.testing.assert_array_equal(g, w)
    rt = plan.runtime
    up, down = rt.transfer_queues()
    # by label, the first command's queue, and the last download's: distortion's own transfers (the
    # velocity it alone reads, its resampled depth and velocity) stay on the compute queue
    events = pending[-1]._events
    queue_of = {}
    for label, ev in events:
        queue_of.setdefault(label, ev.get_info(cl.event_info.COMMAND_QUEUE).int_ptr)
    assert events[-1][0] == "download"
    assert events[-1][1].get_info(cl.event_info.COMMAND_QUEUE).int_ptr == down.int_ptr
    assert queue_of["upload"] == up.int_ptr
    assert queue_of["stage_in"] == queue_of["stage_out"] == queue_of["dof"] == rt.queue.int_ptr
    assert set(plan.last_timings) >= {"upload", "stage_in", "dof", "distortion", "stage_out", "download"}


def test_submit_downloads_into_pinned_out_arrays_and_mixes_with_run(rng):
    """Pinned inputs and ``out=`` arrays per frame: the returned colour is ``out``; a Plan.run
    between submitted frames sees its own frame (one compute queue orders them)."""
    frame = scene(rng, w=64, h=24)
    cam = Camera(f_number=2.0, depth_of_field=True, blades=6, focus_distance_m=0.8)
    plan = Pipeline(cam, quality="draft").plan_for(frame)
    frames = _frames(frame, 3)
    want = [plan.run(f).color for f in frames]
    rt = plan.runtime
    pinned = []
    for f in frames:
        c, d = rt.pinned_empty(f.color.shape), rt.pinned_empty(f.depth.shape)
        c[...], d[...] = f.color, f.depth
        pinned.append(f.replace(color=c, depth=d, copy=False))  # a Frame copies its arrays unless told
        assert pinned[-1].color is c and pinned[-1].depth is d
    outs = [rt.pinned_empty(w.shape) for w in want]
    plan.pipelined = True
    first = plan.submit(pinned[0], out=outs[0])
    middle = plan.run(pinned[1], out=outs[1])
    last = plan.submit(pinned[2], out=outs[2])
    got = [first.result(), middle, last.result()]
    for g, o, w in zip(got, outs, want):
        assert g.color is o
        np.testing.assert_array_equal(o, w)


def test_a_refused_frame_leaves_nothing_in_flight(rng):
    """A wrong ``out``, a frame of another size or without the depth a stage reads, a camera of
    another structure: one InputError line each, raised before anything is enqueued (the slot
    ring does not move, ``out`` is untouched), and the next frame runs as usual."""
    frame = scene(rng, w=64, h=24)
    cam = Camera(f_number=2.0, depth_of_field=True, blades=6, focus_distance_m=0.8)
    plan = Pipeline(cam, quality="draft").plan_for(frame)
    want = plan.run(frame).color
    plan.pipelined = True
    plan.submit(frame).result()
    stream = plan.buffers.stream
    before = stream.next
    bad_out = np.full((24, 64, 3), 7.0, np.float32)[:, :, ::-1]  # right shape, not C-contiguous
    cases = [
        (dict(frame=frame, out=np.empty((24, 63, 3), np.float32)), r"out= must be .*\(24, 64, 3\)"),
        (dict(frame=frame, out=bad_out), "C-contiguous"),
        (dict(frame=scene(rng, w=16, h=9)), "built for 64x24"),
        (dict(frame=Frame(frame.color)), "needs the frame's depth"),
        (dict(frame=frame, camera=cam.with_(blades=5)), "Pipeline.run"),
        (dict(frame=frame.color), "clpost.Frame"),
    ]
    for kwargs, match in cases:
        with pytest.raises(InputError, match=match) as err:
            plan.submit(**kwargs)
        assert "\n" not in str(err.value)
    for bad in (0, -1, 1.5, True):
        plan.in_flight = bad
        with pytest.raises(InputError, match="in_flight must be .* >= 1, not") as err:
            plan.submit(frame)
        assert "\n" not in str(err.value)
    plan.in_flight = 2
    assert stream.next == before and np.all(bad_out == 7.0)
    np.testing.assert_array_equal(plan.submit(frame).result().color, want)


def test_on_a_cpu_device_submit_runs_the_frame_at_once(rng):
    """Without a discrete GPU submit is Plan.run returning a finished frame: no staging, no
    transfer queues."""
    frame = scene(rng, w=40, h=16)
    plan = Pipeline(Camera(f_number=2.0, depth_of_field=True, focus_distance_m=0.8), quality="draft").plan_for(frame)
    if plan.runtime.discrete:
        pytest.skip("a discrete GPU pipelines by default")
    assert plan.pipelined is False
    pending = plan.submit(frame)
    assert pending.done() and plan.buffers.stream is None
    np.testing.assert_array_equal(pending.result().color, plan.run(frame).color)


def test_the_frame_index_of_each_submitted_frame_reaches_its_noise(rng):
    """Motion blur and the sensor hash the frame index (their noise): in flight, each frame gets
    its own index — the per-frame scalars of a replayed launch are the frame's, not the next's."""
    w, h = 40, 24
    velocity = np.zeros((h, w, 2), np.float32)
    velocity[..., 0] = np.linspace(0, 9, w)[None, :]
    color = rng.uniform(0, 1, (h, w, 3)).astype(np.float32)
    cam = Camera(shutter_s=1 / 48, frame_rate_fps=24.0, sensor_preset="smartphone")
    stages = ["exposure", "motion_blur", "sensor"]
    frames = [Frame(color, depth=np.full((h, w), 3.0, np.float32), velocity=velocity, metadata={"frame_index": i})
              for i in range(4)]
    plan = Pipeline(cam, stages=stages).plan_for(frames[0])
    assert plan.stage_names == ["motion_blur", "sensor"]
    want = [plan.run(f).color for f in frames]
    assert np.any(want[0] != want[1])
    plan.pipelined = True
    got = [p.result().color for p in [plan.submit(f) for f in frames]]
    for g, w_ in zip(got, want):
        np.testing.assert_array_equal(g, w_)


def test_submit_returns_while_the_device_is_busy_and_waits_only_for_a_slot(worst):
    """With the compute queue held (a user event), ``in_flight`` frames are submitted without
    waiting; the next waits until the frame that used its slot is complete — the staging
    buffers are never overwritten under a frame in flight."""
    import threading

    plan, frame, cam = worst
    frames = _frames(frame, 3)
    want = [plan.run(f, cam).color for f in frames]
    rt = plan.runtime
    hold = cl.UserEvent(rt.context)
    plan.pipelined, plan.in_flight = True, 2
    try:
        cl.enqueue_barrier(rt.queue, wait_for=[hold])
        pending = [plan.submit(f, cam) for f in frames[:2]]  # returns: nothing waits for the device
        assert not pending[0].done()
        third = []
        t = threading.Thread(target=lambda: third.append(plan.submit(frames[2], cam)))
        t.start()
        t.join(0.5)
        assert t.is_alive() and not third  # its slot is the first frame's, still in flight
    finally:
        hold.set_status(cl.command_execution_status.COMPLETE)
    t.join(30)
    plan.pipelined = False
    assert not t.is_alive()
    for p, w in zip(pending + third, want):
        np.testing.assert_array_equal(p.result().color, w)


def test_a_first_frame_submitted_records_its_stages_with_the_downloads_moved(rng):
    """A plan whose first frame is submitted records its gather stages there (the Recorder's
    downloads — distortion's depth and velocity — staged for the download worker) and replays
    them next; a plan whose later stage would read those host arrays back keeps them on the
    compute queue. Both: what Plan.run gives."""
    pipe, frame, cam, stages = _worst_case(rng)
    frames = _frames(frame, 3)
    ref = Pipeline(cam, quality="final", stages=stages).plan_for(frame)
    want = [ref.run(f, cam) for f in frames]
    plan = pipe.plan_for(frame)
    plan.pipelined = True
    assert plan.nodes[0].recording is None and not plan._aux_reread
    pending = [plan.submit(f, cam) for f in frames]
    got = [p.result() for p in pending]
    down = plan.runtime.transfer_queues()[1].int_ptr
    for p in pending[:2]:  # recorded, then replayed: depth, velocity and image by the download worker
        assert [ev.get_info(cl.event_info.COMMAND_QUEUE).int_ptr for label, ev in p._events
                if label == "download"] == [down] * 3
    plan._aux_reread = True  # as if a stage after distortion read depth (none does today)
    again = plan.submit(frames[1], cam)
    compute = plan.runtime.queue.int_ptr
    assert [ev.get_info(cl.event_info.COMMAND_QUEUE).int_ptr for label, ev in again._events
            if label == "download"] == [compute, compute]  # distortion's depth and velocity
    got.append(again.result())
    for w, g in zip(want + want[1:2], got):
        np.testing.assert_array_equal(g.color, w.color)
        np.testing.assert_array_equal(g.depth, w.depth)
        np.testing.assert_array_equal(g.velocity, w.velocity)


def test_the_download_worker_never_blocks_in_a_read_and_bounces_the_plans_own_arrays(rng, monkeypatch):
    """NVIDIA's driver holds every other thread's enqueue while a blocking read into pageable
    memory runs, which serialised the frames in flight on the H200 (docs/benchmarks.md, "Frames in
    flight"): the download worker's copies are non-blocking, and those into arrays the plan made
    (distortion's depth and velocity, the image without ``out``) land in the slot's page-locked
    bounce arrays, then a host copy; a caller's ``out`` is copied into directly. The frames are
    still Plan.run's, each with arrays of its own."""
    import threading

    pipe, frame, cam, stages = _worst_case(rng)
    frames = _frames(frame, 3)
    plan = pipe.plan_for(frame)
    want = [plan.run(f, cam) for f in frames]
    plan.pipelined, plan.in_flight = True, 1
    seen, real = [], cl.enqueue_copy

    def spy(queue, dst, src, **kw):
        if threading.current_thread().name == "clpost-download":
            seen.append((dst, kw.get("is_blocking", True)))
        return real(queue, dst, src, **kw)

    monkeypatch.setattr(cl, "enqueue_copy", spy)
    out = plan.runtime.pinned_empty(want[0].color.shape)
    got = [plan.submit(f, cam).result() for f in frames[:2]]
    got.append(plan.submit(frames[2], cam, out=out).result())
    assert seen and not any(blocking for _, blocking in seen)
    bounces = [a for s in plan.buffers.stream.slots for a in s.bounces.values()]
    assert len(bounces) == 3  # depth, velocity, image: one slot's
    assert sum(any(dst is b for b in bounces) for dst, _ in seen) == 3 * 2 + 2  # the last image went to out
    assert sum(dst is out for dst, _ in seen) == 1
    for w, g in zip(want, got):
        np.testing.assert_array_equal(g.color, w.color)
        np.testing.assert_array_equal(g.depth, w.depth)
        np.testing.assert_array_equal(g.velocity, w.velocity)
        assert not any(np.may_share_memory(g.depth, b) or np.may_share_memory(g.velocity, b) for b in bounces)
    assert got[2].color is out and not any(np.may_share_memory(g.color, b) for g in got[:2] for b in bounces)


def test_label_planes_resampled_in_flight_belong_to_their_frame(rng):
    """Distortion re-records every frame that has label planes (its upload of them is not
    replayable): each submitted frame's labels, depth and image are its own, as Plan.run's."""
    import warnings

    from test_labels import MODELS, _frame

    frames = [_frame(rng, MODELS["barrel"]) for _ in range(3)]
    cam = Camera(distortion=MODELS["barrel"])
    pipe = Pipeline(cam, stages=["distortion"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rcam = pipe.camera_for(frames[0])
        plan = pipe.plan_for(frames[0], rcam)
        want = [plan.run(f, rcam) for f in frames]
        plan.pipelined = True
        got = [p.result() for p in [plan.submit(f, rcam) for f in frames]]
    assert not np.array_equal(want[0].labels["id"], want[1].labels["id"])
    for w, g in zip(want, got):
        np.testing.assert_array_equal(g.color, w.color)
        np.testing.assert_array_equal(g.depth, w.depth)
        assert g.labels.keys() == w.labels.keys()
        for k in w.labels:
            np.testing.assert_array_equal(g.labels[k], w.labels[k])


@pytest.mark.parametrize("submit", [False, True])
def test_an_error_mid_enqueue_leaves_no_stale_kernel_argument(rng, monkeypatch, submit):
    """A stage that raises part-way through a re-recording (its first launches already given the
    new focus on the kernel objects it shares with the previous recording) must not leave those
    arguments behind: the next frame, at the old focus, is what a fresh plan gives — image and
    errors alike."""
    from clpost import runtime_record

    pipe, frame, cam, stages = _worst_case(rng)
    plan = pipe.plan_for(frame)
    near = cam.with_(focus_distance_m=0.7)
    fresh = Pipeline(cam, quality="final", stages=stages).plan_for(frame)
    want = fresh.run(frame, cam).color
    plan.pipelined = submit
    go = (lambda c: plan.submit(frame, c).result()) if submit else (lambda c: plan.run(frame, c))
    np.testing.assert_array_equal(go(cam).color, want)
    launch, calls = runtime_record.Recorder.launch, []

    def failing(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise RuntimeError("injected")
        return launch(self, *args, **kwargs)

    monkeypatch.setattr(runtime_record.Recorder, "launch", failing)
    with pytest.raises(RuntimeError, match="injected"):
        go(near)
    monkeypatch.setattr(runtime_record.Recorder, "launch", launch)
    np.testing.assert_array_equal(go(cam).color, want)
    np.testing.assert_array_equal(go(near).color, fresh.run(frame, near).color)


def test_a_failed_download_is_its_frames_error_and_frees_its_slot(rng, monkeypatch):
    """A frame whose download fails raises from its own ``result()`` (every time); the frames
    submitted after it, which reuse its slot, run as usual instead of raising its error."""
    import clpost.stream as stream

    frame = scene(rng, w=64, h=24)
    plan = Pipeline(Camera(f_number=2.0, depth_of_field=True, blades=6, focus_distance_m=0.8),
                    quality="draft").plan_for(frame)
    want = plan.run(frame).color
    plan.pipelined, plan.in_flight = True, 2
    download = stream._download

    def failing(queue, copies):
        raise RuntimeError("download failed")

    monkeypatch.setattr(stream, "_download", failing)
    bad = plan.submit(frame)
    monkeypatch.setattr(stream, "_download", download)
    later = [plan.submit(frame) for _ in range(4)]
    for _ in range(2):
        with pytest.raises(RuntimeError, match="download failed"):
            bad.result()
    for p in later:
        np.testing.assert_array_equal(p.result().color, want)
    plan.drain()


def test_an_out_array_still_in_flight_is_refused(rng):
    """``out`` belongs to its frame until ``result()``: giving it to another frame while that
    frame's download may still write it (submit or run) is one InputError line, and the first
    frame's image is its own. The frame whose slot a submit waits for first does not hold its
    ``out`` any more, so two arrays round robin over two frames in flight are fine."""
    frame = scene(rng, w=64, h=24)
    cam = Camera(f_number=2.0, depth_of_field=True, blades=6, focus_distance_m=0.8)
    plan = Pipeline(cam, quality="draft").plan_for(frame)
    frames = _frames(frame, 4)
    want = [plan.run(f).color for f in frames]
    plan.pipelined, plan.in_flight = True, 2
    rt = plan.runtime
    out = np.empty_like(want[0])
    hold = cl.UserEvent(rt.context)
    try:
        cl.enqueue_barrier(rt.queue, wait_for=[hold])
        first = plan.submit(frames[0], out=out)
        for call in (plan.submit, plan.run):
            with pytest.raises(InputError, match="still in flight") as err:
                call(frames[1], out=out[:, :])
            assert "\n" not in str(err.value)
    finally:
        hold.set_status(cl.command_execution_status.COMPLETE)
    np.testing.assert_array_equal(first.result().color, want[0])
    np.testing.assert_array_equal(plan.submit(frames[1], out=out).result().color, want[1])
    outs = [np.empty_like(want[0]) for _ in range(2)]
    pending = [plan.submit(f, out=outs[k % 2]) for k, f in enumerate(frames)]
    for p, w in zip(pending[2:], want[2:]):
        np.testing.assert_array_equal(p.result().color, w)


def test_an_interrupted_wait_keeps_the_frame_in_flight(rng, monkeypatch):
    """A KeyboardInterrupt while ``result()`` waits for the download thread is not the frame's
    error: the frame stays in flight (its slot is not handed to the next frame), and the next
    ``result()`` gives its image."""
    import concurrent.futures

    frame = scene(rng, w=64, h=24)
    plan = Pipeline(Camera(f_number=2.0, depth_of_field=True, blades=6, focus_distance_m=0.8),
                    quality="draft").plan_for(frame)
    want = plan.run(frame).color
    plan.pipelined, plan.in_flight = True, 1
    pending = plan.submit(frame)
    result = concurrent.futures.Future.result
    monkeypatch.setattr(concurrent.futures.Future, "result",
                        lambda self, timeout=None: (_ for _ in ()).throw(KeyboardInterrupt()))
    with pytest.raises(KeyboardInterrupt):
        pending.result()
    assert plan.buffers.stream.slots[0].pending is pending and not pending._waited
    monkeypatch.setattr(concurrent.futures.Future, "result", result)
    np.testing.assert_array_equal(pending.result().color, want)
    np.testing.assert_array_equal(plan.submit(frame).result().color, want)


def _complete_within(events, seconds: float) -> bool:
    """Whether every event completes within ``seconds`` (polled, so a queue that is held cannot
    hang the test)."""
    import time

    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if all(ev.command_execution_status == cl.command_execution_status.COMPLETE for ev in events):
            return True
        time.sleep(0.01)
    return False


@pytest.mark.parametrize("in_flight", [2, 3])
def test_a_focus_pull_uploads_each_frames_tables_beside_a_busy_compute_queue(worst, in_flight):
    """A focus pull changes vignetting's table every frame (the exit pupil moves). With the
    compute queue held, ``in_flight`` frames of the pull are submitted without waiting for it
    (their table uploads go on the upload queue, not blocking on the compute queue) and all their
    uploads complete before any kernel runs; still each frame reads its own table — bit for bit
    Plan.run's. A staging buffer shared between slots would hand the earlier frames the last
    one's table; a table copied on the compute queue would block the submits."""
    import threading

    plan, frame, cam = worst
    cams = [cam.with_(focus_distance_m=f) for f in (1.2, 2.5, 5.0)[:in_flight]]
    frames = _frames(frame, in_flight)
    plan.pipelined = False
    want, tables = [], []
    for f, c in zip(frames, cams):
        want.append(plan.run(f, c))
        tables.append(plan.buffers.uploaded[("vignetting", "ri")].key)  # built from the frame's LUT
    assert all(a != b for a, b in zip(tables, tables[1:]))  # a new table each frame
    rt = plan.runtime
    up = rt.transfer_queues()[0].int_ptr
    hold = cl.UserEvent(rt.context)
    plan.pipelined, plan.in_flight = True, in_flight
    pending: list = []
    t = threading.Thread(target=lambda: pending.extend(plan.submit(f, c) for f, c in zip(frames, cams)))
    try:
        cl.enqueue_barrier(rt.queue, wait_for=[hold])
        t.start()
        t.join(60)
        submitted = not t.is_alive()
        if submitted:
            uploads = [ev for p in pending for label, ev in p._events if label == "upload"]
            assert {ev.get_info(cl.event_info.COMMAND_QUEUE).int_ptr for ev in uploads} == {up}
            assert _complete_within(uploads, 30)  # while the compute queue still holds every frame
            assert not any(p.done() for p in pending)
    finally:
        hold.set_status(cl.command_execution_status.COMPLETE)
        t.join(60)
        plan.pipelined = False
    assert submitted, "a submit waited for the compute queue (a table copied on it, blocking)"
    for w, p in zip(want, pending):
        g = p.result()
        np.testing.assert_array_equal(g.color, w.color)
        np.testing.assert_array_equal(g.depth, w.depth)
    assert all(slot.tables for slot in plan.buffers.stream.slots)  # each slot staged its frame's tables


def test_close_ends_the_download_thread_and_a_closed_plan_refuses_frames(rng):
    """``with pipeline:`` (Pipeline.close → Plan.close) waits for the frames in flight and ends
    the download thread; the closed plan's run and submit are one InputError line each; the
    pipeline plans anew afterwards, and a plan dropped without close ends its thread too (the
    stream's finalizer)."""
    import threading

    frame = scene(rng, w=64, h=24)
    cam = Camera(f_number=2.0, depth_of_field=True, blades=6, focus_distance_m=0.8)
    frames = _frames(frame, 3)
    with Pipeline(cam, quality="draft") as pipe:
        plan = pipe.plan_for(frame)
        want = [plan.run(f).color for f in frames]
        plan.pipelined = True
        pending = [plan.submit(f) for f in frames]
        thread = plan.buffers.stream._thread
        assert thread in threading.enumerate()
    assert thread not in threading.enumerate() and plan.closed
    assert all(p.done() for p in pending)
    for p, w in zip(pending, want):
        np.testing.assert_array_equal(p.result().color, w)
    for call in (plan.submit, plan.run):
        with pytest.raises(InputError, match="closed .*Pipeline.plan_for") as err:
            call(frame)
        assert "\n" not in str(err.value)
    plan.close()  # idempotent
    again = pipe.plan_for(frame)
    assert again is not plan and not again.closed
    again.pipelined = True
    np.testing.assert_array_equal(again.submit(frames[1]).result().color, want[1])
    thread = again.buffers.stream._thread
    assert thread.is_alive()
    del again, pipe, plan, pending
    gc.collect()
    thread.join(10)
    assert not thread.is_alive()


def test_the_interpreter_exits_with_a_download_that_never_completes(tmp_path):
    """A frame whose download never ends (here the download function waits forever; a device
    that hangs does the same to the download thread) must not hold the interpreter's exit: the
    download thread is a daemon, not joined at exit. (With a thread pool it hung.)"""
    import subprocess
    import sys
    from pathlib import Path

    script = tmp_path / "hang.py"
    script.write_text(
        "import threading\n"
        "import numpy as np\n"
        "import clpost.stream as stream\n"
        "from clpost import Camera, Frame, Pipeline\n"
        "stream._download = lambda queue, copies: threading.Event().wait()\n"
        "rng = np.random.default_rng(1)\n"
        "frame = Frame(rng.uniform(0, 1, (24, 64, 3)).astype(np.float32), depth=np.full((24, 64), 2.0, np.float32))\n"
        "plan = Pipeline(Camera(f_number=2.0, depth_of_field=True, focus_distance_m=0.8), quality='draft').plan_for(frame)\n"
        "plan.pipelined = True\n"
        "pending = plan.submit(frame)\n"
        "assert not pending.done()\n"
        "print('submitted', flush=True)\n")
    root = Path(__file__).resolve().parents[1]
    run = subprocess.run([sys.executable, str(script)], cwd=root, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "submitted" in run.stdout


def test_the_output_frames_depth_and_velocity_go_into_the_callers_arrays(rng):
    """``out`` as a dict: the image, and the depth and velocity distortion makes at the output
    size, downloaded into the caller's arrays (page-locked ones: a GPU's DMA, no host copy) —
    by Plan.run on the recording frame and on replays, and by submitted frames in flight, which
    then use no bounce array for them. Each frame is what Plan.run gives with new arrays."""
    pipe, frame, cam, stages = _worst_case(rng)
    frames = _frames(frame, 4)
    plan = pipe.plan_for(frame)
    rt = plan.runtime
    w, h = plan.output_size

    def outs():
        return {"color": rt.pinned_empty((h, w, 3)), "depth": rt.pinned_empty((h, w)),
                "velocity": np.empty((h, w, 2), np.float32)}
    ref = Pipeline(cam, quality="final", stages=stages).plan_for(frame)
    want = [ref.run(f, cam) for f in frames]
    for f, wnt in zip(frames[:2], want):  # recorded, then replayed
        o = outs()
        got = plan.run(f, cam, out=o)
        assert got.color is o["color"] and got.depth is o["depth"] and got.velocity is o["velocity"]
        for n in ("color", "depth", "velocity"):
            np.testing.assert_array_equal(getattr(got, n), getattr(wnt, n))
    only = plan.run(frames[2], cam, out={"depth": rt.pinned_empty((h, w))})  # the rest new
    np.testing.assert_array_equal(only.velocity, want[2].velocity)
    plan.pipelined, plan.in_flight = True, 2
    try:
        given = [outs() for _ in frames]
        pending = [plan.submit(f, cam, out=o) for f, o in zip(frames, given)]
        got = [p.result() for p in pending]
    finally:
        plan.pipelined = False
    assert not any(s.bounces for s in plan.buffers.stream.slots)
    for g, o, wnt in zip(got, given, want):
        for n in ("color", "depth", "velocity"):
            assert getattr(g, n) is o[n]
            np.testing.assert_array_equal(getattr(g, n), getattr(wnt, n))


def test_wrong_output_arrays_are_refused_with_one_line(rng):
    """A name no plan downloads, an array of the wrong shape, a depth array for a plan that makes
    no new depth, and an array a frame in flight still writes: one InputError line each, before
    anything is enqueued."""
    pipe, frame, cam, stages = _worst_case(rng)
    plan = pipe.plan_for(frame)
    w, h = plan.output_size
    with pytest.raises(InputError, match="'alpha'"):
        plan.run(frame, cam, out={"alpha": np.empty((h, w), np.float32)})
    with pytest.raises(InputError, match=r"out\['velocity'\] must be .*\(%d, %d, 2\)" % (h, w)):
        plan.run(frame, cam, out={"velocity": np.empty((h, w), np.float32)})
    with pytest.raises(InputError, match="must be a float32 image array or a dict"):
        plan.run(frame, cam, out=[np.empty((h, w, 3), np.float32)])
    plain = Pipeline(Camera(f_number=2.0, depth_of_field=True, focus_distance_m=0.8), quality="draft")
    small = Frame(frame.color, depth=frame.depth)
    with pytest.raises(InputError, match=r"out\['depth'\] given, but this plan makes no new depth"):
        plain.plan_for(small).run(small, out={"depth": np.empty(frame.depth.shape, np.float32)})
    depth = plan.runtime.pinned_empty((h, w))
    plan.pipelined, plan.in_flight = True, 2
    try:
        first = plan.submit(frame, cam, out={"depth": depth})
        with pytest.raises(InputError, match=r"out\['depth'\] is an array of a submitted frame still in flight"):
            plan.submit(frame, cam, out={"depth": depth})
        first.result()
        plan.submit(frame, cam, out={"depth": depth}).result()  # taken: free again
    finally:
        plan.pipelined = False

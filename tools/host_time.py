"""Host time per frame of ``Pipeline.run``: this tree and a git revision in one process.

Host time is the calling thread's CPU time (``time.thread_time``) over one ``Pipeline.run`` —
resolving the camera, planning, tables, argument setting, enqueueing — so it leaves out the
device's threads and the waits for them. Median of 15 frames after 2 warm-ups, 1920×1080 bench
scenes, old and this tree interleaved frame by frame; the extended-frustum row renders at
``required_render``'s size for the calibration, the case that solves the render's intrinsics.

``--against`` also gives ``Plan.run`` alone (the target: ≤ 1 ms besides the kernels), for a fixed
camera and for a focus pull (the focus changes every frame: the stages' launch code runs again and
sets the changed arguments).

    PYTHONPATH=. python -W ignore tools/host_time.py --against a4db22e
    PYTHONPATH=. python -W ignore tools/host_time.py --against 89893fe --python-only  # Python alone
    PYTHONPATH=. python -W ignore tools/host_time.py --breakdown    # where Plan.run's time goes
"""
from __future__ import annotations

import argparse
import importlib
import statistics
import time

import clpost
from clpost.bench_ab import load_revision


def _case(pkg, scene_name: str, quality: str, w: int, h: int, extended: bool = False):
    """(pipeline, frame, camera) of a bench scene in package ``pkg`` (this tree or a revision)."""
    bench = importlib.import_module(pkg.__name__ + ".bench")
    pipeline = importlib.import_module(pkg.__name__ + ".pipeline")
    scene = bench.SCENES[scene_name]
    cam, _ = scene.camera(w, h)
    if extended:
        spec = importlib.import_module(pkg.__name__ + ".calibration").required_render(cam.distortion)
        frame = bench.synthetic_frame(spec.width, spec.height, velocity_px=scene.velocity_px)
    else:
        frame = bench.synthetic_frame(w, h, velocity_px=scene.velocity_px)
    return pipeline.Pipeline(cam, quality=quality, stages=list(scene.wants)), frame, cam


def _animated(cam, i: int):
    """Frame ``i`` of a focus pull: the camera's focus 1 % further each frame (a per-frame scalar)."""
    return cam.with_(focus_distance_m=cam.focus_distance_m * (1.0 + 0.01 * (i % 16)))


def host_ms(pkgs, scene_name: str, quality: str, w: int, h: int, extended: bool, frames: int = 15,
            plan_only: bool = False, animated: bool = False) -> list[float]:
    """Median host ms per package in ``pkgs`` of ``Pipeline.run`` (``plan_only``: of ``Plan.run``
    alone, the pipeline's plan for the frame) over ``frames`` after 2 warm-ups, the packages
    interleaved frame by frame (load drifts hit all alike); ``animated``: a focus pull."""
    cases = [_case(pkg, scene_name, quality, w, h, extended) for pkg in pkgs]
    times: list[list[float]] = [[] for _ in pkgs]
    for i in range(frames + 2):
        for (pipe, frame, cam), t in zip(cases, times):
            c = _animated(cam, i) if animated else cam
            if plan_only:
                resolved = pipe.camera_for(frame, c)
                plan = pipe.plan_for(frame, resolved)
                plan.run(frame, resolved)
                t.append(plan.last_host_ms)
            else:
                t0 = time.thread_time()
                pipe.run(frame, c)
                t.append((time.thread_time() - t0) * 1e3)
    return [statistics.median(t[2:]) for t in times]


def breakdown(scene_name: str, quality: str, w: int, h: int, frames: int = 15, extended: bool = False) -> str:
    """One table row: Plan.run's host ms per frame and the part spent in pyopencl's calls."""
    import collections

    import pyopencl as cl

    spent, calls = collections.Counter(), collections.Counter()

    def timed(name, fn):
        def call(*a, **k):
            t0 = time.thread_time()
            try:
                return fn(*a, **k)
            finally:
                spent[name] += time.thread_time() - t0
                calls[name] += 1
        return call

    saved = cl.enqueue_nd_range_kernel, cl.enqueue_copy, cl.Kernel.set_args, cl.Kernel.set_arg
    cl.enqueue_nd_range_kernel = timed("enqueue", saved[0])
    cl.enqueue_copy = timed("copy", saved[1])
    cl.Kernel.set_args = timed("set_args", saved[2])
    cl.Kernel.set_arg = timed("set_args", saved[3])
    try:
        pipe, frame, cam = _case(clpost, scene_name, quality, w, h, extended)
        cam = pipe.camera_for(frame, cam)
        plan = pipe.plan_for(frame, cam)
        for _ in range(3):
            plan.run(frame, cam)
        spent.clear(), calls.clear()
        times = []
        for _ in range(frames):
            plan.run(frame, cam)
            times.append(plan.last_host_ms)
    finally:
        cl.enqueue_nd_range_kernel, cl.enqueue_copy, cl.Kernel.set_args, cl.Kernel.set_arg = saved
    part = {k: spent[k] / frames * 1e3 for k in ("set_args", "enqueue", "copy")}
    n = {k: calls[k] // frames for k in part}
    rest = statistics.median(times) - sum(part.values())
    label = f"{scene_name}{', extended frustum' if extended else ''}"
    return (f"| {label} | {quality} | {statistics.median(times):.2f} | "
            + " | ".join(f"{part[k]:.2f} ({n[k]})" for k in part) + f" | {rest:.2f} |")


def python_only(pkgs, scene_name: str, quality: str, w: int, h: int, extended: bool, runs: int = 200) -> list[float]:
    """Median host ms of ``Plan.run`` per package with every pyopencl enqueue (kernels, copies)
    replaced by a no-op: the Python part alone, which the device's threads do not slow down (on a
    loaded box they inflate the rest); the packages interleaved run by run."""
    import pyopencl as cl

    class Event:
        def wait(self):
            pass

    event = Event()
    cases = []
    for pkg in pkgs:
        pipe, frame, cam = _case(pkg, scene_name, quality, w, h, extended)
        cam = pipe.camera_for(frame, cam)
        plan = pipe.plan_for(frame, cam)
        for _ in range(3):
            plan.run(frame, cam)
        cases.append((plan, frame, cam))
    saved = cl.enqueue_nd_range_kernel, cl.enqueue_copy, cl.NannyEvent
    cl.enqueue_nd_range_kernel = cl.enqueue_copy = lambda *a, **k: event
    cl.NannyEvent = Event
    times: list[list[float]] = [[] for _ in pkgs]
    try:
        for _ in range(runs):
            for (plan, frame, cam), t in zip(cases, times):
                plan.run(frame, cam)
                t.append(plan.last_host_ms)
    finally:
        cl.enqueue_nd_range_kernel, cl.enqueue_copy, cl.NannyEvent = saved
    return [statistics.median(t) for t in times]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", help="git revision to compare with")
    ap.add_argument("--breakdown", action="store_true",
                    help="this tree only: Plan.run's host ms split into pyopencl calls and the rest")
    ap.add_argument("--python-only", action="store_true",
                    help="with --against: Plan.run's Python alone (pyopencl's enqueues made no-ops)")
    ap.add_argument("--size", default="1920x1080")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    if args.breakdown:
        print(f"| scene {w}x{h} | quality | Plan.run host ms | set_args/set_arg ms (calls) | enqueue ms (calls) "
              "| copies ms (calls) | rest (Python) ms |")
        print("|---|---|---:|---:|---:|---:|---:|")
        for scene, extended in (("worst", False), ("no_defocus", False), ("full", False), ("worst", True)):
            for quality in ("draft", "final"):
                print(breakdown(scene, quality, w, h, extended=extended), flush=True)
        return 0
    if not args.against:
        ap.error("give --against REV or --breakdown")
    old = load_revision(args.against)
    cases = [(s, q, False) for s in ("worst", "no_defocus", "full") for q in ("draft", "final")]
    cases += [("worst", q, True) for q in ("draft", "final")]
    if args.python_only:
        print(f"| scene {w}x{h} | quality | Python of Plan.run: {args.against} ms | this tree ms |")
        print("|---|---|---:|---:|")
        for scene, quality, extended in cases:
            a, b = python_only((old, clpost), scene, quality, w, h, extended)
            label = f"{scene}{', extended frustum' if extended else ''}"
            print(f"| {label} | {quality} | {a:.2f} | {b:.2f} |", flush=True)
        return 0
    print(f"| scene {w}x{h} | quality | Pipeline.run {args.against} | this tree | Plan.run {args.against} "
          f"| this tree | Plan.run, focus pull: {args.against} | this tree |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for scene, quality, extended in cases:
        row = []
        for plan_only, animated in ((False, False), (True, False), (True, True)):
            row += host_ms((old, clpost), scene, quality, w, h, extended, plan_only=plan_only, animated=animated)
        label = f"{scene}{', extended frustum' if extended else ''}"
        print(f"| {label} | {quality} | " + " | ".join(f"{v:.2f}" for v in row) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

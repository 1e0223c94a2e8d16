"""Host time per frame of ``Pipeline.run``: this tree and a git revision in one process.

Host time is the calling thread's CPU time (``time.thread_time``) over one ``Pipeline.run`` —
resolving the camera, planning, tables, argument setting, enqueueing — so it leaves out the
device's threads and the waits for them. Median of 7 frames after 2 warm-ups, 1920×1080 bench
scenes, interleaved per case (old, then this tree); the extended-frustum row renders at
``required_render``'s size for the calibration, the case that solves the render's intrinsics.

    PYTHONPATH=. python tools/host_time.py --against a4db22e
    PYTHONPATH=. python tools/host_time.py --breakdown    # this tree: where Plan.run's time goes
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


def host_ms(pkg, scene_name: str, quality: str, w: int, h: int, extended: bool, frames: int = 7) -> float:
    pipe, frame, _ = _case(pkg, scene_name, quality, w, h, extended)
    for _ in range(2):
        pipe.run(frame)
    times = []
    for _ in range(frames):
        t0 = time.thread_time()
        pipe.run(frame)
        times.append((time.thread_time() - t0) * 1e3)
    return statistics.median(times)


def breakdown(scene_name: str, quality: str, w: int, h: int, frames: int = 15) -> str:
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

    saved = cl.enqueue_nd_range_kernel, cl.enqueue_copy, cl.Kernel.set_args
    cl.enqueue_nd_range_kernel = timed("enqueue", saved[0])
    cl.enqueue_copy = timed("copy", saved[1])
    cl.Kernel.set_args = timed("set_args", saved[2])
    try:
        pipe, frame, cam = _case(clpost, scene_name, quality, w, h)
        plan = pipe.plan_for(frame, cam)
        for _ in range(3):
            plan.run(frame, cam)
        spent.clear(), calls.clear()
        times = []
        for _ in range(frames):
            plan.run(frame, cam)
            times.append(plan.last_host_ms)
    finally:
        cl.enqueue_nd_range_kernel, cl.enqueue_copy, cl.Kernel.set_args = saved
    part = {k: spent[k] / frames * 1e3 for k in ("set_args", "enqueue", "copy")}
    n = {k: calls[k] // frames for k in part}
    rest = statistics.median(times) - sum(part.values())
    return (f"| {scene_name} | {quality} | {statistics.median(times):.2f} | "
            + " | ".join(f"{part[k]:.2f} ({n[k]})" for k in part) + f" | {rest:.2f} |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", help="git revision to compare with")
    ap.add_argument("--breakdown", action="store_true",
                    help="this tree only: Plan.run's host ms split into pyopencl calls and the rest")
    ap.add_argument("--size", default="1920x1080")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    if args.breakdown:
        print(f"| scene {w}x{h} | quality | Plan.run host ms | set_args ms (calls) | enqueue ms (calls) "
              "| copies ms (calls) | rest (Python) ms |")
        print("|---|---|---:|---:|---:|---:|---:|")
        for scene in ("worst", "no_defocus", "full"):
            for quality in ("draft", "final"):
                print(breakdown(scene, quality, w, h), flush=True)
        return 0
    if not args.against:
        ap.error("give --against REV or --breakdown")
    old = load_revision(args.against)
    print(f"| scene {w}x{h} | quality | {args.against} host ms/frame | this tree |")
    print("|---|---|---:|---:|")
    cases = [(s, q, False) for s in ("worst", "no_defocus", "full") for q in ("draft", "final")]
    cases += [("worst", q, True) for q in ("draft", "final")]
    for scene, quality, extended in cases:
        a = host_ms(old, scene, quality, w, h, extended)
        b = host_ms(clpost, scene, quality, w, h, extended)
        label = f"{scene}{', extended frustum' if extended else ''}"
        print(f"| {label} | {quality} | {a:.1f} | {b:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

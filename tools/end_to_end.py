"""End-to-end frame time of ``Plan.run`` (upload, kernels, download, host work: wall clock) for
the bench scenes, with the frame's arrays and the output in ordinary (pageable) NumPy memory
and in page-locked memory (``Runtime.pinned_empty``, ``Plan.run(out=...)``). On a CPU device
the two are the same; on a discrete GPU the pinned form copies at the bus's rate. Median of
``--repeats`` after warm-up.

    python tools/end_to_end.py --device nvidia --scenes worst,no_defocus,full --qualities draft,final
"""
from __future__ import annotations

import argparse
import statistics
import time

from clpost.bench import SCENES, synthetic_frame
from clpost.pipeline import Pipeline


def _pinned_frame(rt, frame):
    arrays = {}
    for name in ("color", "depth", "velocity"):
        a = getattr(frame, name)
        if a is not None:
            p = rt.pinned_empty(a.shape, a.dtype)
            p[...] = a
            arrays[name] = p
    return frame.replace(**arrays)


def _wall(plan, frame, cam, repeats: int, out=None) -> float:
    times = []
    for i in range(repeats + 2):
        t0 = time.perf_counter()
        plan.run(frame, cam, out=out)
        if i >= 2:
            times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device")
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--scenes", default="worst,no_defocus,full")
    ap.add_argument("--qualities", default="draft,final")
    ap.add_argument("--repeats", type=int, default=15)
    a = ap.parse_args(argv)
    w, h = (int(v) for v in a.size.split("x"))
    print("| scene | quality | pageable ms | fps | pinned ms | fps |\n|---|---|---:|---:|---:|---:|")
    for name in a.scenes.split(","):
        scene = SCENES[name]
        for q in a.qualities.split(","):
            cam, _ = scene.camera(w, h)
            frame = synthetic_frame(w, h, velocity_px=scene.velocity_px)
            pipe = Pipeline(cam, quality=q, stages=list(scene.wants), device=a.device)
            rcam = pipe.camera_for(frame, cam)
            plan = pipe.plan_for(frame, rcam)
            plain = _wall(plan, frame, rcam, a.repeats)
            pf = _pinned_frame(pipe.runtime, frame)
            ow, oh = plan.launches[-1].out_size if plan.launches else (w, h)
            out = pipe.runtime.pinned_empty((oh, ow, 3))
            pinned = _wall(plan, pf, rcam, a.repeats, out=out)
            print(f"| {name} | {q} | {plain:.2f} | {1e3 / plain:.0f} | {pinned:.2f} | {1e3 / pinned:.0f} |",
                  flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

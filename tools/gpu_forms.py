"""Both forms of the kernels that have a one-pixel (GPU) and a 16-lane (CPU) form on one device, in
one process: the ``full`` bench scene (motion blur, vignetting, exposure, film, grain, print) at
each quality, its plan run with ``Runtime.wide`` forced on (16 or 32 pixels per work-item, the
CPU form) and off (one pixel per work-item, the GPU form) alternately, which first alternating
per repeat. Prints each stage's device ms (OpenCL event time, ``Pipeline.last_timings``; median
of ``--repeats`` after warm-up), wide/narrow, and max|narrow − wide| / max|wide| of the plan's
output (the forms do the same operations per pixel: 0 where the device compiles them alike).

    PYTHONPATH=. python tools/gpu_forms.py --device nvidia            # 1080p, draft and final
    PYTHONPATH=. python tools/gpu_forms.py --device pocl --size 320x180 --repeats 3   # a CPU check
    PYTHONPATH=. python tools/gpu_forms.py --device nvidia --scene worst --qualities final   # dof, distortion
    PYTHONPATH=. python tools/gpu_forms.py --device pocl --scene layers --repeats 5           # front_layer

The device's own choice (``Runtime.wide``: off on a GPU) is printed first; docs/benchmarks.md's
GPU section says what to record. ``Runtime.wide`` also picks the fused pointwise kernels' and
astigmatism's forms, so the plan's device ms moves with them; the stage rows are what to compare.
"""
from __future__ import annotations

import argparse
import statistics
import warnings

import numpy as np

from clpost.bench import SCENES, synthetic_frame
from clpost.pipeline import Pipeline
from clpost.runtime import Runtime

def measure(device: str | None, w: int, h: int, quality: str, repeats: int, warmup: int = 2,
            scene_name: str = "full") -> dict:
    """Per form (True: wide, False: narrow): stage ms medians, plan device ms median, last output."""
    scene = SCENES[scene_name]
    cam, _ = scene.camera(w, h)
    frame = synthetic_frame(w, h, velocity_px=scene.velocity_px, front=scene.front)
    pipes, times, outs = {}, {True: {}, False: {}}, {}
    for wide in (True, False):
        with Runtime.forced_width(wide):
            pipes[wide] = Pipeline(cam, quality=quality, stages=list(scene.wants), device=device)
    for i in range(warmup + repeats):
        for wide in ((True, False) if i % 2 else (False, True)):
            with Runtime.forced_width(wide):
                out = pipes[wide].run(frame)
            if i >= warmup:
                t = pipes[wide].last_timings
                for k, v in t.items():
                    times[wide].setdefault(k, []).append(v)
                times[wide].setdefault("(plan)", []).append(
                    sum(v for k, v in t.items() if k not in ("upload", "download")))
            outs[wide] = out.color
    med = {wide: {k: statistics.median(v) for k, v in times[wide].items()} for wide in times}
    ref = np.abs(outs[True]).max()
    diff = float(np.abs(outs[False] - outs[True]).max() / ref) if ref > 0 else float(np.abs(outs[False]).max())
    return dict(ms=med, diff=diff, plan=[s.name for s in pipes[False].last_plan.stages])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", help="OpenCL device spec as clpost's --device (default: clpost's choice)")
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--qualities", default="draft,final")
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--scene", default="full", choices=sorted(SCENES), help="a bench scene (default full)")
    a = ap.parse_args(argv)
    w, h = (int(v) for v in a.size.split("x"))
    warnings.simplefilter("ignore")   # the scene is timed, not looked at (exposure warnings)
    rt = Pipeline(SCENES[a.scene].camera(w, h)[0], stages=["exposure"], device=a.device).runtime
    print(f"device: {rt.name}; its own form: {'wide (16 lanes)' if rt.wide else 'narrow (one pixel)'}; "
          f"scene {a.scene} {w}x{h}, median of {a.repeats}, forms interleaved")
    print("| quality | kernel | wide ms | narrow ms | wide/narrow | max abs(narrow-wide)/max abs(wide) |")
    print("|---|---|---:|---:|---:|---:|")
    for q in a.qualities.split(","):
        r = measure(a.device, w, h, q, a.repeats, scene_name=a.scene)
        # every timed kernel: white grain runs inside the fused pointwise group, whose form
        # Runtime.wide picks too
        for k in (*[k for k in r["ms"][True] if k not in ("upload", "download", "(plan)")], "(plan)"):
            wd, nw = r["ms"][True].get(k), r["ms"][False].get(k)
            if wd is None or nw is None:
                continue
            print(f"| {q} | {k} | {wd:.3f} | {nw:.3f} | {wd / nw:.2f} | {r['diff']:.1e} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

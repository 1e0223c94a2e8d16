"""Old vs new field-dependent gathers (astigmatism, coma, lateral_color) in ONE process.

The stage modules and kernel sources of ``--old`` (a git revision) are exported with ``git
archive`` into a temporary folder and loaded beside the working tree's; both run on the same
OpenCL queue, the same planar input and depth buffers, interleaved (old, new, old, new, …), so
machine load hits both alike. Device time = the sum of the stage's kernel events (uploads
excluded), median of ``--repeats`` after 2 warm-ups; the ratio is the median of the per-repeat
ratios (min and max printed too). ``max|old-new|`` compares the outputs of the first run; with
``--truth QUALITY`` each output is also compared with the old stage at that quality (e.g. final:
how far a cheaper model is from the dense one — max and 99.9th percentile of |difference|).

    PYTHONPATH=. python tools/ab_gathers.py --old a46f6c0 --scene no_defocus --size 1920x1080 \\
        --qualities draft,final --repeats 5
"""
from __future__ import annotations

import argparse
import importlib
import importlib.util
import pathlib
import statistics
import subprocess
import tempfile

import numpy as np

CLASSES = {"astigmatism": "Astigmatism", "coma": "Coma", "lateral_color": "LateralColor"}


def export(rev: str, into: pathlib.Path) -> None:
    archive = subprocess.run(["git", "archive", rev, "clpost/stages", "kernels"], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)


def load_old_module(root: pathlib.Path, name: str):
    spec = importlib.util.spec_from_file_location(f"clpost.stages.{name}_old", root / "clpost/stages" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    mod.__package__ = "clpost.stages"  # its relative imports resolve to the working tree's helpers
    spec.loader.exec_module(mod)
    return mod


def main() -> None:
    import pyopencl as cl

    import clpost.runtime as runtime
    from clpost import Pipeline, bench
    from clpost.runtime import event_ms

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", default="a46f6c0", help="git revision of the old stages")
    ap.add_argument("--stages", default="astigmatism,coma,lateral_color")
    ap.add_argument("--qualities", default="draft,final")
    ap.add_argument("--scene", default="no_defocus", choices=sorted(bench.SCENES))
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--lens", default=None,
                    help="a traced lens instead of the scene's parametric coefficients (e.g. zeiss-planar-50-f1.4)")
    ap.add_argument("--f-number", type=float, default=None)
    ap.add_argument("--truth", default=None, help="compare every output with the old stage at this quality")
    args = ap.parse_args()
    w, h = (int(v) for v in args.size.split("x"))

    tmp = tempfile.TemporaryDirectory(prefix="clpost_ab_")
    root = pathlib.Path(tmp.name)
    export(args.old, root)
    new_source = runtime.kernel_source
    use_old = {"on": False}
    # the stages call runtime.kernel_source(name) when they build: the old one gets its own text
    runtime.kernel_source = lambda name: ((root / "kernels" / f"{name}.cl").read_text() if use_old["on"]
                                          else new_source(name))

    cam, _ = bench.SCENES[args.scene].camera(w, h)
    if args.lens is not None:
        cam = cam.with_(lens=args.lens, field_curvature_mm=None, astigmatism_mm=None, coma_mm=None,
                        lateral_color_mm=None, **({} if args.f_number is None else {"f_number": args.f_number}))
    frame = bench.synthetic_frame(w, h)
    rt = Pipeline(cam).runtime
    q = rt.queue
    flags = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
    planar = np.ascontiguousarray(np.moveaxis(frame.color[..., :3], -1, 0), np.float32)
    src = cl.Buffer(rt.context, flags, hostbuf=planar)
    dst = rt.empty((3, h, w))
    aux = {"depth": cl.Buffer(rt.context, flags, hostbuf=np.ascontiguousarray(frame.depth, np.float32))}
    print(f"old {args.old} vs working tree, {args.scene} {w}x{h}, {args.repeats} repeats, interleaved")
    for name in args.stages.split(","):
        new_mod = importlib.import_module(f"clpost.stages.{name}")
        old_mod = load_old_module(root, name)
        truth = None
        if args.truth is not None:
            use_old["on"] = True
            stage = getattr(old_mod, CLASSES[name])(args.truth)
            stage.enqueue(rt, cam, frame, src, dst, aux)
            truth = np.empty((3, h, w), np.float32)
            cl.enqueue_copy(q, truth, dst)
        for quality in args.qualities.split(","):
            stages = {"old": getattr(old_mod, CLASSES[name])(quality), "new": getattr(new_mod, CLASSES[name])(quality)}
            times = {"old": [], "new": []}
            outs = {}
            for it in range(args.repeats + 2):
                for v in ("old", "new"):
                    use_old["on"] = v == "old"
                    events = stages[v].enqueue(rt, cam, frame, src, dst, aux)
                    q.finish()
                    if it >= 2:
                        times[v].append(sum(event_ms(e) for e in events
                                            if e.command_type == cl.command_type.NDRANGE_KERNEL))
                    if it == 0:
                        outs[v] = np.empty((3, h, w), np.float32)
                        cl.enqueue_copy(q, outs[v], dst)
            ratios = [a / b for a, b in zip(times["old"], times["new"])]
            diff = np.abs(outs["old"] - outs["new"])
            print(f"{name:13s} {quality:5s} old {statistics.median(times['old']):8.2f} ms  "
                  f"new {statistics.median(times['new']):8.2f} ms  ratio {statistics.median(ratios):5.2f} "
                  f"(min {min(ratios):.2f}, max {max(ratios):.2f})  max|old-new| {diff.max():.3g} "
                  f"(input {planar.min():.3g}..{planar.max():.3g})")
            if truth is not None:
                for v in ("old", "new"):
                    d = np.abs(outs[v] - truth)
                    print(f"{'':13s} {quality:5s} {v} vs old {args.truth}: max {d.max():.3g}, "
                          f"99.9 % {np.percentile(d, 99.9):.3g}, mean {d.mean():.3g}")


if __name__ == "__main__":
    main()

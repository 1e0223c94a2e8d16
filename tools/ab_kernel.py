"""Per-kernel device ms of a bench scene's plan, and ONE kernel of an older commit against the
working tree on the same buffers, in one process, alternating (the machines are shared: quote
ratios; docs/benchmarks.md, "Worst final, third pass").

    PYTHONPATH=. POCL_MAX_PTHREAD_COUNT=1 python tools/ab_kernel.py --scene worst --quality final \\
        --size 1920x1080 --repeats 7                      # every kernel launch of the plan, ms, sizes
    PYTHONPATH=. python tools/ab_kernel.py --scene no_defocus --stages astigmatism --repeats 7
                                                          # one stage planned alone
    PYTHONPATH=. POCL_MAX_PTHREAD_COUNT=1 python tools/ab_kernel.py --old main \\
        --kernel distortion_bspline_tiles --size 640x360 --repeats 61

``clpost bench`` times whole stages (``Pipeline.last_timings``); this splits them into their
kernels: every ``enqueue_nd_range_kernel`` of one plan run is recorded with its arguments, ms =
OpenCL event time summed per kernel name, median and min over the repeats. With ``--old REV``
the recorded launch of ``--kernel`` is re-enqueued with the same arguments and sizes from a
program built from REV's ``kernels/<file>.cl`` (the file named by the kernel's prefix; the rest of
the program source, generated defines included, is this tree's) and from this tree's, old and new
alternating which runs first; old/new is the median of per-repeat ratios. A kernel whose
arguments or launch changed since REV: ``--old-args N`` gives the old one the first N recorded
arguments, ``--old-global G`` launches it over G (comma-separated) with the device's own
work-groups, e.g. the tile gathers before their row-of-tiles groups (docs/benchmarks.md, "Worst
final, third pass"):

    PYTHONPATH=. python tools/ab_kernel.py --old 2418b09 --kernel distortion_bspline_tiles \
        --old-args 9 --old-global 16,8148 --repeats 21

``--pages`` compares the buffers' pages instead of a kernel: the plan recorded twice, its buffers
in PoCL's own 4 KiB pages ("old") and in huge pages (``Runtime.huge_pages``, "new"), both run
alternating, every kernel's old/new, and the two plans' outputs compared (docs/benchmarks.md,
"Huge pages for the CPU device's buffers"):

    PYTHONPATH=. python tools/ab_kernel.py --pages --scene worst --quality final --repeats 9
"""
from __future__ import annotations

import argparse
import collections
import statistics
import subprocess

import numpy as np
import pyopencl as cl

from clpost import Pipeline
from clpost.bench import SCENES, synthetic_frame
from clpost.runtime import event_ms


def record_plan(scene: str, quality: str, size: tuple[int, int], stages: list[str] | None = None,
                outputs: list | None = None):
    """A warmed-up plan (the scene's stages, or ``stages`` alone) and a function running it once:
    [(kernel, queue, global, local, args, event)]; each run's output arrays (colour and the
    frame's aux planes) are appended to ``outputs`` when given."""
    calls, args = [], {}
    enqueue, set_args, set_arg = cl.enqueue_nd_range_kernel, cl.Kernel.set_args, cl.Kernel.set_arg

    def enq(q, k, g, l=None, *a, **kw):
        ev = enqueue(q, k, g, l, *a, **kw)
        calls.append((k, q, g, l, list(args.get(k.int_ptr, [])), ev))
        return ev

    def sa(self, *a):
        args[self.int_ptr] = list(a)
        return set_args(self, *a)

    def s1(self, i, v):
        d = args.setdefault(self.int_ptr, [])
        d.extend([None] * (i + 1 - len(d)))
        d[i] = v
        return set_arg(self, i, v)

    cl.enqueue_nd_range_kernel, cl.Kernel.set_args, cl.Kernel.set_arg = enq, sa, s1
    sc = SCENES[scene]
    w, h = size
    frame = synthetic_frame(w, h, velocity_px=sc.velocity_px, front=sc.front)
    cam, _ = sc.camera(w, h)
    pipe = Pipeline(cam, quality=quality, stages=stages or list(sc.wants))
    pipe.run(frame)  # builds, first launches

    def run_once():
        calls.clear()
        out = pipe.run(frame)
        if outputs is not None:
            outputs.append([np.array(out.color)] + [np.array(getattr(out, n)) for n in ("depth", "velocity")
                                                     if getattr(out, n, None) is not None])
        for c in calls:
            c[-1].wait()
        return list(calls)

    return run_once, lambda: (setattr(cl, "enqueue_nd_range_kernel", enqueue),
                              setattr(cl.Kernel, "set_args", set_args), setattr(cl.Kernel, "set_arg", set_arg))


def compare_pages(a) -> None:
    """--pages: the scene's plan with 4 KiB-page buffers against huge-page ones, in one process."""
    from clpost.runtime import get_runtime

    rt = get_runtime()
    if not rt.huge_pages:
        raise SystemExit(f"ab_kernel: --pages needs PoCL's CPU device with huge pages on, not {rt.name}")
    size = tuple(int(v) for v in a.size.split("x"))
    stages = a.stages.split(",") if a.stages else None
    runs, outs, restores = {}, {}, []
    for v, huge in (("old", False), ("new", True)):
        rt.__dict__["huge_pages"] = huge  # the cached property, for the buffers this plan makes
        # the second recording wraps the first's hooks: each run records its own plan's launches
        runs[v], restore = record_plan(a.scene, a.quality, size, stages, outs.setdefault(v, []))
        restores.append(restore)
    rt.__dict__["huge_pages"] = True
    t = {v: collections.defaultdict(list) for v in runs}
    for r in range(a.repeats):
        for v in (("old", "new") if r % 2 else ("new", "old")):
            per = collections.Counter()
            for k, _q, _g, _loc, _args, ev in runs[v]():
                per[k.function_name] += event_ms(ev)
            for name, ms in per.items():
                t[v][name].append(ms)
            t[v]["(all kernels)"].append(sum(per.values()))
    print(f"{a.scene} {a.quality} {a.size}, {a.repeats} repeats alternating: kernel, 4 KiB pages (old) | huge "
          "pages (new), median and min ms; old/new as the median of per-repeat ratios, and min/min")
    for name, old in t["old"].items():
        new = t["new"][name]
        ratios = [o / n for o, n in zip(old, new) if n > 0] or [float("nan")]
        print(f"  {name:36s} {statistics.median(old):8.2f} {min(old):8.2f} | {statistics.median(new):8.2f} "
              f"{min(new):8.2f} | {statistics.median(ratios):5.2f} ({min(ratios):.2f}-{max(ratios):.2f}) "
              f"{min(old) / max(min(new), 1e-9):5.2f}")
    for restore in restores[::-1]:
        restore()
    same = all(np.array_equal(x, y) for x, y in zip(outs["old"][-1], outs["new"][-1]))
    print(f"  outputs of the last runs (colour and aux) bit-equal: {same}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="worst")
    ap.add_argument("--quality", default="final")
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--stages", help="comma-separated stages planned alone instead of the scene's plan")
    ap.add_argument("--old", help="git revision of the old kernel (with --kernel)")
    ap.add_argument("--kernel", help="kernel name to compare (with --old)")
    ap.add_argument("--old-args", type=int, help="the old kernel takes the first N recorded arguments")
    ap.add_argument("--old-global", help="the old kernel's global size (comma-separated), PoCL's groups")
    ap.add_argument("--out-arg", type=int, default=1,
                    help="index of the kernel's output argument, compared between old and new (default 1: "
                         "distortion's gathers; astigmatism's gathers: 6)")
    ap.add_argument("--pages", action="store_true",
                    help="the plan's buffers in 4 KiB pages (old) against huge pages (new), every kernel")
    a = ap.parse_args()
    if a.pages:
        return compare_pages(a)
    size = tuple(int(v) for v in a.size.split("x"))
    run_once, restore = record_plan(a.scene, a.quality, size, a.stages.split(",") if a.stages else None)
    if not a.old:
        times, launches = collections.defaultdict(list), {}
        for _ in range(a.repeats):
            per = collections.Counter()
            for k, _q, g, loc, _args, ev in run_once():
                per[k.function_name] += event_ms(ev)
                launches.setdefault(k.function_name, (g, loc))
            for name, ms in per.items():
                times[name].append(ms)
        total = sum(statistics.median(v) for v in times.values())
        print(f"{a.scene} {a.quality} {a.size}: kernel, median ms, min ms, share of the summed medians, "
              "the first launch's global and local size and work-group count (auto: the device picks)")
        for name, v in times.items():
            m = statistics.median(v)
            g, loc = launches[name]
            groups = int(np.prod([-(-gi // li) for gi, li in zip(g, loc)])) if loc else "auto"
            print(f"  {name:36s} {m:8.2f} {min(v):8.2f} {100 * m / total:5.1f} %  "
                  f"{'x'.join(map(str, g))} / {'x'.join(map(str, loc)) if loc else '-'} = {groups}")
        print(f"  {'sum':36s} {total:8.2f}")
        return
    calls = [c for c in run_once() if c[0].function_name == a.kernel]
    restore()
    if not calls:
        raise SystemExit(f"ab_kernel: the plan launches no kernel '{a.kernel}'")
    k, q, g, loc, args, _ = calls[0]
    src = k.program.get_info(cl.program_info.SOURCE)
    fname = a.kernel.split("_")[0]
    new_cl = open(f"kernels/{fname}.cl").read()
    if new_cl not in src:
        raise SystemExit(f"ab_kernel: kernels/{fname}.cl is not verbatim in the program of '{a.kernel}'")
    old_cl = subprocess.run(["git", "show", f"{a.old}:kernels/{fname}.cl"], capture_output=True, text=True,
                            check=True).stdout
    opts = k.program.get_build_info(q.device, cl.program_build_info.OPTIONS)
    kern = {v: getattr(cl.Program(q.context, s).build(options=opts), a.kernel)
            for v, s in (("old", src.replace(new_cl, old_cl)), ("new", src))}
    kern["old"].set_args(*(args[:a.old_args] if a.old_args else args))
    kern["new"].set_args(*args)
    launch = {"new": (g, loc), "old": (tuple(int(v) for v in a.old_global.split(",")), None) if a.old_global
              else (g, loc)}
    outs = {}
    t = collections.defaultdict(list)
    out = args[a.out_arg]
    out_buf = out if isinstance(out, cl.Buffer) else None  # the kernel's output (--out-arg)
    if out_buf is not None:  # as recorded, put back after the compared first runs
        recorded = np.empty(out_buf.size, np.uint8)
        cl.enqueue_copy(q, recorded, out_buf).wait()
    for r in range(a.repeats + 1):
        if r == 1 and out_buf is not None:
            cl.enqueue_copy(q, out_buf, recorded).wait()
        for v in (("old", "new") if r % 2 else ("new", "old")):
            if not r and out_buf is not None:  # a sentinel first: what one form does not write
                # must not pass as equal to what the other wrote into the same buffer before it
                cl.enqueue_fill_buffer(q, out_buf, np.float32(-1234.5), 0, out_buf.size)
            ev = cl.enqueue_nd_range_kernel(q, kern[v], *launch[v])
            ev.wait()
            if r:
                t[v].append(event_ms(ev))
            elif out_buf is not None:
                outs[v] = np.empty(out_buf.size // 4, np.float32)
                cl.enqueue_copy(q, outs[v], out_buf).wait()
    ratios = [o / n for o, n in zip(t["old"], t["new"])]
    print(f"{a.kernel} ({a.scene} {a.quality} {a.size}, {len(calls)} launch(es), the first): "
          f"old median {statistics.median(t['old']):.2f} min {min(t['old']):.2f} ms | new median "
          f"{statistics.median(t['new']):.2f} min {min(t['new']):.2f} ms | old/new {statistics.median(ratios):.3f} "
          f"({min(ratios):.2f}-{max(ratios):.2f}), min/min {min(t['old']) / min(t['new']):.3f}"
          + (f" | argument {a.out_arg} bit-equal: {np.array_equal(outs['old'], outs['new'])}" if outs else ""))


if __name__ == "__main__":
    main()

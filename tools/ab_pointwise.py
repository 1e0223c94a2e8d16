"""The pointwise kernels (vignetting+exposure+film, grain, print; or exposure+sensor): an old
revision vs this tree in one process — per kernel the min and median device ms of each, new/old of
the mins, and % of the copy kernel's bandwidth (median; the copy kernel runs right after every plan
run); each revision's own kernels (this tree fuses white grain with film and print into one) and
the sum of a plan's kernels, whose % of copy counts one pass over the frame.

    PYTHONPATH=. POCL_MAX_PTHREAD_COUNT=1 .venv/bin/python tools/ab_pointwise.py --old main --size 640x360 --repeats 61
    ... --scene sensor --sensor-gain 40   (or 10: a dark frame, nearly all exact Poisson)

Scenes (SCENES): the bench's full camera without motion blur and distortion (vignetting, exposure,
film Ektar 100, grain, print), or exposure+sensor, on the bench's synthetic frame; the two plans
run alternately, the order swapped every repeat. On a loaded machine medians and % of copy swing by ±30 % between runs; the
min over many short single-threaded runs (a cache-resident 640×360 frame: the kernels' compute) is
what repeats. Bytes as `clpost bench` counts them (RGB float read + write, + the RI plane for the
vignetting group).
"""
from __future__ import annotations

import argparse
import importlib
import statistics
import warnings

SCENES = {
    # the bench's full camera without motion blur and distortion
    "film": dict(wants=("vignetting", "exposure", "film", "grain", "print"),
                 fields=dict(luminance_scale=1.0, f_number=4.0, vignetting="natural", film="kodak-ektar-100")),
    # a digital camera at a high ISO: the smartphone preset at ISO 800 (375 e⁻ at saturation),
    # the frame scaled by --sensor-gain (the exposure maps the synthetic frame to ≈ 1.7 e⁻ median:
    # × 40 is a mid-grey exposure, median 66 e⁻ and 13 % of the means ≤ 32 e⁻, the exact-Poisson
    # branch; × 10 a dark one, median 17 e⁻, 98 % of them)
    "sensor": dict(wants=("exposure", "sensor"),
                   fields=dict(luminance_scale=1.0, f_number=2.8, shutter_s=1 / 100, iso=800,
                               sensor_preset="smartphone")),
}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--old", default="main")
    ap.add_argument("--quality", default="draft")
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--warmup", type=int, default=2)
    ap.add_argument("--scene", choices=tuple(SCENES), default="film",
                    help="film: vignetting+exposure+film, grain, print; sensor: exposure+sensor")
    ap.add_argument("--sensor-gain", type=float, default=40.0,
                    help="the sensor scene's frame × this (40: mid-grey, median 66 e⁻; 10: dark, median 17 e⁻)")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    import clpost
    from clpost import bench as nb, bench_ab as ab
    from clpost.runtime import get_runtime

    old = ab.load_revision(args.old)
    ob = importlib.import_module(f"{old.__name__}.bench")
    sc = SCENES[args.scene]
    for m in (nb, ob):
        m.SCENES["pointwise"] = m.Scene("pointwise", f"pointwise {args.scene} chain", wants=sc["wants"],
                                        camera_fields=sc["fields"])
    w, h = (int(v) for v in args.size.split("x"))
    frame = nb.synthetic_frame(w, h)
    if args.scene == "sensor":
        frame.color[...] *= args.sensor_gain
    runs = [(args.old, *ab._pipeline(old, ob, "pointwise", w, h, args.quality, None, frame)),
            ("this tree", *ab._pipeline(clpost, nb, "pointwise", w, h, args.quality, None, frame))]
    copier = nb.CopyKernel(get_runtime(None), w * h * 12)
    ms: dict = {}
    pct: dict = {}
    kernels: dict = {}   # per revision, its plan's kernels in order (a revision may fuse them otherwise)
    for i in range(args.warmup + args.repeats):
        for tag, pipe, f in (runs if i % 2 else runs[::-1]):
            pipe.run(f)
            times = {k: v for k, v in pipe.last_timings.items() if k not in ("upload", "download")}
            times[PLAN] = sum(times.values())
            gbps = copier.gbps()
            kernels[tag] = list(times)
            if i >= args.warmup:
                for k, t in times.items():
                    ms.setdefault((k, tag), []).append(t)
                    pct.setdefault((k, tag), []).append(100.0 * _bytes(k, w, h) / (t * 1e6) / gbps)
    old_tag, new_tag = runs[0][0], runs[1][0]
    print(f"{w}x{h} {args.quality}, {args.repeats} repeats: device ms min / median (% of copy, median), "
          f"new/old of the mins and of each repeat (where both plans launch the kernel)")
    for k in dict.fromkeys(kernels[old_tag] + kernels[new_tag]):
        cols = []
        for tag in (old_tag, new_tag):
            v = ms.get((k, tag))
            cols.append(f"{tag} {min(v):7.2f} / {statistics.median(v):7.2f} ({statistics.median(pct[(k, tag)]):3.0f} %)"
                        if v else f"{tag} {'–':>25}")
        o, n = ms.get((k, old_tag)), ms.get((k, new_tag))
        ratio = ""
        if o and n:  # of the mins, and the median of the per-repeat ratios (the two ran back to back)
            per = sorted(b / a for a, b in zip(o, n))
            ratio = (f"new/old {min(n) / min(o):.2f} (per repeat: median {statistics.median(per):.2f}, "
                     f"quartiles {per[len(per) // 4]:.2f}–{per[(3 * len(per)) // 4]:.2f})")
        print(f"  {k:<40} {cols[0]}   {cols[1]}   {ratio}")
    return 0


PLAN = "all kernels of the plan"
"""The row summing a run's kernels (its % of copy: one read and one write of the frame, the pass a
plan fused into one kernel would make)."""


def _bytes(kernel: str, w: int, h: int) -> int:
    """Bytes a kernel moves as `clpost bench` counts them: RGB float read + write, + the RI plane
    where vignetting is in the group; the whole plan as one pass."""
    if kernel == PLAN:
        return w * h * 28
    return w * h * (28 if "vignetting" in kernel.split("__") else 24)


if __name__ == "__main__":
    raise SystemExit(main())

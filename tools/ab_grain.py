"""grain's Gaussian path, old revision vs this tree in one process (interleaved), at a chosen grain
radius — the bench's full scene has grains too small for the correlated 3×3 path (ρ < 0.02: one
normal per pixel and layer), so this times that path on its own.

    PYTHONPATH=. .venv/bin/python tools/ab_grain.py --old 4c1b168 --radius-px 0.6

Input: uniform-random image densities 0.1–2.0 above the stock's D_min at --size; the grain stage
alone (film already applied), draft; radius set through the sensor width as tests/test_grain.py
does. Prints device ms of each (medians; the kernel named grain: the gather, or — white noise in
this tree — the fused pointwise kernel of grain alone, without the gather's two layout conversions),
the median per-run ratio new/old and max |old − new| (densities).
"""
from __future__ import annotations

import argparse
import statistics
import warnings

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--old", default="4c1b168")
    ap.add_argument("--radius-px", type=float, default=0.6)
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--stock", default="kodak-ektar-100")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    import clpost
    from clpost.bench_ab import load_revision
    from clpost.film_stock import load_stock
    from clpost.grain_model import grain_radius_um

    old = load_revision(args.old, ".")
    w, h = (int(v) for v in args.size.lower().split("x"))
    stock = load_stock(args.stock)
    r_mm = grain_radius_um(stock.iso) / 1000.0
    d = (stock.d_min() + np.random.default_rng(0).uniform(0.1, 2.0, (h, w, 3))).astype(np.float32)
    runs = {}
    for name, mod in ((args.old, old), ("this tree", clpost)):
        cam = mod.Camera(film=args.stock, film_output="negative", sensor_mm=(r_mm * w / args.radius_px, 1.0))
        runs[name] = (mod.Pipeline(cam, quality="draft", stages=["grain"], already_applied=("film",)), mod.Frame(d))
    times = {k: [] for k in runs}
    outs = {}
    for i in range(args.repeats + 1):
        for name, (p, f) in runs.items():
            outs[name] = p.run(f).color
            if i:
                times[name].append(p.last_timings["grain"])
    a, b = times[args.old], times["this tree"]
    p, f = runs["this tree"]
    cam = p.camera_for(f)
    stage = p.plan_for(f, cam).stages[0]
    # white noise (ρ < 0.02) runs as the pointwise GrainWhite here: one normal per pixel and layer
    taps = stage.taps_per_pixel(cam, f) if hasattr(stage, "taps_per_pixel") else 3
    print(f"grain {w}x{h}, radius {args.radius_px} px ({taps} filter taps per pixel): {args.old} "
          f"{statistics.median(a):.1f} ms, this tree {statistics.median(b):.1f} ms, new/old "
          f"{statistics.median(y / x for x, y in zip(a, b)):.3f}, max |diff| "
          f"{float(np.abs(outs[args.old] - outs['this tree']).max()):.2g} D")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Device time and closed-form errors of the lens-aberration stages (astigmatism, coma,
lateral_color) with the flagship lens wide open.

For each stage and quality: the stage alone on a deterministic HDR frame (clpost.bench's
synthetic frame: depth 1–21 m, so astigmatism's ellipses reach their cap), OpenCL profiling
events (median of --repeats runs after --warmup), and the float64 numpy reference once for the
ratio. Then the closed-form checks: point-source ellipse axes, comet centroid and R–B fringe
measured on the kernels' output vs the formulas. Uses only the public API.

    PYTHONPATH=. python tools/bench_aberrations.py --size 1280x720 --repeats 10
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from clpost import Camera, Frame, Pipeline
from clpost.bench import synthetic_frame
from clpost.stages import QUALITIES
from clpost.stages import astigmatism as ast
from clpost.stages import coma
from clpost.stages import lateral_color as lc

STAGES = ("astigmatism", "coma", "lateral_color")


def device_ms(cam, stage, quality, frame, repeats, warmup):
    pipe = Pipeline(cam, quality=quality, stages=[stage])
    times = []
    for i in range(warmup + repeats):
        pipe.run(frame)
        if i >= warmup:
            times.append(pipe.last_timings[stage])
    t0 = time.perf_counter()
    pipe.reference(frame)
    return statistics.median(times), (time.perf_counter() - t0) * 1e3


def _moments(img, xs, ys):
    m = img / img.sum()
    mx, my = (m * xs).sum(), (m * ys).sum()
    return mx, my, (m * (xs - mx) ** 2).sum(), (m * (ys - my) ** 2).sum()


def closed_form_errors(w, h):
    """Relative/absolute errors of the measured point-source geometry vs the formulas."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    cy, x0 = (h - 1) // 2, int(0.9 * w)
    cx = (w - 1) / 2
    out = {}
    cam = Camera(f_number=2.0, focus_distance_m=3.0, field_curvature_mm=1.0, astigmatism_mm=1.0)
    r_mm = (x0 - cx) * 36.0 / w
    want_s, want_t = ast.point_source_axes_px(cam, r_mm, 3.0, w)
    color = np.zeros((h, w, 3), np.float32)
    color[cy, x0] = 1.0
    res = Pipeline(cam, stages=["astigmatism"]).run(Frame(color, depth=np.full((h, w), 3.0, np.float32))).color[..., 1]
    got_s, got_t = ast.splat_axes_px(res, 64)
    out["astigmatism sagittal axis"] = (want_s, got_s)
    out["astigmatism tangential axis"] = (want_t, got_t)
    out["astigmatism energy"] = (1.0, float(res.sum()))
    cam = Camera(coma_mm=0.3)
    g = coma.comet_geometry_px(cam, r_mm, w)
    res = Pipeline(cam, stages=["coma"]).run(Frame(color)).color[..., 0].astype(np.float64)
    mx, my, _, _ = _moments(res, xs, ys)
    out["coma centroid shift"] = (g["centroid"], mx - x0)
    out["coma energy"] = (1.0, float(res.sum()))
    cam = Camera(lateral_color_mm=0.1)
    want = lc.fringe_px(cam, r_mm, w)
    spot = np.exp(-((xs - x0) ** 2 + (ys - cy) ** 2) / (2 * 1.5 ** 2))
    res = Pipeline(cam, stages=["lateral_color"]).run(Frame(np.repeat(spot[..., None], 3, -1).astype(np.float32))).color
    shifts = [(_moments(res[..., c].astype(np.float64), xs, ys)[0] - x0) for c in range(3)]
    out["lateral colour R-B fringe"] = (float(want[0] - want[2]), shifts[0] - shifts[2])
    out["lateral colour flux (blue)"] = (float(spot.sum()), float(res[..., 2].sum()))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--warmup", type=int, default=2)
    ap.add_argument("--lens", default="zeiss-planar-50-f1.4")
    ap.add_argument("--f-number", type=float, default=1.4)
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.lower().split("x"))
    cam = Camera(lens=a.lens, f_number=a.f_number, focus_distance_m=3.0)
    frame = synthetic_frame(w, h)
    print(f"| stage | quality | device ms (median of {a.repeats}) | numpy float64 ms | ratio |")
    print("|---|---|---|---|---|")
    for stage in STAGES:
        for q in (QUALITIES if stage != "lateral_color" else ("final",)):
            ms, np_ms = device_ms(cam, stage, q, frame, a.repeats, a.warmup)
            print(f"| {stage} | {q} | {ms:.1f} | {np_ms:.0f} | {np_ms / ms:.0f}× |")
    print()
    print("| tile model (16×8 tiles) | value |")
    print("|---|---|")
    err, (ex, ey) = coma.Coma("final").shape_error_px(cam, w, h)
    print(f"| coma: largest landing-point change across a tile (exact while < 0.5 px) | {err:.3f} px at ({ex}, {ey}) |")
    exact = ast.Astigmatism("final").tile_plan(cam, frame)[-1]
    print(f"| astigmatism: tiles on the exact per-pixel path | {exact.mean():.1%} of {exact.size} |")
    print()
    print("| closed-form check | expected | measured | error |")
    print("|---|---|---|---|")
    for k, (want, got) in closed_form_errors(w, h).items():
        print(f"| {k} | {want:.4f} | {got:.4f} | {abs(got - want) / max(abs(want), 1e-12):.2%} |")


if __name__ == "__main__":
    main()

"""Measure the trade: velocity-buffer motion blur (each quality) vs the sub-frame reference.

Renders frame 0 of the demo scene (its cube "mover" slides 6 cm and spins 4° per frame at 5 m),
renders the exact motion blur from K sub-frames (clpost.render.motion), runs the motion_blur
stage alone at each quality and reports, on the mover's region and on the whole image:

- PSNR on linear scene values with peak 1 (the demo's sunlit diffuse white ≈ 1);
- mean HDR-FLIP (NVIDIA, flip-evaluator) when installed;
- device time of the stage: OpenCL events, median of --repeats runs after one warm-up.

Writes a Markdown table (stdout) and PNG crops into --pngs. Uses only the public API.

    PYTHONPATH=. python tools/bench_motion_blur.py --size 960x640 --subframes 64 --angles 180,360
"""
from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import numpy as np

from clpost import Camera, Pipeline
from clpost.atomic import write_png
from clpost.render import DemoScene, PyVistaRenderer
from clpost.render.motion import render_motion_blur_reference
from clpost.stages import QUALITIES
from clpost.stages.motion_blur import shutter_from_angle


def psnr(a: np.ndarray, b: np.ndarray, peak: float = 1.0) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(peak * peak / mse)


def flip(ref: np.ndarray, test: np.ndarray) -> float | None:
    try:
        import flip_evaluator
    except ImportError:
        return None
    _, mean, _ = flip_evaluator.evaluate(np.ascontiguousarray(ref, np.float32),
                                         np.ascontiguousarray(test, np.float32), "HDR",
                                         applyMagma=False)
    return float(mean)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", default="960x640")
    p.add_argument("--subframes", type=int, default=64)
    p.add_argument("--angles", default="180,360", help="shutter angles in degrees at --fps")
    p.add_argument("--fps", type=float, default=24.0)
    p.add_argument("--repeats", type=int, default=10)
    p.add_argument("--pngs", default="/tmp/motion_check/bench")
    args = p.parse_args(argv)
    w, h = (int(v) for v in args.size.lower().split("x"))
    pngs = Path(args.pngs)
    renderer = PyVistaRenderer(DemoScene.default())
    rows = []
    try:
        for angle in (float(a) for a in args.angles.split(",")):
            cam = Camera(lens="thin:50", f_number=2.0, focus_distance_m=3.0, frame_rate_fps=args.fps,
                         shutter_s=shutter_from_angle(angle, args.fps))
            sharp = renderer.render(cam, (w, h), 0)
            ref = render_motion_blur_reference(cam, (w, h), 0, subframes=args.subframes, renderer=renderer)
            ids, names = sharp.metadata["object_id"], sharp.metadata["object_names"]
            ys, xs = np.nonzero(ids == names.index("mover"))
            pad = int(np.ceil(np.abs(sharp.velocity[ids == names.index("mover")]).max() * cam.shutter_s * args.fps)) + 4
            y0, y1 = max(ys.min() - pad, 0), min(ys.max() + pad + 1, h)
            x0, x1 = max(xs.min() - pad, 0), min(xs.max() + pad + 1, w)
            region = (slice(y0, y1), slice(x0, x1))
            crops = {"sharp": sharp.color, "reference": ref.color}
            cases = [("none (sharp frame)", sharp.color, None)]
            for q in QUALITIES:
                pipe = Pipeline(cam, quality=q, stages=["motion_blur"])
                out = pipe.run(sharp)
                times = []
                for _ in range(args.repeats):
                    pipe.run(sharp)
                    times.append(pipe.last_timings["motion_blur"])
                cases.append((f"motion_blur {q}", out.color, statistics.median(times)))
                crops[q] = out.color
            for label, img, ms in cases:
                rows.append((angle, label, psnr(img[region], ref.color[region]), psnr(img, ref.color),
                             flip(ref.color[region], img[region]), ms))
            strip = np.concatenate([np.kron(crops[k][region], np.ones((2, 2, 1))) for k in
                                    ("sharp", "reference", "final", "draft")], axis=1)
            write_png(pngs / f"mover_{int(angle)}deg_sharp_ref_final_draft.png", strip * 0.6)
            write_png(pngs / f"full_{int(angle)}deg_reference.png", ref.color * 0.6)
            write_png(pngs / f"full_{int(angle)}deg_final.png", crops["final"] * 0.6)
    finally:
        renderer.close()
    from clpost.runtime import get_runtime

    print(f"device: {get_runtime().name}; {w}x{h}; reference: {args.subframes} sub-frames; "
          f"mover region {x1 - x0}x{y1 - y0} px")
    print()
    print("| shutter | method | PSNR mover (dB) | PSNR image (dB) | FLIP mover | device ms (median) |")
    print("|---|---|---|---|---|---|")
    for angle, label, pm, pi, fl, ms in rows:
        fl_s = "n/a" if fl is None else f"{fl:.4f}"
        ms_s = "—" if ms is None else f"{ms:.1f}"
        print(f"| {angle:g}° @ {args.fps:g} fps | {label} | {pm:.2f} | {pi:.2f} | {fl_s} | {ms_s} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

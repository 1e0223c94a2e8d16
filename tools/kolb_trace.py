"""The three-way comparison of docs/image_based_lens.md: a Kolb-style distribution ray tracer
(:mod:`clpost.render.kolb_trace`, the reference) against the image-based lens model and the
post-process stages, on analytic checker planes.

    PYTHONPATH=. python tools/kolb_trace.py --lens thorlabs-lb1471 --size 192 128 --rays 256 --out /tmp/kolb

prints the error table (RMS and 99th-percentile relative error against the traced image, in the
regions away from the frame border) and writes PNGs of the images and the error maps.
"""
from __future__ import annotations

import argparse
import math
import time
import warnings
from pathlib import Path

import numpy as np

from clpost.render.kolb_trace import errors, ibl_image, kolb_image, planes_scene, post_image

def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--lens", default="thorlabs-lb1471")
    ap.add_argument("--f-number", type=float, default=4.0)
    ap.add_argument("--focus", type=float, default=3.0, help="focus distance from the film (m)")
    ap.add_argument("--sensor", type=float, nargs=2, default=(12.0, 8.0), help="film size (mm)")
    ap.add_argument("--size", type=int, nargs=2, default=(192, 128))
    ap.add_argument("--rays", type=int, default=256, help="rays per pixel of the traced reference")
    ap.add_argument("--seeds", type=int, default=1,
                    help="independent references of --rays each, averaged; with >= 2 the reference's own noise is "
                         "measured from the difference of the even- and odd-seed halves")
    ap.add_argument("--box", type=int, default=1,
                    help="render the image-based, post-process and pinhole images at BOX× the size and average "
                         "BOX×BOX blocks: the traced reference integrates over each pixel's area, a point-sampled "
                         "image differs from it at every sharp edge by aliasing alone")
    ap.add_argument("--pupil-n", type=int, default=3)
    ap.add_argument("--pupil-pattern", choices=("grid", "spiral"), default="grid")
    ap.add_argument("--ibl-path", nargs="+", choices=("numpy", "raster"), default=["numpy"],
                    help="the image-based model's projections: numpy shading and/or the rasterizer path")
    ap.add_argument("--out", default="/tmp/kolb")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    from clpost.atomic import write_png

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scene = planes_scene()
    size = tuple(args.size)
    common = (args.lens, args.f_number, args.focus, tuple(args.sensor), size, scene)
    t0 = time.perf_counter()
    refs = [kolb_image(*common, rays=args.rays, seed=s) for s in range(max(1, args.seeds))]
    ref = np.mean(refs, 0)
    t_ref = time.perf_counter() - t0
    k = max(1, args.box)
    big = (args.lens, args.f_number, args.focus, tuple(args.sensor), (size[0] * k, size[1] * k), scene)

    def down(img):  # k×k box average: the pixel-area integral the traced reference estimates
        img = np.asarray(img, np.float64)[..., :3]
        return img.reshape(size[1], k, size[0], k, 3).mean((1, 3))

    ibls = {}
    for path in args.ibl_path:
        img, st = ibl_image(*big, pupil_n=args.pupil_n, pupil_pattern=args.pupil_pattern, rasterizer=path == "raster")
        ibls[path] = (down(img), st)
    ibl = next(iter(ibls.values()))[0]
    post, plan, t_post, pin = post_image(*big)
    post = down(post)
    pin_c = down(pin.color)
    border = max(2, size[0] // 40)
    noise = None
    if len(refs) >= 2:
        # halves of n_a, n_b seeds differ by σ√(1/n_a + 1/n_b); the average of all K carries σ/√K
        n_a, n_b = len(refs[0::2]), len(refs[1::2])
        half = errors(np.mean(refs[0::2], 0), np.mean(refs[1::2], 0), border)["rms"]
        noise = half * math.sqrt((1 / len(refs)) / (1 / n_a + 1 / n_b))
    rows = [("Kolb et al. distribution ray tracing", f"{len(refs)} × {args.rays} rays/px", t_ref, None)]
    rows += [(f"image-based lens (Heidrich et al.), {path} projections",
              f"{st['projections']} projections, {st['pupil_samples']} pupil samples", st["frame_s"],
              errors(img, ref, border))
             for path, (img, st) in ibls.items()]
    rows += [("post-process: dof + vignetting + distortion", "pinhole render ×3 supersampled + 3 stages", t_post,
              errors(post, ref, border)),
             ("pinhole only (no lens)", "pinhole render", 0.0, errors(pin_c, ref, border))]
    print(f"lens {args.lens} f/{args.f_number:g}, focus {args.focus:g} m, film {args.sensor[0]:g}×{args.sensor[1]:g} mm, "
          f"{size[0]}×{size[1]} px (others rendered at {k}× and box-averaged); IBL max ray-angle error {st['max_angle_deg']:.3f}°, preprocessing "
          f"{st['preprocess_s']:.2f} s, warp {st['warp_device_ms']:.1f} ms device")
    if noise is not None:
        print(f"reference noise (RMS rel., from the two seed halves): {noise:.4f}")
    print("| method | work | time (s) | RMS rel. error | RMS, reference noise removed | 99th pct | max (at px) |")
    print("|---|---|---|---|---|---|---|")
    for name, work, t, e in rows:
        if e is None:
            print(f"| {name} | {work} | {t:.1f} | reference | {'' if noise is None else f'noise {noise:.4f}'} | | |")
        else:
            clean = "" if noise is None else f"{math.sqrt(max(e['rms'] ** 2 - noise ** 2, 0.0)):.4f}"
            print(f"| {name} | {work} | {t:.2f} | {e['rms']:.4f} | {clean} | {e['p99']:.4f} | {e['max']:.3f} {e['max_at']} |")
    print("plan:", "; ".join(str(p) for p in plan))
    stem = f"{args.lens}"
    if "raster" in ibls:
        write_png(out / f"{stem}_ibl_raster.png", ibls["raster"][0].astype(np.float32))
    for name, img in (("kolb", ref), ("ibl", ibl), ("post", post), ("pinhole", pin_c)):
        write_png(out / f"{stem}_{name}.png", img.astype(np.float32))
    for name, img in (("ibl", ibl), ("post", post)):
        e = np.abs(img - ref).mean(-1) / ref.mean()
        write_png(out / f"{stem}_{name}_error.png", np.repeat(np.clip(e / 0.25, 0, 1)[..., None], 3, -1).astype(np.float32))
    print(f"wrote {out}/{stem}_*.png (error maps: white = 25 % of the mean)")


if __name__ == "__main__":
    main()

r"""Measurements of the image-based lens model (docs/image_based_lens.md).

``pupil``: the demo's frame 0 through ``--lens`` for several pupil samplings at the same size,
each given as ``PATTERN:N:DEPTH`` (pupil pattern ``grid`` or ``spiral``, N² pupil samples,
quad-tree depth limit): projections, wall time of render + warp, the OpenCL warp's device time,
and the RMS difference from the first configuration given as ``--reference`` (a dense sampling);
writes the images and 2× crops of a defocused region to ``--out``.

``fps``: the paper's table — projections per frame, frames per second (median wall time of
render + warp over ``--repeats`` frames after one warm-up, and the median process CPU time per
frame, which a loaded shared machine disturbs less; the warp's device time from OpenCL
profiling events) and the maximum ray-angle error, for the checker-plane scene of
:mod:`clpost.render.kolb_trace`, through the numpy-shading path and the rasterizer path
(``--path``). ``--cases legacy``: the achromatic doublet on a 4×4 mm film at f/8 and the
bi-convex singlet on 12×8 mm with ``--pupil-n``² grid samples; ``--cases paper``: the paper's
rows, 10 spiral pupil samples of one projection each (doublet, 3×3 mm) and 40 projections
(singlet, 5.5×5.5 mm).

Usage::

    PYTHONPATH=. python tools/ibl_bench.py pupil --size 480 320 --reference spiral:12:1 grid:3:2 spiral:3:2 spiral:6:1
    PYTHONPATH=. python tools/ibl_bench.py fps --size 480 480 --repeats 5
    PYTHONPATH=. python tools/ibl_bench.py fps --cases paper --size 256 256 --repeats 9
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from clpost.atomic import write_png  # noqa: E402
from clpost.render.image_based_lens import build, pyvista_render_fn, render_image_based  # noqa: E402


def _config(text: str) -> tuple[str, int, int]:
    pattern, n, depth = text.split(":")
    return pattern, int(n), int(depth)


def _display(img: np.ndarray, white: float) -> np.ndarray:
    return (np.clip(img / white, 0, 1) ** (1 / 2.2)).astype(np.float32)


def pupil(args) -> None:
    from clpost.camera import Camera
    from clpost.demo import DEMO_CAMERA_DEFAULTS
    from clpost.render.demo_scene import DemoScene
    from clpost.render.pyvista_renderer import PyVistaRenderer

    cam = Camera(**dict(DEMO_CAMERA_DEFAULTS, lens=args.lens))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    size = tuple(args.size)
    r = PyVistaRenderer(DemoScene.default(camera_motion=True))
    results = {}
    try:
        for text in ([args.reference] if args.reference else []) + args.configs:
            pattern, n, depth = _config(text)
            model = build(cam.lens, float(cam.focus_from_film_m), cam.f_number, tuple(cam.sensor_mm), pupil_n=n,
                          max_depth=depth, pupil_pattern=pattern)
            t0 = time.perf_counter()
            img, st = render_image_based(model, size, pyvista_render_fn(r, 0))
            results[text] = (img, st, time.perf_counter() - t0, model)
    finally:
        r.close()
    ref = results[args.reference][0] if args.reference else None
    white = float(np.percentile(next(iter(results.values()))[0], 99))  # shared by all images
    x0, y0, w, h = args.crop
    print(f"{args.lens} f/{cam.f_number:g}, focus {cam.focus_distance_m:g} m, {size[0]}×{size[1]} px; "
          f"crop x {x0}..{x0 + w}, y {y0}..{y0 + h}")
    print("| pupil samples | quad-tree depth | projections | max ray-angle error | render + warp (s) | warp device (ms) "
          "| RMS display difference from the reference (whole / crop) |")
    print("|---|---|---|---|---|---|---|")
    crops = []
    for text, (img, st, wall, model) in results.items():
        pattern, n, depth = _config(text)
        if ref is not None and text != args.reference:
            # in display values (white = the first image's 99th percentile, gamma 2.2): the sun and
            # the emitters are 10³× the mean radiance and would decide a radiance RMS alone
            d = np.abs(_display(img, white) - _display(ref, white)).mean(-1)
            e = f"{np.sqrt((d ** 2).mean()):.4f} / {np.sqrt((d[y0:y0 + h, x0:x0 + w] ** 2).mean()):.4f}"
        else:
            e = "reference"
        print(f"| {n * n} {pattern} | {depth} | {st['projections']} | {model.max_angle_deg:.2f}° | {wall:.2f} "
              f"| {st['warp_device_ms']:.1f} | {e} |")
        name = text.replace(":", "_")
        write_png(out / f"pupil_{name}.png", _display(img, white))
        crops.append(np.repeat(np.repeat(_display(img[y0:y0 + h, x0:x0 + w], white), 2, 0), 2, 1))
    strip = np.concatenate([np.pad(c, ((0, 0), (0, 4), (0, 0)), constant_values=1.0) for c in crops], 1)
    write_png(out / "pupil_crops.png", strip)
    print(f"wrote {out}/pupil_*.png (crops left to right in the order of the table)")


FPS_CASES = {
    # the table before the rasterizer path: 2×2 grid pupil samples (--pupil-n)
    "legacy": (("thorlabs-ac254-050-a", (4.0, 4.0), None), ("thorlabs-lb1471", (12.0, 8.0), None)),
    # the paper's two rows: 10 pupil samples of one projection each (the achromat over a 3×3 mm
    # film fits a pinhole per sample to 0.05°), and 40 projections (the singlet over 5.5×5.5 mm:
    # 10 samples of 1–7 cells)
    "paper": (("thorlabs-ac254-050-a", (3.0, 3.0), 10), ("thorlabs-lb1471", (5.5, 5.5), 10)),
}


def fps(args) -> None:
    import os

    from clpost.render.image_based_lens import open_rasterizer, rasterizer_render_fn
    from clpost.render.kolb_trace import planes_scene
    from clpost.render.pyvista_renderer import PyVistaRenderer

    load = os.getloadavg()
    print(f"f/{args.f_number:g}, focus 3 m, threshold 0.05°, median of {args.repeats} frames after one warm-up; "
          f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} CPUs; "
          f"LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', 'unset')}")
    print("| lens | film | output | pupil samples | projections per frame (per pupil sample) | max ray-angle error "
          "| preprocessing (s) | path | frame wall, median (ms) | fps | frame CPU, median (ms) | fps by CPU time "
          "| of which rendering, wall (ms) | warp device, median (ms) | bake, first frame (s) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    scene = planes_scene()
    r = PyVistaRenderer(scene)
    raster = open_rasterizer(scene, log=print) if "raster" in args.path else None
    try:
        for lens, film, count in FPS_CASES[args.cases]:
            build.cache_clear()
            if count is None:
                model = build(lens, 3.0, args.f_number, film, pupil_n=args.pupil_n)
                samples = f"{args.pupil_n}² grid"
            else:
                model = build(lens, 3.0, args.f_number, film, pupil_pattern="spiral", pupil_count=count)
                samples = f"{count} spiral"
            size = (args.size[0], int(round(args.size[0] * film[1] / film[0])))
            per = sorted(set(model.projections_per_sample().tolist()))
            for path in args.path:
                if path == "raster" and raster is None:
                    continue
                fn = rasterizer_render_fn(raster, 0) if path == "raster" else pyvista_render_fn(r, 0)
                walls, cpus, dev, rend = [], [], [], []
                bake = 0.0
                for k in range(args.repeats + 1):
                    t0, c0 = time.perf_counter(), time.process_time()
                    _, st = render_image_based(model, size, fn)
                    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
                    if k == 0 and path == "raster":
                        bake = raster.bake_s
                    if k:
                        walls.append(wall)
                        cpus.append(cpu)
                        dev.append(st["warp_device_ms"])
                        rend.append(st["render_s"])
                wall, cpu = statistics.median(walls), statistics.median(cpus)
                print(f"| {lens} | {film[0]:g}×{film[1]:g} mm | {size[0]}×{size[1]} | {samples} "
                      f"| {len(model.projections)} ({per}) | {model.max_angle_deg:.3f}° | {model.preprocess_s:.2f} "
                      f"| {path} | {1e3 * wall:.1f} | {1 / wall:.1f} | {1e3 * cpu:.1f} | {1 / cpu:.1f} "
                      f"| {1e3 * statistics.median(rend):.1f} | {statistics.median(dev):.2f} "
                      + (f"| {bake:.2f} |" if path == "raster" else "| — |"))
    finally:
        r.close()
        if raster is not None:
            raster.close()


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("pupil")
    p.add_argument("configs", nargs="+", help="PATTERN:N:DEPTH, e.g. grid:3:2 spiral:6:1")
    p.add_argument("--reference", default=None, help="a dense PATTERN:N:DEPTH to measure the others against")
    p.add_argument("--lens", default="thorlabs-ac254-050-a")
    p.add_argument("--size", type=int, nargs=2, default=(480, 320))
    p.add_argument("--crop", type=int, nargs=4, default=(300, 0, 180, 120), help="x y w h of the 2× crops")
    p.add_argument("--out", default="/tmp/ibl_bench")
    f = sub.add_parser("fps")
    f.add_argument("--size", type=int, nargs=2, default=(480, 480), help="output width (height from the film)")
    f.add_argument("--f-number", type=float, default=8.0)
    f.add_argument("--pupil-n", type=int, default=2)
    f.add_argument("--repeats", type=int, default=5)
    f.add_argument("--cases", choices=sorted(FPS_CASES), default="legacy",
                   help="legacy: the 2×2-sample table; paper: 10 samples × 1 projection and 40 projections")
    f.add_argument("--path", nargs="+", choices=("numpy", "raster"), default=["numpy", "raster"],
                   help="numpy: per-projection numpy shading; raster: baked textures rasterised by VTK")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    (pupil if args.cmd == "pupil" else fps)(args)


if __name__ == "__main__":
    main()

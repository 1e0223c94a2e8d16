"""Cost and error of the traced bokeh texture (dof with a lens_data lens) and of halation, per
quality level, on a synthetic frame:

    PYTHONPATH=. python tools/traced_bokeh_cost.py --size 1280 720 --repeat 3 --out /tmp/traced_bokeh

prints the pencil map's build time, the dof stage's time per quality with the parametric texture
(thin lens, spherical_aberration 0.5) and the traced one (the Planar 1.4/50), the traced draft and
preview error against final (RMS over the mean), the rendered rim/core ratio of a defocused point
per quality, and halation's time; writes halation before/after PNGs (film + print).
"""
from __future__ import annotations

import argparse
import statistics
import time
import warnings
from pathlib import Path

import numpy as np

from clpost import Camera, Frame, Pipeline
from clpost.stages import dof as D


def scene(w: int, h: int, seed: int = 0) -> Frame:
    """Ground plane receding from 0.7 m (bottom) to 12 m (top) with a texture, and a few lamps."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    depth = (0.7 * (12 / 0.7) ** (1 - yy / (h - 1))).astype(np.float32)
    base = 0.1 + 0.08 * ((xx // 24 + yy // 24) % 2)
    color = np.repeat(base[..., None], 3, -1) * (0.8 + 0.4 * rng.random((h, w, 1)))
    for _ in range(12):
        y, x = int(rng.integers(4, h - 4)), int(rng.integers(4, w - 4))
        color[y - 1:y + 2, x - 1:x + 2] = (200.0, 160.0, 90.0)
    return Frame(color.astype(np.float32), depth=depth)


def timed(pipe, frame, repeat):
    pipe.run(frame)  # plan, build, tables
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = pipe.run(frame)
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), out.color[..., :3].astype(np.float64)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, nargs=2, default=(1280, 720))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default="/tmp/traced_bokeh")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    from clpost.atomic import write_png

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    w, h = args.size
    frame = scene(w, h)
    common = dict(depth_of_field=True, f_number=1.4, focus_distance_m=2.0, shutter_s=1 / 50)
    thin = Camera(**common, spherical_aberration=0.5)
    traced = Camera(**common, lens="zeiss-planar-50-f1.4")
    t0 = time.perf_counter()
    D.traced_profile(traced, w)
    print(f"pencil map at {w} px: {time.perf_counter() - t0:.2f} s (host, numpy; once per lens/focus/f-number/size, "
          "all qualities)")
    res = {}
    print("| quality | parametric (thin lens) s | traced (Planar 1.4/50) s | parametric vs its final: mean abs / mean "
          "| traced vs its final |")
    print("|---|---|---|---|---|")
    for q in ("draft", "preview", "final"):
        tp, ip = timed(Pipeline(thin, quality=q, stages=["dof"]), frame, args.repeat)
        tt, it = timed(Pipeline(traced, quality=q, stages=["dof"]), frame, args.repeat)
        res[q] = (tp, tt, ip, it)

    def err(a, b):
        return float(np.mean(np.abs(a - b)) / np.mean(b))

    for q in ("draft", "preview", "final"):
        tp, tt, ip, it = res[q]
        print(f"| {q} | {tp:.3f} | {tt:.3f} | {err(ip, res['final'][2]):.4f} | {err(it, res['final'][3]):.4f} |")
    # halation: a night frame (dark ground, bright lamps)
    night = Frame((frame.color * np.where(frame.color > 50, 25.0, 0.03)).astype(np.float32), depth=frame.depth)
    cam_h = Camera(film="kodak-gold-200", shutter_s=1 / 100, f_number=4.0, halation=True)
    th, _ = timed(Pipeline(cam_h, stages=["halation"]), night, args.repeat)
    print(f"halation at {w}x{h}: {th:.3f} s (the same at every quality)")
    imgs = {}
    for name, on in (("before", False), ("after", True)):
        img = np.clip(Pipeline(cam_h.with_(halation=on)).run(night).color[..., :3], 0, 1).astype(np.float32)
        write_png(out / f"halation_{name}.png", img)
        imgs[name] = img
    lum = night.color[..., 0]
    y, x = np.unravel_index(int(np.argmax(lum)), lum.shape)
    y, x = min(max(y, 40), h - 41), min(max(x, 40), w - 41)
    crops = [np.kron(imgs[n][y - 40:y + 41, x - 40:x + 41], np.ones((3, 3, 1), np.float32)) for n in ("before", "after")]
    write_png(out / "halation_before_after.png",
              np.concatenate([crops[0], np.ones((crops[0].shape[0], 6, 3), np.float32), crops[1]], 1))
    print(f"wrote {out}/halation_before.png, halation_after.png, halation_before_after.png (3x crop at a lamp)")


if __name__ == "__main__":
    main()

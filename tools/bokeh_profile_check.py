"""The traced bokeh texture (clpost/optics/pencil.py, used by the dof stage for a traced lens)
against the Kolb-style backward tracer (clpost.render.kolb_trace.point_source_profile) on
defocused axial point sources in front of and behind focus:

    PYTHONPATH=. python tools/bokeh_profile_check.py --lens zeiss-planar-50-f1.4 --f-number 1.4 \\
        --focus 2 --depths 1.2 6 --out /tmp/bokeh

prints, per depth, the green radial profiles (pencil map at the exact depth, the dof stage's
rendered disc, the tracer; bins of t = ρ/ρ₀, ρ₀ the thin-lens disc radius) and the rim/core
ratios (rim: mean over t ∈ [0.7, 0.95], core: t < 0.3), and writes a PNG per depth: the rendered
disc beside a disc drawn from the tracer's R, G, B profiles.
"""
from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

from clpost import Camera, Frame, Pipeline
from clpost.optics import pencil
from clpost.render.kolb_trace import disc_blurred, point_source_profile
from clpost.stages import dof as D

CORE = (0.0, 0.3)
RIM = (0.7, 0.95)


def band_mean(p: np.ndarray, edges: np.ndarray, lo: float, hi: float) -> float:
    """Area-weighted mean of a binned radial profile over bins whose centres lie in [lo, hi)."""
    c = 0.5 * (edges[1:] + edges[:-1])
    a = np.diff(edges ** 2)
    m = (c >= lo) & (c < hi)
    return float(np.sum(p[m] * a[m]) / np.sum(a[m]))


def rim_core(p: np.ndarray, edges: np.ndarray) -> float:
    return band_mean(p, edges, *RIM) / band_mean(p, edges, *CORE)


def rendered_profiles(cam: Camera, depth_m: float, size: int, edges: np.ndarray, quality: str = "final"):
    """Radial profiles (3, bins) of the dof stage's disc of one bright pixel at ``depth_m``,
    normalised like the pencil map, and the output image."""
    color = np.zeros((size, size, 3), np.float32)
    c = size // 2
    color[c, c] = 1e4
    frame = Frame(color, depth=np.full((size, size), depth_m, np.float32))
    out = Pipeline(cam, quality=quality, stages=["dof"]).run(frame).color[..., :3].astype(np.float64)
    r = abs(float(D.coc_px(cam, depth_m, size)))
    yy, xx = np.mgrid[0:size, 0:size]
    t = np.hypot(xx - c, yy - c) / r
    b = np.searchsorted(edges, t, side="right") - 1
    ok = (b >= 0) & (b < len(edges) - 1)
    prof = []
    for ch in range(3):
        s = np.bincount(b[ok], out[..., ch][ok], len(edges) - 1) / np.maximum(np.bincount(b[ok], minlength=len(edges) - 1), 1)
        prof.append(s / np.sum(s * np.diff(edges ** 2)))
    return np.array(prof), out, r


def disc_image(prof: np.ndarray, edges: np.ndarray, r_px: float, size: int) -> np.ndarray:
    """A disc of radius r_px drawn from radial profiles (3, bins) (for the figure)."""
    c = size // 2
    yy, xx = np.mgrid[0:size, 0:size]
    t = np.hypot(xx - c, yy - c) / r_px
    b = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, len(edges) - 2)
    img = np.stack([np.where(t < edges[-1], prof[ch][b], 0.0) for ch in range(3)], -1)
    return img


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--lens", default="zeiss-planar-50-f1.4")
    ap.add_argument("--f-number", type=float, default=1.4)
    ap.add_argument("--focus", type=float, default=2.0, help="focus depth (m)")
    ap.add_argument("--depths", type=float, nargs="+", default=[1.2, 6.0])
    ap.add_argument("--radius-px", type=float, default=24.0, help="disc radius of the rendered images (px)")
    ap.add_argument("--quality", default="final")
    ap.add_argument("--bins", type=int, default=13, help="bins over [0, T_MAX]")
    ap.add_argument("--points", type=int, default=200, help="tracer: film points per bin")
    ap.add_argument("--rays", type=int, default=500, help="tracer: rays per film point")
    ap.add_argument("--rgb", action="store_true", help="trace R and B too, at their band's centre (for the figure)")
    ap.add_argument("--out", default="/tmp/bokeh")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    from clpost.atomic import write_png

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    edges = np.linspace(0.0, pencil.T_MAX, args.bins + 1)
    fine = np.linspace(0.0, pencil.T_MAX, 10 * args.bins + 1)
    source_t = 0.1
    size = 121
    print(f"{args.lens} f/{args.f_number:g}, focus {args.focus:g} m; profiles of G in bins of t = rho/rho0 "
          f"({args.bins} over [0, {pencil.T_MAX}]); tracer source disc {source_t} rho0; rim t in {RIM}, core t < {CORE[1]}")
    for depth in args.depths:
        base = Camera(lens=args.lens, f_number=args.f_number, focus_distance_m=args.focus, depth_of_field=True,
                      shutter_s=1 / 100)
        r_mm = abs(float(D.coc_mm(base, depth))) / 2.0
        # sensor width so that the disc has --radius-px radius on a size-px image
        cam = base.with_(sensor_mm=(size * r_mm / args.radius_px, size * r_mm / args.radius_px))
        t0 = time.perf_counter()
        pen_fine, rho0 = pencil.depth_profile(cam, depth, fine)
        pen = np.array([np.bincount(np.minimum(np.arange(len(fine) - 1) // 10, args.bins - 1),
                                    disc_blurred(p, fine, source_t) * np.diff(fine ** 2), args.bins)
                        / np.diff(edges ** 2) for p in pen_fine])
        pen_point = np.array([np.bincount(np.minimum(np.arange(len(fine) - 1) // 10, args.bins - 1),
                                          p * np.diff(fine ** 2), args.bins) / np.diff(edges ** 2) for p in pen_fine])
        rend, img, r_px = rendered_profiles(cam, depth, size, edges, args.quality)
        t1 = time.perf_counter()
        chans = (0, 1, 2) if args.rgb else (1,)
        kolb = np.full((3, args.bins), np.nan)
        for ch in chans:
            # green over its whole band (the numbers); red and blue (the figure) at their band's centre
            bands = pencil.BANDS[ch] if ch == 1 else pencil.BANDS[ch][1:2]
            kolb[ch] = point_source_profile(cam, depth, edges, rho0, bands, source_t=source_t,
                                            points_per_bin=args.points, rays=args.rays, seed=ch)
        t2 = time.perf_counter()
        np.set_printoptions(precision=3, linewidth=240)
        side = "front" if depth < args.focus else "back"
        print(f"\ndepth {depth:g} m ({side}), rho0 {rho0:.4f} mm, rendered r {r_px:.1f} px; pencil+render {t1 - t0:.1f} s, "
              f"tracer {t2 - t1:.1f} s")
        print(" t bins      ", 0.5 * (edges[1:] + edges[:-1]))
        print(" pencil (src)", pen[1])
        print(" rendered    ", rend[1])
        print(" tracer      ", kolb[1])
        peak = np.nanmax(kolb[1])
        print(f" |pencil - tracer| max {np.max(np.abs(pen[1] - kolb[1])):.3f} ({np.max(np.abs(pen[1] - kolb[1])) / peak:.1%} of the "
              f"tracer's peak)")
        print(f" rim/core: pencil (point) {rim_core(pen_point[1], edges):.3f}, pencil (src) {rim_core(pen[1], edges):.3f}, "
              f"rendered {rim_core(rend[1], edges):.3f}, tracer {rim_core(kolb[1], edges):.3f}")
        if args.rgb:
            print(" rim/core R, B: pencil (src) "
                  f"{rim_core(pen[0], edges):.3f}, {rim_core(pen[2], edges):.3f}; tracer {rim_core(kolb[0], edges):.3f}, "
                  f"{rim_core(kolb[2], edges):.3f}")
            ref = disc_image(kolb, edges, r_px, size)
            ref *= img.sum() / max(ref.sum(), 1e-30)
            both = np.concatenate([img, np.zeros((size, 4, 3)), ref], 1)
            write_png(out / f"bokeh_{args.lens}_f{args.f_number:g}_{side}_{depth:g}m.png",
                      np.clip(both / np.percentile(img[img > 0], 99.5) * 0.9, 0, 1).astype(np.float32))
    print(f"\nwrote {out}" if args.rgb else "")


if __name__ == "__main__":
    main()

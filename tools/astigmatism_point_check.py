"""astigmatism's point classes vs the 64-tap bilinear model they replace, on the float64 reference
(clpost/stages/astigmatism.py, "Point taps"; the numbers quoted there and in docs/benchmarks.md).

1. Crops of ``clpost bench``'s worst frame at 1080p (final): both models and a 1024-tap truth of
   the same tile model (bilinear), rms / 99.9th percentile / max |error| per kind of tile.
2. A lone highlight on point tiles (601 × 81 frames, flat depth, 20 cameras and positions): the
   splat's second moments (axes from the class's spiral, as tests/test_astigmatism.py measures
   them) and energy against the closed form, for both models.

    PYTHONPATH=. python tools/astigmatism_point_check.py [--crops 20,10 24,53 40,30] [--truth-taps 1024]
"""
from __future__ import annotations

import argparse

import numpy as np

from clpost import Camera, Frame
from clpost.bench import SCENES, synthetic_frame
from clpost.stages import _field as fld
from clpost.stages import astigmatism as ast


def crops(tiles, truth_taps):
    w, h = 1920, 1080
    frame = synthetic_frame(w, h)
    cam, _ = SCENES["worst"].camera(w, h)
    st = ast.Astigmatism("final")
    a_s, a_t, _, _ = st.semi_axes_px(cam, frame)
    bs, bt, tex, tey, exact, _ = st.tile_plan(cam, frame)
    point = fld.per_pixel(st.point_taps(cam, frame, exact), w, h)
    per = [fld.per_pixel(v, w, h) for v in (bs, bt, tex, tey)]
    m = 2 * fld.PAD  # margin: the crop's own edge padding reaches only this far
    for ty, tx in tiles:
        y0, x0 = ty * fld.TILE_H, tx * fld.TILE_W
        win = np.s_[y0 - m:y0 + 128 + m, x0 - m:x0 + 192 + m]
        args = [v[win] for v in (a_s, a_t, *per)]
        col = frame.color[win].astype(np.float64)
        inner = np.s_[m:-m, m:-m]
        truth = st._gather(col, *args, own=True, n=truth_taps)[inner]
        old = st._gather(col, *args, own=True, n=64)[inner]
        new = np.zeros_like(old)
        pt = point[win][inner]
        for n in np.unique(pt[pt > 0]):
            new[pt == n] = st._gather(col, *args, own=True, n=int(n), box=True)[inner][pt == n]
        for n in np.unique(pt[pt > 0]):
            sel = pt == n
            for name, o in (("64 bilinear", old), (f"point p{n}", new)):
                e = np.abs(o - truth)[sel]
                print(f"crop tiles ({ty}, {tx}), p{n} tiles ({sel.sum()} px): {name:12s} rms {np.sqrt((e ** 2).mean()):.3f} "
                      f"p99.9 {np.percentile(e, 99.9):.2f} max {e.max():.2f}")


def highlights():
    w, h = 601, 81
    cy, cx = (h - 1) // 2, (w - 1) / 2
    st = ast.Astigmatism("final")
    rows = []
    for fc, a in ((-3.0, 1.0), (-3.5, 0.5), (-4.0, 1.0), (-5.0, 0.5), (-5.5, 1.0), (-6.0, 0.3), (-4.5, -1.0),
                  (4.0, 1.0), (5.0, -0.5)):
        for x0 in (480, 515, 551):
            cam = Camera(lens="thin:50", f_number=2.0, focus_distance_m=3.0, field_curvature_mm=fc, astigmatism_mm=a)
            want_s, want_t = ast.point_source_axes_px(cam, (x0 - cx) * 36.0 / w, 3.0, w)
            color = np.zeros((h, w, 3))
            color[cy, x0] = 1.0
            frame = Frame(color.astype(np.float32), depth=np.full((h, w), 3.0, np.float32))
            a_s, a_t, _, _ = st.semi_axes_px(cam, frame)
            bs, bt, tex, tey, exact, _ = st.tile_plan(cam, frame)
            n = int(st.point_taps(cam, frame, exact)[cy // fld.TILE_H, x0 // fld.TILE_W])
            if n == 0 or exact[cy // fld.TILE_H - 1:cy // fld.TILE_H + 2, x0 // fld.TILE_W - 1:x0 // fld.TILE_W + 2].any():
                continue
            args = [a_s, a_t] + [fld.per_pixel(v, w, h) for v in (bs, bt, tex, tey)]

            def moments(out, taps):
                got_s, got_t = ast.splat_axes_px(out[..., 1], taps)
                return got_s / want_s - 1, got_t / want_t - 1, out[..., 1].sum() - 1

            old = moments(st._gather(color, *args, own=True, n=64), 64)
            new = moments(st._gather(color, *args, own=True, n=n, box=True), n)
            rows.append((n, old, new))
            print(f"fc {fc:+.1f} A {a:+.1f} x0 {x0}: axes {want_s:.1f} x {want_t:.1f} px, p{n}; axis and energy "
                  f"errors 64 bilinear {old[0]:+.3f} {old[1]:+.3f} {old[2]:+.3f} | point {new[0]:+.3f} {new[1]:+.3f} "
                  f"{new[2]:+.3f}")
    o = np.array([r[1] for r in rows])
    p = np.array([r[2] for r in rows])
    print(f"{len(rows)} highlights: |axis error| 64 bilinear {np.abs(o[:, :2]).min():.3f}-{np.abs(o[:, :2]).max():.3f} "
          f"(mean {np.abs(o[:, :2]).mean():.3f}), point {np.abs(p[:, :2]).min():.3f}-{np.abs(p[:, :2]).max():.3f} "
          f"(mean {np.abs(p[:, :2]).mean():.3f}); |energy error| max {np.abs(o[:, 2]).max():.3f} vs {np.abs(p[:, 2]).max():.3f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--crops", nargs="*", default=["20,10", "24,53", "40,30"], help="tile row,column of a crop's corner")
    ap.add_argument("--truth-taps", type=int, default=1024)
    a = ap.parse_args()
    crops([tuple(int(v) for v in c.split(",")) for c in a.crops], a.truth_taps)
    highlights()


if __name__ == "__main__":
    main()

"""astigmatism's point classes vs the 64-tap bilinear model they replace, on the float64 reference
(clpost/stages/astigmatism.py, "Point taps"; the numbers quoted there and in docs/benchmarks.md).

1. Crops of ``clpost bench``'s worst frame at 1080p (final): both models and a 1024-tap truth of
   the same tile model (bilinear), rms / 99.9th percentile / max |error| per kind of tile.
2. A lone highlight on point tiles (601 × 81 frames, flat depth, 20 cameras and positions): the
   splat's second moments (axes from the class's spiral, as tests/test_astigmatism.py measures
   them) and energy against the closed form, for both models. Two more columns split the point
   model's axis error (docs/benchmarks.md, "astigmatism: why 16 point taps bias a highlight's
   sagittal axis"): *disc* reads the same splat with a uniform disc's ⟨u²⟩ = ¼ instead of the
   spiral's (the physical axes; the test's measure differs by the spiral's own second moments),
   *own* is the point model with every pixel's own ellipse as its bound (no tile bound).

What-if options (the reference only, no kernel; the module's constants are patched for this
process): ``--point-classes 8:16`` replaces POINT_CLASSES, ``--box 8`` POINT_BOX (and the shrink
that goes with it), ``--pattern matched`` gives the point classes' gathers a spiral whose mean is
zero and whose second moments are a uniform disc's (⟨u_x²⟩ = ⟨u_y²⟩ = ¼, ⟨u_x u_y⟩ = 0: the
Vogel spiral centred and whitened).

    PYTHONPATH=. python tools/astigmatism_point_check.py [--crops 20,10 24,53 40,30] [--truth-taps 1024]
        [--point-classes 8:16] [--box 8] [--pattern vogel|matched] [--no-crops]
    PYTHONPATH=. python tools/astigmatism_point_check.py --membership   (only the table below)

``--membership``: for a pixel whose own semi-axes are ρ times its tile's bound, the per-axis spread of
the taps it keeps (membership clamp(9 − 8 μ², 0, 1), μ = |u|/ρ) against its own uniform ellipse, per
spiral — how a sparse pattern turns the tile bound into an axis error.
"""
from __future__ import annotations

import argparse
import contextlib
import math

import numpy as np

from clpost import Camera, Frame
from clpost.bench import SCENES, synthetic_frame
from clpost.stages import _field as fld
from clpost.stages import astigmatism as ast

VOGEL = fld.vogel_disc
PATTERN = "vogel"


def matched_disc(n: int) -> np.ndarray:
    """The n-point Vogel spiral centred and whitened: mean 0, ⟨u uᵀ⟩ = I/4 (a uniform unit disc's)."""
    u = VOGEL(n).astype(np.float64)
    u = u - u.mean(0)
    chol = np.linalg.cholesky(u.T @ u / n)
    return (0.5 * u @ np.linalg.inv(chol).T).astype(np.float32)


@contextlib.contextmanager
def point_pattern():
    """The point classes' spiral (``--pattern``) for the gathers and measures inside the block."""
    if PATTERN == "matched":
        fld.vogel_disc = matched_disc
    try:
        yield
    finally:
        fld.vogel_disc = VOGEL


def point_gather(st, col, *args, n):
    with point_pattern():
        return st._gather(col, *args, own=True, n=n, box=True)


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
            new[pt == n] = point_gather(st, col, *args, n=int(n))[inner][pt == n]
        for n in np.unique(pt[pt > 0]):
            sel = pt == n
            for name, o in (("64 bilinear", old), (f"point p{n}", new)):
                e = np.abs(o - truth)[sel]
                print(f"crop tiles ({ty}, {tx}), p{n} tiles ({sel.sum()} px): {name:12s} rms {np.sqrt((e ** 2).mean()):.3f} "
                      f"p99.9 {np.percentile(e, 99.9):.2f} max {e.max():.2f}")


def disc_axes_px(splat) -> tuple[float, float]:
    """Full axes (sagittal, tangential) in px of a splat read as a uniform ellipse (⟨u²⟩ = ¼ per
    axis) plus bilinear's 1/6 px²: the physical size, whatever spiral made it."""
    m = np.asarray(splat, np.float64)
    m = m / m.sum()
    ys, xs = np.mgrid[0:m.shape[0], 0:m.shape[1]]
    mx, my = (m * xs).sum(), (m * ys).sum()
    vx, vy = (m * (xs - mx) ** 2).sum(), (m * (ys - my) ** 2).sum()
    return 2 * math.sqrt(max(vy - 1 / 6, 0) / 0.25), 2 * math.sqrt(max(vx - 1 / 6, 0) / 0.25)


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
            a_s, a_t, pex, pey = st.semi_axes_px(cam, frame)
            bs, bt, tex, tey, exact, _ = st.tile_plan(cam, frame)
            n = int(st.point_taps(cam, frame, exact)[cy // fld.TILE_H, x0 // fld.TILE_W])
            if n == 0 or exact[cy // fld.TILE_H - 1:cy // fld.TILE_H + 2, x0 // fld.TILE_W - 1:x0 // fld.TILE_W + 2].any():
                continue
            args = [a_s, a_t] + [fld.per_pixel(v, w, h) for v in (bs, bt, tex, tey)]

            def moments(out, taps, measure=None):
                if measure is None:
                    with point_pattern() if taps < 0 else contextlib.nullcontext():
                        got_s, got_t = ast.splat_axes_px(out[..., 1], abs(taps))
                else:
                    got_s, got_t = measure(out[..., 1])
                return got_s / want_s - 1, got_t / want_t - 1, out[..., 1].sum() - 1

            old = moments(st._gather(color, *args, own=True, n=64), 64)
            splat = point_gather(st, color, *args, n=n)
            new = moments(splat, -n)
            disc = moments(splat, n, disc_axes_px)
            own = moments(point_gather(st, color, a_s, a_t, a_s, a_t, pex, pey, n=n), n, disc_axes_px)
            rows.append((n, old, new, disc, own))
            print(f"fc {fc:+.1f} A {a:+.1f} x0 {x0}: axes {want_s:.1f} x {want_t:.1f} px, p{n}; axis and energy "
                  f"errors 64 bilinear {old[0]:+.3f} {old[1]:+.3f} {old[2]:+.3f} | point {new[0]:+.3f} {new[1]:+.3f} "
                  f"{new[2]:+.3f} | disc {disc[0]:+.3f} {disc[1]:+.3f} | own {own[0]:+.3f} {own[1]:+.3f}")
    o, p, d, q = (np.array([r[k] for r in rows]) for k in (1, 2, 3, 4))
    print(f"{len(rows)} highlights: |axis error| 64 bilinear {np.abs(o[:, :2]).min():.3f}-{np.abs(o[:, :2]).max():.3f} "
          f"(mean {np.abs(o[:, :2]).mean():.3f}), point {np.abs(p[:, :2]).min():.3f}-{np.abs(p[:, :2]).max():.3f} "
          f"(mean {np.abs(p[:, :2]).mean():.3f}); |energy error| max {np.abs(o[:, 2]).max():.3f} vs {np.abs(p[:, 2]).max():.3f}")
    print(f"point model, max |axis error| sagittal / tangential: test's measure {np.abs(p[:, 0]).max():.3f} / "
          f"{np.abs(p[:, 1]).max():.3f}, disc measure {np.abs(d[:, 0]).max():.3f} / {np.abs(d[:, 1]).max():.3f}, "
          f"own ellipses (disc measure) {np.abs(q[:, 0]).max():.3f} / {np.abs(q[:, 1]).max():.3f}")


def membership():
    for name, u in (("Vogel 16", VOGEL(16)), ("matched 16", matched_disc(16)), ("Vogel 32", VOGEL(32)),
                    ("matched 32", matched_disc(32)), ("Vogel 64", VOGEL(64))):
        u = u.astype(np.float64)
        cells = []
        for rho in (1.0, 0.97, 0.94, 0.92, 0.90, 0.85):
            m = np.clip(9.0 - 8.0 * (u ** 2).sum(1) / rho ** 2, 0.0, 1.0)
            mean = (m[:, None] * u).sum(0) / m.sum()
            var = (m[:, None] * (u - mean) ** 2).sum(0) / m.sum()
            ax = np.sqrt(var / (rho ** 2 / 4)) - 1  # sagittal u_x, tangential u_y
            cells.append(f"rho {rho:.2f}: s {ax[0]:+.3f} t {ax[1]:+.3f}")
        print(f"{name:10s} " + " | ".join(cells))


def main():
    global PATTERN
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--crops", nargs="*", default=["20,10", "24,53", "40,30"], help="tile row,column of a crop's corner")
    ap.add_argument("--no-crops", action="store_true", help="only the highlights")
    ap.add_argument("--truth-taps", type=int, default=1024)
    ap.add_argument("--point-classes", help="what-if POINT_CLASSES, e.g. 8:16 or 8:32,4:64 (px:taps, largest first)")
    ap.add_argument("--box", type=int, help="what-if POINT_BOX (the shrink follows: 4(k²/12 − 1/6))")
    ap.add_argument("--pattern", choices=("vogel", "matched"), default="vogel",
                    help="the point classes' spiral: Vogel (the kernels') or centred and whitened")
    ap.add_argument("--membership", action="store_true", help="only the kept-taps table (module docstring)")
    a = ap.parse_args()
    if a.membership:
        membership()
        return
    if a.point_classes:
        ast.POINT_CLASSES = tuple((float(px), int(n)) for px, n in (c.split(":") for c in a.point_classes.split(",")))
    if a.box:
        ast.POINT_BOX = a.box
        ast.POINT_SHRINK_PX2 = 4.0 * (a.box * a.box / 12.0 - 1.0 / 6.0)
    PATTERN = a.pattern
    if not a.no_crops:
        crops([tuple(int(v) for v in c.split(",")) for c in a.crops], a.truth_taps)
    highlights()


if __name__ == "__main__":
    main()

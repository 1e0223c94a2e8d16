"""The distortion stage's final filter around HDR highlights (issue 16): the demo scene rendered for
an OpenCV calibration (barrel, tangential) at the extended frustum, resampled at draft (bilinear) and
final; counts the pixels that come out RGB 0 with alpha 1 (black rings around the lamps), values
below / above the least / largest of their 2x2 source samples, one-channel-zero colour specks, and
the energy kept by small HDR spots and lines (box-filtered Gaussians of σ 0–2 px, 1000 on 0.1)
through the numpy oracle; writes crops around the three brightest lamps.

    PYTHONPATH=. python tools/distortion_hdr_check.py --png /tmp/resample16

(measurements: docs/distortion_calibration.md#hdr-safe-final-filter; run it on the parent commit's
checkout for the filter before.)
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from clpost import Camera, Frame, Pipeline
from clpost.calibration import OpenCVModel, required_render
from clpost.stages.distortion import distortion_map, resample, source_intrinsics

MODEL = OpenCVModel(960, 640, 800.0, 805.0, 479.5, 319.5, k1=-0.2, k2=0.05, p1=0.001, p2=-0.002, k3=0.01)


def demo_frame(cache: Path | None) -> Frame:
    spec = required_render(MODEL)
    if cache is not None and cache.exists():
        d = np.load(cache)
        return Frame(d["color"], depth=d["depth"], metadata={"intrinsics": tuple(d["k"])})
    from clpost.render import render_demo_sequence

    frame = render_demo_sequence(Camera(distortion=MODEL), (spec.width, spec.height), 1,
                                 intrinsics=spec.intrinsics())[0]
    if cache is not None:
        np.savez(cache, color=frame.color, depth=frame.depth, k=np.array(spec.intrinsics()))
    return frame


def cell_bounds(plane: np.ndarray, m: np.ndarray, ok: np.ndarray):
    h, w = plane.shape
    x0 = np.floor(np.where(ok, m[0], 0)).astype(np.int64)
    y0 = np.floor(np.where(ok, m[1], 0)).astype(np.int64)
    taps = [plane[np.clip(y0 + j, 0, h - 1), np.clip(x0 + i, 0, w - 1)] for j in (0, 1) for i in (0, 1)]
    return np.minimum.reduce(taps), np.maximum.reduce(taps)


def spot_energy() -> list[str]:
    from scipy.special import erf

    def prof(n, c, s):
        x = np.arange(n)
        if s == 0:
            return ((x - 0.5 < c) & (c <= x + 0.5)).astype(float)
        return 0.5 * (erf((x + 0.5 - c) / (np.sqrt(2) * s)) - erf((x - 0.5 - c) / (np.sqrt(2) * s)))

    rows = []
    for kind in ("spot", "line"):
        for sig in (0.0, 0.3, 0.5, 0.8, 1.2, 2.0):
            got = []
            for dx, dy in ((0.5, 0.5), (0.3, 0.0), (0.25, 0.7)):
                py, px = prof(33, 15.9, sig), prof(33, 16.2, sig)
                img = 0.1 + 1e3 * (np.outer(np.ones(33), px) if kind == "line" else np.outer(py, px))
                yy, xx = np.mgrid[4:29, 4:29].astype(float)
                out = resample(img, np.stack([xx + dx, yy + dy]), 3)
                got.append((out - 0.1).sum() / (img[4:29, 4:29] - 0.1).sum())
            rows.append(f"| {kind} | {sig} | " + " | ".join(f"{g:.3f}" for g in got) + " |")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--png", default=None, help="directory for the lamp crops (draft row, final row)")
    ap.add_argument("--cache", default=None, help="npz cache of the rendered demo frame")
    args = ap.parse_args()
    frame = demo_frame(Path(args.cache) if args.cache else None)
    m, ok = distortion_map(MODEL, frame.size, source_intrinsics(MODEL, frame))
    m = m.astype(np.float32).astype(np.float64)  # the device's positions
    outs = {}
    for q in ("draft", "final"):
        out = Pipeline(Camera(distortion=MODEL), quality=q, stages=["distortion"]).run(frame)
        v = out.color.astype(np.float64)
        outs[q] = v
        black = ok & (v.max(-1) == 0) & (out.alpha == 1)
        below = above = 0
        for c in range(3):
            lo, hi = cell_bounds(frame.color[..., c].astype(np.float64), m, ok)
            tol = 1e-5 * hi + 3e-6 * float(frame.color[..., c].max())
            below += int((ok & (v[..., c] < lo - tol)).sum())
            above += int((ok & (v[..., c] > hi + tol)).sum())
        speck = int((ok & (v.min(-1) == 0) & (v.max(-1) > 0.3)).sum())
        print(f"{q}: RGB 0 with alpha 1: {int(black.sum())}; values below their 2x2 cell: {below}, above: {above}; "
              f"one channel 0 and another > 0.3: {speck}; negative: {int((v < 0).sum())}")
    print("\nenergy kept by HDR spots/lines through the final filter's oracle (sub-pixel shifts (0.5, 0.5), (0.3, 0), (0.25, 0.7)):")
    print("| source | σ px | " + " | ".join(["kept"] * 3) + " |")
    print("\n".join(spot_energy()))
    if args.png:
        from PIL import Image

        lum = outs["final"].sum(-1)
        picked: list[tuple[int, int]] = []
        for k in np.argsort(lum.ravel())[::-1]:
            y, x = divmod(int(k), lum.shape[1])
            if all(abs(y - a) >= 30 or abs(x - b) >= 30 for a, b in picked):
                picked.append((y, x))
            if len(picked) == 3:
                break
        rows = []
        for q in ("draft", "final"):
            tiles = []
            for y, x in picked:
                c = outs[q][max(y - 12, 0):y + 12, max(x - 12, 0):x + 12]
                c = (c / (1 + c)) ** (1 / 2.2)  # Reinhard, then a display gamma: rings stay visible
                tiles.append(np.pad(np.kron(c, np.ones((6, 6, 1))), ((2, 2), (2, 2), (0, 0)), constant_values=1))
            rows.append(np.concatenate(tiles, 1))
        path = Path(args.png) / "distortion_hdr_lamps.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray((np.concatenate(rows, 0) * 255).astype(np.uint8)).save(path)
        print(f"\nlamp crops at {picked} (rows: draft, final): {path}")


if __name__ == "__main__":
    main()

"""What a baked 3D LUT (log2 shaper + N³ lattice, trilinear) would cost in accuracy against
OpenColorIO's own CPU processor, for the ACES 2.0 views of the studio config on held-out HDR
images — the measurement behind previews running OCIO's CPU processor rather than a baked LUT on
the device (docs/measurements.md#ocio-previews).

    .venv/bin/python tools/ocio_lut_error.py [--sizes 33,65,129]
"""
from __future__ import annotations

import argparse

import numpy as np

from clpost.ocio import OcioView

CONFIG = "ocio://studio-config-latest"
VIEWS = [("sRGB - Display", "ACES 2.0 - SDR 100 nits (Rec.709)"),
         ("Rec.2100-PQ - Display", "ACES 2.0 - HDR 1000 nits (P3 D65)"),
         ("sRGB - Display", "Un-tone-mapped")]
LO, HI = -12.0, 10.0
"""Shaper range in stops (log2 of scene-linear ACEScg); values outside are clamped."""


def shaper(x):
    return (np.log2(np.clip(x, 2.0 ** LO, 2.0 ** HI)) - LO) / (HI - LO)


def bake(view, n):
    g = 2.0 ** (LO + (HI - LO) * np.linspace(0.0, 1.0, n))
    lat = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3).astype(np.float32)
    return view.encode(lat, "acescg").reshape(n, n, n, 3).astype(np.float64)


def trilinear(lut, x):
    n = lut.shape[0]
    t = shaper(x) * (n - 1)
    i = np.clip(np.floor(t).astype(int), 0, n - 2)
    f = t - i
    out = 0.0
    for dr in (0, 1):
        for dg in (0, 1):
            for db in (0, 1):
                w = ((f[:, 0] if dr else 1 - f[:, 0]) * (f[:, 1] if dg else 1 - f[:, 1])
                     * (f[:, 2] if db else 1 - f[:, 2]))
                out = out + w[:, None] * lut[i[:, 0] + dr, i[:, 1] + dg, i[:, 2] + db]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="33,65,129")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(42)
    x = 2.0 ** rng.uniform(LO + 1, HI - 1, (200000, 3))
    x[::4] *= rng.random((x[::4].shape[0], 3)) ** 3  # saturated colours
    x = np.clip(x, 2.0 ** LO, None).astype(np.float32)
    for d, v in VIEWS:
        view = OcioView.resolve(CONFIG, d, v)
        exact = np.clip(view.encode(x, "acescg").astype(np.float64), 0.0, 1.0)  # what an image holds
        for n in (int(s) for s in args.sizes.split(",")):
            err = np.abs(np.clip(trilinear(bake(view, n), x.astype(np.float64)), 0.0, 1.0) - exact)
            print(f"{d} / {v}: {n}^3 log2 shaper [{LO:g}, {HI:g}] stops: max |Δ| {err.max():.3g}, "
                  f"99.9th pct {np.quantile(err, 0.999):.3g}, mean {err.mean():.2g}, "
                  f"> 1e-4: {np.mean(err > 1e-4):.1%} of values, > half an 8-bit code: {np.mean(err > 0.5 / 255):.1%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

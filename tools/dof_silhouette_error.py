r"""Where a DoF result's error against a Cycles truth lies by *signed distance to a blurred
foreground's silhouette* (docs/fidelity.md, "Occluder and h_fence at final: the error by distance
to the silhouette"): a finer split of ``tools/occlusion_error.py``'s band.

    PYTHONPATH=. .venv/bin/python tools/dof_silhouette_error.py --scenes occluder \
        [--data tests/data/cycles] [--qualities final] [--out /tmp/dofsil]

The foreground is the pinhole's pixels with thin-lens CoC radius r < −``--fg-px`` (px, signed,
:func:`clpost.fidelity.coc_px` of the Cycles camera, as ``occlusion_error.regions``). Signed distance
d to its silhouette (Euclidean distance transform, −½ px so the two pixels either side of the
silhouette get d in (−1, 0] and (0, 1]): d ≤ 0 inside the foreground, d > 0 outside. The band is
``occlusion_error``'s (band_in ∪ band_out: within |r| + 1 px of the silhouette), split into
distance bins; outside it the foreground's body, the in-focus background (|r| < ``--sharp-px``)
and the defocused rest. Per class: pixels, share of the squared sRGB error, PSNR over its pixels.
Writes ``<out>/<scene>_<quality>_err8.png`` (|error| × 8, sRGB) and ``<out>/<scene>_classes.png``
(red: |d| ≤ 2 px; orange: band inside, |d| > 2; green: band outside, d > 2; purple: body).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parent))

import cycles_compare as cc  # noqa: E402
import occlusion_error as oe  # noqa: E402

from clpost import fidelity as fd  # noqa: E402

BINS = ((-np.inf, -8), (-8, -4), (-4, -2), (-2, -1), (-1, 0), (0, 1), (1, 2), (2, 4), (4, 8), (8, np.inf))


def classes(frame, entry: dict, fg_px: float, sharp_px: float):
    """(name, mask) per class, and the signed distance map."""
    masks = oe.regions(frame, entry, fg_px, sharp_px)
    band = masks["band_in"] | masks["band_out"]
    fg = masks["band_in"] | masks["body"]
    sd = np.where(fg, -(ndimage.distance_transform_edt(fg) - 0.5), ndimage.distance_transform_edt(~fg) - 0.5)
    rows = [(f"band, d in ({lo:g}, {hi:g}] px", band & (sd > lo) & (sd <= hi)) for lo, hi in BINS]
    rows += [("fg body (beyond |r| + 1 px)", masks["body"]),
             (f"background away from fg, |r| < {sharp_px:g}", masks["sharp_bg"]),
             ("the rest (defocused, away from fg)", masks["other"])]
    return rows, sd, fg, band


def table(img, truth, rows):
    e2 = np.sum((fd.srgb_view(img) - fd.srgb_view(truth)) ** 2, axis=-1) / 3.0
    total = float(e2.sum())
    out = []
    for name, m in rows:
        s = float(e2[m].sum())
        out.append((name, int(m.sum()), s / total, 10 * np.log10(m.sum() / s) if s > 0 else float("inf")))
    return 10 * np.log10(e2.size / total), out, e2


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", required=True)
    p.add_argument("--data", default=str(cc.DATA))
    p.add_argument("--qualities", default="final")
    p.add_argument("--out", default="/tmp/dofsil")
    p.add_argument("--fg-px", type=float, default=2.0)
    p.add_argument("--sharp-px", type=float, default=1.5)
    a = p.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    from PIL import Image

    for name in a.scenes.split(","):
        entry, frame, _, truths = cc.load_scene(name, Path(a.data))
        truth = truths["dof"][0]
        rows, sd, fg, band = classes(frame, entry, a.fg_px, a.sharp_px)
        cls = np.zeros(fg.shape + (3,), np.uint8)
        cls[band & (np.abs(sd) <= 2)] = (255, 0, 0)
        cls[band & (np.abs(sd) > 2) & fg] = (255, 160, 0)
        cls[band & (np.abs(sd) > 2) & ~fg] = (0, 200, 0)
        cls[fg & ~band] = (120, 0, 160)
        Image.fromarray(cls).save(out / f"{name}_classes.png")
        for q in a.qualities.split(","):
            img = cc.run_clpost(frame, entry, "dof", q, 0)[0]
            psnr, tab, e2 = table(img, truth, rows)
            Image.fromarray((np.clip(np.sqrt(e2) * 8, 0, 1) * 255 + 0.5).astype(np.uint8)).save(
                out / f"{name}_{q}_err8.png")
            print(f"{name} {q}: PSNR {psnr:.2f}  (class: px, share of squared error, PSNR)")
            for row_name, px, share, ps in tab:
                print(f"  {row_name:42s} {px:7d}  {share:6.3f}  {ps:6.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

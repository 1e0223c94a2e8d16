r"""Where a DoF result's error against a Cycles truth lies, by region of a blurred foreground
(docs/fidelity.md, "Partial occlusion: where the error is").

    PYTHONPATH=. .venv/bin/python tools/occlusion_error.py --scenes occluder \
        [--data tests/data/cycles] [--qualities draft,final] [--out /tmp/occl] [--reference]

Regions, from the pinhole depth and the thin-lens CoC radius r (px, signed, :func:`clpost.fidelity.coc_px`
of the Cycles camera; r < 0 in front of the focus):

- **fg**: pixels of a blurred foreground, r < −``--fg-px``;
- **(a) band**: where the foreground's blurred edge mixes with what is behind it — non-fg pixels
  within |r| + 1 px of a fg pixel (``band_out``: the background is seen in the pinhole) and fg
  pixels within their own |r| + 1 px of a non-fg pixel (``band_in``: the background behind them is
  hidden in the pinhole);
- **(b) body**: fg pixels deeper inside than that;
- **(c) sharp bg**: the rest with |r| < ``--sharp-px`` (in-focus background away from any fg);
- **(d) other**: everything else (a blurred background, mid-ground).

For each region: its pixels, its share of the squared sRGB error and its PSNR (over its own
pixels). Writes per quality a 4× crop sheet ``<out>/<scene>_<quality>_err.png`` (pinhole | Cycles |
result | |error| × 4) around the fg's worst error, and the region map ``<out>/<scene>_regions.png``.
``--reference``: the numpy reference (:func:`clpost.stages.dof.dof_reference`) instead of the
OpenCL pipeline (slow; what experiments in the reference are measured with).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parent))

import cycles_compare as cc  # noqa: E402

from clpost import fidelity as fd  # noqa: E402

REGIONS = ("band_out", "band_in", "body", "sharp_bg", "other")


def regions(frame, entry: dict, fg_px: float, sharp_px: float) -> dict[str, np.ndarray]:
    shot = entry["shot"]
    w = entry["size"][0]
    depth = np.where(np.isfinite(frame.depth), frame.depth, 1e10)
    r = fd.coc_px(depth, shot["focus_m"], shot["focal_mm"], shot["f_number"], shot["sensor_mm"], w) / 2
    r = np.where(depth < shot["focus_m"], -r, r)
    fg = r < -fg_px
    d_out, idx = ndimage.distance_transform_edt(~fg, return_indices=True)
    r_near = np.abs(r[idx[0], idx[1]])
    band_out = ~fg & (d_out <= r_near + 1)
    d_in = ndimage.distance_transform_edt(fg)
    band_in = fg & (d_in <= np.abs(r) + 1)
    body = fg & ~band_in
    sharp_bg = ~fg & ~band_out & (np.abs(r) < sharp_px)
    other = ~(band_out | band_in | body | sharp_bg)
    return {"band_out": band_out, "band_in": band_in, "body": body, "sharp_bg": sharp_bg, "other": other}


def decompose(img, truth, masks) -> dict:
    e2 = np.sum((fd.srgb_view(img) - fd.srgb_view(truth)) ** 2, axis=-1) / 3.0
    total = float(e2.sum())
    rows = {"all": {"px": int(e2.size), "share": 1.0, "psnr": float(10 * np.log10(e2.size / total))}}
    for k in REGIONS:
        m = masks[k]
        s = float(e2[m].sum())
        rows[k] = {"px": int(m.sum()), "share": s / total,
                   "psnr": float(10 * np.log10(m.sum() / s)) if s > 0 else float("inf")}
    return rows


def crop_box(masks, err, size=(64, 96)):
    """A (y0, y1, x0, x1) window around the worst error in the foreground's band."""
    band = masks["band_in"] | masks["band_out"]
    if not band.any():
        band = np.ones_like(band)
    e = ndimage.uniform_filter(np.where(band, err, 0.0), 15)
    y, x = np.unravel_index(np.argmax(e), e.shape)
    h, w = err.shape
    y0 = int(np.clip(y - size[0] // 2, 0, h - size[0]))
    x0 = int(np.clip(x - size[1] // 2, 0, w - size[1]))
    return y0, y0 + size[0], x0, x0 + size[1]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", required=True)
    p.add_argument("--data", default=str(cc.DATA))
    p.add_argument("--qualities", default="draft,final")
    p.add_argument("--out", default="/tmp/occl")
    p.add_argument("--fg-px", type=float, default=2.0)
    p.add_argument("--sharp-px", type=float, default=1.5)
    p.add_argument("--reference", action="store_true")
    p.add_argument("--json", default=None, help="write the numbers here")
    a = p.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    data = Path(a.data)
    result = {}
    for name in a.scenes.split(","):
        entry, frame, _, truths = cc.load_scene(name, data)
        truth = truths["dof"][0]
        masks = regions(frame, entry, a.fg_px, a.sharp_px)
        pin = frame.color[..., :3]
        result[name] = {"pinhole": decompose(pin, truth, masks)}
        imgs = {}
        for q in a.qualities.split(","):
            if a.reference:
                from clpost.stages.dof import dof_reference

                cam = fd.cycles_camera(entry["shot"], *entry["size"])
                img = dof_reference(cam, np.asarray(frame.color[..., :3], np.float64), frame.depth, q).astype(np.float32)
            else:
                img = cc.run_clpost(frame, entry, "dof", q, 0)[0]
            imgs[q] = img
            result[name][q] = decompose(img, truth, masks)
        _pictures(out, name, pin, truth, imgs, masks)
        print(f"{name}: region px / share of squared error / PSNR")
        for img_name, rows in result[name].items():
            cells = "  ".join(f"{k} {rows[k]['px']} {rows[k]['share']:.3f} {rows[k]['psnr']:.2f}"
                              for k in ("all",) + REGIONS)
            print(f"  {img_name:8s} {cells}")
    if a.json:
        Path(a.json).write_text(json.dumps(result, indent=1))
    return 0


def _pictures(out: Path, name: str, pin, truth, imgs: dict, masks) -> None:
    from PIL import Image

    colours = {"band_out": (255, 160, 0), "band_in": (255, 0, 0), "body": (120, 0, 160),
               "sharp_bg": (0, 160, 255), "other": (60, 60, 60)}
    rgb = np.zeros(masks["other"].shape + (3,), np.uint8)
    for k, c in colours.items():
        rgb[masks[k]] = c
    view = (fd.srgb_view(pin) * 255).astype(np.uint8)
    Image.fromarray((0.5 * rgb + 0.5 * view).astype(np.uint8)).save(out / f"{name}_regions.png")
    for q, img in imgs.items():
        err = np.abs(fd.srgb_view(img) - fd.srgb_view(truth)).mean(-1)
        y0, y1, x0, x1 = crop_box(masks, err)
        panels = [fd.srgb_view(pin), fd.srgb_view(truth), fd.srgb_view(img), np.repeat(np.clip(err * 4, 0, 1)[..., None], 3, -1)]
        tiles = [(pn[y0:y1, x0:x1] * 255 + 0.5).astype(np.uint8) for pn in panels]
        gap = np.full((y1 - y0, 2, 3), 255, np.uint8)
        row = np.concatenate(sum(([t, gap] for t in tiles), [])[:-1], axis=1)
        Image.fromarray(row).resize((row.shape[1] * 4, row.shape[0] * 4), Image.NEAREST).save(
            out / f"{name}_{q}_err.png")
        full = np.concatenate([panels[1], panels[2], panels[3]], axis=1)
        Image.fromarray((full * 255 + 0.5).astype(np.uint8)).save(out / f"{name}_{q}_full_err.png")
        print(f"  crop {name} {q}: y {y0}:{y1} x {x0}:{x1}")


if __name__ == "__main__":
    raise SystemExit(main())

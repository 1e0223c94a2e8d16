"""The before/after figure and numbers of docs/labels.md: a synthetic render with an instance-id
pass and COCO boxes/keypoints, through a fisheye calibration's distortion stage and `map_coco`.

    .venv/bin/python tools/labels_figure.py [OUT.png]   (from the repository root; default
    docs/figures/labels_before_after.png)

Prints: how many output ids a bilinear resampling of the id pass would invent (values in no source
pixel) against the stage's nearest rule, and the mapped box against its corners-only box.
"""
import sys
import warnings
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw
from scipy.ndimage import map_coordinates

from clpost import Camera, Frame, Pipeline
from clpost.calibration import OpenCVModel, required_render
from clpost.labels import map_coco
from clpost.labels.coco import Mapping, map_points
from clpost.stages.distortion import distortion_map

OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("docs/figures/labels_before_after.png")
MODEL = OpenCVModel(320, 240, 160, 160, 159.5, 119.5, k1=0.04, k2=-0.01, distortion_model="fisheye")
spec = required_render(MODEL)
W, H = spec.width, spec.height
K = spec.intrinsics()

# the scene: boxes and discs with ids 1..n on a background 0, colour per id, 4x4 supersampled colour
SHAPES = [("box", (0.10, 0.15, 0.35, 0.45)), ("disc", (0.62, 0.30, 0.12)), ("box", (0.45, 0.60, 0.92, 0.85)),
          ("disc", (0.25, 0.75, 0.10)), ("box", (0.70, 0.05, 0.95, 0.20)), ("disc", (0.50, 0.40, 0.06))]
rng = np.random.default_rng(7)
PALETTE = np.vstack([[0.05, 0.05, 0.06], rng.uniform(0.15, 0.95, (len(SHAPES), 3))])


def ids_at(x, y):
    out = np.zeros(x.shape, np.uint32)
    for i, (kind, p) in enumerate(SHAPES, 1):
        u, v = x / W, y / H
        inside = ((u >= p[0]) & (u <= p[2]) & (v >= p[1]) & (v <= p[3])) if kind == "box" else (
            np.hypot((u - p[0]) * W / H, v - p[1]) <= p[2])
        out[inside] = i
    return out


yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
ids = ids_at(xx, yy)
ss = np.mean([PALETTE[ids_at(xx + dx, yy + dy)] for dx in (-0.375, -0.125, 0.125, 0.375)
              for dy in (-0.375, -0.125, 0.125, 0.375)], axis=0)
grid = ((np.floor(xx / 12) + np.floor(yy / 12)) % 2)[..., None] * 0.08
color = (ss + grid).astype(np.float32)
frame = Frame(color, labels={"id": ids}, metadata={"intrinsics": K})
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    out = Pipeline(Camera(distortion=MODEL), stages=["distortion"]).run(frame)

# the naive alternative: ids resampled bilinearly (what a colour path would do)
pos, ok = distortion_map(MODEL, (W, H), K)
bil = map_coordinates(ids.astype(np.float64), [np.where(ok, pos[1], 0), np.where(ok, pos[0], 0)], order=1)
new_value = np.abs(bil - np.rint(bil)) > 1e-6  # between two ids (rounding error of a flat area is not)
invented = int(np.count_nonzero(ok & new_value))
non_source = int(np.count_nonzero(ok & ~np.isin(out.labels["id"], np.unique(ids))))
print(f"render {W}x{H} -> {MODEL.width}x{MODEL.height}: bilinear ids invent {invented} values not in the source "
      f"(of {int(ok.sum())} pixels); the stage's nearest ids: {non_source}")

# COCO: one box and keypoints per shape, in the render
anns = []
for i, (kind, p) in enumerate(SHAPES, 1):
    if kind == "box":
        b = [p[0] * W, p[1] * H, (p[2] - p[0]) * W, (p[3] - p[1]) * H]
    else:
        r = p[2] * H
        b = [p[0] * W - r, p[1] * H - r, 2 * r, 2 * r]
    kp = [b[0] + b[2] / 2 - 0.5, b[1] + b[3] / 2 - 0.5, 2, b[0] - 0.5, b[1] - 0.5, 2]
    anns.append({"id": i, "image_id": 1, "category_id": 1, "bbox": b, "area": b[2] * b[3], "keypoints": kp,
                 "num_keypoints": 2})
coco = {"images": [{"id": 1, "width": W, "height": H}], "annotations": anns, "categories": [{"id": 1, "name": "s"}]}
mapped, rep = map_coco(coco, lambda w, h: Mapping(MODEL, K))
print(rep)
mp = Mapping(MODEL, K)
worst = 0.0
for a, m in zip(anns, mapped["annotations"]):
    x, y, w, h = a["bbox"]
    u, v, vis = map_points(mp, np.array([x, x + w, x + w, x]) - 0.5, np.array([y, y, y + h, y + h]) - 0.5)
    if vis.all():
        corners = [u.min() + 0.5, v.min() + 0.5, u.max() + 0.5, v.max() + 0.5]
        mb = m["bbox"]
        worst = max(worst, max(abs(corners[0] - mb[0]), abs(corners[1] - mb[1]), abs(corners[2] - mb[0] - mb[2]),
                               abs(corners[3] - mb[1] - mb[3])))
print(f"largest difference between the mapped box and the box of its mapped corners: {worst:.2f} px")


def srgb(c):
    c = np.clip(c, 0, 1)
    return (np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055) * 255 + 0.5).astype(np.uint8)


def id_image(a):
    return srgb(PALETTE[np.minimum(np.rint(a).astype(int), len(PALETTE) - 1)] * (1 + 0 * a[..., None]))


def boxes(img, annotations, colour, scale=1):
    im = Image.fromarray(img)
    d = ImageDraw.Draw(im)
    for a in annotations:
        x, y, w, h = (scale * t for t in a["bbox"])
        d.rectangle([x, y, x + w - 1, y + h - 1], outline=colour)
        k = np.array(a["keypoints"]).reshape(-1, 3)
        for px, py, vv in k:
            if vv > 0:
                px, py = scale * (px + 0.5), scale * (py + 0.5)
                d.ellipse([px - 3, py - 3, px + 3, py + 3], outline=(255, 255, 255))
    return np.asarray(im)


def up(img, s=2):
    return np.repeat(np.repeat(img, s, 0), s, 1)


def titled(img, text):
    im = Image.fromarray(np.vstack([np.full((16, img.shape[1], 3), 255, np.uint8), img]))
    ImageDraw.Draw(im).text((4, 2), text, fill=(0, 0, 0))
    return np.asarray(im)


def pad(img, w, h):
    out = np.full((h, w, 3), 255, np.uint8)
    out[:img.shape[0], :img.shape[1]] = img
    return out


bil_img = id_image(bil)
bil_img[ok & new_value] = (255, 0, 255)
panels = [
    [titled(boxes(srgb(color), anns, (255, 255, 0)), f"render {W}x{H}: colour, COCO boxes + keypoints"),
     titled(id_image(ids.astype(float)), "render: instance ids (false colour)"), None],
    [titled(boxes(up(srgb(out.color)), mapped["annotations"], (255, 255, 0), 2),
            f"fisheye {MODEL.width}x{MODEL.height} (x2): map_coco boxes + keypoints"),
     titled(up(id_image(out.labels["id"].astype(float))), "ids through distortion: nearest, 0 invented"),
     titled(up(bil_img), f"ids bilinear (not clpost): {invented} invented (magenta)")]]
cw = max(p.shape[1] for r in panels for p in r if p is not None) + 6
rows = []
for r in panels:
    rh = max(p.shape[0] for p in r if p is not None)
    rows.append(np.hstack([pad(p if p is not None else np.full((1, 1, 3), 255, np.uint8), cw, rh) for p in r]))
OUT.parent.mkdir(parents=True, exist_ok=True)
Image.fromarray(np.vstack([rows[0], np.full((6, rows[0].shape[1], 3), 255, np.uint8), rows[1]])).save(OUT)
print(f"wrote {OUT}")

r"""COCO annotations mapped from the undistorted render into the distorted image, exactly.

A point of the render at pixel s (OpenCV pixel centres, ``docs/conventions.md``) is the ray of
undistorted normalised coordinates :math:`x' = (s_x - c_{r,x})/f_{r,x}`, :math:`y' = (s_y -
c_{r,y})/f_{r,y}` (the render's pinhole intrinsics), which the camera's **forward** model puts at
:math:`(u, v) = \mathrm{project}(x', y')` — ``OpenCVModel.project``, i.e. ``cv2.projectPoints`` /
``cv2.fisheye.distortPoints`` (checked in ``tests/test_labels.py``); no inverse, no resampling.
The point is **visible** when the distortion stage shows it there: (u, v) lies in the image
([−½, W − ½] × [−½, H − ½]) and the stage's inverse at (u, v) returns the same ray (to 10⁻³ px in
the render) — beyond a model's fold radius two rays meet at one pixel and the image shows only the
inner one.

COCO's coordinates (Lin et al., "Microsoft COCO", 2014; cocodataset.org "Data format"):

* ``keypoints`` [x₁, y₁, v₁, …] are pixel indices (pixel centres, as OpenCV's): mapped as points;
  one that is not visible becomes (0, 0, 0), COCO's "not labelled"; ``num_keypoints`` is recounted.
* ``bbox`` [x, y, w, h] and polygon ``segmentation`` are continuous coordinates with the image's
  top-left *corner* at (0, 0): shifted by −½ into pixel centres, mapped, shifted back. A box
  becomes the bounding box of its mapped **boundary** — every edge sampled at ≤ ¼ render px (at
  least 16 samples), not its four corners: a distortion bows edges, so the extreme of a mapped edge
  lies between corners — clipped to the image [0, W] × [0, H]; for a homeomorphism the mapped
  boundary bounds the mapped region, so this is the box of the mapped object. Polygon edges are
  densified the same way before mapping. Samples that are not visible are left out; an annotation
  with no visible sample, or an empty clipped box, is dropped (counted).
* ``area``: the shoelace area of the mapped polygons when there are any, else the original area
  scaled by the ratio of the mapped box's area to the original box's.
* RLE ``segmentation`` (crowd masks) cannot be mapped as geometry: it is removed (counted); carry
  masks as a label channel through the image stages instead (``--labels``).

``images[].width/height`` become the calibration's; everything else is copied unchanged.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import InputError

STEP_PX = 0.25
"""Largest spacing (render px) of the samples along a box edge or polygon edge."""
MIN_SAMPLES = 16
"""Fewest samples per box edge."""
ROUND_TRIP_PX = 1e-3
"""Largest distance (render px) between a point and the stage's inverse of its image for it to
count as visible."""


@dataclass(frozen=True)
class Mapping:
    """What maps render pixels to image pixels: the camera's ``model`` (the one the distortion stage
    renders, ``--fill crop``'s magnification included) and the render's pinhole intrinsics ``src_k``
    (f_x, f_y, c_x, c_y)."""

    model: object
    src_k: tuple[float, float, float, float]


def map_points(mapping: Mapping, sx, sy) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Render pixels (s_x, s_y) → image pixels (u, v) and whether each is visible (module docstring)."""
    from ..calibration import undistort

    m = mapping.model
    fx, fy, cx, cy = mapping.src_k
    x = (np.asarray(sx, np.float64) - cx) / fx
    y = (np.asarray(sy, np.float64) - cy) / fy
    u, v = m.project(x, y)
    inside = np.isfinite(u) & np.isfinite(v) & (u >= -0.5) & (u <= m.width - 0.5) & (v >= -0.5) & (v <= m.height - 0.5)
    exact = replace(m, inverse="newton") if getattr(m, "inverse", "newton") != "newton" else m
    xb, yb, ok = undistort(exact, np.where(inside, u, m.cx), np.where(inside, v, m.cy))
    back = np.hypot((xb - x) * fx, (yb - y) * fy)
    return u, v, inside & ok & (back <= ROUND_TRIP_PX)


def _densify(xs: np.ndarray, ys: np.ndarray, closed: bool = True, min_n: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Points along the polyline (closed: back to the start) at ≤ :data:`STEP_PX` spacing."""
    x1, y1 = (np.roll(xs, -1), np.roll(ys, -1)) if closed else (xs[1:], ys[1:])
    x0, y0 = (xs, ys) if closed else (xs[:-1], ys[:-1])
    outx, outy = [], []
    for a, b, c, d in zip(x0, y0, x1, y1):
        n = max(min_n, math.ceil(math.hypot(c - a, d - b) / STEP_PX))
        t = np.arange(n) / n
        outx.append(a + (c - a) * t)
        outy.append(b + (d - b) * t)
    if not closed and len(xs):
        outx.append(xs[-1:])
        outy.append(ys[-1:])
    return (np.concatenate(outx), np.concatenate(outy)) if outx else (xs, ys)


def map_box(mapping: Mapping, box) -> list[float] | None:
    """COCO [x, y, w, h] → the mapped box (module docstring), or None when nothing of it is visible."""
    x, y, w, h = (float(t) for t in box)
    cx = np.array([x, x + w, x + w, x]) - 0.5
    cy = np.array([y, y, y + h, y + h]) - 0.5
    sx, sy = _densify(cx, cy, closed=True, min_n=MIN_SAMPLES)
    u, v, vis = map_points(mapping, sx, sy)
    if not vis.any():
        return None
    m = mapping.model
    x0, x1 = np.clip([u[vis].min() + 0.5, u[vis].max() + 0.5], 0, m.width)
    y0, y1 = np.clip([v[vis].min() + 0.5, v[vis].max() + 0.5], 0, m.height)
    if x1 <= x0 or y1 <= y0:
        return None
    return [float(x0), float(y0), float(x1 - x0), float(y1 - y0)]


def _shoelace(px: np.ndarray, py: np.ndarray) -> float:
    return 0.5 * abs(float(np.dot(px, np.roll(py, -1)) - np.dot(py, np.roll(px, -1))))


def map_polygon(mapping: Mapping, poly) -> list[float] | None:
    """A COCO polygon [x₁, y₁, …] (continuous coordinates) → its mapped, densified polygon
    (visible samples only), or None when fewer than 3 are visible."""
    p = np.asarray(poly, np.float64).reshape(-1, 2) - 0.5
    sx, sy = _densify(p[:, 0], p[:, 1], closed=True)
    u, v, vis = map_points(mapping, sx, sy)
    if vis.sum() < 3:
        return None
    return np.stack([u[vis] + 0.5, v[vis] + 0.5], -1).ravel().tolist()


def map_keypoints(mapping: Mapping, kps) -> list[float]:
    """COCO keypoints [x, y, v, …] → mapped; not visible (or v = 0 already) → 0, 0, 0."""
    k = np.asarray(kps, np.float64).reshape(-1, 3)
    u, v, vis = map_points(mapping, k[:, 0], k[:, 1])
    keep = vis & (k[:, 2] > 0)
    out = np.stack([np.where(keep, u, 0.0), np.where(keep, v, 0.0), np.where(keep, k[:, 2], 0.0)], -1)
    return [float(t) if i % 3 != 2 else int(t) for i, t in enumerate(out.ravel())]


@dataclass
class MapReport:
    """What :func:`map_coco` did, for the command's one-line summary."""

    annotations: int = 0
    dropped: list = field(default_factory=list)
    rle_removed: int = 0
    keypoints_hidden: int = 0

    def __str__(self) -> str:
        text = f"{self.annotations} annotation(s) mapped"
        if self.dropped:
            text += f", {len(self.dropped)} dropped (nothing visible in the distorted image: ids {self.dropped[:10]}" \
                    f"{' …' if len(self.dropped) > 10 else ''})"
        if self.keypoints_hidden:
            text += f", {self.keypoints_hidden} keypoint(s) now outside the image (v=0)"
        if self.rle_removed:
            text += f", RLE segmentation removed from {self.rle_removed} (carry masks with --labels)"
        return text


def _where(src: str, what: str) -> str:
    return f"{src}: {what}" if src else what


def map_coco(data: dict, mapping_for, source: str = "") -> tuple[dict, MapReport]:
    """A COCO dict → the same dataset in the distorted image (module docstring). ``mapping_for(width,
    height)`` gives the :class:`Mapping` of an image of that render size (raising InputError for a
    size it cannot place)."""
    if not isinstance(data, dict) or not isinstance(data.get("images"), list) or not isinstance(
            data.get("annotations", []), list):
        raise InputError(_where(source, "not a COCO file (needs an 'images' list and an 'annotations' list)"))
    out = copy.deepcopy(data)
    maps = {}
    for im in out["images"]:
        try:
            iid, w, h = im["id"], int(im["width"]), int(im["height"])
        except (KeyError, TypeError, ValueError):
            raise InputError(_where(source, f"image {im.get('id', '?') if isinstance(im, dict) else im!r} needs "
                                            "'id', 'width' and 'height'")) from None
        try:
            mp = mapping_for(w, h)
        except InputError as exc:
            raise InputError(_where(source, f"image {iid}: {exc}")) from None
        maps[iid] = mp
        im["width"], im["height"] = mp.model.width, mp.model.height
    rep = MapReport()
    kept = []
    for ann in out.get("annotations", []):
        aid = ann.get("id", "?") if isinstance(ann, dict) else "?"
        if not isinstance(ann, dict) or ann.get("image_id") not in maps:
            raise InputError(_where(source, f"annotation {aid}: its image_id is not in 'images'"))
        mp = maps[ann["image_id"]]
        try:
            old_box = ann.get("bbox")
            polys = None
            seg = ann.get("segmentation")
            if isinstance(seg, list):
                polys = [q for q in (map_polygon(mp, p) for p in seg) if q is not None]
                ann["segmentation"] = polys
            elif seg is not None:
                del ann["segmentation"]
                rep.rle_removed += 1
            if "keypoints" in ann:
                before = sum(1 for i in range(2, len(ann["keypoints"]), 3) if ann["keypoints"][i] > 0)
                ann["keypoints"] = map_keypoints(mp, ann["keypoints"])
                ann["num_keypoints"] = sum(1 for i in range(2, len(ann["keypoints"]), 3) if ann["keypoints"][i] > 0)
                rep.keypoints_hidden += before - ann["num_keypoints"]
            if old_box is not None:
                box = map_box(mp, old_box)
                if box is None:
                    rep.dropped.append(aid)
                    continue
                ann["bbox"] = box
                if polys:
                    ann["area"] = float(sum(_shoelace(np.asarray(q[0::2]), np.asarray(q[1::2])) for q in polys))
                elif "area" in ann and old_box[2] * old_box[3] > 0:
                    ann["area"] = float(ann["area"]) * box[2] * box[3] / (float(old_box[2]) * float(old_box[3]))
        except (TypeError, ValueError, IndexError) as exc:
            raise InputError(_where(source, f"annotation {aid}: malformed bbox/keypoints/segmentation ({exc}); "
                                            "COCO's bbox is [x, y, w, h], keypoints [x, y, v, …]")) from None
        kept.append(ann)
        rep.annotations += 1
    out["annotations"] = kept
    return out, rep

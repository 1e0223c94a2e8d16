"""Instance ids carried through the distortion stage against ids ray-cast directly in the distorted
image (docs/labels.md, "Against ray-cast ids"): the demo scene rendered as a pinhole at the
calibration's `required_render` frustum (PyVistaRenderer, its object-id buffer as a label plane),
distorted by clpost, compared pixel by pixel with `render_reference` — every output pixel's own
undistorted ray cast into the analytic scene (an independent path: no resampling at all).

    .venv/bin/python tools/labels_vs_raycast.py [OUT.png]   (from the repository root)

Prints the share of valid pixels whose id agrees, how far the disagreeing pixels are from an id
boundary of the reference, and how many ids a bilinear resampling of the id buffer would invent.
The first model has no distortion: the baseline disagreement of the rasteriser and the ray cast.
"""
import sys
import warnings
from pathlib import Path

import numpy as np
from scipy.ndimage import distance_transform_edt, map_coordinates

from clpost import Camera, Frame, Pipeline
from clpost.calibration import OpenCVModel, required_render
from clpost.render.demo_scene import DemoScene
from clpost.render.geometry_distortion import render_reference
from clpost.render.pyvista_renderer import PyVistaRenderer
from clpost.stages.distortion import distortion_map

OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else None
MODELS = {"none (baseline: rasteriser vs ray cast)": OpenCVModel(480, 320, 400, 400, 239.5, 159.5, p1=1e-12),
          "barrel": OpenCVModel(480, 320, 400, 400, 239.5, 159.5, k1=-0.3, k2=0.1, p1=0.002),
          "pincushion": OpenCVModel(480, 320, 400, 400, 239.5, 159.5, k1=0.2, k2=0.05)}
scene = DemoScene.default()
cam = Camera()
warnings.simplefilter("ignore")
for name, model in MODELS.items():
    spec = required_render(model)
    k = spec.intrinsics()
    r = PyVistaRenderer(scene)
    try:
        src = r.render(cam, (spec.width, spec.height), 0, intrinsics=k)
    finally:
        r.close()
    ids = np.asarray(src.metadata["object_id"], np.int32)
    frame = Frame(src.color, depth=src.depth, labels={"object_id": ids}, metadata={"intrinsics": k})
    out = Pipeline(Camera(distortion=model), stages=["distortion"]).run(frame)
    ref = render_reference(scene, model, 0)
    rid = np.asarray(ref.metadata["object_id"], np.int32)
    ok = (out.alpha > 0) & (ref.alpha > 0)
    got = out.labels["object_id"]
    agree = (got == rid) & ok
    # distance (px) of each pixel from the nearest reference pixel that touches another id (0: it does)
    edge = np.zeros(rid.shape, bool)
    edge[:, 1:] |= rid[:, 1:] != rid[:, :-1]
    edge[:, :-1] |= rid[:, 1:] != rid[:, :-1]
    edge[1:] |= rid[1:] != rid[:-1]
    edge[:-1] |= rid[1:] != rid[:-1]
    dist = distance_transform_edt(~edge)
    bad = ok & ~agree
    pos, okm = distortion_map(model, frame.size, k)
    bil = map_coordinates(ids.astype(np.float64), [np.where(okm, pos[1], 0), np.where(okm, pos[0], 0)], order=1)
    invented = ok & (np.abs(bil - np.rint(bil)) > 1e-6)
    print(f"{name}: render {spec.width}x{spec.height} -> {model.width}x{model.height}; nearest ids agree with the "
          f"ray-cast ids on {100 * agree.sum() / ok.sum():.3f} % of {int(ok.sum())} pixels; the {int(bad.sum())} "
          f"others lie within {dist[bad].max() if bad.any() else 0:.2f} px of a reference pixel touching another id "
          f"({100 * np.mean(dist[bad] <= 1.0) if bad.any() else 100:.1f} % at 1 px); ids invented: {int(np.count_nonzero(~np.isin(got[ok], ids)))}"
          f" (bilinear ids: {int(invented.sum())} invented)")
    if OUT is not None and name == "barrel":
        from PIL import Image

        pal = np.random.default_rng(3).uniform(0.2, 1.0, (ids.max() + 2, 3))
        pal[0] = 0.08

        def show(a):
            return (pal[np.clip(a, -1, None) + 1] * 255).astype(np.uint8)

        diff = np.zeros(rid.shape + (3,), np.uint8)
        diff[ok] = 40
        diff[bad] = (255, 0, 255)
        c = np.clip(src.color / np.percentile(src.color, 99), 0, 1) ** (1 / 2.2)
        d = np.clip(out.color / np.percentile(src.color, 99), 0, 1) ** (1 / 2.2)
        pad = np.full((spec.height, 6, 3), 255, np.uint8)
        top = np.hstack([(c * 255).astype(np.uint8), pad, show(ids)])
        h2 = model.height
        row = [(d * 255).astype(np.uint8), show(got), show(rid), diff]
        bottom = np.hstack(sum(([p, np.full((h2, 6, 3), 255, np.uint8)] for p in row), [])[:-1])
        wmax = max(top.shape[1], bottom.shape[1])
        canvas = np.full((top.shape[0] + 6 + h2, wmax, 3), 255, np.uint8)
        canvas[:top.shape[0], :top.shape[1]] = top
        canvas[top.shape[0] + 6:, :bottom.shape[1]] = bottom
        Image.fromarray(canvas).save(OUT)
        print(f"wrote {OUT}")

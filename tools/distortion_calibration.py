"""Verify the distortion stage as Lambers, Sommerhoff & Kolb did: render checkerboards, distort
them with known OpenCV parameters, calibrate with OpenCV, compare.

For each parameter set (barrel, pincushion, tangential): N views of a 14×10-square board
(13×9 inner corners) in varied poses are rendered by the pyvista renderer at the extended frustum
of :func:`clpost.calibration.required_render` (no unfilled pixels), distorted by the clpost
pipeline (``--stages distortion``, final = bicubic), and fed to ``cv2.findChessboardCorners`` +
``cornerSubPix`` + ``cv2.calibrateCamera`` (k3 fixed at 0, as the paper). Also reports the
residuals of both inverses and the round trip distort → ``cv2.undistort`` vs a direct render.

    PYTHONPATH=. /tmp/venv/bin/python tools/distortion_calibration.py --views 17 --size 800x600 \
        --png /tmp/distortion_check
"""
from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace

import numpy as np

from clpost import Camera, Pipeline
from clpost.calibration import OpenCVModel, inverse_residual_px, required_render
from clpost.render import DemoScene, PyVistaRenderer
from clpost.render.demo_scene import Material, Plane, RigidMotion, SceneObject

SQUARES = (14, 10)
SQUARE_M = 0.035
PATTERN = (SQUARES[0] - 1, SQUARES[1] - 1)


def parameter_sets(size: tuple[int, int]) -> dict[str, OpenCVModel]:
    w, h = size
    s = w / 800.0
    base = dict(width=w, height=h, fx=820.0 * s, fy=815.0 * s, cx=405.3 * s, cy=296.8 * s)
    return {
        "barrel": OpenCVModel(**base, k1=-0.25, k2=0.08),
        "pincushion": OpenCVModel(**base, k1=0.2, k2=0.05),
        "tangential": OpenCVModel(**base, k1=-0.1, k2=0.02, p1=0.004, p2=-0.003),
    }


def board_scene(view: int, n_views: int, model: OpenCVModel | None = None) -> DemoScene:
    """The board in the world xy plane (z up), seen from view ``view`` of ``n_views``: azimuth
    around the board, elevation 40–75°, distance 0.65–0.95 m and a look-at point off the board's
    centre so the board reaches every part of the image (distortion is largest at the edges).
    With ``model``, poses whose board (plus half a square) would leave the image are redrawn."""
    board = SceneObject("board", Plane(0.36), Material(albedo=(0.9, 0.9, 0.9), albedo2=(0.04, 0.04, 0.04),
                                                       texture="board", texture_scale_m=SQUARE_M,
                                                       board_squares=SQUARES), casts_shadow=False)
    rng = np.random.default_rng(1000 + view)
    hx, hy = (0.5 * SQUARES[0] + 0.5) * SQUARE_M, (0.5 * SQUARES[1] + 0.5) * SQUARE_M
    corners = np.array([[sx * hx, sy * hy, 0.0] for sx in (-1, 1) for sy in (-1, 1)])
    for _ in range(200):
        az = 2 * math.pi * view / n_views + rng.uniform(-0.3, 0.3)
        el = math.radians(rng.uniform(40, 75))
        dist = rng.uniform(0.65, 0.95)
        target = np.array([rng.uniform(-0.2, 0.2), rng.uniform(-0.15, 0.15), 0.0])
        pos = target + dist * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        cam = RigidMotion.camera(tuple(pos), tuple(target - pos))
        if model is None:
            break
        rot = cam.matrix(0)[:3, :3]
        xc = (corners - pos) @ rot
        u, v = model.project(xc[:, 0] / xc[:, 2], xc[:, 1] / xc[:, 2])
        if u.min() > 5 and v.min() > 5 and u.max() < model.width - 6 and v.max() < model.height - 6:
            break
    return DemoScene(objects=(board,), camera_motion=cam, sun_direction=(0.0, 0.0, 1.0), sun_irradiance=1.0,
                     ambient=0.3, emitter_lighting=False)


def render_views(model: OpenCVModel, n_views: int, supersample: int = 1):
    """(undistorted renders at the extended frustum, distorted outputs) for ``n_views`` poses."""
    spec = required_render(model)
    cam = Camera(distortion=model)
    pipe = Pipeline(cam, quality="final", stages=["distortion"])
    renderer = PyVistaRenderer(board_scene(0, n_views), supersample=supersample)
    raw, out = [], []
    try:
        for v in range(n_views):
            # the VTK actors depend only on the objects, identical in every view: swap the scene
            renderer.scene = board_scene(v, n_views, model)
            f = renderer.render(cam, (spec.width, spec.height), 0, spec.intrinsics())
            raw.append(f)
            out.append(pipe.run(f))
    finally:
        renderer.close()
    return raw, out


def to_gray8(color: np.ndarray) -> np.ndarray:
    y = color @ np.array([0.2126, 0.7152, 0.0722])
    return np.clip(np.rint(y / max(float(y.max()), 1e-6) * 255), 0, 255).astype(np.uint8)


def calibrate(frames, size) -> tuple[dict, int, float]:
    """cv2.calibrateCamera on the detected corners: (estimates, views used, RMS reprojection px)."""
    import cv2

    objp = np.zeros((PATTERN[0] * PATTERN[1], 3), np.float32)
    objp[:, :2] = np.mgrid[0:PATTERN[0], 0:PATTERN[1]].T.reshape(-1, 2) * SQUARE_M
    obj, img = [], []
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    for fr in frames:
        g = to_gray8(fr.color)
        ok, corners = cv2.findChessboardCorners(g, PATTERN, flags=cv2.CALIB_CB_ADAPTIVE_THRESH)
        if not ok:
            continue
        # refine on the float image: no 8-bit quantisation in the sub-pixel fit
        y = (fr.color @ np.array([0.2126, 0.7152, 0.0722])).astype(np.float32)
        corners = cv2.cornerSubPix(y / y.max(), corners, (5, 5), (-1, -1), crit)
        obj.append(objp)
        img.append(corners)
    if len(obj) < 3:
        raise RuntimeError(f"only {len(obj)} board(s) detected")
    rms, k, d, _, _ = cv2.calibrateCamera(obj, img, size, None, None, flags=cv2.CALIB_FIX_K3)
    d = d.ravel()
    est = dict(fx=k[0, 0], fy=k[1, 1], cx=k[0, 2], cy=k[1, 2], k1=d[0], k2=d[1], p1=d[2], p2=d[3])
    return {n: float(v) for n, v in est.items()}, len(obj), float(rms)


def compare(model: OpenCVModel, est: dict) -> dict:
    """Per parameter: true, estimated, relative error (absolute for a true value of 0)."""
    rows = {}
    for n, e in est.items():
        t = getattr(model, n)
        rows[n] = (t, e, abs(e - t) / abs(t) if t else abs(e - t))
    return rows


def undistort_roundtrip(model: OpenCVModel, view: int = 3, n_views: int = 17) -> dict:
    """distort (clpost) → cv2.undistort → compare with a direct render at the model's K
    (fx = fy required by the renderer, so fy is set to fx here)."""
    import cv2

    m = replace(model, fy=model.fx)
    raw, out = render_views_single(m, view, n_views)
    und = cv2.undistort(out.color.astype(np.float32), m.matrix(), m.vector()[:8])
    valid = cv2.undistort(out.alpha.astype(np.float32), m.matrix(), m.vector()[:8]) > 0.999
    valid[:4], valid[-4:], valid[:, :4], valid[:, -4:] = False, False, False, False
    e = np.abs(und - raw.color)[valid]
    white = float(np.percentile(raw.color, 99))
    return {"mean_abs_rel_white": float(e.mean() / white), "median_abs_rel_white": float(np.median(e) / white),
            "p99_abs_rel_white": float(np.percentile(e, 99) / white), "pixels": int(valid.sum()),
            "undistorted": und, "reference": raw.color, "distorted": out.color}


def render_views_single(model: OpenCVModel, view: int, n_views: int):
    cam = Camera(distortion=model)
    renderer = PyVistaRenderer(board_scene(view, n_views, model))
    try:
        raw = renderer.render(cam, (model.width, model.height), 0, (model.fx, model.fy, model.cx, model.cy))
    finally:
        renderer.close()
    return raw, Pipeline(cam, quality="final", stages=["distortion"]).run(raw)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--views", type=int, default=17)
    ap.add_argument("--size", default="800x600")
    ap.add_argument("--png", default=None, help="directory for PNGs of the first views")
    args = ap.parse_args()
    size = tuple(int(t) for t in args.size.split("x"))
    for name, model in parameter_sets(size).items():
        t0 = time.perf_counter()
        raw, out = render_views(model, args.views)
        est, used, rms = calibrate(out, size)
        spec = required_render(model)
        print(f"\n{name}: {used}/{args.views} views detected, reprojection RMS {rms:.4f} px, "
              f"render {spec.width}x{spec.height} (f={spec.f:.1f}) for {size[0]}x{size[1]}, {time.perf_counter() - t0:.1f} s")
        print(f"  {'param':<6}{'true':>12}{'estimated':>14}{'error':>12}")
        for n, (t, e, err) in compare(model, est).items():
            unit = "rel" if t else "abs"
            print(f"  {n:<6}{t:>12.6g}{e:>14.6g}{err * (100 if t else 1):>11.4g}{'%' if t else ' abs'}")
        for meth in ("newton", "heikkila"):
            r = inverse_residual_px(model, meth)
            print(f"  inverse {meth:<9} max {r['max_px']:.3g} px at {r['argmax_xy']}, RMS {r['rms_px']:.3g} px")
        if args.png:
            from pathlib import Path

            from clpost.atomic import write_png

            d = Path(args.png)
            for k in range(2):
                write_png(d / f"board_{name}_{k}_distorted.png", out[k].color / out[k].color.max())
                write_png(d / f"board_{name}_{k}_render.png", raw[k].color / raw[k].color.max())
    rt = undistort_roundtrip(parameter_sets(size)["barrel"])
    print(f"\ndistort → cv2.undistort vs direct render (barrel, fy=fx): mean |e| {rt['mean_abs_rel_white']:.4f}, "
          f"median {rt['median_abs_rel_white']:.4f}, p99 {rt['p99_abs_rel_white']:.4f} of white over {rt['pixels']} px")


if __name__ == "__main__":
    main()

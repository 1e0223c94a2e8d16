"""Geometry pre-processing distortion vs the post-processing path (Lambers et al., Table 1 with
measurements): error against the exact ray cast and cost, on the demo scene and on the
checkerboard calibration test of clpost.calib_check.checkerboard (tools/distortion_calibration.py).

    PYTHONPATH=. /tmp/venv/bin/python tools/geometry_distortion_compare.py --size 960x640 --views 9 \
        --png /tmp/renderlens_check

Error metrics (both methods against :func:`clpost.render.geometry_distortion.render_reference`,
the analytic scene intersected by every pixel's exact undistorted ray): share of pixels whose
object id differs, holes (background where the reference has an object), depth relative error
on pixels where both see the same object (median, 99th percentile), colour mean absolute error
relative to the reference's 99th-percentile white and PSNR (peak = that white), both on colours
clipped at that white (display-referred: the demo's lamps are 250–1000× white).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from clpost import Camera, Pipeline
from clpost.calibration import OpenCVModel, required_render, undistort_newton
from clpost.render import DemoScene, PyVistaRenderer
from clpost.render.geometry_distortion import GeometryDistortionRenderer, render_reference


def metrics(ref_color, ref_depth, ref_ids, color, depth, ids, valid) -> dict:
    white = float(np.percentile(ref_color[valid], 99))
    v = valid & (ref_ids >= -1)
    same = v & (ids == ref_ids) & np.isfinite(ref_depth) & np.isfinite(depth) & (ref_ids >= 0)
    rel = np.abs(depth[same] / ref_depth[same] - 1.0)
    # display-referred: clip at the white so a few emitter pixels (250–1000× white) do not swamp it
    err = np.abs(np.clip(color, 0, white) - np.clip(ref_color, 0, white))[v]
    mse = float(np.mean(err ** 2))
    return {"id_mismatch_pct": 100.0 * float((ids != ref_ids)[v].mean()),
            "holes_px": int(((ids < 0) & (ref_ids >= 0) & v).sum()),
            "depth_rel_median": float(np.median(rel)), "depth_rel_p99": float(np.percentile(rel, 99)),
            "color_mae_rel": float(err.mean() / white), "psnr_db": float(10 * np.log10(white ** 2 / mse))}


def post_path(scene: DemoScene, model: OpenCVModel, frame: int = 0) -> tuple[dict, dict]:
    """Render the extended frustum (required_render), run the distortion stage; ids by nearest
    lookup through the same Newton map (what a careful post-process does for ids)."""
    spec = required_render(model)
    t0 = time.perf_counter()
    r = PyVistaRenderer(scene)
    try:
        raw = r.render(Camera(), (spec.width, spec.height), frame, spec.intrinsics())
    finally:
        r.close()
    t_render = time.perf_counter() - t0
    pipe = Pipeline(Camera(distortion=model), quality="final", stages=["distortion"])
    pipe.run(raw)  # warm-up: kernel build and map
    dev = []
    for _ in range(5):
        out = pipe.run(raw)
        dev.append(sum(v for k, v in pipe.last_timings.items() if k not in ("upload", "download")))
    vv, uu = np.mgrid[0:model.height, 0:model.width].astype(np.float64)
    x, y, ok = undistort_newton(model, uu, vv)
    i = np.clip(np.rint(spec.f * x + spec.cx).astype(int), 0, spec.width - 1)
    j = np.clip(np.rint(spec.f * y + spec.cy).astype(int), 0, spec.height - 1)
    ids = np.where(ok, raw.metadata["object_id"][j, i], -1)
    return ({"color": out.color.astype(np.float64), "depth": out.depth.astype(np.float64), "ids": ids},
            {"render_s": t_render, "render_px": spec.width * spec.height, "stage_device_ms": float(np.median(dev))})


def geometry_path(scene: DemoScene, model: OpenCVModel, error_px: float, frame: int = 0) -> tuple[dict, dict]:
    r = GeometryDistortionRenderer(scene, model, error_px=error_px)
    try:
        r.render(frame)  # warm-up (VTK context, Newton ray map)
        t0 = time.perf_counter()
        f = r.render(frame)
        total = time.perf_counter() - t0
    finally:
        r.close()
    gd = f.metadata["geometry_distortion"]
    return ({"color": f.color.astype(np.float64), "depth": f.depth.astype(np.float64), "ids": f.metadata["object_id"]},
            {**gd, "total_s": total})


def demo_table(size, error_levels, png: Path | None) -> None:
    w, h = size
    fx = Camera().intrinsics(w, h)[0]
    models = {"barrel": OpenCVModel(w, h, fx, fx, (w - 1) / 2 + 3.3, (h - 1) / 2 - 2.1, k1=-0.25, k2=0.08),
              "full (k1-k6, p, s, tilt)": OpenCVModel(w, h, fx, fx, (w - 1) / 2, (h - 1) / 2, k1=-0.2, k2=0.05,
                                                     p1=0.002, p2=-0.0015, k3=0.01, k4=0.02, s1=0.001,
                                                     s3=0.0007, tau_x=0.01, tau_y=-0.008)}
    scene = DemoScene.default()
    for name, model in models.items():
        t0 = time.perf_counter()
        ref = render_reference(scene, model, 0)
        t_ref = time.perf_counter() - t0
        rc, rd, ri = ref.color.astype(np.float64), ref.depth.astype(np.float64), ref.metadata["object_id"]
        valid = ref.alpha > 0
        print(f"\n### demo scene {w}x{h}, {name} (exact ray cast: {t_ref:.2f} s)\n")
        print("| method | id mismatch | holes (px) | depth rel. err. median / p99 | colour MAE / white | PSNR | cost |")
        print("|---|---|---|---|---|---|---|")
        post, pc = post_path(scene, model)
        m = metrics(rc, rd, ri, post["color"], post["depth"], post["ids"], valid)
        print(f"| post-process (render {pc['render_px'] / (w * h):.2f}× pixels + distortion stage) | "
              f"{m['id_mismatch_pct']:.3f} % | {m['holes_px']} | {m['depth_rel_median']:.2e} / {m['depth_rel_p99']:.2e} | "
              f"{m['color_mae_rel']:.4f} | {m['psnr_db']:.1f} dB | render {pc['render_s'] * 1e3:.0f} ms + stage "
              f"{pc['stage_device_ms']:.1f} ms device |")
        for eps in error_levels:
            geo, gc = geometry_path(scene, model, eps)
            m = metrics(rc, rd, ri, geo["color"], geo["depth"], geo["ids"], valid)
            print(f"| geometry, chord error {eps:g} px ({gc['triangles_in']} → {gc['triangles_out']} triangles, "
                  f"{gc['levels']} levels, max chord {gc['max_chord_error_px']:.2f} px) | {m['id_mismatch_pct']:.3f} % | "
                  f"{m['holes_px']} | {m['depth_rel_median']:.2e} / {m['depth_rel_p99']:.2e} | {m['color_mae_rel']:.4f} | "
                  f"{m['psnr_db']:.1f} dB | subdivide {gc['subdivide_s'] * 1e3:.0f} ms + rasterise "
                  f"{gc['rasterize_s'] * 1e3:.0f} ms + shade {gc['shade_s'] * 1e3:.0f} ms |")
            if png is not None and eps == error_levels[0]:
                from clpost.atomic import write_png

                tag = name.split()[0]
                white = float(np.percentile(rc, 99))
                write_png(png / f"gd_{tag}_geometry.png", geo["color"] / white)
                write_png(png / f"gd_{tag}_post.png", post["color"] / white)
                write_png(png / f"gd_{tag}_reference.png", rc / white)
                diff = np.stack([(geo["ids"] != ri), (post["ids"] != ri), np.zeros_like(valid)], -1)
                write_png(png / f"gd_{tag}_id_errors_red_geometry_green_post.png", diff.astype(np.float32))


def calibration_table(size, n_views: int) -> None:
    """The checkerboard calibration check (:mod:`clpost.calib_check.checkerboard`) with the
    geometry path in place of the stage."""
    from clpost.calib_check import checkerboard as dc

    print(f"\n### checkerboard calibration, {size[0]}x{size[1]}, {n_views} views (cv2.calibrateCamera, k3 fixed)\n")
    print("| set | method | views found | RMS reproj. (px) | k1 rel. err | k2 rel. err | fx rel. err | cx abs err (px) |")
    print("|---|---|---|---|---|---|---|---|")
    for name, model in dc.parameter_sets(size).items():
        model = OpenCVModel(model.width, model.height, model.fx, model.fx, model.cx, model.cy,
                            k1=model.k1, k2=model.k2, p1=model.p1, p2=model.p2)  # the renderer's square pixels
        _, post = dc.render_views(model, n_views)
        geo = []
        r = GeometryDistortionRenderer(dc.board_scene(0, n_views), model, error_px=0.05)
        try:
            for v in range(n_views):
                r.scene = dc.board_scene(v, n_views, model)
                geo.append(r.render(0))
        finally:
            r.close()
        for meth, frames in (("post-process", post), ("geometry", geo)):
            est, used, rms = dc.calibrate(frames, size)
            c = dc.compare(model, est)
            print(f"| {name} | {meth} | {used}/{n_views} | {rms:.4f} | {c['k1'][2]:.2%} | {c['k2'][2]:.2%} | "
                  f"{c['fx'][2]:.3%} | {abs(c['cx'][1] - c['cx'][0]):.3f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="960x640")
    ap.add_argument("--views", type=int, default=9)
    ap.add_argument("--errors", default="0.1,0.5,2", help="chord errors (px) of the geometry path")
    ap.add_argument("--png", default=None)
    ap.add_argument("--skip-calibration", action="store_true")
    a = ap.parse_args()
    size = tuple(int(t) for t in a.size.split("x"))
    demo_table(size, [float(t) for t in a.errors.split(",")], Path(a.png) if a.png else None)
    if not a.skip_calibration:
        calibration_table((800, 600), a.views)


if __name__ == "__main__":
    main()

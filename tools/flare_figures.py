"""docs/flare.md's figures and numbers: a lamp of the demo scene throwing ghosts and a starburst,
next to the traced reference, and the stages' cost per quality.

    python tools/flare_figures.py RENDER_EXR OUT_DIR [--f-number 8] [--boost 1000]

RENDER_EXR: `clpost demo OUT --frames 1 --size 640x360` writes OUT/render/demo.0001.exr. The demo's
lamps (250–1000 × diffuse white) are multiplied by ``--boost`` (default 1000: the sun's luminance
over a sunlit white, about 10⁵–10⁶) so their ghosts and diffraction show as they do for the sun or
a street lamp at night. The shutter is the demo meter's at f/2 for the unboosted scene, scaled to
the f-number.

Writes: demo_plain.png, demo_flare.png (ghosts + glare), ghosts_first_order.png and
ghosts_traced.png (the brightest lamp's ghosts alone: the stage's ghosts (fitted from traces) and full
traces of every kept ghost path through the real tracer, on the same pixels), starburst.png
(a crop around the lamp), and prints the timings.
"""
from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

from clpost import Camera, Frame, Pipeline
from clpost.atomic import write_png
from clpost.demo import DEMO_CAMERA_DEFAULTS
from clpost.exr import read_frame
from clpost.optics import ghosts as gh
from clpost.stages import _field as fld
from clpost.stages.ghosts import Ghosts, find_sources, threshold_scene
from clpost.stages.lateral_color import channel_wavelengths_nm


def camera(n: float, **kw) -> Camera:
    d = dict(DEMO_CAMERA_DEFAULTS)
    d.update(f_number=n, shutter_s=1 / 1250 * (n / 2.0) ** 2, exposure_compensation_ev=0.0, depth_of_field=False,
             lens_distortion=False, vignetting="off")
    d.update(kw)
    return Camera(**d)


def traced_ghost_image(cam: Camera, stage: Ghosts, src: np.ndarray, w: int, h: int, rays: int = 301) -> np.ndarray:
    """Full traces of the kept ghost paths for one source, splatted on pixels (flux per ray from the
    direct path's arriving rays; reflectances per channel as the stage's)."""
    lens = cam.optics
    n = lens.clamp_f_number(cam.f_number, warn=False)
    pres = lens.focused(cam.focus_from_film_m * 1000.0, n)
    r_stop = lens.stop_radius_mm(n)
    pitch = fld.pitch_mm(cam, w)
    cx, cy = fld.principal_point_px(cam, w, h)
    paths = stage.fitted(cam, w)[2]
    img = np.zeros((h, w, 3))
    for c, lam in enumerate(channel_wavelengths_nm()):
        (a0, b0), cr = gh.paraxial_path(pres, None, lam)
        c0 = b0 - a0 * cr[0][1] / cr[0][0]
        px, py = (src[0] - cx) * pitch, (src[1] - cy) * pitch
        tx, ty = px / c0, py / c0  # slopes of the source's direction
        d = np.array([tx, ty, 1.0]) / math.sqrt(1 + tx * tx + ty * ty)
        u = np.linspace(-1, 1, rays) * pres.surfaces[0].semi_diameter_mm
        x, y = np.meshgrid(u, u)
        keep = x ** 2 + y ** 2 <= u[-1] ** 2
        o = np.stack([x[keep] - 5 * d[0] / d[2], y[keep] - 5 * d[1] / d[2], np.full(keep.sum(), -5.0)], 1)
        dirs = np.broadcast_to(d, o.shape)
        shape = (cam.blades, cam.blade_rotation_deg, cam.aperture_roundness)
        _, st0 = gh.trace_path(pres, None, o, dirs, lam, r_stop, aperture=shape)
        per_ray = src[2 + c] / max(int((st0 == 0).sum()), 1)
        for code in paths:
            i, j = int(code) // 100, int(code) % 100
            pos, st = gh.trace_path(pres, (i, j), o, dirs, lam, r_stop, aperture=shape)
            ok = st == 0
            refl = gh.surface_reflectance(pres, i, lam) * gh.surface_reflectance(pres, j, lam)
            gx = np.round(cx + pos[ok, 0] / pitch).astype(int)
            gy = np.round(cy + pos[ok, 1] / pitch).astype(int)
            inside = (gx >= 0) & (gx < w) & (gy >= 0) & (gy < h)
            np.add.at(img[..., c], (gy[inside], gx[inside]), per_ray * refl)
    return img


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("render")
    ap.add_argument("out")
    ap.add_argument("--f-number", type=float, default=8.0)
    ap.add_argument("--boost", type=float, default=1000.0)
    ap.add_argument("--veiling-glare", type=float, default=0.02)
    ap.add_argument("--timing", action="store_true", help="time draft/preview/final (slow at final)")
    ap.add_argument("--ghosts-only", action="store_true", help="only the first-order vs traced ghost pair")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    frame = read_frame(Path(a.render))
    c = frame.color.astype(np.float32).copy()
    lamp = c.max(axis=2) > 100.0
    c[lamp] *= a.boost
    frame = Frame(c)
    h, w = c.shape[:2]
    plain = camera(a.f_number)
    flare = camera(a.f_number, ghosts=True, diffraction=True, veiling_glare=a.veiling_glare)
    gain = 1.0
    for name, cam, stages in () if a.ghosts_only else (("demo_plain", plain, None), ("demo_flare", flare, None)):
        for q in ("draft", "preview", "final") if a.timing else ("final",):
            pipe = Pipeline(cam, quality=q)
            pipe.run(frame)  # build
            t0 = time.perf_counter()
            res = pipe.run(frame)
            dt = time.perf_counter() - t0
            tm = pipe.last_timings
            print(f"{name} {q}: {dt * 1000:.0f} ms wall; ghosts {tm.get('ghosts', 0):.0f} ms, glare "
                  f"{tm.get('glare', 0):.0f} ms device (+ FFTs outside the profile)")
        write_png(out / f"{name}.png", res.color * gain)
    # ghosts alone for the brightest source, first order vs traced
    cam = flare
    st = Ghosts("final")
    src = find_sources(c, threshold_scene(cam), 1)[0]
    base = Frame(np.zeros_like(c))
    only = np.zeros((h, w, 3))
    one = np.zeros_like(c)
    ty0, tx0 = int(src[6]), int(src[5])
    one[ty0:ty0 + 16, tx0:tx0 + 16] = c[ty0:ty0 + 16, tx0:tx0 + 16]
    keep = st.sources(cam, Frame(one))[0, 7:10]
    first = st.reference(cam, Frame(one), one) - one * keep
    traced = traced_ghost_image(cam, st, src, w, h)
    del base, only
    s = 1.0 / max(first.max(), 1e-30)
    from clpost.photometry import exposure_gain
    g = exposure_gain(cam)
    print(f"brightest source at ({src[0]:.1f}, {src[1]:.1f}) px; ghost flux first order {first.sum():.4g}, "
          f"traced {traced.sum():.4g} (scene units); peak ghost {first.max() * g:.3g} × saturation")
    write_png(out / "ghosts_first_order.png", first * s)
    write_png(out / "ghosts_traced.png", traced * s)
    if a.ghosts_only:
        return
    x0, y0 = int(src[0]), int(src[1])
    crop = res.color[max(y0 - 60, 0):y0 + 60, max(x0 - 60, 0):x0 + 60]
    write_png(out / "starburst.png", np.kron(crop, np.ones((3, 3, 1))))


if __name__ == "__main__":
    main()

"""Every bench plan and the stages with bright-source or raw inputs on one OpenCL device against
another (default: an NVIDIA GPU against PoCL), same frame: the plan must be the same and the images
agree to float rounding (the GPU runs the one-pixel forms of kernels whose CPU form is 16 lanes wide,
``Runtime.wide``).

    PYTHONPATH=. python tools/device_vs_device.py [--a pocl] [--b nvidia] [--size 320x184]
"""
import argparse
import warnings; warnings.simplefilter("ignore")
import numpy as np
from dataclasses import replace
from clpost import Camera, Pipeline
from clpost.bench import SCENES, synthetic_frame

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--a", default="pocl")
ap.add_argument("--b", default="nvidia")
ap.add_argument("--size", default="320x184")
args = ap.parse_args()
W, H = (int(v) for v in args.size.split("x"))
cases = []
for name in ("worst", "no_defocus", "full"):
    cam, _ = SCENES[name].camera(W, H)
    for q in ("draft", "final"):
        cases.append((f"{name} {q}", cam, list(SCENES[name].wants), q, SCENES[name].velocity_px, 1.0))
base = Camera(f_number=2.0, shutter_s=1 / 50, luminance_scale=1.0)
cases += [
    ("halation+film", replace(base, film="kodak-ektar-100", halation=True), ["exposure", "halation", "film"], "final", 0, 5e4),
    ("ghosts", replace(base, lens="zeiss-planar-50-f1.4", f_number=8.0, ghosts=True, ghost_sources=2), ["ghosts"], "final", 0, 5e4),
    ("glare", replace(base, blades=6, diffraction=True, veiling_glare=0.02), ["glare"], "final", 0, 5e4),
    ("raw+isp", replace(base, raw_calibration="a7s2-like", iso=800.0, isp=True), ["exposure", "raw", "isp"], "final", 0, 1.0),
    ("traced dof", replace(base, lens="zeiss-planar-50-f1.4", f_number=1.4, depth_of_field=True, focus_distance_m=2.0), ["dof"], "final", 0, 1.0),
]
for label, cam, stages, q, vel, scale in cases:
    f = synthetic_frame(W, H, velocity_px=vel)
    if scale != 1.0:
        f = f.replace(color=(f.color * np.float32(scale)).astype(np.float32))
    outs = []
    for dev in (args.a, args.b):
        p = Pipeline(cam, quality=q, stages=stages, device=dev)
        outs.append((p.plan(f), p.run(f).color.astype(np.float64)))
    (pa, a), (pb, b) = outs
    ref = max(float(np.abs(a).max()), 1e-30)
    d = np.abs(a - b)
    print(f"{label:16s} plan {pa == pb} {'-'.join(pa)} max|b-a|/max {d.max() / ref:.2e} mean {d.mean() / max(np.abs(a).mean(), 1e-30):.2e} finite {np.isfinite(b).all()}", flush=True)

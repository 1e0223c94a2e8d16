"""Do the field stages' gathers keep huge finite colour finite? Each stage alone, draft and final,
on a 161×91 ``odd_frame`` (tests/conftest.py) with a hot pixel, × 2^119 (hot pixel 3.3e38, the
rest up to ~1e37; FLT_MAX = 3.4e38) and × 1: the count of non-finite output pixels
(docs/benchmarks.md, "astigmatism (and coma): class ties and huge colour").

    PYTHONPATH=. python tools/huge_colour_probe.py
"""
import sys
from pathlib import Path
import numpy as np
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from clpost import Camera, Frame, Pipeline
from clpost.calibration import OpenCVModel
from conftest import odd_frame
rng = np.random.default_rng(3)
w, h = 161, 91
base = odd_frame(rng, w=w, h=h, scale=10.0).color.copy()
base[40, 100] = 500.0
depth = (1.5 + 2.5 * rng.random((h, w))).astype(np.float32)
m = OpenCVModel(w, h, 120, 120, (w - 1) / 2, (h - 1) / 2, k1=-0.3, k2=0.1, p1=0.01, s1=0.002)
cases = {
    "astigmatism": Camera(lens="thin:50", f_number=2.0, focus_distance_m=3.0, field_curvature_mm=-0.4, astigmatism_mm=0.15),
    "coma": Camera(coma_mm=1.2),
    "lateral_color": Camera(lateral_color_mm=0.3),
    "distortion": Camera(distortion=m),
}
for name, cam in cases.items():
    for q in ("draft", "final"):
        pipe = Pipeline(cam, stages=[name], quality=q)
        for scale in (2.0 ** 119, 1.0):
            k = np.float32(scale)
            fr = Frame(base * k, depth=depth)
            out = pipe.run(fr).color
            bad = ~np.isfinite(out)
            print(f"{name:14s} {q:6s} scale {scale:.3g}: max in {float((base*k).max()):.3g}, non-finite out {int(bad.sum())}, max out {float(np.nanmax(np.where(bad, np.nan, out))):.3g}")

"""Time the glare stage alone per frame size and quality (docs/flare.md "Cost"): python tools/glare_timing.py"""
import time, numpy as np
from clpost import Camera, Frame, Pipeline
for w, h in ((640, 360), (1280, 720)):
    c = np.full((h, w, 3), 0.1, np.float32); c[h//3, w//2] = 1e6; c[h//2, w//4] = 1e5
    f = Frame(c)
    for q in ("draft", "preview", "final"):
        cam = Camera(luminance_scale=1.0, lens="thin:50", f_number=8.0, shutter_s=1/100, focus_distance_m=3.0,
                     diffraction=True, veiling_glare=0.01, blades=6)
        pipe = Pipeline(cam, stages=["glare"], quality=q)
        t0 = time.perf_counter(); pipe.run(f); t1 = time.perf_counter()
        ts = []
        for _ in range(3):
            a = time.perf_counter(); pipe.run(f); ts.append(time.perf_counter() - a)
        k = pipe.last_plan.stages[0].kernels(pipe.camera_for(f), w).shape[1]
        print(f"{w}x{h} {q}: first {t1 - t0:.2f} s (PSF, spectra, FFT plans), then {min(ts) * 1000:.0f} ms/frame; PSF {k} px")

"""Cost of the label path of docs/labels.md ("Cost"): a 1080p frame through the distortion stage with 0, 1
and 3 uint32 label planes (median of 5 runs after a warm-up), and the numpy reference of the host buffers.

    .venv/bin/python tools/labels_bench.py   (from the repository root)
"""
import time, warnings
import numpy as np
from clpost import Camera, Frame, Pipeline
from clpost.calibration import OpenCVModel
warnings.simplefilter("ignore")
m = OpenCVModel(1920, 1080, 1500, 1500, 959.5, 539.5, k1=-0.2, k2=0.05)
rng = np.random.default_rng(0)
col = rng.random((1080, 1920, 3)).astype(np.float32)
dep = rng.uniform(1, 9, (1080, 1920)).astype(np.float32)
ids = rng.integers(0, 2**31, (1080, 1920)).astype(np.uint32)
for q in ("preview",):
    pipe = Pipeline(Camera(distortion=m), quality=q, stages=["distortion"])
    for name, fr in (("no labels", Frame(col, depth=dep)), ("1 id plane", Frame(col, depth=dep, labels={"id": ids})),
                     ("3 planes", Frame(col, depth=dep, labels={"id": ids, "a": ids, "b": ids}))):
        pipe.run(fr)
        ts = []
        for _ in range(5):
            t = time.perf_counter(); pipe.run(fr); ts.append(time.perf_counter() - t)
        st = pipe.plan_for(fr, pipe.camera_for(fr)).stages[0]
        t = time.perf_counter(); st.host_buffers(pipe.camera_for(fr), fr); th = time.perf_counter() - t
        print(f"{q} {name}: median {np.median(ts)*1e3:.1f} ms/frame (min {min(ts)*1e3:.1f}); numpy host_buffers {th*1e3:.1f} ms")

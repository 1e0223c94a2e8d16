"""dof worst-case timing: whole image defocused (50 mm f/1.4 focused at 0.7 m, depth 4 m .. inf).

    PYTHONPATH=. python tools/dof_worstcase.py [levels, default draft,preview,final] [repeats, default 5]

Prints dof device ms per level at 640x360, 1280x720, 1920x1080 (OpenCL events, median after one warm-up).
"""
import statistics, sys
import numpy as np
from clpost import Camera, Frame, Pipeline
sizes = [(640, 360), (1280, 720), (1920, 1080)]
levels = sys.argv[1].split(",") if len(sys.argv) > 1 else ["draft", "preview", "final"]
reps = int(sys.argv[2]) if len(sys.argv) > 2 else 5
cam = Camera(lens="thin:50", f_number=1.4, focus_distance_m=0.7, shutter_s=1/50, blades=6, depth_of_field=True)
rng = np.random.default_rng(1)
for w, h in sizes:
    yy, xx = np.mgrid[0:h, 0:w]
    color = (0.5 + 0.4 * np.sin(xx / 17.0)[..., None] * np.cos(yy / 23.0)[..., None] * np.array([1, .8, .6])).astype(np.float32)
    color = np.repeat(color, 1, 0) if color.shape[-1] == 3 else np.broadcast_to(color, (h, w, 3)).copy()
    color = np.ascontiguousarray(np.broadcast_to(color, (h, w, 3))).astype(np.float32)
    pts = rng.integers(0, [h, w], (40, 2)); color[pts[:, 0], pts[:, 1]] = 200.0
    depth = (4.0 + 20.0 * xx / w).astype(np.float32); depth[: h // 4] = np.inf
    frame = Frame(color, depth=depth)
    for q in levels:
        pipe = Pipeline(cam, quality=q, stages=["dof"])
        t = []
        for i in range(reps + 1):
            pipe.run(frame)
            if i: t.append(pipe.last_timings["dof"])
        print(f"{w}x{h} {q}: {statistics.median(t):.1f} ms (min {min(t):.1f})", flush=True)

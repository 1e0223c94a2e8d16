"""``clpost view``'s latency: a slider change to an updated image ready for the page, at draft.

Builds the real page object (:class:`clpost.view.app.ViewApp`, not started), then for each
dragged parameter applies a sweep of values the way the slider handler does (``apply``: a new
camera, the plan reused for a scalar) and times ``_render_page`` — camera_for, plan_for, Plan.run,
display encoding, histogram and the JPEG/PNG data URLs the websocket carries. Not in the number:
the websocket hop on loopback and the browser's JPEG decode (a few ms). Reported: median and
90th percentile per parameter after one warm-up change, and the process's CPU time per change
(all threads: on a shared, loaded box the wall time is the CPU time stretched by the other load;
`uptime` is printed).

    PYTHONPATH=. python tools/bench_view.py                 # demo scene, 960x540, thin 50 mm
    PYTHONPATH=. python tools/bench_view.py --lens zeiss-planar-50-f1.4 --vignetting lens
    PYTHONPATH=. python tools/bench_view.py --input demo.exr   # a file (no renderer needed)
"""
from __future__ import annotations

import argparse
import os
import statistics
import time
import warnings

from clpost import Camera
from clpost.view.command import VIEW_CAMERA_DEFAULTS
from clpost.view.session import DRAFT, ViewSession, open_input

SWEEPS = {
    "f_number": [2.2, 2.5, 2.8, 3.2, 3.5, 4.0, 4.5, 5.0, 5.6, 6.3],
    "focus_distance_m": [2.0, 2.2, 2.5, 2.8, 3.2, 3.6, 4.0, 4.5, 5.0, 6.0],
    "exposure_compensation_ev": [0.0, 0.3, 0.6, 0.9, 1.2, 1.5, 1.8, 2.1, 2.4, 2.7],
    "shutter_s": [1 / 1000, 1 / 800, 1 / 640, 1 / 500, 1 / 400, 1 / 320, 1 / 250, 1 / 200, 1 / 160, 1 / 125],
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="960x540")
    ap.add_argument("--lens", default=VIEW_CAMERA_DEFAULTS["lens"])
    ap.add_argument("--vignetting", default=VIEW_CAMERA_DEFAULTS["vignetting"])
    ap.add_argument("--input", default=None, help="an EXR (or pattern) instead of rendering the demo scene")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    w, h = map(int, args.size.split("x"))
    camera = Camera(**{**VIEW_CAMERA_DEFAULTS, "lens": args.lens, "vignetting": args.vignetting})
    t0 = time.perf_counter()
    numbers, load, label = open_input(args.input, camera, size=(w, h), n_frames=1)
    print(f"{args.input or 'demo scene'} {w}x{h} ready in {time.perf_counter() - t0:.1f} s; camera {args.lens}, "
          f"vignetting {args.vignetting}")
    from clpost.view.app import ViewApp

    app = ViewApp(ViewSession(numbers, load, camera, label, final_quality=DRAFT))
    t0 = time.perf_counter()
    page = app._render_page(0, DRAFT, 1.0, "none")
    print(f"first draft (plan built): {(time.perf_counter() - t0) * 1e3:.0f} ms; plan {page['plan_text']}")
    for name, values in SWEEPS.items():
        ms, cpu, built = [], [], 0
        for i, v in enumerate(values):
            if name == "shutter_s":  # a manual shutter: leave auto-exposure for this sweep
                app.apply({"shutter_s": v}, name)
            else:
                app.apply({name: v}, name)
            t, c = time.perf_counter(), time.process_time()
            page = app._render_page(0, DRAFT, 1.0, "none")
            dt, dc = (time.perf_counter() - t) * 1e3, (time.process_time() - c) * 1e3
            built += "plan built" in page["status"]
            if i:  # the first change is the warm-up
                ms.append(dt)
                cpu.append(dc)
        ms.sort()
        p90 = ms[min(len(ms) - 1, int(round(0.9 * (len(ms) - 1))))]
        print(f"{name:26s} median {statistics.median(ms):6.1f} ms   p90 {p90:6.1f} ms   "
              f"CPU (all threads, PoCL's too) median {statistics.median(cpu):6.1f} ms   "
              f"plans built {built}/{len(values)}")
        app.apply({"shutter_s": None} if name == "shutter_s" else {}, name)
    app.close()
    print("load average (1, 5, 15 min):", " ".join(f"{x:.1f}" for x in os.getloadavg()))


if __name__ == "__main__":
    main()

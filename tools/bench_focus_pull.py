"""Bench a focus pull against a static camera, and render the pull's contact sheet.

    .venv/bin/python tools/bench_focus_pull.py --size 1280x720 --repeats 3 \\
        --sheet /tmp/i18-anim/focus_pull_sheet.png

The pull: planes at 1, 2 and 4 m (clpost.focus_pull.planes_scene), thin:50 at f/1.4 with depth of
field, focus 1 → 1.5 → 2 → 3 → 4 m, one value per frame. ``--sheet`` also runs the pull the way a
user does — five EXRs carrying the OpenEXR ``focus`` attribute through ``clpost process`` — and
stacks the outputs top to bottom (frame 1 at the top). Prints JSON: seconds per frame (median after
a warm-up frame), plans and programs of each pipeline.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import sys
import tempfile
from pathlib import Path

DEPTHS = (1.0, 2.0, 4.0)
FOCUS = (1.0, 1.5, 2.0, 3.0, 4.0)


def main(argv=None) -> int:
    from clpost import Camera, exr
    from clpost.atomic import write_png
    from clpost.cli import main as clpost_main
    from clpost.focus_pull import bench, contact_sheet, planes_scene, write_pull

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", default="1280x720", help="WIDTHxHEIGHT (default 1280x720)")
    p.add_argument("--repeats", type=int, default=3, help="passes over the five frames (default 3)")
    p.add_argument("--device", default=None)
    p.add_argument("--sheet", default=None, help="also write the pull's contact sheet PNG here")
    p.add_argument("--exr-camera", default="on", choices=("on", "off"),
                   help="off: ignore the inputs' focus attributes (a constant camera, as before per-frame sources)")
    a = p.parse_args(argv)
    w, h = (int(x) for x in a.size.lower().split("x"))
    frame = planes_scene(w, h, DEPTHS)
    cam = Camera(f_number=1.4, depth_of_field=True, focus_distance_m=FOCUS[0])
    doc = {"size": [w, h], "focus_m": FOCUS, "depths_m": DEPTHS, "bench": bench(cam, frame, FOCUS, a.repeats, a.device)}
    if a.sheet:
        with tempfile.TemporaryDirectory() as tmp:
            src = write_pull(Path(tmp) / "in", frame, FOCUS)
            out = str(Path(tmp) / "o.####.exr")
            with contextlib.redirect_stdout(sys.stderr):  # stdout is the JSON
                rc = clpost_main(["process", src, "-o", out, "--depth-of-field", "on", "--f-number", "1.4", "--quiet",
                                  "--exr-camera", a.exr_camera]
                                 + (["--device", a.device] if a.device else []))
            if rc:
                return rc
            frames = [exr.read_frame(Path(tmp) / f"o.{i:04d}.exr").color for i in range(1, len(FOCUS) + 1)]
            frames = [f / frames[0].mean() * 0.4 for f in frames]  # one gain for all: mid-grey-ish
            write_png(a.sheet, contact_sheet(frames, gap=max(4, h // 60)))
            doc["sheet"] = a.sheet
    json.dump(doc, sys.stdout, indent=2)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())

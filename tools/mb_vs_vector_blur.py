"""motion_blur's speed next to Blender's Vector Blur node on the same frame, in one run.

    PYTHONPATH=. .venv/bin/python tools/mb_vs_vector_blur.py --size 1920x1080 \\
        --blender /work/bpyvenv/bin/python --rounds 2

The frame is ``--input`` or the bench's ``full`` scene frame (clpost.bench.synthetic_frame, horizontal motion 0 to
24 px/frame, depth 1–21 m), written as a Blender multilayer EXR (Combined, Depth, Vector). Per
round, alternately: Blender's compositor with Vector Blur (``tools/blender_vector_blur.py``: 32
samples, shutter 0.5 frame = 180°, ``--threads``; its own timing — wall time of the compositor
with the node minus without it, median of 3) and clpost's motion_blur stage alone at each quality
(180° at 24 fps; device ms from OpenCL events and wall ms of ``Pipeline.run`` with transfers,
medians of ``--repeats``). Prints ms and Blender / clpost per quality (medians over rounds).
Accuracy is not measured here (synthetic vectors have no truth): docs/motion_blur.md has both
filters against the Cycles motion truth.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--blender", default="/work/bpyvenv/bin/python", help="a Python with bpy")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--input", default=None,
                    help="a Blender multilayer EXR (Combined, Depth, Vector) instead of the synthetic frame, "
                         "e.g. tests/data/cycles/motion/pinhole.exr (--size is then its own)")
    args = ap.parse_args(argv)

    from clpost import Camera, Pipeline, exr
    from clpost.bench import synthetic_frame
    from clpost.stages import QUALITIES

    if args.input:
        frame = exr.read_frame(args.input)
        w, h = frame.width, frame.height
    else:
        w, h = (int(v) for v in args.size.lower().split("x"))
        frame = synthetic_frame(w, h, velocity_px=24.0)
    cam = Camera(frame_rate_fps=24.0, shutter_s=1 / 48)
    pipes = {q: Pipeline(cam, quality=q, stages=["motion_blur"]) for q in QUALITIES}
    tool = Path(__file__).with_name("blender_vector_blur.py")
    res: dict[str, list[float]] = {}
    with tempfile.TemporaryDirectory(prefix="clpost-mb-vb-") as tmp:
        src, out, js = Path(tmp) / "in.exr", Path(tmp) / "vb.exr", Path(tmp) / "t.json"
        if args.input:
            src = Path(args.input).resolve()
        else:
            exr.write_frame(src, frame, layout="blender")
        for p in pipes.values():
            p.run(frame)  # build
        for _ in range(args.rounds):
            subprocess.run([args.blender, str(tool), str(src), str(out), "--shutter", "0.5", "--samples", "32",
                            "--threads", str(args.threads), "--json", str(js)], check=True,
                           capture_output=True, cwd=str(tool.parent))
            res.setdefault("blender", []).append(_blender_ms(json.loads(js.read_text())))
            for q, p in pipes.items():
                dev, wall = [], []
                for _ in range(args.repeats):
                    t0 = time.perf_counter()
                    p.run(frame)
                    wall.append((time.perf_counter() - t0) * 1e3)
                    dev.append(p.last_timings.get("motion_blur", 0.0))
                res.setdefault(f"{q} device", []).append(statistics.median(dev))
                res.setdefault(f"{q} wall", []).append(statistics.median(wall))
    med = {k: statistics.median(v) for k, v in res.items()}
    print(f"{w}x{h}, device {pipes['draft'].runtime.name}, {args.rounds} round(s); Blender Vector Blur "
          f"(32 samples, {args.threads} threads): {med['blender']:.0f} ms")
    print("| quality | motion_blur device ms | with transfers ms | Blender / device | Blender / with transfers |")
    print("|---|---:|---:|---:|---:|")
    for q in pipes:
        d, wl = med[f"{q} device"], med[f"{q} wall"]
        print(f"| {q} | {d:.1f} | {wl:.1f} | {med['blender'] / d:.1f} | {med['blender'] / wl:.1f} |")
    return 0


def _blender_ms(doc: dict) -> float:
    """The node's own time: compositor with Vector Blur minus without it (blender_vector_blur.py)."""
    return float(doc["vector_blur_s"]) * 1e3


if __name__ == "__main__":
    sys.exit(main())

"""Measure what a frame costs on one worker, to model a Dask cluster on a shared filesystem.

For 1920×1080 and 3840×2160 frames (clpost's synthetic HDR test frame with depth and velocity):
pipeline compute (exposure plan, wall incl. transfers), EXR read and write time and bytes per
frame for each lossless compression, then serial vs ``--workers 2`` throughput on a short
sequence. Prints a Markdown report (docs/scaling.md is this script's output plus prose).

    python tools/measure_scaling.py [--frames 8] > /tmp/scaling.md
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from clpost import Camera, Pipeline, exr
from clpost.batch import FrameJob, process_sequence
from clpost.bench import synthetic_frame
from clpost.distributed import PipelineSpec, connect, disconnect, process_sequence_dask

CAM = Camera(f_number=2.8, shutter_s=1 / 60, iso=200, luminance_scale=50.0)


def median_ms(fn, repeats=5, warmup=1):
    out = []
    for i in range(warmup + repeats):
        t0 = time.perf_counter()
        fn()
        if i >= warmup:
            out.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(out)


def per_frame(size, tmp: Path):
    w, h = size
    f = synthetic_frame(w, h)
    f = f.replace(velocity=np.zeros((h, w, 2), np.float32))
    pipe = Pipeline(CAM)
    rows = {"compute_ms": median_ms(lambda: pipe.run(f))}
    for comp in exr.COMPRESSIONS:
        p = tmp / f"f_{w}_{comp}.exr"
        rows[f"write_{comp}_ms"] = median_ms(lambda: exr.write_frame(p, f, compression=comp), repeats=3)
        rows[f"read_{comp}_ms"] = median_ms(lambda: exr.read_frame(p), repeats=3)
        rows[f"bytes_{comp}"] = p.stat().st_size
    return rows


def throughput(tmp: Path, n: int, size=(1920, 1080)):
    w, h = size
    f = synthetic_frame(w, h)
    for i in range(1, n + 1):
        exr.write_frame(tmp / f"in.{i:04d}.exr", f)
    res = {}
    for comp in ("zip", "none"):
        jobs = [FrameJob(i, tmp / f"in.{i:04d}.exr", tmp / f"s_{comp}" / f"o.{i:04d}.exr") for i in range(1, n + 1)]
        t0 = time.perf_counter()
        process_sequence(Pipeline(CAM), jobs, compression=comp)
        res[f"serial_{comp}"] = n / (time.perf_counter() - t0)
        client = connect(workers=2)
        try:
            client.run(lambda: None)
            jobs = [FrameJob(i, j.src, tmp / f"d_{comp}" / j.dst.name) for i, j in enumerate(jobs, 1)]
            t0 = time.perf_counter()
            process_sequence_dask(client, PipelineSpec(CAM), jobs, compression=comp)
            res[f"dask2_{comp}"] = n / (time.perf_counter() - t0)
        finally:
            disconnect(client)
    return res


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=8)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        print("| per frame | 1920×1080 | 3840×2160 |\n|---|---|---|")
        r = {s: per_frame(s, tmp) for s in ((1920, 1080), (3840, 2160))}
        a, b = r[(1920, 1080)], r[(3840, 2160)]
        print(f"| compute (exposure plan, incl. host↔device) | {a['compute_ms']:.1f} ms | {b['compute_ms']:.1f} ms |")
        for comp in exr.COMPRESSIONS:
            print(f"| EXR `{comp}`: write / read / size | {a[f'write_{comp}_ms']:.0f} / {a[f'read_{comp}_ms']:.0f} ms / "
                  f"{a[f'bytes_{comp}'] / 1e6:.1f} MB | {b[f'write_{comp}_ms']:.0f} / {b[f'read_{comp}_ms']:.0f} ms / "
                  f"{b[f'bytes_{comp}'] / 1e6:.1f} MB |")
        t = throughput(tmp, args.frames)
        print(f"\n| 1080p sequence of {args.frames} frames | zip | none |\n|---|---|---|")
        print(f"| serial (frames/s) | {t['serial_zip']:.2f} | {t['serial_none']:.2f} |")
        print(f"| `--workers 2` (frames/s) | {t['dask2_zip']:.2f} | {t['dask2_none']:.2f} |")


if __name__ == "__main__":
    main()

"""Sequence throughput of `clpost process` next to plain OpenEXR read + write, in one run.

    PYTHONPATH=. python tools/process_throughput.py --size 1920x1080 --frames 8 --rounds 2

Writes ``--frames`` synthetic frames (colour, depth, velocity: clpost.bench.synthetic_frame, 24 px of
motion) as EXRs with ``--compression`` into a temporary folder, then per round, interleaved:

* ``plain``: OpenEXR's own read of every channel + write of RGB, depth and velocity with the same
  compression (``OpenEXR.File``; no clpost code) — the I/O floor of a sequence;
* ``clpost I/O``: clpost's reader and atomic writer (``exr.read_frame`` / ``exr.write_frame``);
* ``exposure`` and ``cinematic`` (DoF, 180° motion blur at 24 fps, vignetting, film, grain, print;
  ``--quality``, default draft): :func:`clpost.batch.process_sequence`, overlapped (reads ahead,
  writes behind), and ``… serial``: the same frames one at a time (``process_one``), as the loop
  ran before the overlap.

Reported: ms per frame (wall time of the whole sequence / frames; medians over rounds), each
row's throughput as a multiple of ``plain`` (≥ 0.8 is the target; the median over rounds of each
round's own ratio, so load drifting between rounds cancels) and the process's CPU time per frame
(all threads: what the row costs a loaded machine). ``--rows`` picks rows. Kernels are built in a warm-up
pass first. ``--threads N`` sets OpenEXR's global thread count for every row alike (default: one
per CPU, what ``clpost process`` sets, :func:`clpost.batch.exr_threads`; OpenEXR's own default is 0).
"""
from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path



def _plain_io(src: Path, dst: Path, compression) -> None:
    import OpenEXR

    with OpenEXR.File(str(src), separate_channels=True) as f:
        ch = {k: v.pixels for k, v in f.channels().items()}
    OpenEXR.File({"compression": compression, "type": OpenEXR.scanlineimage}, ch).write(str(dst))


ROWS = ("plain", "clpost I/O", "exposure", "exposure serial", "cinematic", "cinematic serial")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--compression", default="zip")
    ap.add_argument("--quality", default="draft")
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 1,
                    help="OpenEXR global thread count for every row (default: one per CPU)")
    ap.add_argument("--device", default=None)
    ap.add_argument("--rows", default=",".join(ROWS),
                    help="comma-separated rows to run (default all; 'plain' always runs)")
    args = ap.parse_args(argv)

    import warnings

    import OpenEXR

    from clpost import Camera, Pipeline, exr
    from clpost.batch import FrameJob, process_one, process_sequence
    from clpost.bench import synthetic_frame
    from clpost.exr.io import COMPRESSIONS
    from clpost.metering import ExposureWarning

    warnings.simplefilter("ignore", ExposureWarning)
    warnings.simplefilter("ignore", UserWarning)
    OpenEXR.set_global_thread_count(args.threads)
    w, h = (int(v) for v in args.size.lower().split("x"))
    comp = getattr(OpenEXR, COMPRESSIONS[args.compression][0])
    cams = {
        "exposure": Camera(luminance_scale=1.0),
        "cinematic": Camera(luminance_scale=1.0, f_number=2.8, focus_distance_m=4.0, depth_of_field=True,
                            frame_rate_fps=24.0, shutter_s=1 / 48, vignetting="natural",
                            film="kodak-ektar-100"),
    }
    with tempfile.TemporaryDirectory(prefix="clpost-throughput-") as tmp:
        root = Path(tmp)
        srcs = []
        for k in range(args.frames):
            f = synthetic_frame(w, h, seed=k, velocity_px=24.0)
            p = root / f"in.{k:04d}.exr"
            exr.write_frame(p, f, compression=args.compression)
            srcs.append(p)
        out = root / "out"
        out.mkdir()
        pipes = {name: Pipeline(cam, quality=args.quality, device=args.device) for name, cam in cams.items()}

        def jobs(tag):
            return [FrameJob(k, s, out / f"{tag}.{k:04d}.exr") for k, s in enumerate(srcs)]

        def run(name):
            t0, c0 = time.perf_counter(), time.process_time()
            if name == "plain":
                for j in jobs("plain"):
                    _plain_io(j.src, j.dst, comp)
            elif name == "clpost I/O":
                for j in jobs("io"):
                    exr.write_frame(j.dst, exr.read_frame(j.src), compression=args.compression)
            elif name.endswith(" serial"):
                base = name.split()[0]
                for j in jobs(base + "s"):
                    process_one(pipes[base], j, compression=args.compression)
            else:
                process_sequence(pipes[name], jobs(name), overwrite=True, compression=args.compression)
            return ((time.perf_counter() - t0) * 1e3 / args.frames, (time.process_time() - c0) * 1e3 / args.frames)

        wanted = {r.strip() for r in args.rows.split(",")}
        unknown = wanted - set(ROWS)
        if unknown:
            ap.error(f"--rows: unknown {', '.join(sorted(unknown))}; pick from {', '.join(ROWS)}")
        names = [n for n in ROWS if n == "plain" or n in wanted]
        load0 = os.getloadavg()
        for name in {n.split()[0] for n in names} & set(cams):  # build kernels and plans
            process_one(pipes[name], FrameJob(0, srcs[0], out / "warm.exr"), compression=args.compression)
        times = {n: [] for n in names}
        for _ in range(args.rounds):
            for n in names:
                times[n].append(run(n))
        # the floor must write what clpost writes: the same channels, pixel types and compression
        def kind(path):
            with OpenEXR.File(str(path), header_only=True) as f:
                return exr.read_header(path)[0].channels, f.header()["compression"]

        tags = {"plain": "plain", "clpost I/O": "io", **{n: n for n in cams}}
        floor = kind(out / "plain.0000.exr")
        for n in names:
            if not n.endswith(" serial") and kind(out / f"{tags[n]}.0000.exr") != floor:
                print(f"warning: {n} wrote {kind(out / f'{tags[n]}.0000.exr')}, plain {floor}: not the same work")
        med = {n: statistics.median(t for t, _ in v) for n, v in times.items()}
        cpu = {n: statistics.median(c for _, c in v) for n, v in times.items()}
        # each round's own ratio (its rows ran back to back), then the median: robust to load drifting
        ratio = {n: statistics.median(p[0] / t[0] for p, t in zip(times["plain"], v)) for n, v in times.items()}
        print(f"{args.frames} frames {w}x{h}, {args.compression}, quality {args.quality}, OpenEXR threads "
              f"{OpenEXR.global_thread_count() if hasattr(OpenEXR, 'global_thread_count') else '?'}, "
              f"{args.rounds} round(s), device {pipes['exposure'].runtime.name}, {os.cpu_count()} CPUs, load average "
              f"{load0[0]:.1f} before, {os.getloadavg()[0]:.1f} after")
        print("| row | ms/frame | throughput / plain read+write | CPU ms/frame (all threads) |\n|---|---:|---:|---:|")
        for n in names:
            print(f"| {n} | {med[n]:.0f} | {ratio[n]:.2f} | {cpu[n]:.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

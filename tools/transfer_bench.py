"""Host↔device transfer rates of one 1080p RGB float32 frame: pageable NumPy arrays (what
``Plan.run`` uploads and downloads today), pinned (page-locked, ``ALLOC_HOST_PTR``) host memory,
and a fresh output array (first touch of its pages included) — the bound on end-to-end frame
rates on a discrete GPU — and the download thread's host copy out of a page-locked array into a
fresh or a reused one. Median of ``--repeats`` after one warm-up, OpenCL events and wall clock.

    python tools/transfer_bench.py --device nvidia
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import pyopencl as cl

from clpost.runtime import event_ms, get_runtime


def _median(fn, repeats: int) -> tuple[float, float]:
    fn()
    dev, wall = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        ev = fn()
        ev.wait()
        wall.append((time.perf_counter() - t0) * 1e3)
        dev.append(event_ms(ev))
    return statistics.median(dev), statistics.median(wall)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device")
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--repeats", type=int, default=9)
    a = ap.parse_args(argv)
    w, h = (int(v) for v in a.size.split("x"))
    rt = get_runtime(a.device)
    q, ctx = rt.queue, rt.context
    host = np.random.default_rng(0).random((h, w, 3), dtype=np.float32)
    nbytes = host.nbytes
    dbuf = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, nbytes)
    pinned = cl.Buffer(ctx, cl.mem_flags.READ_WRITE | cl.mem_flags.ALLOC_HOST_PTR, nbytes)
    pin_view, _ = cl.enqueue_map_buffer(q, pinned, cl.map_flags.READ | cl.map_flags.WRITE, 0, host.shape,
                                        np.float32)
    pin_view[...] = host
    out = np.empty_like(host)
    rows = [
        ("upload, pageable array", lambda: cl.enqueue_copy(q, dbuf, host, is_blocking=False)),
        ("upload, pinned array", lambda: cl.enqueue_copy(q, dbuf, pin_view, is_blocking=False)),
        ("download, pageable array (reused)", lambda: cl.enqueue_copy(q, out, dbuf, is_blocking=False)),
        ("download, fresh array (np.empty each frame)",
         lambda: cl.enqueue_copy(q, np.empty_like(host), dbuf, is_blocking=False)),
        ("download, pinned array", lambda: cl.enqueue_copy(q, pin_view, dbuf, is_blocking=False)),
    ]
    print(f"{rt.name}: {w}x{h} RGB float32, {nbytes / 1e6:.1f} MB")
    print("| transfer | event ms | wall ms | GB/s (wall) |\n|---|---:|---:|---:|")
    for name, fn in rows:
        d, wl = _median(fn, a.repeats)
        print(f"| {name} | {d:.2f} | {wl:.2f} | {nbytes / wl / 1e6:.1f} |")
    # the download thread's host copy (clpost/stream.py _download) out of a page-locked bounce array:
    # into a fresh array (first touch of its pages: what a caller without out= gets) on one thread
    # and split over threads, and into a reused one
    from concurrent.futures import ThreadPoolExecutor

    pool = ThreadPoolExecutor(4)

    def split(dst, k):
        parts = np.array_split(np.arange(dst.shape[0]), k)
        for f in [pool.submit(np.copyto, dst[p[0]:p[-1] + 1], pin_view[p[0]:p[-1] + 1]) for p in parts]:
            f.result()

    host_rows = [
        ("host copy into the pinned array", lambda: np.copyto(pin_view, host)),
        ("host copy pinned → reused array", lambda: np.copyto(out, pin_view)),
        ("host copy pinned → fresh array, 1 thread", lambda: np.copyto(np.empty_like(host), pin_view)),
        ("host copy pinned → fresh array, 4 threads", lambda: split(np.empty_like(host), 4)),
    ]
    for name, fn in host_rows:
        fn()
        times = []
        for _ in range(a.repeats):
            t0 = time.perf_counter()
            fn()
            times.append((time.perf_counter() - t0) * 1e3)
        wl = statistics.median(times)
        print(f"| {name} | – | {wl:.2f} | {nbytes / wl / 1e6:.1f} |")
    pool.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Per-resolution benchmarks of a plan: OpenCL device time from profiling events (median of
repeats, warm-up excluded), achieved bandwidth against the device's buffer-copy bandwidth measured
in the same run, wall time with host transfers, and the numpy reference of the same plan.

Bytes moved per kernel are counted as each input read once and each output written once
(3 float32 channels in and out for a colour pass).
"""
from __future__ import annotations

import statistics
import time
from dataclasses import asdict, dataclass

import numpy as np

from .camera import Camera
from .frame import Frame
from .pipeline import Pipeline

DEFAULT_SIZES = ((640, 360), (1280, 720), (1920, 1080), (3840, 2160))


def synthetic_frame(width: int, height: int, seed: int = 0) -> Frame:
    """A deterministic HDR test frame: smooth gradients, noise and a few hot pixels, with depth."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    base = 0.5 + 0.4 * np.sin(x[..., None] / 37.0 + np.array([0, 1, 2], np.float32)) * np.cos(y[..., None] / 23.0)
    color = (base * rng.uniform(0.8, 1.2, (height, width, 3))).astype(np.float32)
    hot = rng.integers(0, height * width, size=max(1, height * width // 5000))
    color.reshape(-1, 3)[hot] = 500.0
    depth = (1.0 + 20.0 * y / height).astype(np.float32)
    return Frame(color, depth=depth)


@dataclass
class BenchRow:
    width: int
    height: int
    plan: str
    kernels: dict
    """Per kernel: device ms (median) and achieved GB/s."""
    device_ms: float
    upload_ms: float
    download_ms: float
    wall_ms: float
    numpy_ms: float
    copy_gbps: float
    fused_gbps: float

    @property
    def fps(self) -> float:
        return 1000.0 / self.wall_ms

    def as_dict(self) -> dict:
        d = asdict(self)
        d["fps"] = self.fps
        d["speedup_vs_numpy"] = self.numpy_ms / self.wall_ms
        d["percent_of_copy"] = 100.0 * self.fused_gbps / self.copy_gbps if self.copy_gbps else 0.0
        return d


def copy_bandwidth_gbps(pipeline: Pipeline, nbytes: int, repeats: int) -> float:
    """Device buffer→buffer copy bandwidth (read + write bytes / time), median of repeats."""
    import pyopencl as cl

    from .runtime import event_ms

    rt = pipeline.runtime
    a, b = rt.empty((nbytes // 4,)), rt.empty((nbytes // 4,))
    cl.enqueue_fill_buffer(rt.queue, a, np.float32(1), 0, nbytes).wait()
    times = []
    for i in range(repeats + 2):
        ev = cl.enqueue_copy(rt.queue, b, a, byte_count=nbytes)
        ev.wait()
        if i >= 2:
            times.append(event_ms(ev))
    return 2 * nbytes / (statistics.median(times) * 1e-3) / 1e9


def bench_size(camera: Camera, width: int, height: int, *, quality: str = "final",
               stages: list[str] | None = None, device: str | None = None,
               repeats: int = 10, warmup: int = 2) -> BenchRow:
    pipe = Pipeline(camera, quality=quality, stages=stages, device=device)
    frame = synthetic_frame(width, height)
    per_kernel: dict[str, list[float]] = {}
    walls = []
    for i in range(warmup + repeats):
        t0 = time.perf_counter()
        pipe.run(frame)
        wall = (time.perf_counter() - t0) * 1e3
        if i >= warmup:
            walls.append(wall)
            for k, v in pipe.last_timings.items():
                per_kernel.setdefault(k, []).append(v)
    med = {k: statistics.median(v) for k, v in per_kernel.items()}
    px_bytes = width * height * 3 * 4
    kernels = {k: {"ms": v, "gbps": 2 * px_bytes / (v * 1e-3) / 1e9 if v > 0 else 0.0}
               for k, v in med.items() if k not in ("upload", "download")}
    np_times = []
    for i in range(1 + max(3, repeats // 3)):
        t0 = time.perf_counter()
        pipe.reference(frame)
        if i:
            np_times.append((time.perf_counter() - t0) * 1e3)
    fused = [v["gbps"] for k, v in kernels.items()]
    return BenchRow(
        width=width, height=height, plan="+".join(pipe.plan(frame)) or "(identity)",
        kernels=kernels, device_ms=sum(v["ms"] for v in kernels.values()),
        upload_ms=med.get("upload", 0.0), download_ms=med.get("download", 0.0),
        wall_ms=statistics.median(walls), numpy_ms=statistics.median(np_times),
        copy_gbps=copy_bandwidth_gbps(pipe, px_bytes, repeats),
        fused_gbps=min(fused) if fused else 0.0,
    )


def format_table(rows: list[BenchRow], device_name: str) -> str:
    head = (f"device: {device_name}\n"
            f"{'size':>11} {'plan':<22} {'kernel ms':>9} {'GB/s':>6} {'%copy':>6} {'+xfer ms':>8} "
            f"{'wall ms':>8} {'fps':>7} {'numpy ms':>9} {'vs numpy':>8}")
    lines = [head]
    for r in rows:
        d = r.as_dict()
        lines.append(
            f"{r.width:>5}x{r.height:<5} {r.plan:<22} {r.device_ms:9.2f} {r.fused_gbps:6.1f} "
            f"{d['percent_of_copy']:5.0f}% {r.upload_ms + r.download_ms:8.2f} {r.wall_ms:8.2f} "
            f"{r.fps:7.1f} {r.numpy_ms:9.2f} {d['speedup_vs_numpy']:7.1f}x"
        )
    return "\n".join(lines)

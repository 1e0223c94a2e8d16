r"""A focus pull over planes at known depths: the scene, the thin-lens prediction, a blur measure
and the bench of a pull against a static camera (``tools/bench_focus_pull.py``; the numbers are
in ``docs/measurements.md``).

The scene is fronto-parallel planes side by side (vertical strips), each at one depth and
covered by a fine random texture. The thin lens's blur-circle diameter on the sensor for an
object at depth d with focus u (Hecht, *Optics*, 5th ed., §5.2; the dof stage's own formula):

.. math::

    c = \frac{f}{N} \cdot \frac{f}{u - f} \cdot \frac{|d - u|}{d}

so the sharp frame of a plane is the one whose focus equals its depth (c = 0).
Blur is measured as the texture's gradient energy inside a strip (away from its edges by more
than the largest blur radius) relative to the input's: 1 = untouched, → 0 as the blur grows.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .frame import Frame


def planes_scene(width: int, height: int, depths_m, seed: int = 0) -> Frame:
    """Strips of equal width, strip i at ``depths_m[i]`` metres, a random texture in [0.05, 1]."""
    rng = np.random.default_rng(seed)
    color = (0.05 + 0.95 * rng.random((height, width, 3))).astype(np.float32)
    depth = np.empty((height, width), np.float32)
    edges = np.linspace(0, width, len(depths_m) + 1).round().astype(int)
    for d, x0, x1 in zip(depths_m, edges[:-1], edges[1:]):
        depth[:, x0:x1] = d
    return Frame(color, depth=depth)


def strip_slices(width: int, n: int, margin: int) -> list[slice]:
    """Column ranges of the n strips' interiors (``margin`` px from each edge)."""
    edges = np.linspace(0, width, n + 1).round().astype(int)
    return [slice(int(a) + margin, int(b) - margin) for a, b in zip(edges[:-1], edges[1:])]


def coc_px(depth_m: float, focus_m: float, focal_mm: float, f_number: float, pitch_mm: float) -> float:
    """Thin-lens blur-circle diameter (px) of depth ``depth_m`` with focus ``focus_m``."""
    f = focal_mm / 1000.0
    return (focal_mm / f_number) * f / (focus_m - f) * abs(depth_m - focus_m) / depth_m / pitch_mm


def gradient_energy(img: np.ndarray, cols: slice) -> float:
    """Mean squared horizontal + vertical difference of the luminance-ish mean over ``cols``."""
    y = np.asarray(img, np.float64)[..., :3].mean(axis=-1)[:, cols]
    return float((np.diff(y, axis=0) ** 2).mean() + (np.diff(y, axis=1) ** 2).mean())


def sharpness(out: np.ndarray, ref: np.ndarray, cols: slice) -> float:
    """Gradient energy of ``out`` relative to ``ref`` (each normalised by its mean level, so an
    exposure gain does not count as blur)."""
    a = np.asarray(out, np.float64)[..., :3][:, cols]
    b = np.asarray(ref, np.float64)[..., :3][:, cols]
    return gradient_energy(a / a.mean(), slice(None)) / gradient_energy(b / b.mean(), slice(None))


def write_pull(folder: Path, frame: Frame, focus_m, *, first: int = 1, extra: dict | None = None) -> str:
    """Write the frame once per focus value with the OpenEXR ``focus`` attribute; returns the
    input pattern (``pull.####.exr``)."""
    from . import exr

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for i, u in enumerate(focus_m):
        exr.write_frame(folder / f"pull.{first + i:04d}.exr", frame, header={"focus": float(u), **(extra or {})})
    return str(folder / "pull.####.exr")


def bench(camera, frame: Frame, focus_m, repeats: int = 3, device: str | None = None) -> dict:
    """Seconds per frame of a pull (focus per frame) and of a static camera on one pipeline each,
    after one warm-up pass; with the plans and programs each built."""
    from .pipeline import Pipeline

    out = {}
    for name, cams in (("static", [camera] * len(focus_m)),
                       ("pull", [camera.with_(focus_distance_m=float(u)) for u in focus_m])):
        pipe = Pipeline(camera, device=device)
        rt = pipe.runtime
        programs0 = len(rt._programs)
        t0 = time.perf_counter()
        pipe.run(frame, cams[0])  # warm-up: builds the plan
        first = time.perf_counter() - t0
        plans, programs = len(pipe._plans), len(rt._programs)
        times = []
        for _ in range(repeats):
            for cam in cams:
                t0 = time.perf_counter()
                pipe.run(frame, cam)
                times.append(time.perf_counter() - t0)
        out[name] = {"first_frame_s": first, "median_frame_s": float(np.median(times)),
                     "plans": len(pipe._plans), "plans_after_warmup": plans,
                     "programs_built": len(rt._programs) - programs0,
                     "programs_after_warmup": programs - programs0, "frames": len(times)}
    return out


def contact_sheet(frames: list[np.ndarray], gap: int = 4) -> np.ndarray:
    """The frames stacked top to bottom with a black gap (a (H·n + gap·(n−1), W, 3) image)."""
    h, w = frames[0].shape[:2]
    sheet = np.zeros((h * len(frames) + gap * (len(frames) - 1), w, 3), np.float32)
    for i, f in enumerate(frames):
        sheet[i * (h + gap):i * (h + gap) + h] = np.asarray(f)[..., :3]
    return sheet



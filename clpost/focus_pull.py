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
    """Strips of equal width, strip i at ``depths_m[i]`` metres, a texture in [0.05, 1]: per-pixel
    random colour (what blur wipes out first) on a checkerboard of width/48-px squares (what an
    eye sees blur on in a contact sheet)."""
    rng = np.random.default_rng(seed)
    sq = max(width // 48, 2)
    yy, xx = np.mgrid[0:height, 0:width]
    checker = (((yy // sq) + (xx // sq)) % 2).astype(np.float32)[..., None]
    color = (0.05 + 0.95 * (0.4 * rng.random((height, width, 3)) + 0.6 * checker)).astype(np.float32)
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
    """Seconds per frame of a pull (the focus changes every frame) against static cameras at the
    same focus values (the dof's cost depends on the blur sizes, so each pull frame is compared
    with a static run at its own focus), after one warm-up frame; with the plans each pipeline
    holds and the programs each built. Interleaved (static u, pull) per repeat, so machine load
    drifts hit both."""
    from .pipeline import Pipeline

    cams = [camera.with_(focus_distance_m=float(u)) for u in focus_m]
    static = {u: Pipeline(c, device=device) for u, c in zip(focus_m, cams)}
    pull = Pipeline(cams[0], device=device)
    rt = pull.runtime
    programs0 = len(rt._programs)
    t0 = time.perf_counter()
    pull.run(frame, cams[0])  # warm-up: builds the plan (and the programs)
    first = time.perf_counter() - t0
    plans_warm, programs_warm = len(pull._plans), len(rt._programs)
    for u, c in zip(focus_m, cams):
        static[u].run(frame, c)
    t_static = {u: [] for u in focus_m}
    t_pull = {u: [] for u in focus_m}
    for _ in range(repeats):
        for u, c in zip(focus_m, cams):
            t0 = time.perf_counter()
            static[u].run(frame, c)
            t_static[u].append(time.perf_counter() - t0)
        for u, c in zip(focus_m, cams):  # the pull: one pipeline, the focus changes every frame
            t0 = time.perf_counter()
            pull.run(frame, c)
            t_pull[u].append(time.perf_counter() - t0)
    per_focus = [{"focus_m": u, "static_s": float(np.median(t_static[u])), "pull_s": float(np.median(t_pull[u]))}
                 for u in focus_m]
    return {"first_frame_s": first, "per_focus": per_focus,
            "static_median_s": float(np.median(sum(t_static.values(), []))),
            "pull_median_s": float(np.median(sum(t_pull.values(), []))),
            "pull_over_static": float(np.median([r["pull_s"] / r["static_s"] for r in per_focus])),
            "pull_plans": len(pull._plans), "pull_plans_after_warmup": plans_warm,
            "programs_built_after_warmup": len(rt._programs) - programs_warm,
            "programs_built_by_warmup": programs_warm - programs0, "frames": repeats * len(focus_m)}


def contact_sheet(frames: list[np.ndarray], gap: int = 4) -> np.ndarray:
    """The frames stacked top to bottom with a black gap (a (H·n + gap·(n−1), W, 3) image)."""
    h, w = frames[0].shape[:2]
    sheet = np.zeros((h * len(frames) + gap * (len(frames) - 1), w, 3), np.float32)
    for i, f in enumerate(frames):
        sheet[i * (h + gap):i * (h + gap) + h] = np.asarray(f)[..., :3]
    return sheet



"""The dof speed/accuracy trade: milliseconds per frame (OpenCL events, median of repeats, warm-up
excluded) and error against the accumulation-buffer thin-lens reference
(:mod:`clpost.render.thin_lens`) for each quality level, on the demo scene.

Errors:

- PSNR on linear values: :math:`10\\log_{10}(P^2/\\mathrm{MSE})` with P the reference's maximum
  (the brightest lamp's bokeh, the usual HDR convention); no clipping, so the lamps' bokeh dominate.
- FLIP (Andersson et al. 2020, ``flip-evaluator`` from PyPI, LDR mode, 67 ppd) on sRGB-encoded
  images exposed so diffuse white ≈ 0.5 and clipped to [0, 1] — what a viewer sees.

Camera: the demo's 50 mm at f/2 focused at 3 m, six blades; spherical aberration and cat's-eye
off, because the reference is the ideal thin lens.
"""
from __future__ import annotations

import statistics
import time
from dataclasses import dataclass

import numpy as np

from .camera import Camera
from .colorspace import cctf_encode
from .pipeline import Pipeline
from .stages import QUALITIES

DOF_BENCH_SIZES = ((640, 360), (1280, 720))
BENCH_CAMERA = dict(lens="thin:50", f_number=2.0, focus_distance_m=3.0, shutter_s=1 / 50, blades=6,
                    depth_of_field=True)
VIEW_SCALE = 0.5


def srgb(linear: np.ndarray) -> np.ndarray:
    """sRGB code values in [0, 1] of a linear image (the FLIP inputs)."""
    return cctf_encode(linear, "sRGB")


def psnr_linear(ref: np.ndarray, test: np.ndarray) -> float:
    peak = float(np.max(ref))
    mse = float(np.mean((np.asarray(test, np.float64) - ref) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(peak * peak / mse)


def flip_ldr(ref: np.ndarray, test: np.ndarray) -> float | None:
    """Mean FLIP of the sRGB views, or None where flip-evaluator is not installed."""
    try:
        import flip_evaluator
    except ImportError:
        return None
    a = srgb(ref * VIEW_SCALE).astype(np.float32)
    b = srgb(np.asarray(test, np.float64) * VIEW_SCALE).astype(np.float32)
    return float(flip_evaluator.evaluate(a, b, "LDR", inputsRGB=True, applyMagma=False)[1])


@dataclass
class DofRow:
    width: int
    height: int
    quality: str
    ms: float
    psnr_db: float
    flip: float | None


def run_dof_bench(sizes=DOF_BENCH_SIZES, samples=(128, 64), repeats: int = 5, device: str | None = None,
                  log=print, save_dir=None):
    """Rows per (size, quality) plus the pinhole row and the reference's convergence
    ``{size: (M, [(k, PSNR of the k-sample average vs the M-sample one)])}``."""
    from .render import DemoScene, PyVistaRenderer
    from .render.thin_lens import accumulate

    camera = Camera(**BENCH_CAMERA)
    rows, convergence = [], {}
    renderer = PyVistaRenderer(DemoScene.default())
    try:
        for (w, h), m in zip(sizes, samples):
            t0 = time.perf_counter()
            checkpoints = tuple(k for k in (4, 8, 16, 32, 64, 128, 256) if k < m)
            ref_frame, partial = accumulate(camera, (w, h), m, renderer=renderer, checkpoints=checkpoints)
            pin = renderer.render(camera, (w, h), 0)
            log(f"{w}x{h}: reference from {m} aperture samples in {time.perf_counter() - t0:.0f} s")
            ref = ref_frame.color.astype(np.float64)
            convergence[(w, h)] = (m, [(k, psnr_linear(ref, partial[k])) for k in checkpoints])
            rows.append(DofRow(w, h, "pinhole", 0.0, psnr_linear(ref, pin.color), flip_ldr(ref, pin.color)))
            log(f"  pinhole: PSNR {rows[-1].psnr_db:.2f} dB, FLIP {rows[-1].flip}")
            if save_dir is not None:
                from .atomic import write_png
                write_png(f"{save_dir}/reference_{w}x{h}.png", ref * VIEW_SCALE)
                np.savez(f"{save_dir}/reference_{w}x{h}.npz", ref=ref_frame.color, pinhole=pin.color,
                         depth=pin.depth)
            for q in QUALITIES:
                pipe = Pipeline(camera, quality=q, stages=["dof"], device=device)
                times = []
                for i in range(repeats + 1):
                    out = pipe.run(pin).color
                    if i:
                        times.append(pipe.last_timings["dof"])
                rows.append(DofRow(w, h, q, statistics.median(times), psnr_linear(ref, out), flip_ldr(ref, out)))
                if save_dir is not None:
                    write_png(f"{save_dir}/{q}_{w}x{h}.png", out * VIEW_SCALE)
                    np.save(f"{save_dir}/{q}_{w}x{h}.npy", out)
                log(f"  {q}: {rows[-1].ms:.1f} ms, PSNR {rows[-1].psnr_db:.2f} dB, FLIP {rows[-1].flip}")
    finally:
        renderer.close()
    return rows, convergence


def format_dof_table(rows, convergence, device_name: str) -> str:
    lines = [f"device: {device_name}", "",
             "| size | quality | dof ms/frame (median) | PSNR linear (dB) | FLIP (sRGB, mean) |",
             "|---|---|---|---|---|"]
    for r in rows:
        flip = "n/a" if r.flip is None else f"{r.flip:.4f}"
        ms = "—" if r.quality == "pinhole" else f"{r.ms:.1f}"
        lines.append(f"| {r.width}×{r.height} | {r.quality} | {ms} | {r.psnr_db:.2f} | {flip} |")
    lines += ["", "Reference convergence (PSNR in dB of the average of the first M aperture samples against "
              "the full reference; it bounds how finely the table above can rank errors):", "",
              "| size | full M | M: PSNR |", "|---|---|---|"]
    for (w, h), (m, pts) in convergence.items():
        lines.append(f"| {w}×{h} | {m} | "
                     + ", ".join(f"{k}: {p:.1f}" for k, p in pts) + " |")
    return "\n".join(lines)


def plot(rows, path) -> None:
    """Error (PSNR) against time per quality level, one line per size."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for size in sorted({(r.width, r.height) for r in rows}):
        rs = [r for r in rows if (r.width, r.height) == size and r.quality != "pinhole"]
        ax.plot([r.ms for r in rs], [r.psnr_db for r in rs], "o-", label=f"{size[0]}×{size[1]}")
        for r in rs:
            ax.annotate(r.quality, (r.ms, r.psnr_db))
    ax.set_xscale("log")
    ax.set_xlabel("dof device ms / frame (OpenCL events, median)")
    ax.set_ylabel("PSNR vs thin-lens reference (dB, linear)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)

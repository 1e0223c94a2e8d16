r"""Fidelity metrics against an independent renderer's truth (docs/fidelity.md): image error as a
viewer sees it, and what happens to each small emitter.

Image error:

- :func:`psnr_srgb`: PSNR of the sRGB views (linear × ``exposure``, clipped to [0, 1], sRGB-encoded),
  peak 1: :math:`10\log_{10}(1/\mathrm{MSE})`. Clipping means a saturated bokeh disc counts by its
  shape, not by its (noisy, unbounded) linear values.
- :func:`flip_ldr`: mean FLIP (Andersson et al. 2020, ``flip-evaluator``, LDR, 67 ppd) of the same
  views; ``None`` when ``flip-evaluator`` is not installed.

Emitters (lamps a few pixels wide, given by pixel centre and depth):

- thin-lens circle of confusion on the image of a camera that does not breathe (Cycles' thin lens),
  diameter in pixels :math:`c = (f/N)\,f_{px}\,|1/u - 1/S|` with :math:`f_{px} = f W / s_w`
  (:func:`coc_px`);
- :func:`saturated_area`: pixels within a disc whose luminance reaches ``level`` (1 = the view's
  white) — the visible size of a bokeh disc;
- on lamp-only images (the renderer's emission pass; for a post-process, the result on the full
  input minus the result on the input without its emission — exact for a method linear in light,
  and for any method it is the light the lamps added): :func:`halo_pixels`, pixels more than
  ``inner`` px from an in-focus lamp above ``level`` — light spread where a sharp lamp has none;
  :func:`window_energy`, the lamp's light in a window, whose ratio test/truth is the energy ratio.

Luminance is Rec. 709 Y of linear RGB. Pixel coordinates follow docs/conventions.md (pixel (i, j)
is centred at x = i, y = j).
"""
from __future__ import annotations

import math

import numpy as np

from .colorspace import cctf_encode

REC709_Y = np.array([0.2126, 0.7152, 0.0722])


def read_rgb(path, prefix: str = "") -> np.ndarray:
    """R, G, B of an EXR (or ``prefix``R/G/B, or a Blender pass ``<layer>.<prefix>R``…) as float32
    (H, W, 3): how the Cycles truths and passes are read."""
    import OpenEXR

    from .errors import InputError

    for part in OpenEXR.File(str(path), separate_channels=True).parts:
        ch = part.channels
        for pre in (prefix, *(n[:-1] for n in ch if prefix and n.endswith("." + prefix + "R"))):
            if all(pre + c in ch for c in "RGB"):
                return np.stack([ch[pre + c].pixels for c in "RGB"], -1).astype(np.float32)
    raise InputError(f"{path}: no {prefix or 'R, G, B'} channels; give an EXR with {prefix}R, {prefix}G, {prefix}B")


def srgb_view(linear: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """sRGB code values in [0, 1]: ``linear × exposure`` clipped, then encoded (float64)."""
    x = np.clip(np.asarray(linear, np.float64)[..., :3] * exposure, 0.0, 1.0)
    return cctf_encode(x, "sRGB")


def psnr_srgb(ref: np.ndarray, test: np.ndarray, exposure: float = 1.0) -> float:
    """PSNR (dB) of the sRGB views, peak 1; ``inf`` for identical views."""
    if np.shape(ref)[:2] != np.shape(test)[:2]:
        raise ValueError(f"psnr_srgb: shapes differ, {np.shape(ref)} vs {np.shape(test)}")
    mse = float(np.mean((srgb_view(ref, exposure) - srgb_view(test, exposure)) ** 2))
    return float("inf") if mse == 0 else 10.0 * math.log10(1.0 / mse)


def flip_ldr(ref: np.ndarray, test: np.ndarray, exposure: float = 1.0) -> float | None:
    """Mean LDR-FLIP of the sRGB views, or None where ``flip-evaluator`` is not installed."""
    try:
        import flip_evaluator
    except ImportError:
        return None
    a = srgb_view(ref, exposure).astype(np.float32)
    b = srgb_view(test, exposure).astype(np.float32)
    return float(flip_evaluator.evaluate(a, b, "LDR", inputsRGB=True, applyMagma=False)[1])


def luminance(rgb: np.ndarray) -> np.ndarray:
    return np.asarray(rgb, np.float64)[..., :3] @ REC709_Y


def coc_px(depth_m, focus_m: float, focal_mm: float, f_number: float, sensor_w_mm: float, width: int):
    """Thin-lens CoC diameter in pixels on a non-breathing image (Cycles' thin lens: the aperture of
    diameter f/N at the pinhole, rays converging on the plane at ``focus_m``)."""
    f_px = focal_mm * width / sensor_w_mm
    aperture_m = focal_mm / 1000.0 / f_number
    return aperture_m * f_px * np.abs(1.0 / np.asarray(depth_m, np.float64) - 1.0 / focus_m)


def _dist(shape, x: float, y: float) -> np.ndarray:
    jj, ii = np.mgrid[0:shape[0], 0:shape[1]]
    return np.hypot(ii - x, jj - y)


def saturated_area(img: np.ndarray, x: float, y: float, radius: float, level: float = 1.0) -> int:
    """Pixels within ``radius`` of (x, y) whose luminance is ≥ ``level``."""
    inside = _dist(img.shape, x, y) <= radius
    return int(np.count_nonzero(inside & (luminance(img) >= level)))


def halo_pixels(lamp_img: np.ndarray, x: float, y: float, radius: float, level: float, inner: float = 3.0) -> int:
    """Pixels with inner < distance ≤ radius from (x, y) where the lamp-only image's luminance
    exceeds ``level``."""
    d = _dist(lamp_img.shape, x, y)
    return int(np.count_nonzero((d > inner) & (d <= radius) & (luminance(lamp_img) > level)))


def window_energy(lamp_img: np.ndarray, x: float, y: float, radius: float) -> float:
    """Luminance of the lamp-only image summed within ``radius`` of (x, y)."""
    return float(np.sum(luminance(lamp_img)[_dist(lamp_img.shape, x, y) <= radius]))


def emitter_metrics(test: np.ndarray, truth: np.ndarray, lamp_test: np.ndarray, lamp_truth: np.ndarray,
                    lamp: dict, camera: dict, white: float, exposure: float = 1.0,
                    halo_radius: float = 30.0) -> dict:
    """Per-lamp comparison of a result with the truth. ``test``/``truth``: the full images;
    ``lamp_test``/``lamp_truth``: the lamps alone (truth: the renderer's emission pass; test: the
    method on the full input minus the method on the input without its emission pass — both linear
    in the input's light). ``lamp``: x_px, y_px, depth_m, diameter_px; ``camera``: focus_m,
    focal_mm, f_number, sensor_mm (width).

    In focus (CoC < 2 px): halo pixels (lamp-only luminance > 5 % of ``white`` beyond 3 px, within
    ``halo_radius``), test and truth. Defocused: saturated area of the disc in the full images
    (luminance ≥ the view's white, 1/exposure) within the disc radius + lamp radius + 3 px. Always:
    the lamp's energy ratio over that window (None where the truth shows no light of it, e.g. a
    hidden lamp)."""
    h, w = truth.shape[:2]
    c = float(coc_px(lamp["depth_m"], camera["focus_m"], camera["focal_mm"], camera["f_number"],
                     camera["sensor_mm"], w))
    x, y = lamp["x_px"], lamp["y_px"]
    window = c / 2 + lamp["diameter_px"] / 2 + 4.5
    out = {"name": lamp["name"], "coc_px": c, "in_focus": c < 2.0}
    if out["in_focus"]:
        level = 0.05 * white
        out["halo_test"] = halo_pixels(lamp_test, x, y, halo_radius, level)
        out["halo_truth"] = halo_pixels(lamp_truth, x, y, halo_radius, level)
    else:
        out["area_test"] = saturated_area(test, x, y, window, 1.0 / exposure)
        out["area_truth"] = saturated_area(truth, x, y, window, 1.0 / exposure)
        out["area_ratio"] = out["area_test"] / out["area_truth"] if out["area_truth"] else None
    e_truth = window_energy(lamp_truth, x, y, window)
    out["energy_truth"] = e_truth
    out["energy_ratio"] = window_energy(lamp_test, x, y, window) / e_truth if e_truth > 1e-3 * white else None
    return out


def without_lamps(frame, emit: np.ndarray):
    """``frame`` minus its emission pass ``emit`` (linear RGB, clipped at 0): the same scene with the
    lamps' light removed, the input of the lamp-only image of a post-process."""
    from .frame import Frame

    return Frame(color=np.maximum(frame.color[..., :3] - emit, 0.0).astype(np.float32), depth=frame.depth,
                 velocity=frame.velocity, alpha=frame.alpha, front=frame.front)


def lamp_metrics(run, data, entry: dict, frame, white: float, truth: str = "dof", lamps=None) -> list[dict]:
    """:func:`emitter_metrics` of each lamp of a Cycles manifest ``entry`` in folder ``data``
    (``lamps``: a subset) for a post-process ``run(frame) -> linear RGB`` against ``truth``: the
    result's lamp-only image is its result on ``frame`` minus its result on :func:`without_lamps`
    of the pinhole's Emission pass."""
    from pathlib import Path

    data = Path(data)
    t = data / entry["truths"][truth]["file"]
    out = run(frame)
    lamp_img = out - run(without_lamps(frame, read_rgb(data / entry["pinhole"]["file"], "Emission.")))
    truth_img, truth_lamps = read_rgb(t), read_rgb(t, "emit.")
    return [emitter_metrics(out, truth_img, lamp_img, truth_lamps, lamp, entry["shot"], white)
            for lamp in (entry["lamps"] if lamps is None else lamps)]


def motion_box(velocity: np.ndarray, shutter_frames: float, margin: int = 4, threshold: float = 0.5):
    """(y0, y1, x0, x1) bounding the pixels that move by more than ``threshold`` px per frame, grown
    by the longest blur (|v|·shutter) + ``margin``; None when nothing moves."""
    speed = np.hypot(velocity[..., 0], velocity[..., 1])
    moving = speed > threshold
    if not moving.any():
        return None
    grow = int(math.ceil(float(speed.max()) * shutter_frames)) + margin
    jj, ii = np.nonzero(moving)
    h, w = speed.shape
    return (max(0, jj.min() - grow), min(h, jj.max() + grow + 1), max(0, ii.min() - grow), min(w, ii.max() + grow + 1))


def cycles_camera(shot: dict, width: int, height: int, dof: bool = True, motion: bool = False):
    r"""The clpost :class:`~clpost.camera.Camera` that images like a Blender camera with Cycles' thin
    lens (``shot``: focal_mm, sensor_mm (width, horizontal fit), f_number, focus_m, blades,
    rotation_deg, fps, shutter_frames).

    Cycles' thin lens does not breathe: the image keeps the pinhole's focal length f at any focus,
    and the aperture of diameter f/N sits at the pinhole, so a point at depth u spreads over
    :math:`(f/N)\,f\,|1/u - 1/S|` on the film. clpost's thin lens renders with the focused focal
    length :math:`F = f' S/(S - f')` and CoC :math:`(f'/N')\,F\,|1/u - 1/S|` (docs/conventions.md,
    "Breathing"); the two agree exactly for :math:`f' = f S/(S + f)` (so F = f) and
    :math:`N' = N f'/f` (same aperture diameter). ``thin:50`` at f/N instead would enlarge every
    CoC by S/(S − f): 2.6 % at 2 m, 20 % at 0.3 m.
    """
    from .camera import Camera

    f, s_mm = shot["focal_mm"], shot["focus_m"] * 1000.0
    f_lens = f * s_mm / (s_mm + f)
    kw = dict(lens=f"thin:{f_lens:.6f}", f_number=shot["f_number"] * f_lens / f, focus_distance_m=shot["focus_m"],
              sensor_mm=(shot["sensor_mm"], shot["sensor_mm"] * height / width), depth_of_field=dof,
              blades=shot["blades"], blade_rotation_deg=shot["rotation_deg"])
    if motion:
        kw.update(frame_rate_fps=shot["fps"], shutter_angle_deg=360.0 * shot["shutter_frames"])
    return Camera(**kw)


def cycles_layers(data, entry: dict):
    """The two-layer frame of a Cycles manifest ``entry`` with ``layers`` (tools/cycles_truth/make.py
    ``--layers``): its ``bg.exr`` with its ``fg.exr`` (premultiplied, as a transparent film writes
    it) as the :attr:`~clpost.frame.Frame.front` layer."""
    from pathlib import Path

    from .exr import read_frame
    from .frame import front_of

    path = Path(data) / entry["layers"]["fg"]["file"]
    bg = read_frame(Path(data) / entry["layers"]["bg"]["file"])
    return bg.with_front(front_of(read_frame(path), str(path)), copy=False)


CYCLES_STAGES = {"dof": ["dof"], "motion": ["motion_blur"], "dofmotion": ["dof", "motion_blur"]}
"""A Cycles truth's kind -> the clpost stages that reproduce it from the pinhole export."""


def cycles_pipeline(entry: dict, kind: str, quality: str, front: bool = False):
    """The :class:`~clpost.pipeline.Pipeline` that reproduces truth ``kind`` of a Cycles manifest
    ``entry`` from its pinhole export (:func:`cycles_camera`, :data:`CYCLES_STAGES`); ``front``:
    from its two layers (the ``front_layer`` stage added)."""
    from .pipeline import Pipeline

    w, h = entry["size"]
    cam = cycles_camera(entry["shot"], w, h, dof=kind != "motion", motion=kind != "dof")
    stages = CYCLES_STAGES[kind] + (["front_layer"] if front else [])
    return Pipeline(cam, quality=quality, stages=stages)

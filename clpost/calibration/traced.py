r"""A traced ``lens_data`` lens's distortion as an OpenCV radial model (what the distortion
stage applies when a real lens has no calibration file)."""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from .model import OpenCVModel

TRACED_SOURCE = "traced distortion curve"
"""Marks a model traced from a lens (not a user's calibration) in ``OpenCVModel.source``."""


@lru_cache(maxsize=32)
def _radial_fit(lens: str, focus_distance_m: float, f_number: float, r_max_mm: float):
    """k1, k2, k3 least-squares fitted to the traced distortion curve over image heights up to
    ``r_max_mm``, and the fit's worst residual in percent."""
    from ..optics import lens_curves

    c = lens_curves(lens, focus_distance_m, f_number)
    keep = c.image_height_mm <= r_max_mm + 1e-9
    t = np.tan(np.radians(c.field_angle_deg[keep]))
    d = c.distortion_pct[keep] / 100.0
    a = np.stack([t ** 2, t ** 4, t ** 6], -1)
    k = np.linalg.lstsq(a, d, rcond=None)[0]
    return tuple(float(v) for v in k), float(100.0 * np.max(np.abs(a @ k - d), initial=0.0))


def lens_distortion_model(camera, size: tuple[int, int]) -> "OpenCVModel | None":
    r"""The traced lens's distortion as an OpenCV radial model at ``size`` (None for a thin lens,
    with ``camera.lens_distortion`` off, or when the lens is distortion-free to 0.001 %).

    The traced curve gives :math:`D(\theta) = r_{real}/r_{par} - 1` against the chief ray's
    object-space angle θ (:mod:`clpost.optics.curves`); the pinhole render puts that ray at the
    normalised radius :math:`\tan\theta`, so :math:`x_d = x_u (1 + D)` is OpenCV's radial model
    with :math:`D \approx k_1 t^2 + k_2 t^4 + k_3 t^6`, t = tan θ, fitted by least squares over the
    sensor's half diagonal (the worst residual is kept in the model's ``source``). The scale is
    the camera's own (f = v / pixel pitch): the curve sets the shape, the focus sets the size.
    """
    if camera.optics is None or not camera.lens_distortion:
        return None
    w, h = (int(v) for v in size)
    return _traced_model(camera.lens, camera.focus_from_film_m, camera.f_number, (w, h), camera.intrinsics(w, h),
                         camera.pixel_pitch_mm(w))


@lru_cache(maxsize=32)
def _traced_model(lens: str, focus_distance_m: float, f_number: float, size: tuple[int, int],
                  intrinsics: tuple[float, float, float, float], pitch_mm: float) -> "OpenCVModel | None":
    """:func:`lens_distortion_model` per (lens, focus, f-number, size, K, pitch): the same frozen
    model object every frame, so the caches keyed on it downstream hit."""
    w, h = size
    r_max = 0.5 * math.hypot(w * pitch_mm, h * pitch_mm)
    (k1, k2, k3), resid = _radial_fit(lens, focus_distance_m, f_number, r_max)
    if max(abs(k1), abs(k2), abs(k3)) < 1e-5:
        return None
    fx, fy, cx, cy = intrinsics
    return OpenCVModel(w, h, fx, fy, cx, cy, k1=k1, k2=k2, k3=k3,
                       source=f"{lens} {TRACED_SOURCE}, fit residual {resid:.3g} %")

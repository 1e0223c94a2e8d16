"""The thin-lens circle of confusion on the film: the one formula the DoF stage, the traced bokeh
table (:mod:`clpost.optics.pencil`) and the references share."""
from __future__ import annotations

import math

import numpy as np


def coc_mm(camera, depth_m) -> np.ndarray:
    r"""Signed CoC *diameter* on the film in mm (far > 0): :math:`c = \frac{fF}{N}(1/u - 1/S)`.

    Depths S and the focus depth u are measured from the pinhole (a real lens's entrance pupil,
    diameter f/N). The cone from a point at S through the pupil cuts the sharp plane at u in a disc
    of diameter (f/N)·|u − S|/S, which the lens images at magnification F/u, F the
    :attr:`~clpost.camera.Camera.render_focal_length_mm` (paraxially exact; thin lens F = v, the
    classic f v/N (1/u − 1/S))."""
    s = np.asarray(depth_m, dtype=np.float64)
    u = camera.focused_depth_m
    inv_u = 0.0 if math.isinf(u) else 1.0 / (u * 1e3)
    with np.errstate(divide="ignore"):
        inv_s = np.where(np.isinf(s), 0.0, 1.0 / (s * 1e3))
    return camera.focal_length_mm * camera.render_focal_length_mm / camera.f_number * (inv_u - inv_s)

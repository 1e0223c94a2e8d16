"""Highlight thresholds of the stages that act on bright sources only (ghosts, glare): a threshold
is given in multiples of the exposure's saturation and compared in scene values, before exposure
(scene value = multiple / exposure gain, :func:`clpost.photometry.exposure_gain`)."""
from __future__ import annotations

import numpy as np


def scene_threshold(camera, multiple: float) -> float:
    """The scene value of ``multiple`` × the exposure's saturation."""
    from ..photometry import exposure_gain

    return multiple / exposure_gain(camera)


def below_threshold(camera, frame, multiple: float, what: str) -> str | None:
    """The skip reason when no pixel of ``frame`` exceeds ``multiple`` × saturation, else None."""
    t = scene_threshold(camera, multiple)
    peak = float(np.max(frame.color)) if frame.color.size else 0.0
    if peak > t:
        return None
    return f"no {what} above the threshold ({multiple:g} × saturation = {t:.3g}; brightest pixel {peak:.3g})"

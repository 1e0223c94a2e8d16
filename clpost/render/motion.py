r"""Reference motion blur by sub-frame accumulation: the ground truth for the motion_blur stage.

The demo scene's motions are functions of a real frame index (:class:`~clpost.render.demo_scene.
RigidMotion`), so the renderer can show the scene at any time. A shutter open for the fraction
s = ``shutter_s`` × ``frame_rate_fps`` of a frame, centred on frame i (as the motion_blur stage
assumes), is split into K equal slices; slice k is rendered at its midpoint

.. math::

    \tau_k = i - \frac{s}{2} + \frac{(k + \tfrac12)\,s}{K}, \qquad
    C = \frac1K \sum_{k=0}^{K-1} C(\tau_k)

and accumulated exactly (each slice stands for s/K of a frame, :mod:`clpost.expose`). As K grows
this converges to the time integral (midpoint rule: error O(1/K²) for smooth motion; visibility
changes make it O(1/K) at silhouettes).

Rolling shutter (``readout_time_s`` = r > 0): row y is open during
:math:`[\tau_y - s/2, \tau_y + s/2]` with :math:`\tau_y = i + rF\,(y/(H-1) - \tfrac12)`. Slices of
width s/K are rendered across the union of all rows' intervals and each row takes every slice with
the exact overlap of the slice's interval and its own (per-row sub-frame selection).

Depth and velocity of the result are those of frame i (the centre of the shutter), which is what
a renderer hands the post-process version.
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np

from ..camera import Camera
from ..errors import InputError
from ..frame import Frame
from .demo_scene import DemoScene
from .pyvista_renderer import PyVistaRenderer


def _fraction(camera: Camera) -> float:
    if camera.frame_rate_fps is None or camera.shutter_s is None:
        raise InputError("a motion-blur reference needs Camera.frame_rate_fps (--fps) and a manual shutter_s")
    return float(camera.shutter_s) * float(camera.frame_rate_fps)


def render_motion_blur_reference(camera: Camera, size: tuple[int, int], frame_index: float = 0.0,
                                 subframes: int = 64, scene: DemoScene | None = None,
                                 renderer: PyVistaRenderer | None = None,
                                 camera_motion: bool = False) -> Frame:
    """Frame ``frame_index`` of the demo scene with exact motion blur from ``subframes`` slices
    of the shutter (rolling shutter per row when ``camera.readout_time_s`` > 0)."""
    if int(subframes) != subframes or subframes < 1:
        raise InputError(f"subframes={subframes!r} must be an integer >= 1 (e.g. 64)")
    s = _fraction(camera)
    own = renderer is None
    r = renderer or PyVistaRenderer(scene if scene is not None else DemoScene.default(camera_motion=camera_motion))
    try:
        centre = r.render(camera, size, frame_index)
        w, h = centre.width, centre.height
        ro = camera.readout_time_s * camera.frame_rate_fps
        if ro == 0 or h == 1:
            from ..expose import ExposureAccumulator

            acc = ExposureAccumulator((w, h), Fraction(1))      # time in frames: fps = 1
            for k in range(subframes):
                tau = frame_index - s / 2 + (k + 0.5) * s / subframes
                acc.add(r.render(camera, size, tau).color, Fraction(1, subframes))
            color = acc.partial().mean()
        else:
            # slices of width s/K covering every row's interval; per-row exact overlaps (float64)
            delta = s / subframes
            lo, hi = frame_index - ro / 2 - s / 2, frame_index + ro / 2 + s / 2
            n = int(np.ceil((hi - lo) / delta - 1e-9))
            rows = np.arange(h, dtype=np.float64)
            tau_y = frame_index + ro * (rows / (h - 1) - 0.5)
            acc = np.zeros((h, w, 3))
            wsum = np.zeros(h)
            for k in range(n):
                a, b = lo + k * delta, lo + (k + 1) * delta
                wy = np.clip(np.minimum(b, tau_y + s / 2) - np.maximum(a, tau_y - s / 2), 0.0, None)
                if not wy.any():
                    continue
                img = r.render(camera, size, (a + b) / 2).color.astype(np.float64)
                acc += wy[:, None, None] * img
                wsum += wy
            color = (acc / wsum[:, None, None]).astype(np.float32)
        meta = dict(centre.metadata, motion_blur_reference={"subframes": int(subframes), "shutter_fraction": s,
                                                            "readout_frames": ro})
        return centre.replace(color=color, metadata=meta)
    finally:
        if own:
            r.close()

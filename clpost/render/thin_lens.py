r"""The dof ground truth: accumulation-buffer thin-lens rendering (``quality="reference"``).

Haeberli & Akeley, "The Accumulation Buffer", SIGGRAPH 1990, and Heidrich, Slusallek & Seidel,
"An Image-Based Model for Realistic Lens Systems in Interactive Computer Graphics", GI 1997,
§2.3: a thin lens focused at u is the average of pinhole images taken from points a of its
aperture, each with a frustum sheared so that all of them agree on the plane at u. A point at
planar depth S then lands at

.. math::

    x(a) = x_0 + f_{px}\,a\,\Big(\frac1u - \frac1S\Big)

which sweeps exactly the thin-lens blur disc of :mod:`clpost.stages.dof` (radius
:math:`f_{px}\,\frac{f}{2N}\,(1/u - 1/S)`) — with correct occlusion, because every view is a
real visibility render. Samples: a golden-angle (Vogel) spiral over the disc of radius f/(2N)
(the entrance pupil), kept where they fall inside the aperture polygon of
:func:`clpost.stages.dof.aperture_radius` (same blades, rotation and roundness as the gather),
all with equal weight. The reference is the ideal thin lens: no spherical aberration texture and
no cat's-eye (set those to 0 when comparing). It converges as O(1/√M) in noise and as the
sampling of the disc edges in M; :func:`accumulate` returns partial averages for a convergence
plot.
"""
from __future__ import annotations

import math

import numpy as np

from ..camera import Camera
from ..errors import InputError
from ..frame import Frame


def aperture_samples(camera: Camera, count: int) -> np.ndarray:
    """``count`` points (metres, camera x right / y down) inside the aperture polygon, in an
    order whose every prefix is spread over the whole aperture (golden-angle spiral)."""
    from ..stages.dof import aperture_area, aperture_radius

    if int(count) != count or count < 1:
        raise InputError(f"reference samples={count!r} must be an integer >= 1, e.g. 64")
    radius_m = camera.focal_length_mm / (2.0 * camera.f_number) * 1e-3
    frac = aperture_area(camera.blades, camera.blade_rotation_deg, camera.aperture_roundness) / math.pi
    m = int(math.ceil(count / frac * 1.1)) + 8
    out = []
    while True:
        k = np.arange(m) + 0.5
        rho = np.sqrt(k / m)
        phi = k * math.pi * (3.0 - math.sqrt(5.0))
        inside = rho <= aperture_radius(phi, camera.blades, camera.blade_rotation_deg, camera.aperture_roundness)
        pts = np.stack([rho * np.cos(phi), rho * np.sin(phi)], 1)[inside]
        if len(pts) >= count:
            out = pts
            break
        m = int(m * 1.3) + 8
    # the spiral runs from the centre outwards: reorder by the base-2 radical inverse of the
    # index (van der Corput) so every prefix (a convergence checkpoint) spans the whole aperture
    n = len(out)
    bits = max(1, int(n - 1).bit_length())
    rev = np.array([int(format(i, f"0{bits}b")[::-1], 2) for i in range(n)])
    return out[np.argsort(rev, kind="stable")][:count] * radius_m


def accumulate(camera: Camera, size: tuple[int, int], samples: int, *, frame_index: int = 0,
               scene=None, renderer=None, checkpoints: tuple[int, ...] = ()) -> tuple[Frame, dict]:
    """Average of ``samples`` sheared pinhole renders; returns the frame (colour = average,
    depth = the centre pinhole's) and ``{m: average of the first m samples}`` for ``checkpoints``."""
    from .demo_scene import DemoScene
    from .pyvista_renderer import PyVistaRenderer

    own = renderer is None
    if own:
        renderer = PyVistaRenderer(scene if scene is not None else DemoScene.default())
    try:
        pin = renderer.render(camera, size, frame_index)
        acc = np.zeros(pin.color.shape, np.float64)
        partial = {}
        for i, a in enumerate(aperture_samples(camera, samples), start=1):
            acc += renderer.render(camera, size, frame_index, aperture_offset_m=tuple(a)).color
            if i in checkpoints:
                partial[i] = acc / i
        return pin.replace(color=(acc / samples).astype(np.float32), velocity=None), partial
    finally:
        if own:
            renderer.close()

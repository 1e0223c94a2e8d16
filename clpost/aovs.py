r"""Diagnostic passes (AOVs) on request — ``clpost process --aovs coc,focus,blur`` — written as
extra channels of the output EXR, computed from the output frame's depth and velocity (so they
line up with the output's pixels, also after a distortion resampled them).

============  ===========  =====================================================================
``--aovs``    channel      meaning
============  ===========  =====================================================================
``coc``       ``coc.Y``    signed circle-of-confusion **diameter** in output pixels: negative in
                           front of the focus, positive behind it, 0 on the focus plane
``focus``     ``focus.A``  focus matte: 1 inside the depth of field (:math:`|c| \le c_{lim}`),
                           falling linearly to 0 at :math:`|c| = 2c_{lim}`
``blur``      ``blur.Y``   motion-blur streak length in output pixels over the shutter
============  ===========  =====================================================================

Names follow Nuke's ``layer.channel`` (a lower-case layer, like its ``depth.Z`` and
``forward.u``); ``Y`` is OpenEXR's name for one grey value and ``A`` for a matte, so Nuke shows
``coc.Y`` and ``focus.alpha`` (a mask input takes it directly) and Blender's Image node lists
them as passes.

Formulas — the same code as the stages that produce the effect, one place each:

* CoC: the dof stage's thin-lens formula (:func:`clpost.stages.dof.coc_coefficients`,
  Hecht §5.2; Potmesil & Chakravarty 1981) :math:`c = 2k\,(1/u - 1/S)` px, with
  :math:`k = fF/(2Np)` (f focal length, F the render focal length, N the f-number, p the pixel
  pitch at the output's image (display window) width, u the focused depth, S the pixel's planar depth; sky S = ∞ gives the
  finite far limit). Unlike the stage's internal CoC it is not clamped to the gather's largest
  radius and does not apply the stage's fringe rule (a pixel taking a nearer neighbour's depth): it is the lens's
  CoC of each pixel's depth.
* Focus matte: :math:`m = \mathrm{clamp}(2 - |c|/c_{lim}, 0, 1)` with the depth-of-field CoC limit
  :math:`c_{lim}` = sensor diagonal / 1500 (:func:`coc_limit_mm`; 0.0288 mm on 36 × 24 mm, the
  classic 0.03 mm), in pixels at the output's pitch.
* Blur: :math:`b = s\,|v|` px with s the motion_blur stage's shutter fraction
  (:func:`clpost.stages.motion_blur.shutter_fraction`, shutter × fps) and v the forward velocity
  in px per frame: the full streak a point sweeps while the shutter is open. The stage's
  reconstruction clamps its half-length at 20 px (a 40 px streak); the pass reports the physical
  length.

The device computes them with ``kernels/aovs.cl`` (float32); :func:`reference` is the float64 oracle
(``tests/test_aovs.py`` checks both against a closed-form thin-lens CoC).
"""
from __future__ import annotations

import math

import numpy as np

from .errors import InputError
from .stages._field import image_width_px

AOVS = {
    # name: (EXR channel, what it needs, the fix when it is missing)
    "coc": ("coc.Y", "depth", "re-render with a depth pass (Z) or leave coc out of --aovs"),
    "focus": ("focus.A", "depth", "re-render with a depth pass (Z) or leave focus out of --aovs"),
    "blur": ("blur.Y", "velocity", "re-render with a velocity pass or leave blur out of --aovs"),
}
"""The passes by ``--aovs`` name (see the module docstring)."""

COC_LIMIT_DIVISOR = 1500.0
"""Depth-of-field CoC limit = sensor diagonal / 1500 (the classic 0.03 mm of 35 mm film)."""


def parse_aovs(text: str) -> tuple[str, ...]:
    """``coc,focus,blur`` → the names, checked (argparse type of ``--aovs``)."""
    names = tuple(dict.fromkeys(t.strip() for t in str(text).split(",") if t.strip()))
    bad = [n for n in names if n not in AOVS]
    if bad or not names:
        raise InputError(f"--aovs {text!r}: unknown pass {bad[0] if bad else '(none)'!r}; use a comma-separated "
                         f"list of {', '.join(AOVS)}")
    return names


def coc_limit_mm(camera) -> float:
    """The camera's depth-of-field CoC limit in mm: sensor diagonal / :data:`COC_LIMIT_DIVISOR`."""
    w, h = camera.sensor_mm
    return math.hypot(w, h) / COC_LIMIT_DIVISOR


def _check(camera, frame, names) -> None:
    from .stages.motion_blur import shutter_fraction

    src = frame.metadata.get("path")
    where = f"{src}: " if src else ""
    for n in names:
        need, fix = AOVS[n][1], AOVS[n][2]
        if getattr(frame, need) is None:
            raise InputError(f"{where}--aovs {n} needs the frame's {need} buffer; {fix}")
    if any(AOVS[n][1] == "depth" for n in names) and camera.f_number is None:
        raise InputError("--aovs coc/focus need an f-number: give --f-number (the CoC is f·F/N (1/u − 1/S))")
    if "blur" in names and (camera.frame_rate_fps is None or camera.shutter_s is None):
        raise InputError("--aovs blur needs --fps and a shutter (--shutter or --shutter-angle): the streak is "
                         "velocity × shutter × fps")
    if "blur" in names:
        shutter_fraction(camera)


def _constants(camera, width: int) -> tuple[float, float, float, float]:
    """(k2 = 2k px·m, 1/u, 1/c_lim px, shutter fraction s) of the module's formulas."""
    from .stages.dof import coc_coefficients
    from .stages.motion_blur import shutter_fraction

    k, inv_u = coc_coefficients(camera, width)
    lim_px = coc_limit_mm(camera) / camera.pixel_pitch_mm(width)
    return 2.0 * k, inv_u, 1.0 / lim_px, shutter_fraction(camera)


def reference(camera, frame, names) -> dict[str, np.ndarray]:
    """float64 passes {channel: (H, W)} of ``frame`` (its depth/velocity) for ``names``."""
    from .stages.dof import coc_px

    _check(camera, frame, names)
    out = {}
    if any(AOVS[n][1] == "depth" for n in names):
        c = 2.0 * coc_px(camera, frame.depth, image_width_px(frame))
        _, _, inv_lim, _ = _constants(camera, image_width_px(frame))
        if "coc" in names:
            out["coc.Y"] = c
        if "focus" in names:
            out["focus.A"] = np.clip(2.0 - np.abs(c) * inv_lim, 0.0, 1.0)
    if "blur" in names:
        _, _, _, s = _constants(camera, image_width_px(frame))
        out["blur.Y"] = s * np.hypot(frame.velocity[..., 0].astype(np.float64), frame.velocity[..., 1])
    return out


class _Owner:
    """The owner of the passes' device buffers (:meth:`clpost.runtime.Runtime.scratch`)."""


_BUFFERS = _Owner()


def compute(runtime, camera, frame, names) -> dict[str, np.ndarray]:
    """The passes {channel: (H, W) float32} on the device (``kernels/aovs.cl``)."""
    from .runtime import kernel_source

    _check(camera, frame, names)
    w, h = frame.size
    n = w * h
    coc = any(AOVS[nm][1] == "depth" for nm in names)
    blur = "blur" in names
    k2, inv_u, inv_lim, s = _constants(camera, image_width_px(frame))
    knl = runtime.kernel(kernel_source("aovs"), "aovs", {"AOVS_COC": int(coc), "AOVS_BLUR": int(blur)})
    dummy = np.zeros(1, np.float32)
    depth = np.ascontiguousarray(frame.depth, np.float32) if coc else dummy
    vel = np.ascontiguousarray(frame.velocity, np.float32) if blur else dummy
    # the same device buffers every frame of a sequence (runtime.scratch), not three new ones
    d_buf = runtime.scratch(_BUFFERS, "depth", depth.shape)
    v_buf = runtime.scratch(_BUFFERS, "velocity", vel.shape)
    o_buf = runtime.scratch(_BUFFERS, "out", (3, h, w))
    runtime.copy(d_buf, depth)
    runtime.copy(v_buf, vel)
    runtime.launch(knl, (n,), (64,), d_buf, v_buf, o_buf, np.int32(n), np.float32(k2), np.float32(inv_u),
                   np.float32(inv_lim), np.float32(s))
    planes = np.empty((3, h, w), np.float32)
    runtime.copy(planes, o_buf, blocking=True)
    out = {}
    for i, nm in enumerate(("coc", "focus", "blur")):
        if nm in names:
            out[AOVS[nm][0]] = planes[i]
    return out

r"""vignetting: the fall-off of illumination towards the image corners, a pointwise factor.

Natural vignetting of the thin lens (``Camera.vignetting = "natural"``): the aperture is the
exit pupil, at the image distance v from the film (v from ``Camera.image_distance_mm``, so it
follows focus). Light reaching image height r arrives at :math:`\tan\theta = r/v`, and the
irradiance falls as

.. math::

    \mathrm{RI}(r) = \cos^4\theta = \Big(1 + \frac{r^2}{v^2}\Big)^{-2}

(cos θ for the oblique pupil, cos θ for the oblique film, cos² θ for the longer path; Hecht,
*Optics*, 5th ed., §5.7.1; Ray, *Applied Photographic Optics*, 3rd ed., §24.4). r is in mm on
the sensor from the principal point (the calibration's c_x, c_y when ``Camera.distortion`` is
set, else the image centre); the image spans the sensor width (pixel pitch ``sensor_w/W``).

Other sources of RI(r) (all normalised to 1 on the axis):

* ``"lens"`` — a real lens's traced relative-illumination curve for the camera's f-number and
  focus (``camera.lens_curves()``, :mod:`clpost.optics.curves`: pupil area that passes × cos
  factors, so it includes natural *and* optical vignetting). A thin lens has no traced curve.
* ``"table:<path>"`` — a manufacturer-style table (:func:`read_table`): text lines
  ``image_height_mm relative_illumination`` (comma or whitespace separated) starting at 0 mm,
  with a ``# source:`` provenance comment; linear interpolation. The table must reach the sensor's
  half diagonal.

The curve is sampled on the host into a LUT of ``LUT_SIZE`` entries over
:math:`[0, \sqrt{w^2 + h^2}]` of the sensor (twice the half diagonal, so an off-centre principal
point stays inside), interpolated linearly (max error < 1e-5 for cos⁴ of a 12 mm lens) at every
pixel's image height once per curve and size — on the device (``kernels/vignetting_plane.cl``;
:meth:`Vignetting.ri_plane` is its host form); the kernel multiplies by that plane. Fused with exposure (both linear, pointwise).

Default: ``off`` (opt-in). A real camera always vignettes, but turning it on by default would
change every existing output and plan (exposure-only plans, metered levels); ``--vignetting
natural`` turns it on.

Domain/range: input ≥ 0 → output ≥ 0, never larger than the input (RI ≤ 1).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import InputError
from ..params import param
from . import _field as fld
from .base import DeviceTable, PointwiseStage, per_camera


def _check_mode(name, v):
    if not isinstance(v, str) or not (v in ("off", "natural", "lens") or (v.startswith("table:") and len(v) > 6)):
        raise InputError(f"Camera.{name}={v!r} must be 'off', 'natural', 'lens' or 'table:<path>'")
    return v


@dataclass(frozen=True)
class VignettingParams:
    """vignetting: ``off``, ``natural`` (cos⁴θ of the thin lens), ``lens`` (the traced
    relative-illumination curve of ``lens``) or ``table:<path>`` (manufacturer-style table)."""

    vignetting: str = param("off", unit="mode", flag="--vignetting", check=_check_mode, header="clpost.vignetting",
                            show=lambda v: None if v == "off" else v, scalar=False,
                            help="off, natural (cos^4), lens (traced) or table:<file>")


LUT_SIZE = 1024

RelativeIllumination = Callable[[np.ndarray], np.ndarray]


def natural(camera) -> RelativeIllumination:
    """cos⁴θ with tan θ = r / v (thin lens, exit pupil at the lens)."""
    v = camera.image_distance_mm
    return lambda r: (1.0 + (np.asarray(r, np.float64) / v) ** 2) ** -2


@lru_cache(maxsize=16)
def read_table(path: str) -> tuple[np.ndarray, np.ndarray, str]:
    """(image_height_mm, RI, provenance) of a relative-illumination table file."""
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise InputError(f"--vignetting table:{path}: cannot read it ({exc})") from None
    source, rows = "", []
    for n, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            if s[1:].strip().lower().startswith("source:"):
                source = s[1:].strip()[7:].strip()
            continue
        parts = s.replace(",", " ").split()
        try:
            rows.append((float(parts[0]), float(parts[1])))
        except (ValueError, IndexError):
            if not rows:  # a header line such as "image_height_mm,relative_illumination"
                continue
            raise InputError(f"{path}:{n}: expected 'image_height_mm relative_illumination', got {s!r}") from None
    if not source:
        raise InputError(f"{path}: no '# source: …' line; a relative-illumination table must say where it comes from")
    if len(rows) < 2:
        raise InputError(f"{path}: needs at least two rows 'image_height_mm relative_illumination'")
    r, ri = np.array(rows).T
    if r[0] != 0 or np.any(np.diff(r) <= 0):
        raise InputError(f"{path}: image heights must start at 0 mm and increase")
    if not np.all((ri > 0) & (ri <= 1)):
        raise InputError(f"{path}: relative illumination must be in (0, 1] (a fraction, 1 on the axis), "
                         f"got {ri.min():g} … {ri.max():g}; divide percentages by 100")
    return r, ri, source


def relative_illumination(camera) -> RelativeIllumination | None:
    """The camera's RI(r_mm) curve (None when vignetting is off)."""
    mode = camera.vignetting
    if mode == "off":
        return None
    if mode == "natural":
        return natural(camera)
    if mode == "lens":
        if camera.optics is None:
            raise InputError(f"--vignetting lens needs a traced lens from lens_data (e.g. --lens "
                             f"zeiss-planar-50-f1.4), not {camera.lens!r}; for a thin lens use "
                             "--vignetting natural (cos⁴θ) or table:<file>")
        curves = camera.lens_curves()
        return lambda r: np.clip(curves.at("relative_illumination", np.asarray(r, np.float64)), 0.0, 1.0)
    r, ri, _ = read_table(mode[6:])
    half_diag = 0.5 * math.hypot(*camera.sensor_mm)
    if r[-1] < half_diag - 1e-9:
        raise InputError(f"{mode[6:]}: the table ends at {r[-1]:g} mm but the sensor's half diagonal is "
                         f"{half_diag:.4g} mm; extend the table to the image corner")
    return lambda x: np.interp(np.asarray(x, np.float64), r, ri)


def field_geometry(camera, frame) -> tuple[float, float, float]:
    """(pixel pitch mm, c_x, c_y px in the frame's arrays): the sensor spans the image (display
    window) width, image height is measured from the optical centre
    (:func:`clpost.stages._field.image_width_px`, :func:`~clpost.stages._field.field_centre_px`)."""
    cx, cy = fld.field_centre_px(camera, frame)
    return camera.sensor_mm[0] / fld.image_width_px(frame), cx, cy


def image_height_mm(pitch: float, cx: float, cy: float, w: int, h: int) -> np.ndarray:
    """(h, w) float64: each pixel centre's distance from the optical centre on the film (mm)."""
    x = (np.arange(w) - cx) * pitch
    y = (np.arange(h) - cy) * pitch
    return np.hypot(x[None, :], y[:, None])


class Vignetting(PointwiseStage):
    name = "vignetting"
    order = 60.0
    role = "fixed to the sensor, so after everything that moves image content"
    domains = ("image", "image")
    params = VignettingParams
    args = (("__global const float *", "ri"),)

    def __init__(self, quality: str = "final") -> None:
        super().__init__(quality)
        self._plane: tuple = (None, None)
        self._radius: tuple = (None, None)

    def skip_reason(self, camera, frame):
        ri = relative_illumination(camera)
        if ri is None:
            return "Camera.vignetting is 'off' (opt-in: --vignetting natural)"
        if np.all(self._lut(camera) == 1.0):
            return "relative illumination is 1 over the whole sensor"
        return None

    def reason_needed(self, camera, frame):
        lut = self._lut(camera)
        half = 0.5 * math.hypot(*camera.sensor_mm)
        corner = float(relative_illumination(camera)(np.array(half)))
        return f"{camera.vignetting}: RI at the sensor corner {corner:.3f} ({math.log2(corner):+.2f} EV); LUT {lut.size}"

    def _r_max(self, camera) -> float:
        return math.hypot(*camera.sensor_mm)

    @per_camera
    def _lut(self, camera) -> np.ndarray:
        r = np.linspace(0.0, self._r_max(camera), LUT_SIZE)
        return np.clip(relative_illumination(camera)(r), 0.0, 1.0).astype(np.float32)

    def defines(self, camera):
        return {}

    def _radius_plane(self, pitch: float, cx: float, cy: float, w: int, h: int) -> np.ndarray:
        """Image height (mm) of every pixel, kept while only the LUT changes (a focus pull moves
        the exit pupil, so the LUT changes every frame; the pixels' radii do not)."""
        key = (pitch, cx, cy, w, h)
        if self._radius[0] != key:
            self._radius = (key, image_height_mm(pitch, cx, cy, w, h))
        return self._radius[1]

    def ri_plane(self, camera, frame) -> np.ndarray:
        """RI at every pixel (float32 (h, w), read-only): the LUT interpolated in float64 at the
        pixel's image height — the host form of the plane :meth:`values` has the device build
        (tests compare the two)."""
        lut = self._lut(camera)
        pitch, cx, cy = field_geometry(camera, frame)
        w, h = frame.size
        key = (lut.tobytes(), pitch, cx, cy, w, h)
        if self._plane[0] != key:
            r = self._radius_plane(pitch, cx, cy, w, h)
            grid = np.linspace(0.0, self._r_max(camera), LUT_SIZE)
            plane = np.interp(r, grid, lut.astype(np.float64)).astype(np.float32)
            plane.setflags(write=False)
            self._plane = (key, plane)
        return self._plane[1]

    def values(self, camera, frame):
        """The RI plane as a :class:`~clpost.stages.base.DeviceTable`: built on the device
        (``kernels/vignetting_plane.cl``) once per curve, principal point and size — a focus pull
        changes the curve every frame, and interpolating a 1080p plane on the host took ≈ 20 ms of
        the frame's host time. The apply kernel reads one float per pixel: PoCL cannot vectorise
        data-dependent loads, so a per-pixel LUT lookup there would be most of the stage's cost
        (docs/measurements.md#kernel-forms-on-pocl)."""
        lut = self._lut(camera)
        pitch, cx, cy = field_geometry(camera, frame)
        w, h = frame.size
        r_max = self._r_max(camera)

        def fill(rt, buf, upload):
            from ..runtime import kernel_source, private_kernel

            radius = rt.constant(lambda: self._radius_plane(pitch, cx, cy, w, h).astype(np.float32),
                                 key=("vignetting_radius", pitch, cx, cy, w, h))
            lut_buf = rt.scratch(self, "lut", (LUT_SIZE,))
            upload(lut_buf, lut)
            # a kernel object of the stage's own, its arguments set only when the buffers or the
            # scale change: a focus pull changes the LUT's content, which sets no argument
            args = (lut_buf, radius, buf, np.int32(w * h), np.int32(LUT_SIZE), np.float32((LUT_SIZE - 1) / r_max))
            key = tuple(a.int_ptr if hasattr(a, "int_ptr") else a for a in args)
            have = self.__dict__.get("_plane_kernel")
            if have is None or have[0] != key:
                k = private_kernel(rt.kernel(kernel_source("vignetting_plane"), "vignetting_plane"))
                k.set_args(*args)
                have = self.__dict__["_plane_kernel"] = (key, k, args)  # args: its buffers kept alive
            return [("vignetting_plane", rt.launch(have[1], (w * h,), None))]

        return (DeviceTable((lut.tobytes(), pitch, cx, cy, w, h, r_max), (h, w), fill),)

    def aux_bytes(self, camera, frame) -> int:
        """Bytes ``vignetting_plane`` moves (``clpost bench``): per pixel its image height read and
        its RI written, plus the LUT."""
        w, h = frame.size
        return w * h * (4 + 4) + 4 * LUT_SIZE

    def reference(self, camera, frame, color):
        color = np.asarray(color, np.float64)
        h, w = color.shape[:2]
        r = np.minimum(image_height_mm(*field_geometry(camera, frame), w, h), self._r_max(camera))
        return color * relative_illumination(camera)(r)[..., None]

r"""Shared geometry of the field-dependent lens stages (astigmatism, coma, lateral_color).

Image height r (mm on the film) is measured from the image centre ((W−1)/2, (H−1)/2) in the
pixel-centre convention of CONVENTIONS.md (these stages run before distortion, on the undistorted
render); the image spans the sensor width, so the pixel pitch
is :math:`p = w_{sensor}/W` mm. The *corner* of the parametric coefficients is the sensor's half
diagonal :math:`r_c = \tfrac12\sqrt{w^2 + h^2}`.

Curves are sampled into LUTs of ``LUT_SIZE`` entries over :math:`[0, \sqrt{w^2 + h^2}]` (twice
the half diagonal, so an off-centre principal point stays inside) and interpolated linearly in
the kernels, as the vignetting stage does.

The gathers read a copy of the image padded by ``PAD`` pixels (edge values repeated, i.e. the
render is assumed to continue as its border) so no tap needs a clamp; every tap
offset is therefore limited to ``PAD − 1`` pixels.

**Tiles.** PoCL vectorises a gather across pixels only when the work-items of a group read at
the same offsets (uniform offsets on planar padded buffers run several times faster than per-pixel
offsets: docs/measurements.md#gather-layouts-on-pocl). The field-dependent PSFs change slowly with
field height, so the gathers run on tiles of ``TILE_W × TILE_H`` pixels (grid from the top-left
pixel; 16 px wide = one AVX-512 vector of floats) whose tap positions are placed by the tile centre
:math:`(t_x W_t + \tfrac{W_t-1}{2},\ t_y H_t + \tfrac{H_t-1}{2})`; each stage documents how it
keeps (or approximates) the per-pixel shape within a tile.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

LUT_SIZE = 512
PAD = 16
TILE_W = 16
TILE_H = 8
GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


def frame_intrinsics(frame) -> tuple[float, float, float, float] | None:
    """The render's own pinhole intrinsics (f_x, f_y, c_x, c_y), as a renderer records them in
    ``frame.metadata["intrinsics"]``; None when absent (or after a resampling stage)."""
    k = frame.metadata.get("intrinsics") if isinstance(frame.metadata, dict) else None
    return None if k is None else tuple(float(t) for t in k)


def render_intrinsics_px(model, w: int, h: int, intrinsics=None):
    """(f_x, f_y, c_x, c_y) of a w × h render: its recorded ``intrinsics`` (see
    :func:`frame_intrinsics`), else, for a calibration ``model`` (or None), the render made for it
    — the calibration's K at its own size, :func:`clpost.calibration.required_render`'s frustum
    at that size — else None."""
    if intrinsics is not None:
        return tuple(float(t) for t in intrinsics)
    if model is not None:
        from ..calibration import render_intrinsics

        return render_intrinsics(model, (w, h))
    return None


@dataclass(frozen=True)
class FieldGeometry:
    """A frame's pixel pitch (mm) and optical centre (px in its arrays) when they are not the
    array's (an EXR's overscan: :func:`frame_geometry`). Passed where the field functions take
    ``intrinsics``; :func:`principal_point_px` and :func:`pitch_mm` honour it."""

    pitch: float
    cx: float
    cy: float


def frame_geometry(camera, frame):
    """What the field stages pass as ``intrinsics`` for ``frame``: a :class:`FieldGeometry` when
    the frame has a display window inside larger arrays (pitch from :func:`image_width_px`, centre
    from :func:`field_centre_px`), else the render's recorded intrinsics (or None)."""
    k = frame_intrinsics(frame)
    if frame.windows.display_size == frame.size and frame.windows.display_offset == (0, 0):
        return k
    cx, cy = field_centre_px(camera, frame)
    return FieldGeometry(camera.sensor_mm[0] / image_width_px(frame), cx, cy)


def principal_point_px(camera, w: int, h: int, intrinsics=None) -> tuple[float, float]:
    """The optical centre (px) of a w × h image: the one definition every stage uses (the field
    stages and vignetting measure image height from it, distortion maps around it). The render's
    recorded ``intrinsics`` when given, else a calibrated camera's (:func:`render_intrinsics_px`:
    before ``distortion`` the render's, after it — at the calibration's size — the calibration's
    own c), else the image centre ((W−1)/2, (H−1)/2) of the pixel-centre convention. A
    :class:`FieldGeometry` gives its own centre."""
    if isinstance(intrinsics, FieldGeometry):
        return intrinsics.cx, intrinsics.cy
    k = render_intrinsics_px(getattr(camera, "distortion", None), w, h, intrinsics)
    if k is not None:
        return k[2], k[3]
    return 0.5 * (w - 1), 0.5 * (h - 1)


def image_width_px(frame) -> int:
    """Pixels across the sensor's width in ``frame``: its display window's width (the image spans
    the sensor width, CONVENTIONS; an EXR's overscan beyond the display window lies outside the
    sensor, its pixels the same size). Every pixel pitch of a frame is taken from this width."""
    return frame.windows.display_size[0]


def field_centre_px(camera, frame) -> tuple[float, float]:
    """The optical centre in ``frame``'s arrays: the render's recorded intrinsics, else
    :func:`principal_point_px` of its display window moved by the window's place in the arrays
    (an overscan frame's arrays start left of and above the image)."""
    k = frame_intrinsics(frame)
    if k is not None:
        return k[2], k[3]
    win = frame.windows
    (dw, dh), (ox, oy) = win.display_size, win.display_offset
    cx, cy = principal_point_px(camera, dw, dh)
    return cx + ox, cy + oy


def pitch_mm(camera, w: int, intrinsics=None) -> float:
    """Pixel pitch (mm) of a w-pixel-wide image spanning the sensor, or a :class:`FieldGeometry`'s."""
    if isinstance(intrinsics, FieldGeometry):
        return intrinsics.pitch
    return camera.sensor_mm[0] / float(w)


def corner_mm(camera) -> float:
    return 0.5 * math.hypot(*camera.sensor_mm)


def lut_range_mm(camera) -> float:
    return math.hypot(*camera.sensor_mm)


def sample_lut(fn, camera, planes: int) -> np.ndarray:
    """(planes, LUT_SIZE) float32 of ``fn(r_mm) -> tuple of planes`` on the LUT grid."""
    r = np.linspace(0.0, lut_range_mm(camera), LUT_SIZE)
    vals = fn(r)
    return np.ascontiguousarray(np.stack([np.broadcast_to(v, r.shape) for v in vals[:planes]]), np.float32)


def vogel_disc(n: int) -> np.ndarray:
    r"""n points uniform over the unit disc (Vogel spiral): :math:`\sqrt{(k+\frac12)/n}\,
    (\cos k\phi_g, \sin k\phi_g)`, φ_g the golden angle. (n, 2) float32, the kernels' taps."""
    k = np.arange(n, dtype=np.float64)
    rad = np.sqrt((k + 0.5) / n)
    return np.stack([rad * np.cos(k * GOLDEN_ANGLE), rad * np.sin(k * GOLDEN_ANGLE)], -1).astype(np.float32)


def radial_frame(w: int, h: int, cx: float, cy: float):
    """Per pixel (float64): dx, dy from the principal point, r_px, and the unit radial vector
    (e_r; (1, 0) at the centre) — the tangential direction of the lens, e_s = (−e_r.y, e_r.x)."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    dx, dy = xs - cx, ys - cy
    r = np.hypot(dx, dy)
    safe = np.where(r > 0, r, 1.0)
    ex = np.where(r > 0, dx / safe, 1.0)
    ey = np.where(r > 0, dy / safe, 0.0)
    return xs, ys, r, ex, ey


def bilinear_padded(color: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``color`` (H, W, C) at pixel positions (px, py) with the image
    continued by its edge values (what the kernels' padded copy holds), float64."""
    h, w = color.shape[:2]
    px = np.clip(px, -PAD, w - 1 + PAD - 1e-9)
    py = np.clip(py, -PAD, h - 1 + PAD - 1e-9)
    x0, y0 = np.floor(px), np.floor(py)
    fx, fy = (px - x0)[..., None], (py - y0)[..., None]
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    xa, xb = np.clip(x0, 0, w - 1), np.clip(x0 + 1, 0, w - 1)
    ya, yb = np.clip(y0, 0, h - 1), np.clip(y0 + 1, 0, h - 1)
    top = color[ya, xa] * (1 - fx) + color[ya, xb] * fx
    bot = color[yb, xa] * (1 - fx) + color[yb, xb] * fx
    return top * (1 - fy) + bot * fy


def upsample_corners(h: int, w: int, hw: int, ww: int, f: int):
    """Bilinear upsampling of an ``hw`` × ``ww`` image at 1/``f`` to ``h`` × ``w`` (pixel centres
    aligned, edges clamped): the four (row index, column index, weight) corners, weights
    broadcasting to (h, w); an upsampled image is Σ weight · img[rows][:, cols]."""
    sx = (np.arange(w) + 0.5) / f - 0.5
    sy = (np.arange(h) + 0.5) / f - 0.5
    x0 = np.clip(np.floor(sx), 0, ww - 1).astype(int)
    y0 = np.clip(np.floor(sy), 0, hw - 1).astype(int)
    fx = np.clip(sx - x0, 0, 1)[None, :]
    fy = np.clip(sy - y0, 0, 1)[:, None]
    x1, y1 = np.minimum(x0 + 1, ww - 1), np.minimum(y0 + 1, hw - 1)
    return ((y0, x0, (1 - fx) * (1 - fy)), (y0, x1, fx * (1 - fy)),
            (y1, x0, (1 - fx) * fy), (y1, x1, fx * fy))


def tiles(w: int, h: int) -> tuple[int, int]:
    """Number of tiles (x, y) covering a w × h frame (the kernels' work-group grid)."""
    return -(-w // TILE_W), -(-h // TILE_H)


def tile_centres(w: int, h: int, cx: float, cy: float):
    """Per tile (tiles_y, tiles_x), float64: the tile centre's dx, dy from the principal point,
    r_px and unit radial vector (e_x, e_y; (1, 0) at the centre)."""
    ntx, nty = tiles(w, h)
    ty, tx = np.mgrid[0:nty, 0:ntx].astype(np.float64)
    dx = tx * TILE_W + 0.5 * (TILE_W - 1) - cx
    dy = ty * TILE_H + 0.5 * (TILE_H - 1) - cy
    r = np.hypot(dx, dy)
    safe = np.where(r > 0, r, 1.0)
    return dx, dy, r, np.where(r > 0, dx / safe, 1.0), np.where(r > 0, dy / safe, 0.0)


def per_pixel(table: np.ndarray, w: int, h: int) -> np.ndarray:
    """Expand a per-tile array (tiles_y, tiles_x, ...) to the pixels (h, w, ...) it covers."""
    return np.repeat(np.repeat(table, TILE_H, 0), TILE_W, 1)[:h, :w]

r"""What the undistorted (pinhole) render must cover so that the distortion stage leaves no
output pixel unfilled, and which intrinsics a render of a given size has.

Both are pure functions of a frozen, hashable :class:`~clpost.calibration.model.OpenCVModel`
and are cached per (model, size): the frustum needs one Newton inverse of the image border
(:func:`~clpost.calibration.model.undistort_newton`), and stages ask for it every frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .model import OpenCVModel, undistort_newton


@dataclass(frozen=True)
class RenderSpec:
    r"""A pinhole render (square pixels) that covers every output pixel of a distorted image.

    Frustum at unit distance in OpenCV's pixel-centre convention (Lambers et al., sec. 3.2;
    ``shared/CONVENTIONS.md``):

    .. math::

        l = -\frac{c_x + 0.5}{f},\ r = \frac{W}{f} + l,\ b = -\frac{c_y + 0.5}{f},\ t = \frac{H}{f} + b

    (b, t are in OpenCV's y-down image axis; an OpenGL projection uses −t, −b.)
    """

    width: int
    height: int
    f: float
    cx: float
    cy: float

    def intrinsics(self) -> tuple[float, float, float, float]:
        return self.f, self.f, self.cx, self.cy

    def frustum(self) -> tuple[float, float, float, float]:
        left = -(self.cx + 0.5) / self.f
        bottom = -(self.cy + 0.5) / self.f
        return left, self.width / self.f + left, bottom, self.height / self.f + bottom


def required_render(model: OpenCVModel, margin_px: float = 2.0) -> RenderSpec:
    r"""The undistorted render that leaves no output pixel unfilled.

    Every point of the output image's border ([−0.5, W−0.5] × [−0.5, H−0.5], 4·(W+H) samples) is
    undistorted; the render keeps the model's larger focal length f = max(f_x, f_y) (the same
    pixel density at the centre) and gets the frustum of the bounding box of those points
    (union with the model's own frustum), widened by ``margin_px`` for the resampling filter's
    support. Barrel distortion → a larger render, pincushion → the model's own frustum.
    Points beyond the fold (no preimage) are left out: they stay alpha 0 anyway.
    Cached per (model, margin): the result is a frozen :class:`RenderSpec`.
    """
    return _required_render(model, float(margin_px))


@lru_cache(maxsize=32)
def border_samples(w: int, h: int) -> tuple[np.ndarray, np.ndarray]:
    """(u, v): a w × h image's outer border, pixel edges at −½ and size − ½, 4 samples a pixel —
    for a radial model the border's preimage bounds the interior's."""
    t = np.linspace(-0.5, w - 0.5, 4 * w + 1)
    s = np.linspace(-0.5, h - 0.5, 4 * h + 1)
    u = np.concatenate([t, t, np.full_like(s, -0.5), np.full_like(s, w - 0.5)])
    v = np.concatenate([np.full_like(t, -0.5), np.full_like(t, h - 0.5), s, s])
    return u, v


def undistorted_bounds(model: OpenCVModel, margin_px: float = 2.0,
                       own_frustum: bool = True) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1): the normalised undistorted coordinates an image must span so that every
    output pixel of ``model`` has a preimage — the bounding box of the undistorted output border
    (4 samples a pixel) and (``own_frustum``) the model's own pinhole frustum, widened by
    ``margin_px`` pixels at f = max(f_x, f_y) for the resampling filter. Points beyond the fold
    are left out."""
    w, h = model.width, model.height
    u, v = border_samples(w, h)
    x, y, ok = undistort_newton(model, u, v)
    # the model's own (pinhole) frustum
    x0, x1 = -(model.cx + 0.5) / model.fx, (w - 0.5 - model.cx) / model.fx
    y0, y1 = -(model.cy + 0.5) / model.fy, (h - 0.5 - model.cy) / model.fy
    if not own_frustum:
        x0, x1, y0, y1 = math.inf, -math.inf, math.inf, -math.inf
    if ok.any():
        x0, x1 = min(x0, x[ok].min()), max(x1, x[ok].max())
        y0, y1 = min(y0, y[ok].min()), max(y1, y[ok].max())
    m = float(margin_px) / max(model.fx, model.fy)
    return float(x0 - m), float(x1 + m), float(y0 - m), float(y1 + m)


PINHOLE_LIMIT_DEG = 75.0
"""The largest angle to the axis (half the field of view, 150° in all) a pinhole render is asked to
cover: a pinhole pixel at θ spans cos³θ of the solid angle of a central one, so at 75° the render
spends 58 × the centre's pixels per solid angle, and its size diverges at 90°."""


def max_ray_angle_deg(model: OpenCVModel) -> float:
    """The largest angle to the optical axis of any output pixel's ray (degrees; the image border,
    4 samples a pixel, for these radial models; 180 if some border pixel has no ray)."""
    x, y, z, ok = model.unproject(*border_samples(model.width, model.height))
    if not ok.any():
        return 180.0
    return float(np.degrees(np.arccos(np.clip(z[ok].min(), -1.0, 1.0))))


@lru_cache(maxsize=32)
def _required_render(model: OpenCVModel, margin_px: float) -> RenderSpec:
    theta = max_ray_angle_deg(model)
    if theta > PINHOLE_LIMIT_DEG:
        from ..errors import InputError

        from .cubemap import required_cubemap

        cube = required_cubemap(model)
        raise InputError(
            f"the calibration{model._where()} sees {theta:.1f}° off axis (a {2 * theta:.0f}° field of view): no pinhole "
            f"render covers more than {2 * PINHOLE_LIMIT_DEG:.0f}°; render a cubemap of six {cube.face} px faces "
            f"({cube.width}x{cube.height} atlas: clpost.calibration.required_cubemap, "
            "PyVistaRenderer.render_cubemap), which the distortion stage samples")
    x0, x1, y0, y1 = undistorted_bounds(model, margin_px)
    f = max(model.fx, model.fy)
    rw, rh = int(math.ceil(f * (x1 - x0))), int(math.ceil(f * (y1 - y0)))
    # l = −(c + 0.5)/f = x0  ⇒  c = −x0 f − 0.5
    return RenderSpec(rw, rh, float(f), float(-x0 * f - 0.5), float(-y0 * f - 0.5))


def overscan_px(model: OpenCVModel, margin_px: float = 2.0) -> tuple[int, int, int, int]:
    r"""Pixels (left, top, right, bottom) a render made with the calibration's own K must reach
    beyond its W × H image so that no output pixel is unfilled. The render's column u covers
    [u − ½, u + ½]; with (x_0, x_1, y_0, y_1) the bounds of the undistorted output border
    (:func:`undistorted_bounds` without the model's own frustum) a side falls short by

    .. math::

        l = -\tfrac12 - (f_x x_0 + c_x), \qquad r = f_x x_1 + c_x - (W - \tfrac12)

    (t, b likewise with f_y, c_y, y_0, y_1, H), and needs ⌈l + margin⌉ px where l > 0, else none
    (a pincushion lens needs no overscan; the margin is the resampling filter's support). This is
    the overscan to set in a renderer that writes an EXR data window beyond the display window
    (Nuke's ScanlineRender ``overscan``); the data window is (−L, −T) − (W − 1 + R, H − 1 + B)."""
    x0, x1, y0, y1 = undistorted_bounds(model, 0.0, own_frustum=False)
    if not math.isfinite(x0):
        return 0, 0, 0, 0
    w, h = model.width, model.height

    def need(short):  # whole pixels, with a hair of tolerance for float round-off
        return int(math.ceil(short + margin_px - 1e-9)) if short > 1e-9 else 0

    return (need(-0.5 - (model.fx * x0 + model.cx)), need(-0.5 - (model.fy * y0 + model.cy)),
            need(model.fx * x1 + model.cx - (w - 0.5)), need(model.fy * y1 + model.cy - (h - 0.5)))


def render_intrinsics(model: OpenCVModel, size: tuple[int, int]) -> tuple[float, float, float, float] | None:
    """(f_x, f_y, c_x, c_y) of an undistorted render of ``size`` made for this calibration: its own
    K at the calibration's size, :func:`required_render`'s frustum at that size; None otherwise.
    Cached per (model, size): stages ask for it every frame."""
    w, h = size
    return _render_intrinsics(model, (int(w), int(h)))


@lru_cache(maxsize=32)
def _render_intrinsics(model: OpenCVModel, size: tuple[int, int]) -> tuple[float, float, float, float] | None:
    if tuple(size) == (model.width, model.height):
        return float(model.fx), float(model.fy), float(model.cx), float(model.cy)
    if max_ray_angle_deg(model) > PINHOLE_LIMIT_DEG:
        return None  # no pinhole render is made for it (a cubemap: clpost.calibration.cubemap)
    spec = required_render(model)
    if tuple(size) == (spec.width, spec.height):
        return spec.intrinsics()
    return None

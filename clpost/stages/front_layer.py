r"""A foreground rendered as its own layer: defocused by its own depth, composited over the image.

A one-layer render holds one surface per pixel, so where a blurred foreground's edge lets the
lens see past it, the background it reveals is not in the image: the dof stage estimates it from
the background beside the edge (docs/fidelity.md, "The background hidden behind a blurred
foreground's edge"). A renderer can give it instead: the near objects as their own layer over
a transparent film (``Frame.front``: premultiplied RGB, coverage α, depth), the image the
background without them. This stage is the layered thin-lens model (as Dr.Bokeh, CVPR 2024, and
MPIB build their layers): every front pixel q spreads its premultiplied colour and coverage over
its own disc,

.. math::
   F(p) = \sum_q \frac{k_{r_q}(p - q)}{N(r_q)}\,(c_q, \alpha_q), \qquad
   k_r(o) = \mathrm{clamp}\big(r\,\rho(\varphi_o) - |o| + \tfrac12,\ 0,\ 1\big), \qquad
   N(r) = \sum_o k_r(o),

with :math:`r_q` the thin-lens CoC radius of q's depth (:func:`clpost.stages.dof.coc_px`, capped
at the quality's largest CoC; 0 with depth of field off) and :math:`\rho` the aperture polygon
(:func:`clpost.stages.dof.aperture_radius`), and the result is :math:`F_{rgb} + (1 - F_\alpha)\,B`
over the dof stage's background B. Exact for one layer without self-occlusion; beyond the frame
the layer continues as its edge pixels (the dof gather's clamp). It runs after dof and before
the aberrations, so every later stage sees both layers; motion blur sees the composite with
the background's vectors, so a front layer that moves against the background is not blurred
along its own motion.

Kernel (``kernels/front_layer.cl``): ``front_layer_tiles`` takes each 8×8 tile's largest front
radius (−1 without coverage); ``front_layer`` gathers, per pixel, the taps within the largest
radius of the tiles that can reach it (none: the image passes unchanged), with ρ(o) and N(r)
from tables (N at 1/256 px, linear).
"""
from __future__ import annotations

import math

import numpy as np

from . import _field as fld
from .base import GatherStage
from .dof import aperture_radius, coc_px, max_coc_px

TILE = 8
NORM_STEPS = 256
"""Entries of the N(r) table per pixel of radius."""


def front_radius(camera, depth: np.ndarray, width_px: int, quality: str) -> np.ndarray:
    """The CoC radius (px, ≥ 0) each front pixel spreads over: 0 with depth of field off."""
    if not camera.depth_of_field:
        return np.zeros(np.shape(depth))
    return np.abs(coc_px(camera, depth, width_px, max_coc_px(quality)))


def reach_px(quality: str) -> int:
    """Half-size of the tap window: the quality's largest radius, its ½-px ramp and a pixel."""
    return int(math.ceil(max_coc_px(quality))) + 1


def offset_tables(reach: int, blades: int, rotation_deg: float, roundness: float):
    """(ρ(φ_o), |o|) of every offset o = (dx, dy) in the (2·reach + 1)² window, row-major by dy."""
    dy, dx = np.mgrid[-reach:reach + 1, -reach:reach + 1].astype(np.float64)
    return aperture_radius(np.arctan2(dy, dx), blades, rotation_deg, roundness), np.hypot(dx, dy)


def disc_weight(r, rho, dist):
    """k_r(o) of the module docstring (broadcasts)."""
    return np.clip(r * rho - dist + 0.5, 0.0, 1.0)


def norm_table(quality: str, blades: int, rotation_deg: float, roundness: float) -> np.ndarray:
    """N(r) at r = i / NORM_STEPS for i in 0 … NORM_STEPS·max radius + 1."""
    rho, dist = offset_tables(reach_px(quality), blades, rotation_deg, roundness)
    r = np.arange(int(max_coc_px(quality) * NORM_STEPS) + 2) / NORM_STEPS
    return np.array([disc_weight(v, rho, dist).sum() for v in r])


def front_reference(front: np.ndarray, radius: np.ndarray, background: np.ndarray, blades: int,
                    rotation_deg: float, roundness: float) -> np.ndarray:
    """float64 oracle: the front layer scattered pixel by pixel (exact N(r) per pixel), over
    ``background``."""
    h, w = radius.shape
    reach = int(math.ceil(float(radius.max()) + 0.5)) if radius.size else 0
    f = np.pad(np.asarray(front, np.float64)[..., :4], ((reach, reach), (reach, reach), (0, 0)), mode="edge")
    rp = np.pad(np.asarray(radius, np.float64), reach, mode="edge")
    hp, wp = rp.shape
    ys, xs = np.nonzero(f[..., 3] > 0)
    src, r = f[ys, xs], rp[ys, xs]
    rho, dist = offset_tables(reach, blades, rotation_deg, roundness)
    norm = np.zeros_like(r)
    for (j, i), _ in np.ndenumerate(rho):
        norm += disc_weight(r, rho[j, i], dist[j, i])
    acc = np.zeros((hp * wp, 4))
    for (j, i), _ in np.ndenumerate(rho):
        g = disc_weight(r, rho[j, i], dist[j, i]) / norm
        ty, tx = ys + j - reach, xs + i - reach
        ok = (g > 0) & (ty >= 0) & (ty < hp) & (tx >= 0) & (tx < wp)
        idx = ty[ok] * wp + tx[ok]
        for c in range(4):
            acc[:, c] += np.bincount(idx, weights=g[ok] * src[ok, c], minlength=hp * wp)
    acc = acc.reshape(hp, wp, 4)[reach:reach + h, reach:reach + w]
    return acc[..., :3] + (1.0 - acc[..., 3:]) * np.asarray(background, np.float64)


class FrontLayer(GatherStage):
    name = "front_layer"
    order = 12.0
    role = ("a foreground rendered as its own layer (Frame.front): defocused by its own depth and "
            "composited over the defocused background, before the aberrations")
    domains = ("render", "render")
    reads = ("front",)
    requires = ("dof",)  # composites over dof's background: both or neither
    turn_off = "leave the front layer out (no --front), or render the scene as one layer"

    def skip_reason(self, camera, frame):
        if frame.front is None:
            return "no front layer (Frame.front; clpost process --front)"
        return None

    def reason_needed(self, camera, frame):
        cov = frame.front[..., 3] > 0
        if not cov.any():
            return "front layer with no coverage (composites as nothing)"
        r = front_radius(camera, frame.front[..., 4][cov], fld.image_width_px(frame), self.quality)
        return (f"front layer over {int(cov.sum())} px, CoC radius {r.min():.3g} … {r.max():.3g} px "
                f"(max {max_coc_px(self.quality):g} px, {self.quality})")

    def defines(self, camera):
        return {"FRONT_TILE": TILE, "FRONT_REACH": reach_px(self.quality), "FRONT_NORM_STEPS": NORM_STEPS}

    def _radius_args(self, camera, frame):
        from .dof import coc_coefficients

        if not camera.depth_of_field:
            return 0.0, 0.0
        return coc_coefficients(camera, fld.image_width_px(frame))

    def reference(self, camera, frame, color):
        radius = front_radius(camera, frame.front[..., 4], fld.image_width_px(frame), self.quality)
        radius = np.where(frame.front[..., 3] > 0, radius, 0.0)
        return front_reference(frame.front, radius, color, camera.blades, camera.blade_rotation_deg,
                               camera.aperture_roundness)

    def enqueue(self, rt, camera, frame, src, dst, aux):
        from ..codegen import library
        from ..runtime import kernel_source

        w, h = frame.width, frame.height
        tw, th = -(-w // TILE), -(-h // TILE)
        shape = (camera.blades, camera.blade_rotation_deg, camera.aperture_roundness)
        knl = rt.kernels(library() + kernel_source("front_layer"), "front_layer", self.defines(camera))
        rho = rt.constant(lambda: offset_tables(reach_px(self.quality), *shape)[0].astype(np.float32),
                          ("front_layer.rho", self.quality, shape))
        norm = rt.constant(lambda: norm_table(self.quality, *shape).astype(np.float32),
                           ("front_layer.norm", self.quality, shape))
        tiles = rt.scratch(self, "tiles", (th, tw))
        k, inv_u = self._radius_args(camera, frame)
        i32, f32 = np.int32, np.float32
        rlim = f32(max_coc_px(self.quality))
        return [rt.launch(knl["front_layer_tiles"], (tw, th), None, aux["front"], tiles, i32(w), i32(h), i32(tw),
                          i32(th), f32(k), f32(inv_u), rlim),
                rt.launch(knl["front_layer"], (w, h), None, src, aux["front"], tiles, rho, norm, dst, i32(w), i32(h),
                          i32(tw), i32(th), f32(k), f32(inv_u), rlim)]

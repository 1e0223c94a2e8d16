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
over the dof stage's background B (:func:`front_scatter`, exact for one layer without
self-occlusion; beyond the frame the layer continues as its edge pixels, the dof gather's clamp).
It runs after dof and before the aberrations, so every later stage sees both layers; motion blur
sees the composite with the background's vectors, so a front layer that moves against the
background is not blurred along its own motion.

**Levels** (what the kernels and :func:`front_reference` compute). A disc of radius r costs
~πr² taps, so a pixel spreads at the level L of a pyramid where its radius is a few level pixels:
L = 0 (full resolution, exact) for r < 2R, else ⌊log₂(r/R)⌋ (radius R … 2R level pixels), with
R = :data:`LEVEL_RADIUS` of the quality. Level L ≥ 1 holds, per 2^L × 2^L block, the mean of the
block's level-L pixels (premultiplied colour and coverage; zero for the others) at their
α-weighted mean radius / 2^L, narrowed by :data:`LEVEL_SHRINK_PX2`; each level is spread as above
at its own resolution and upsampled bilinearly (pixel centres aligned, edges clamped). What the
levels cost against the exact scatter and against Cycles: docs/fidelity.md, "Two layers".

Kernels (``kernels/front_layer.cl``): ``front_layer_prep`` (level 0's planes: colour and coverage
over N(r), radius or −1), ``front_layer_down`` (each level ≥ 1's planes), ``front_layer_tiles``
(each 8×8 tile's largest radius, −1 where nothing spreads), ``front_layer_reach`` (each tile's
reach: the largest radius that can spread onto it), ``front_layer_gather`` (a level ≥ 1 spread),
``front_layer_active`` (whether any level ≥ 1 reaches a full-resolution tile),
``front_layer`` (level 0 spread, the levels upsampled, the composite). On a CPU
(:attr:`~clpost.runtime.Runtime.wide`) every spread is ``front_layer_gather16`` (16 pixels of a
row as float16 lanes, the same taps in the same order), level 0's into a full-resolution buffer
that ``front_layer_add`` composites. ρ(o) and N(r) come from tables (N at 1/256 px, linear).
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
LEVEL_RADIUS = {"draft": 3, "preview": 4, "final": 5}
"""R of the module docstring: a level spreads radii of R … 2R of its pixels (level 0: below 2R)."""
LEVEL_SHRINK_PX2 = 2.0
"""A level ≥ 1 spreads at radius √(r_L² − 2) level px: the block mean and the bilinear upsampling
widen its discs (their variance by ≈ ¼ + the coarser ramp's ≈ 1/12 level px², so 4 × that ≈ 1.3
in r²), and 2.0 is what the exact model favours: the error against :func:`front_scatter` is
least there on the occluder scene's front layer and on a synthetic one, at every quality, in
sweeps of 0 … 3 (docs/fidelity.md, "Two layers")."""


def front_radius(camera, depth: np.ndarray, width_px: int, quality: str) -> np.ndarray:
    """The CoC radius (px, ≥ 0) each front pixel spreads over: 0 with depth of field off."""
    if not camera.depth_of_field:
        return np.zeros(np.shape(depth))
    return np.abs(coc_px(camera, depth, width_px, max_coc_px(quality)))


def n_levels(quality: str) -> int:
    """Levels 0 … n − 1: the quality's largest radius falls in the last."""
    return max(1, int(math.floor(math.log2(max_coc_px(quality) / LEVEL_RADIUS[quality]))) + 1)


def level_of(r: np.ndarray, quality: str) -> np.ndarray:
    """The level each radius r (full-resolution px) spreads at."""
    rb, r = LEVEL_RADIUS[quality], np.asarray(r, np.float64)
    lv = np.zeros(r.shape, int)
    for k in range(1, n_levels(quality)):
        lv += r >= rb * 2 ** k
    return lv


def reach_px(quality: str) -> int:
    """Half-size of a level's tap window: its largest radius 2R, the ½-px ramp, rounded up."""
    return int(math.ceil(2 * LEVEL_RADIUS[quality] + 0.5))


def offset_tables(reach: int, blades: int, rotation_deg: float, roundness: float):
    """(ρ(φ_o), |o|) of every offset o = (dx, dy) in the (2·reach + 1)² window, row-major by dy."""
    dy, dx = np.mgrid[-reach:reach + 1, -reach:reach + 1].astype(np.float64)
    return aperture_radius(np.arctan2(dy, dx), blades, rotation_deg, roundness), np.hypot(dx, dy)


def disc_weight(r, rho, dist):
    """k_r(o) of the module docstring (broadcasts)."""
    return np.clip(r * rho - dist + 0.5, 0.0, 1.0)


def disc_norm(r: np.ndarray, rho: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """N(r) = Σ_o k_r(o) over the window of ``rho``/``dist`` (exact, float64)."""
    r = np.asarray(r, np.float64)
    return sum(disc_weight(r, v, d) for v, d in zip(rho.ravel(), dist.ravel()))


def norm_table(quality: str, blades: int, rotation_deg: float, roundness: float) -> np.ndarray:
    """N(r) at r = i / NORM_STEPS for i in 0 … NORM_STEPS·2R + 1 (every level's radii)."""
    rho, dist = offset_tables(reach_px(quality), blades, rotation_deg, roundness)
    return disc_norm(np.arange(2 * LEVEL_RADIUS[quality] * NORM_STEPS + 2) / NORM_STEPS, rho, dist)


def _spread(planes: np.ndarray, r: np.ndarray, rho: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Σ_q k_{r_q}(p − q) P_q over the window, q clamped to the frame (P already over N)."""
    h, w = r.shape
    reach = rho.shape[0] // 2
    ys, xs = np.arange(h), np.arange(w)
    acc = np.zeros((h, w, planes.shape[2]))
    for (j, i), v in np.ndenumerate(rho):
        qy = np.clip(ys - (j - reach), 0, h - 1)[:, None]
        qx = np.clip(xs - (i - reach), 0, w - 1)[None, :]
        rq = r[qy, qx]
        g = np.where(rq >= 0, disc_weight(rq, v, dist[j, i]), 0.0)
        acc += g[..., None] * planes[qy, qx]
    return acc


def _level_planes(rgba: np.ndarray, r: np.ndarray, lv: np.ndarray, level: int):
    """Level ``level``'s premultiplied colour and coverage (block means of that level's pixels)
    and radius (their α-weighted mean / 2^level; −1 where the block holds none)."""
    f = 2 ** level
    h, w = r.shape
    hl, wl = -(-h // f), -(-w // f)
    mine = (lv == level) & (rgba[..., 3] > 0)
    s = np.zeros((hl, wl, 4)); n = np.zeros((hl, wl)); sa = np.zeros((hl, wl)); sar = np.zeros((hl, wl))
    by, bx = (np.arange(h) // f)[:, None], (np.arange(w) // f)[None, :]
    np.add.at(n, (by, bx), 1.0)
    for c in range(4):
        np.add.at(s[..., c], (by, bx), np.where(mine, rgba[..., c], 0.0))
    np.add.at(sa, (by, bx), np.where(mine, rgba[..., 3], 0.0))
    np.add.at(sar, (by, bx), np.where(mine, rgba[..., 3] * r, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        rl = np.where(sa > 0, np.sqrt(np.maximum((sar / sa / f) ** 2 - LEVEL_SHRINK_PX2, 0.0)), -1.0)
    return s / n[..., None], rl


def front_reference(front: np.ndarray, radius: np.ndarray, background: np.ndarray, quality: str,
                    blades: int, rotation_deg: float, roundness: float) -> np.ndarray:
    """float64 oracle of the kernels: the levels of the module docstring, exact N(r)."""
    rgba = np.where(front[..., 3:4] > 0, np.asarray(front, np.float64)[..., :4], 0.0)
    r = np.where(front[..., 3] > 0, np.asarray(radius, np.float64), -1.0)
    h, w = r.shape
    rho, dist = offset_tables(reach_px(quality), blades, rotation_deg, roundness)
    lv = level_of(np.maximum(r, 0.0), quality)
    r0 = np.where(lv == 0, r, -1.0)
    acc = _spread(np.where(r0[..., None] >= 0, rgba, 0.0) / disc_norm(np.maximum(r0, 0.0), rho, dist)[..., None],
                  r0, rho, dist)
    for level in range(1, n_levels(quality)):
        planes, rl = _level_planes(rgba, np.maximum(r, 0.0), lv, level)
        if (rl < 0).all():
            continue
        spread = _spread(planes / disc_norm(np.maximum(rl, 0.0), rho, dist)[..., None], rl, rho, dist)
        acc += sum(wt[..., None] * spread[ys][:, xs]
                   for ys, xs, wt in fld.upsample_corners(h, w, *rl.shape, 2 ** level))
    return acc[..., :3] + (1.0 - acc[..., 3:]) * np.asarray(background, np.float64)


def front_scatter(front: np.ndarray, radius: np.ndarray, background: np.ndarray, blades: int,
                  rotation_deg: float, roundness: float) -> np.ndarray:
    """The exact model (every pixel spread at full resolution, float64), against which the levels'
    error is measured (tests/test_front_layer.py, docs/fidelity.md)."""
    h, w = radius.shape
    reach = int(math.ceil(float(radius.max()) + 0.5)) if radius.size else 0
    f = np.pad(np.asarray(front, np.float64)[..., :4], ((reach, reach), (reach, reach), (0, 0)), mode="edge")
    rp = np.pad(np.asarray(radius, np.float64), reach, mode="edge")
    hp, wp = rp.shape
    ys, xs = np.nonzero(f[..., 3] > 0)
    src, r = f[ys, xs], rp[ys, xs]
    rho, dist = offset_tables(reach, blades, rotation_deg, roundness)
    norm = disc_norm(r, rho, dist)
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
        lv = level_of(r, self.quality)
        return (f"front layer over {int(cov.sum())} px, CoC radius {r.min():.3g} … {r.max():.3g} px "
                f"(max {max_coc_px(self.quality):g} px, {self.quality}), spread at levels "
                f"{lv.min()} … {lv.max()} (radius {LEVEL_RADIUS[self.quality]} … {2 * LEVEL_RADIUS[self.quality]} "
                f"level px)")

    def defines(self, camera):
        return {"FRONT_TILE": TILE, "FRONT_REACH": reach_px(self.quality), "FRONT_NORM_STEPS": NORM_STEPS,
                "FRONT_RB": f"{float(LEVEL_RADIUS[self.quality])!r}f", "FRONT_LEVELS": n_levels(self.quality),
                "FRONT_SHRINK": f"{LEVEL_SHRINK_PX2!r}f"}

    def _radius_args(self, camera, frame):
        from .dof import coc_coefficients

        if not camera.depth_of_field:
            return 0.0, 0.0
        return coc_coefficients(camera, fld.image_width_px(frame))

    def reference(self, camera, frame, color):
        radius = front_radius(camera, frame.front[..., 4], fld.image_width_px(frame), self.quality)
        return front_reference(frame.front, radius, color, self.quality, camera.blades,
                               camera.blade_rotation_deg, camera.aperture_roundness)

    def enqueue(self, rt, camera, frame, src, dst, aux):
        from ..codegen import library
        from ..runtime import kernel_source

        w, h = frame.width, frame.height
        q = self.quality
        shape = (camera.blades, camera.blade_rotation_deg, camera.aperture_roundness)
        knl = rt.kernels(library() + kernel_source("front_layer"), "front_layer", self.defines(camera))
        rho = rt.constant(lambda: offset_tables(reach_px(q), *shape)[0].astype(np.float32), ("front_layer.rho", q, shape))
        norm = rt.constant(lambda: norm_table(q, *shape).astype(np.float32), ("front_layer.norm", q, shape))
        sizes = [(-(-w // 2 ** L), -(-h // 2 ** L)) for L in range(n_levels(q))]
        tsizes = [(-(-a // TILE), -(-b // TILE)) for a, b in sizes]
        offsets = np.cumsum([0] + [4 * a * b for a, b in sizes[1:]])
        toffsets = np.cumsum([0] + [a * b for a, b in tsizes])
        table = rt.constant(np.array([v for L in range(1, len(sizes))
                                      for v in (*sizes[L], offsets[L - 1], tsizes[L][0], toffsets[L])] or [0], np.int32))
        spread = rt.scratch(self, "spread", (max(int(offsets[-1]), 1),))
        reach = rt.scratch(self, "reach", (int(toffsets[-1]),))
        k, inv_u = self._radius_args(camera, frame)
        i32, f32 = np.int32, np.float32
        rlim = f32(max_coc_px(q))
        form, lanes = ("16", 16) if rt.wide else ("", 1)  # the spreads' 16-pixel forms on a CPU
        evs = []
        for L, ((wl, hl), (tw, th)) in enumerate(zip(sizes, tsizes)):
            planes = rt.scratch(self, f"planes{L}", (5, hl, wl))
            tiles = rt.scratch(self, f"tiles{L}", (th, tw))
            if L == 0:
                planes0 = planes
                evs.append(rt.launch(knl["front_layer_prep"], (w, h), None, aux["front"], norm, planes, i32(w), i32(h),
                                     f32(k), f32(inv_u), rlim))
            else:
                evs.append(rt.launch(knl["front_layer_down"], (wl, hl), None, aux["front"], norm, planes, i32(w), i32(h),
                                     i32(wl), i32(hl), i32(L), f32(k), f32(inv_u), rlim))
            evs.append(rt.launch(knl["front_layer_tiles"], (tw, th), None, planes, tiles, i32(wl), i32(hl), i32(tw),
                                 i32(th)))
            evs.append(rt.launch(knl["front_layer_reach"], (tw, th), None, tiles, reach, i32(tw), i32(th),
                                 i32(toffsets[L])))
            if L > 0:
                zeros = (i32(1),) if rt.wide else ()
                evs.append(rt.launch(knl["front_layer_gather" + form], (-(-wl // lanes), hl), None, planes, reach, rho,
                                     spread, i32(wl), i32(hl), i32(tw), i32(offsets[L - 1]), i32(toffsets[L]), *zeros))
        active = rt.scratch(self, "active", (tsizes[0][1], tsizes[0][0]), np.int32)
        evs.append(rt.launch(knl["front_layer_active"], tsizes[0], None, reach, table, active, i32(tsizes[0][0]),
                             i32(tsizes[0][1])))
        if rt.wide:  # level 0 spread by the 16-pixel gather, then the composite reads it
            spread0 = rt.scratch(self, "spread0", (4, h, w))
            evs.append(rt.launch(knl["front_layer_gather16"], (-(-w // 16), h), None, planes0, reach, rho, spread0,
                                 i32(w), i32(h), i32(tsizes[0][0]), i32(0), i32(0), i32(0)))
            evs.append(rt.launch(knl["front_layer_add"], (w, h), None, src, spread0, reach, spread, table, active, dst,
                                 i32(w), i32(h), i32(tsizes[0][0])))
        else:
            evs.append(rt.launch(knl["front_layer"], (w, h), None, src, planes0, reach, rho, spread, table, active, dst,
                                 i32(w), i32(h), i32(tsizes[0][0])))
        return evs

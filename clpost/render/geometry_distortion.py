r"""Geometry pre-processing distortion (Lambers, Sommerhoff & Kolb, "Realistic Lens Distortion
Rendering", WSCG 2018, sec. 3.2): the OpenCV standard model applied to **vertices** before
rasterisation, so ids, depth and flow — data that must never be interpolated across edges — come
out distorted without resampling.

Vertex stage (what the paper's vertex shader does), for a camera-space vertex (X, Y, Z), Z > 0:

.. math::

    (x', y') = (X/Z,\ Y/Z) \;\xrightarrow{\ D\ }\; (x''', y''')
    \;\xrightarrow{\text{back}}\; \big(x''' Z,\ \tfrac{f_y}{f_x}\,y''' Z,\ Z\big)

with D the full model of :class:`clpost.calibration.OpenCVModel` (radial k1…k6, tangential p,
thin prism s, tilt τ). The transformed vertex, rendered by a pinhole with focal length f_x and
principal point (c_x, c_y), lands exactly on :meth:`OpenCVModel.project` of the original vertex
(``u = f_x x''' + c_x``, ``v = f_y y''' + c_y``); its planar depth Z is unchanged.

Clipping (the paper's fix for vertices the polynomial maps wildly): a triangle is discarded when
a vertex lies outside :math:`[-1-\delta-D,\ 1+\delta+D]^2` in the NDC of the **undistorted**
pinhole image (δ = 0.1), behind the near plane, or beyond the model's fold radius. D is the
distortion margin from the inverse at the image corners,

.. math::

    D = \max\Big(0,\ \max_{\text{corners } q}\ \|\text{ndc}(D^{-1}(q))\|_\infty - 1\Big),

so barrel distortion (whose corners see beyond the pinhole frustum) keeps the geometry it needs.

Adaptive subdivision (edge-based, crack-free): each level splits an edge at its 3-D midpoint m
when both endpoints are inside the region and the chord error

.. math::

    e = \big\|P(m) - \tfrac12\big(P(a) + P(b)\big)\big\|_2 \quad\text{(pixels, } P = \text{project} \circ D)

exceeds ``error_px`` — the straight image-space edge deviates from the curved image of the
3-D edge by about e — or when the edge straddles the region boundary (so large triangles that
reach outside, like the ground quad, are refined until their outside pieces can be discarded:
while the edge is longer than δ in NDC, since a smaller piece with a vertex outside the widened
box cannot reach the image).
The split decision depends only on the edge's endpoints, so both triangles sharing an edge split
it alike (no T-junctions); a triangle is split into 2, 3 or 4 by its number of flagged edges.
Triangles entirely outside one plane of the (widened) frustum are rejected at every level.

Shading stays deferred (:func:`clpost.render.pyvista_renderer.shade`): every output pixel is
shaded at its own undistorted ray (:func:`clpost.calibration.undistort_newton`, computed once per
model), with the visibility (ids) and depth rasterised from the distorted geometry.

:func:`raycast` is the exact reference: the analytic scene intersected by the exact
undistorted ray of every pixel (no tessellation, no resampling).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..calibration import OpenCVModel, undistort_newton
from ..errors import InputError
from ..frame import Frame
from .demo_scene import DemoScene, Plane
from .pyvista_renderer import _NEAR_M, GBuffer, _IdDepthPass, shade, velocity

DELTA_NDC = 0.1
"""δ of Lambers et al.: the clip box is widened by 10 % of the half image in NDC."""


# ---------------------------------------------------------------------------------------------
# Vertex stage
# ---------------------------------------------------------------------------------------------


def distort_points(model: OpenCVModel, pts: np.ndarray) -> np.ndarray:
    """Camera-space points (…×3, Z > 0) → the back-transformed distorted points (…×3), see the
    module docstring. Points with Z ≤ 0 have no image; they are returned unchanged (the
    subdivision discards their triangles)."""
    pts = np.asarray(pts, np.float64)
    z = pts[..., 2]
    front = z > 0
    zs = np.where(front, z, 1.0)
    xd, yd = model.distort_normalized(pts[..., 0] / zs, pts[..., 1] / zs)
    out = np.stack([xd * zs, (model.fy / model.fx) * yd * zs, zs], -1)
    return np.where(front[..., None], out, pts)


def project_distorted(model: OpenCVModel, pts: np.ndarray) -> np.ndarray:
    """Camera-space points (…×3) → distorted pixel coordinates (…×2); Z is clamped to 1e-9 so
    points behind the camera give finite (meaningless) values."""
    z = np.maximum(pts[..., 2], 1e-9)
    u, v = model.project(pts[..., 0] / z, pts[..., 1] / z)
    return np.stack([u, v], -1)


@dataclass(frozen=True)
class ClipRegion:
    """Undistorted normalised bounds x ∈ [x0, x1], y ∈ [y0, y1] (the widened NDC box), the
    margin D (NDC units) and the fold radius (normalised) of the model."""

    x0: float
    x1: float
    y0: float
    y1: float
    margin_d: float
    fold_radius: float
    delta: float
    ndc_scale: tuple[float, float]
    """(2 f_x / W, 2 f_y / H): normalised → NDC lengths."""

    def ndc_length(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """∞-norm NDC length of the pinhole image of segments a–b (…×3, Z clamped > 0)."""
        za, zb = np.maximum(a[..., 2], 1e-9), np.maximum(b[..., 2], 1e-9)
        dx = np.abs(a[..., 0] / za - b[..., 0] / zb) * self.ndc_scale[0]
        dy = np.abs(a[..., 1] / za - b[..., 1] / zb) * self.ndc_scale[1]
        return np.maximum(dx, dy)

    def outcodes(self, pts: np.ndarray) -> np.ndarray:
        """6-bit outcodes of camera-space points (…×3): left, right, top, bottom, near, fold."""
        x, y, z = pts[..., 0], pts[..., 1], pts[..., 2]
        code = (x < self.x0 * z).astype(np.uint8)
        code |= (x > self.x1 * z).astype(np.uint8) << 1
        code |= (y < self.y0 * z).astype(np.uint8) << 2
        code |= (y > self.y1 * z).astype(np.uint8) << 3
        code |= (z < _NEAR_M).astype(np.uint8) << 4
        if math.isfinite(self.fold_radius):
            zs = np.maximum(z, 1e-9)
            code |= ((np.hypot(x / zs, y / zs) >= self.fold_radius) & (z >= _NEAR_M)).astype(np.uint8) << 5
        return code


def clip_region(model: OpenCVModel, delta_ndc: float = DELTA_NDC) -> ClipRegion:
    r"""The clip box :math:`[-1-\delta-D, 1+\delta+D]^2` (undistorted pinhole NDC), in normalised
    coordinates; D from the Newton inverse of the four image corners (module docstring)."""
    if not (math.isfinite(delta_ndc) and delta_ndc >= 0):
        raise InputError(f"delta_ndc={delta_ndc!r} must be a finite number >= 0 (Lambers et al. use 0.1)")
    w, h = model.width, model.height
    cu = np.array([-0.5, w - 0.5, -0.5, w - 0.5])
    cv = np.array([-0.5, -0.5, h - 0.5, h - 0.5])
    x, y, ok = undistort_newton(model, cu, cv)
    ndc_x = 2.0 * (model.fx * x[ok] + model.cx + 0.5) / w - 1.0
    ndc_y = 2.0 * (model.fy * y[ok] + model.cy + 0.5) / h - 1.0
    d = float(max(0.0, np.max(np.abs(np.r_[ndc_x, ndc_y]), initial=1.0) - 1.0))
    if not ok.all():
        # a corner beyond the fold has no preimage: keep everything up to the fold
        d = max(d, 1.0)
    b = 1.0 + delta_ndc + d

    def bounds(lo_ndc, hi_ndc, n, f, c):
        return ((lo_ndc + 1) * n / 2 - 0.5 - c) / f, ((hi_ndc + 1) * n / 2 - 0.5 - c) / f

    x0, x1 = bounds(-b, b, w, model.fx, model.cx)
    y0, y1 = bounds(-b, b, h, model.fy, model.cy)
    return ClipRegion(x0, x1, y0, y1, d, model.fold_radius(), float(delta_ndc),
                      (2.0 * model.fx / w, 2.0 * model.fy / h))


# ---------------------------------------------------------------------------------------------
# Adaptive, crack-free subdivision of a triangle soup
# ---------------------------------------------------------------------------------------------


@dataclass
class SubdivisionStats:
    triangles_in: int = 0
    triangles_out: int = 0
    levels: int = 0
    max_chord_error_px: float = 0.0
    """Largest chord error of an edge left unsplit inside the region (≤ error_px unless the
    level limit stopped the refinement)."""


def subdivide(tris: np.ndarray, model: OpenCVModel, region: ClipRegion, error_px: float = 0.1,
              max_levels: int = 12, stats: SubdivisionStats | None = None) -> np.ndarray:
    """Refine and clip camera-space triangles (N×3×3) as in the module docstring; returns the
    triangles to rasterise (every vertex inside the region)."""
    stats = stats if stats is not None else SubdivisionStats()
    stats.triangles_in += len(tris)
    t = np.asarray(tris, np.float64).reshape(-1, 3, 3)
    level = 0
    while True:
        codes = region.outcodes(t)  # (N, 3)
        reject = (codes[:, 0] & codes[:, 1] & codes[:, 2]) != 0
        t, codes = t[~reject], codes[~reject]
        inside = codes == 0
        a, b = t, t[:, [1, 2, 0]]  # edge k: vertex k → vertex k+1
        ina, inb = inside, inside[:, [1, 2, 0]]
        mid = 0.5 * (a + b)
        both = ina & inb
        chord = np.zeros(both.shape)
        if both.any():
            pa, pb, pm = (project_distorted(model, q[both]) for q in (a, b, mid))
            chord[both] = np.linalg.norm(pm - 0.5 * (pa + pb), axis=-1)
        # a straddling edge needs refining only while it is longer than δ in NDC: a piece
        # smaller than δ with a vertex outside the widened box cannot reach the image
        front = (a[..., 2] >= _NEAR_M) & (b[..., 2] >= _NEAR_M)
        ndc_len = region.ndc_length(a, b)
        flags = (both & (chord > error_px)) | (~both & (~front | (ndc_len > region.delta)))
        flags = _close_flags(a, b, flags)
        if level >= max_levels or not flags.any():
            keep = inside.all(axis=1)
            unsplit = chord[keep]
            stats.max_chord_error_px = max(stats.max_chord_error_px, float(unsplit.max(initial=0.0)))
            t = t[keep]
            break
        t = _split(t, mid, flags)
        level += 1
    stats.levels = max(stats.levels, level)
    stats.triangles_out += len(t)
    return t


def _edge_ids(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Index of every undirected edge (a_k, b_k) of a triangle soup (N×3 edges): endpoints in a
    canonical (lexicographic) order, then identical coordinates → identical id. Shared edges have
    bitwise-equal endpoints because midpoints are computed as ½(a + b) = ½(b + a)."""
    lo, hi = a.reshape(-1, 3), b.reshape(-1, 3)
    swap = (lo[:, 0] > hi[:, 0]) | ((lo[:, 0] == hi[:, 0]) & ((lo[:, 1] > hi[:, 1]) |
                                                             ((lo[:, 1] == hi[:, 1]) & (lo[:, 2] > hi[:, 2]))))
    key = np.where(swap[:, None], np.concatenate([hi, lo], 1), np.concatenate([lo, hi], 1)) + 0.0
    key = np.ascontiguousarray(key).view(np.dtype((np.void, 48))).ravel()
    _, inv = np.unique(key, return_inverse=True)
    return inv.reshape(a.shape[:2])


def _close_flags(a: np.ndarray, b: np.ndarray, flags: np.ndarray) -> np.ndarray:
    """Red–green closure: a triangle with two flagged edges gets its third flagged too (a 4-way
    split instead of the sliver-making 3-way one), propagated over shared edges until stable, so
    refinement keeps triangles well shaped and neighbours agree on every edge."""
    if not flags.any():
        return flags
    eid = _edge_ids(a, b)
    edge_flag = np.zeros(int(eid.max()) + 1, bool)
    edge_flag[eid[flags]] = True
    while True:
        f = edge_flag[eid]
        grow = f.sum(axis=1) == 2
        if not grow.any():
            return f
        edge_flag[eid[grow]] = True


def _split(t: np.ndarray, mid: np.ndarray, flags: np.ndarray) -> np.ndarray:
    """Split each triangle by its flagged edges (0: kept, 1: two, 2: three, 3: four triangles),
    keeping the vertex order (orientation)."""
    n_flag = flags.sum(axis=1)
    out = [t[n_flag == 0]]
    idx = np.arange(3)
    for count in (1, 2, 3):
        sel = np.flatnonzero(n_flag == count)
        if sel.size == 0:
            continue
        f = flags[sel]
        if count == 1:
            s = np.argmax(f, axis=1)  # the flagged edge becomes edge 0
        elif count == 2:
            s = (np.argmin(f, axis=1) + 1) % 3  # the unflagged edge becomes edge 2
        else:
            s = np.zeros(sel.size, int)
        rot = (idx[None, :] + s[:, None]) % 3
        v = np.take_along_axis(t[sel], rot[:, :, None], axis=1)
        m = np.take_along_axis(mid[sel], rot[:, :, None], axis=1)
        v0, v1, v2 = v[:, 0], v[:, 1], v[:, 2]
        m0, m1, m2 = m[:, 0], m[:, 1], m[:, 2]
        if count == 1:
            parts = [(v0, m0, v2), (m0, v1, v2)]
        elif count == 2:
            parts = [(m0, v1, m1), (v0, m0, m1), (v0, m1, v2)]
        else:
            parts = [(v0, m0, m2), (m0, v1, m1), (m2, m1, v2), (m0, m1, m2)]
        out.extend(np.stack(p, axis=1) for p in parts)
    return np.concatenate(out, axis=0)


# ---------------------------------------------------------------------------------------------
# Per-pixel rays of a model (cached) and the exact reference
# ---------------------------------------------------------------------------------------------


@lru_cache(maxsize=8)
def pixel_rays_distorted(model: OpenCVModel) -> tuple[np.ndarray, np.ndarray]:
    """Unit-Z camera-space rays (H×W×3) through every output pixel centre of the distorted
    image (Newton inverse), and their validity (False beyond the fold: no preimage)."""
    vv, uu = np.mgrid[0:model.height, 0:model.width].astype(np.float64)
    x, y, ok = undistort_newton(model, uu, vv)
    rays = np.stack([x, y, np.ones_like(x)], -1)
    rays.setflags(write=False)
    ok.setflags(write=False)
    return rays, ok


def raycast(scene: DemoScene, rays_cam: np.ndarray, cam_pose: np.ndarray, poses: list[np.ndarray]) -> GBuffer:
    """Exact G-buffer: nearest analytic hit of every camera-space ray (H×W×3, unit Z, so the
    ray parameter is the planar depth) with the scene's shapes (planes: the bounded square)."""
    h, w = rays_cam.shape[:2]
    d_world = rays_cam.reshape(-1, 3) @ cam_pose[:3, :3].T
    o_world = cam_pose[:3, 3]
    best = np.full(h * w, np.inf)
    ids = np.full(h * w, -1, np.int32)
    with np.errstate(divide="ignore", invalid="ignore"):
        for k, obj in enumerate(scene.objects):
            rot, t = poses[k][:3, :3], poses[k][:3, 3]
            o = np.broadcast_to((o_world - t) @ rot, d_world.shape)
            d = d_world @ rot
            if isinstance(obj.shape, Plane):
                tt = -o[:, 2] / d[:, 2]
                q = o + tt[:, None] * d
                hs = obj.shape.half_size_m
                hit = (tt > 0) & (np.abs(q[:, 0]) <= hs) & (np.abs(q[:, 1]) <= hs)
            else:
                t_in, t_out = obj.shape.interval(o, d)
                tt = np.where(t_in > 0, t_in, np.inf)
                hit = (t_in <= t_out) & np.isfinite(tt)
            closer = hit & (tt < best)
            best[closer] = tt[closer]
            ids[closer] = k
    return GBuffer(ids=ids.reshape(h, w), depth=best.reshape(h, w))


# ---------------------------------------------------------------------------------------------
# The renderer
# ---------------------------------------------------------------------------------------------


class GeometryDistortionRenderer:
    r"""Renders a :class:`DemoScene` directly into the distorted image of ``model`` (its size and
    intrinsics): color, planar depth, forward flow in distorted pixels, object ids
    (``metadata["object_id"]``) and alpha (0 beyond the fold).

    ``error_px`` is the chord error the subdivision allows (pixels), ``delta_ndc`` the clip
    margin δ, ``max_levels`` the subdivision depth limit. ``metadata["geometry_distortion"]``
    carries the triangle counts, levels and the per-part timings of the frame.
    """

    def __init__(self, scene: DemoScene, model: OpenCVModel, error_px: float = 0.1,
                 delta_ndc: float = DELTA_NDC, max_levels: int = 12) -> None:
        import pyvista as pv

        if not isinstance(scene, DemoScene):
            raise InputError(f"GeometryDistortionRenderer needs a DemoScene, got {type(scene).__name__}")
        if not isinstance(model, OpenCVModel):
            raise InputError(f"GeometryDistortionRenderer needs an OpenCVModel (clpost.calibration), "
                             f"got {type(model).__name__}; load one with clpost.calibration.load_calibration")
        if not (isinstance(error_px, (int, float)) and math.isfinite(error_px) and error_px > 0):
            raise InputError(f"error_px={error_px!r} must be a chord error in pixels > 0, e.g. 0.1")
        if int(max_levels) != max_levels or not 0 <= max_levels <= 20:
            raise InputError(f"max_levels={max_levels!r} must be an integer in [0, 20]")
        self.scene, self.model = scene, model
        self.error_px, self.max_levels = float(error_px), int(max_levels)
        self.region = clip_region(model, delta_ndc)
        self._pass = _IdDepthPass(scene)
        self._local = []
        for obj in scene.objects:
            m = obj.shape.mesh().triangulate()
            faces = np.asarray(m.faces).reshape(-1, 4)[:, 1:]
            self._local.append(np.asarray(m.points, np.float64)[faces])
        self._pv = pv

    def distorted_meshes(self, frame_index: int, stats: SubdivisionStats | None = None) -> list[np.ndarray]:
        """Per object: the refined, clipped, back-transformed triangles (N×3×3, camera space)."""
        cam = self.scene.camera_pose(frame_index)
        out = []
        for k, local in enumerate(self._local):
            pose = self.scene.object_pose(k, frame_index)
            world = local @ pose[:3, :3].T + pose[:3, 3]
            tri = (world - cam[:3, 3]) @ cam[:3, :3]
            tri = subdivide(tri, self.model, self.region, self.error_px, self.max_levels, stats)
            out.append(distort_points(self.model, tri))
        return out

    def gbuffer(self, frame_index: int, stats: SubdivisionStats | None = None) -> tuple[GBuffer, dict]:
        """Rasterise ids and depth of the distorted geometry; returns the G-buffer and timings (s)."""
        t0 = time.perf_counter()
        meshes = self.distorted_meshes(frame_index, stats)
        t1 = time.perf_counter()
        for actor, tri in zip(self._pass.actors, meshes):
            n = len(tri)
            faces = np.hstack([np.full((n, 1), 3, np.int64), np.arange(3 * n, dtype=np.int64).reshape(n, 3)])
            poly = self._pv.PolyData(tri.reshape(-1, 3), faces.ravel()) if n else self._pv.PolyData()
            actor.GetMapper().SetInputData(poly)
        m = self.model
        cam = self.scene.camera_pose(frame_index)
        self._pass.set_camera(cam, m.fx, m.height, (m.cx, m.cy, m.width))
        gbuf = self._pass.render((m.width, m.height), [cam] * len(meshes))
        t2 = time.perf_counter()
        return gbuf, {"subdivide_s": t1 - t0, "rasterize_s": t2 - t1}

    def render(self, frame_index: int = 0) -> Frame:
        stats = SubdivisionStats()
        gbuf, times = self.gbuffer(frame_index, stats)
        t0 = time.perf_counter()
        m = self.model
        rays, ok = pixel_rays_distorted(m)
        cam = self.scene.camera_pose(frame_index)
        poses = [self.scene.object_pose(k, frame_index) for k in range(len(self.scene.objects))]
        color = shade(self.scene, gbuf, m.fx, (m.cx, m.cy), cam, poses, rays=rays)
        vel = velocity(self.scene, gbuf, m.fx, (m.cx, m.cy), frame_index, rays=rays,
                       project_px=lambda p: project_distorted(m, p))
        times["shade_s"] = time.perf_counter() - t0
        alpha = ok.astype(np.float32)
        color = np.where(ok[..., None], color, 0.0)
        vel = np.where(ok[..., None], vel, 0.0)
        return Frame(color=color.astype(np.float32), depth=gbuf.depth.astype(np.float32),
                     velocity=vel.astype(np.float32), alpha=alpha,
                     metadata={"renderer": "GeometryDistortionRenderer", "frame_index": int(frame_index),
                               "intrinsics": (m.fx, m.fy, m.cx, m.cy), "camera_pose": cam,
                               "object_id": gbuf.ids, "object_names": tuple(o.name for o in self.scene.objects),
                               "geometry_distortion": {**stats.__dict__, **times,
                                                       "margin_d_ndc": self.region.margin_d}})

    def close(self) -> None:
        self._pass.close()


def render_reference(scene: DemoScene, model: OpenCVModel, frame_index: int = 0) -> Frame:
    """The exact distorted frame: :func:`raycast` of every pixel's undistorted ray, shaded by the
    same deferred shader (metadata ``object_id``)."""
    rays, ok = pixel_rays_distorted(model)
    cam = scene.camera_pose(frame_index)
    poses = [scene.object_pose(k, frame_index) for k in range(len(scene.objects))]
    gbuf = raycast(scene, rays, cam, poses)
    color = shade(scene, gbuf, model.fx, (model.cx, model.cy), cam, poses, rays=rays)
    color = np.where(ok[..., None], color, 0.0)
    depth = np.where(ok, gbuf.depth, np.inf)
    return Frame(color=color.astype(np.float32), depth=depth.astype(np.float32), alpha=ok.astype(np.float32),
                 metadata={"renderer": "raycast", "object_id": np.where(ok, gbuf.ids, -1)})


def render_geometry_distorted_sequence(model: OpenCVModel, size: tuple[int, int], n_frames: int = 1,
                                       camera_motion: bool = False, scene: DemoScene | None = None,
                                       error_px: float = 0.1) -> list[Frame]:
    """Frames 0 … n_frames−1 of the demo scene rendered through ``model`` (scaled to ``size``)
    by geometry distortion — what ``clpost demo --lens-model geometry-distortion`` uses."""
    if int(n_frames) != n_frames or n_frames < 1:
        raise InputError(f"n_frames={n_frames!r} must be an integer >= 1")
    r = GeometryDistortionRenderer(scene if scene is not None else DemoScene.default(camera_motion=camera_motion),
                                   model.scaled_to(*size), error_px=error_px)
    try:
        return [r.render(i) for i in range(int(n_frames))]
    finally:
        r.close()

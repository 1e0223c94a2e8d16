r"""Offscreen VTK rasterizer (meshes from pyvista) + deferred linear-HDR shading in numpy.

Why deferred: VTK's default framebuffer is 8-bit and clipped, and its shading path mixes
clamped colours, textures and gamma options. So VTK does only what a rasterizer must do exactly —
visibility — in **one** render per frame: every actor is drawn unlit in a flat colour that
encodes its object id (16 bits in R, G), with MSAA off so ids and depth are not blended. The
id image and the depth buffer are read back, and everything else is computed per pixel in
float64 numpy from the analytic scene (:mod:`clpost.render.demo_scene`): exact normals,
filtered procedural textures, sun + shadows, sky, emitters. Color is thus linear HDR with no
clipping, and color, depth and velocity describe the same surface point at every pixel.

Pixel convention (``shared/CONVENTIONS.md``): the centre of column i, row j is (x, y) = (i, j),
row 0 at the top (VTK reads bottom-up: rows are flipped). With intrinsics (f, f, c_x, c_y):

.. math::

    x = f\,\frac{X}{Z} + c_x, \qquad y = f\,\frac{Y}{Z} + c_y

for a camera-space point (X right, Y down, Z forward). VTK's camera is set with the vertical view
angle :math:`2\arctan\big((H/2)/f\big)` and the principal point at the viewport centre, which is
:math:`((W-1)/2, (H-1)/2)` in this convention — the only principal point :class:`Camera` makes.

Depth: OpenGL stores :math:`d = \frac{f_c (Z - n)}{Z (f_c - n)} \in [0, 1]` for near/far clip n,
f_c, hence planar depth :math:`Z = \frac{n f_c}{f_c - d (f_c - n)}`; d = 1 (cleared) is +inf.

Velocity (forward, px per frame): the surface point of pixel (x, y) in world space,

.. math::

    P = R_c(i)\,\big(Z\,((x - c_x)/f,\ (y - c_y)/f,\ 1)\big) + C(i),

moves rigidly with its object, :math:`P' = T_o(i+1)\,T_o(i)^{-1} P`, and is projected with the
camera of frame i+1: :math:`X' = R_c(i+1)^\top (P' - C(i+1))`, velocity :math:`= \pi(X') - (x, y)`.
Background (Z = ∞) is a direction and moves only with the camera's rotation.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from ..camera import Camera
from ..errors import InputError
from ..frame import Frame
from .demo_scene import DemoScene

_NEAR_M = 0.05
"""Near clip plane (m). Objects start at 0.5 m; a larger near plane gives finer depth precision
(OpenGL depth resolution ΔZ ≈ Z²/n · 2⁻²⁴: 3 mm at 50 m with n = 5 cm)."""
_FAR_M = 2000.0


# ---------------------------------------------------------------------------------------------
# VTK: one unlit id + depth pass
# ---------------------------------------------------------------------------------------------


def _offscreen_window():
    """An offscreen VTK render window. Without a display, ask for EGL directly: the generic
    factory first tries X11 and prints a 'bad X server connection' warning on every run."""
    import vtk

    window = None
    if not os.environ.get("DISPLAY"):
        try:
            from vtkmodules.vtkRenderingOpenGL2 import vtkEGLRenderWindow
            window = vtkEGLRenderWindow()
        except ImportError:  # a VTK build without EGL: let the factory choose (OSMesa, X)
            window = None
    if window is None:
        window = vtk.vtkRenderWindow()
    window.SetOffScreenRendering(1)
    # MSAA would average ids of neighbouring objects and corrupt depth at edges
    window.SetMultiSamples(0)
    window.SetLineSmoothing(0)
    window.SetPolygonSmoothing(0)
    return window


def _id_color(index: int) -> tuple[float, float, float]:
    """Flat colour encoding object ``index`` as id = index + 1 = R + 256·G (8-bit channels);
    black (id 0) is the background."""
    code = index + 1
    return (code & 255) / 255.0, (code >> 8) / 255.0, 0.0


def _vtk_matrix(m: np.ndarray):
    import vtk

    out = vtk.vtkMatrix4x4()
    for r in range(4):
        for c in range(4):
            out.SetElement(r, c, float(m[r, c]))
    return out


def set_vtk_camera(cam, pose: np.ndarray, f_px: float, height_px: int,
                   principal: tuple[float, float, int] | None = None) -> None:
    """Set the VTK camera ``cam`` (see :meth:`_IdDepthPass.set_camera`)."""
    c = pose[:3, 3]
    cam.SetPosition(*c)
    cam.SetFocalPoint(*(c + pose[:3, 2]))
    cam.SetViewUp(*(-pose[:3, 1]))
    cam.SetViewAngle(math.degrees(2.0 * math.atan(0.5 * height_px / f_px)))
    cam.SetWindowCenter(0.0, 0.0)
    if principal is not None:
        cx, cy, w = principal
        cam.SetWindowCenter(1.0 - 2.0 * (cx + 0.5) / w, 2.0 * (cy + 0.5) / height_px - 1.0)
    cam.SetClippingRange(_NEAR_M, _FAR_M)


@dataclass
class GBuffer:
    """What the rasterizer measured at pixel centres: object index (−1 = background) and planar
    depth Z in metres (+inf background), both H×W, row 0 at the top."""

    ids: np.ndarray
    depth: np.ndarray


class _IdDepthPass:
    """The VTK scene of a :class:`DemoScene`: actors built once, only transforms change."""

    def __init__(self, scene: DemoScene) -> None:
        import vtk

        self.window = _offscreen_window()
        self.renderer = vtk.vtkRenderer()
        self.renderer.SetBackground(0.0, 0.0, 0.0)
        self.renderer.SetUseFXAA(False)
        self.window.AddRenderer(self.renderer)
        self.actors = []
        for k, obj in enumerate(scene.objects):
            mapper = vtk.vtkPolyDataMapper()
            mapper.SetInputData(obj.shape.mesh())
            mapper.ScalarVisibilityOff()
            actor = vtk.vtkActor()
            actor.SetMapper(mapper)
            prop = actor.GetProperty()
            prop.LightingOff()  # unlit: the fragment colour is exactly the id colour
            prop.SetInterpolationToFlat()
            prop.SetColor(*_id_color(k))
            self.renderer.AddActor(actor)
            self.actors.append(actor)
        self.size: tuple[int, int] | None = None

    def set_camera(self, pose: np.ndarray, f_px: float, height_px: int,
                   principal: tuple[float, float, int] | None = None) -> None:
        """VTK camera from a camera-to-world pose (columns right, down, forward) and f in px.
        ``principal`` = (c_x, c_y, width): an off-centre principal point (distortion's extended
        frustum). VTK shifts the projection by minus its window centre, so the window centre is
        minus the optical axis's NDC position :math:`(2(c_x + ½)/W - 1, 1 - 2(c_y + ½)/H)`
        (checked in tests/test_distortion.py against a crop of a wider centred render)."""
        set_vtk_camera(self.renderer.GetActiveCamera(), pose, f_px, height_px, principal)

    def render(self, size: tuple[int, int], object_poses: list[np.ndarray]) -> GBuffer:
        import vtk
        from vtkmodules.util.numpy_support import vtk_to_numpy

        w, h = size
        if self.size != size:
            self.window.SetSize(w, h)
            self.size = size
        for actor, pose in zip(self.actors, object_poses):
            actor.SetUserMatrix(_vtk_matrix(pose))
        self.window.Render()

        rgb = vtk.vtkUnsignedCharArray()
        self.window.GetPixelData(0, 0, w - 1, h - 1, 0, rgb, 0)
        rgb = vtk_to_numpy(rgb).reshape(h, w, 3)[::-1]
        ids = rgb[..., 0].astype(np.int32) + 256 * rgb[..., 1].astype(np.int32) - 1

        zbuf = vtk.vtkFloatArray()
        self.window.GetZbufferData(0, 0, w - 1, h - 1, zbuf)
        d = vtk_to_numpy(zbuf).reshape(h, w)[::-1].astype(np.float64)
        with np.errstate(divide="ignore"):
            depth = _NEAR_M * _FAR_M / (_FAR_M - d * (_FAR_M - _NEAR_M))
        background = (d >= 1.0) | (ids < 0)
        depth[background] = np.inf
        ids[background] = -1
        return GBuffer(ids=np.ascontiguousarray(ids), depth=np.ascontiguousarray(depth))

    def close(self) -> None:
        self.window.Finalize()


# ---------------------------------------------------------------------------------------------
# Geometry per pixel
# ---------------------------------------------------------------------------------------------


def pixel_rays(size: tuple[int, int], f_px: float, c: tuple[float, float]) -> np.ndarray:
    r"""Camera-space ray directions with unit Z through every pixel centre,
    :math:`((i - c_x)/f, (j - c_y)/f, 1)`, shape H×W×3 (float64)."""
    w, h = size
    x = (np.arange(w, dtype=np.float64) - c[0]) / f_px
    y = (np.arange(h, dtype=np.float64) - c[1]) / f_px
    rays = np.empty((h, w, 3))
    rays[..., 0] = x[None, :]
    rays[..., 1] = y[:, None]
    rays[..., 2] = 1.0
    return rays


def project(points_cam: np.ndarray, f_px: float, c: tuple[float, float]) -> np.ndarray:
    r"""Pinhole projection :math:`(f X/Z + c_x,\ f Y/Z + c_y)` of camera-space points (…×3)."""
    z = points_cam[..., 2]
    return np.stack([f_px * points_cam[..., 0] / z + c[0], f_px * points_cam[..., 1] / z + c[1]], -1)


def _segments(ids: np.ndarray):
    """(object index, flat pixel indices) for every object present in the id image."""
    flat = ids.reshape(-1)
    order = np.argsort(flat, kind="stable")
    sorted_ids = flat[order]
    starts = np.flatnonzero(np.r_[True, sorted_ids[1:] != sorted_ids[:-1]])
    ends = np.r_[starts[1:], flat.size]
    for s, e in zip(starts, ends):
        k = int(sorted_ids[s])
        if k >= 0:
            yield k, order[s:e]


def _footprint(coord: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """Per-pixel texture footprint: the larger over x and y of the smaller one-sided difference of
    ``coord`` (H×W×k) to a neighbour of the same object (0 where there is none). Taking the
    smaller side keeps silhouettes from getting the huge jump to a far surface."""
    big = np.inf
    out = np.zeros(coord.shape)
    for axis in (0, 1):
        n = coord.shape[axis]
        diff = np.abs(np.diff(coord, axis=axis))
        same = np.diff(ids, axis=axis) == 0
        diff = np.where(same[..., None], diff, big)
        lo = [slice(None)] * 2
        hi = [slice(None)] * 2
        lo[axis], hi[axis] = slice(0, n - 1), slice(1, n)
        fwd = np.full(coord.shape, big)
        bwd = np.full(coord.shape, big)
        fwd[tuple(lo)] = diff  # pixel p to p+1
        bwd[tuple(hi)] = diff  # pixel p-1 to p
        best = np.minimum(fwd, bwd)
        out = np.maximum(out, np.where(np.isfinite(best), best, 0.0))
    return out


# ---------------------------------------------------------------------------------------------
# Procedural textures (box-filtered over the pixel footprint so distant checkers do not alias)
# ---------------------------------------------------------------------------------------------


def _square_wave_filtered(x: np.ndarray, w: np.ndarray) -> np.ndarray:
    r"""Square wave s(x) = +1 on [0, 1), −1 on [1, 2) (period 2), box-filtered over width w:
    :math:`(S(x + w/2) - S(x - w/2))/w` with S the triangle-wave integral of s."""
    def tri(t):
        return 1.0 - np.abs(2.0 * (t / 2.0 - np.floor(t / 2.0)) - 1.0)

    sharp = np.where((x - 2.0 * np.floor(x / 2.0)) < 1.0, 1.0, -1.0)
    ww = np.maximum(w, 1e-6)
    filt = (tri(x + 0.5 * ww) - tri(x - 0.5 * ww)) / ww
    return np.where(w < 1e-6, sharp, filt)


def checker(coord: np.ndarray, width: np.ndarray) -> np.ndarray:
    """Filtered checker in [0, 1] over the k dimensions of ``coord`` (cells of size 1)."""
    return 0.5 + 0.5 * np.prod(_square_wave_filtered(coord, width), axis=-1)


def _checker_gaussian(coord: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    r"""Checker in [0, 1] (cells of size 1) filtered by a separable Gaussian of σ (per point and
    axis, cell units), keeping only the nearest edge per axis (the others are ≥ ½ cell away: error
    ≈ erfc(½/(σ√2)), < 1e-9 for σ < 0.08 cell; the calibration board has σ ≈ 0.04):
    :math:`\tfrac12 + \tfrac12\prod_i s_i\,
    \operatorname{erf}(d_i / (\sigma_i\sqrt2))` with :math:`s_i` the cell's sign and :math:`d_i`
    the distance to its nearest edge."""
    from scipy.special import erf

    f = coord - np.floor(coord)
    sign = np.where((coord - 2.0 * np.floor(coord / 2.0)) < 1.0, 1.0, -1.0)
    d = np.minimum(f, 1.0 - f)
    with np.errstate(divide="ignore"):
        g = np.where(sigma > 0, erf(d / (np.maximum(sigma, 1e-300) * math.sqrt(2.0))), 1.0)
    return 0.5 + 0.5 * np.prod(sign * g, axis=-1)


def _hash01(ix: np.ndarray, iy: np.ndarray) -> np.ndarray:
    """Deterministic lattice hash → [0, 1) (integer mixing, identical on every machine)."""
    h = (ix.astype(np.int64) * 374761393 + iy.astype(np.int64) * 668265263) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    h = h ^ (h >> 16)
    return (h & 0xFFFFFF) / float(1 << 24)


def value_noise(xy: np.ndarray) -> np.ndarray:
    """Smooth 2-D value noise in [0, 1] (lattice spacing 1, smoothstep interpolation)."""
    i = np.floor(xy)
    t = xy - i
    t = t * t * (3.0 - 2.0 * t)
    ix, iy = i[..., 0].astype(np.int64), i[..., 1].astype(np.int64)
    a, b = _hash01(ix, iy), _hash01(ix + 1, iy)
    c, d = _hash01(ix, iy + 1), _hash01(ix + 1, iy + 1)
    tx, ty = t[..., 0], t[..., 1]
    return (a * (1 - tx) + b * tx) * (1 - ty) + (c * (1 - tx) + d * tx) * ty


def _albedo(material, coord: np.ndarray, width: np.ndarray) -> np.ndarray:
    """Albedo (N×3) of local points ``coord`` (N×3, metres) with footprint ``width`` (N×3, m)."""
    a1 = np.asarray(material.albedo, dtype=np.float64)
    a2 = np.asarray(material.albedo2, dtype=np.float64)
    if material.texture == "flat":
        return np.broadcast_to(a1, coord.shape).copy()
    if material.texture == "checker":
        s = material.texture_scale_m
        # +0.5 cell keeps the face planes of boxes (whole multiples of the cell) off a boundary
        t = checker(coord / s + 0.5, width / s)
        return a2 + (a1 - a2) * t[:, None]
    if material.texture == "board":
        s = material.texture_scale_m
        nx, ny = material.board_squares
        # cells [k, k+1) of the filtered checker from the board's corner; +1 in x puts the
        # dark colour (albedo2) in the corner square
        xy = coord[:, :2] / s + 0.5 * np.array([nx, ny]) + np.array([1.0, 0.0])
        t = checker(xy, width[:, :2] / s)
        if material.board_blur > 0:  # replaces the box-filtered value
            t = _checker_gaussian(xy, material.board_blur * width[:, :2] / s)
        inside = (np.abs(coord[:, 0]) < 0.5 * nx * s) & (np.abs(coord[:, 1]) < 0.5 * ny * s)
        t = np.where(inside, t, 1.0)
        return a2 + (a1 - a2) * t[:, None]
    # ground: 1 m checker, a faint 0.1 m checker and 3 m value noise, in the local xy plane
    xy, wxy = coord[:, :2], width[:, :2]
    big = checker(xy, wxy)
    fine = checker(xy / 0.1, wxy / 0.1) - 0.5
    noise = value_noise(xy / 3.0 + 17.0)
    base = a2 + (a1 - a2) * big[:, None]
    return np.clip(base * ((1.0 + 0.35 * fine) * (0.75 + 0.5 * noise))[:, None], 0.0, 1.0)


# ---------------------------------------------------------------------------------------------
# Shading
# ---------------------------------------------------------------------------------------------


def _sky(dirs_world: np.ndarray, scene: DemoScene) -> np.ndarray:
    """Sky radiance: horizon colour blending to zenith colour with elevation (linear RGB)."""
    d = dirs_world / np.linalg.norm(dirs_world, axis=-1, keepdims=True)
    t = np.sqrt(np.clip(d[..., 2], 0.0, 1.0))[..., None]
    return (1.0 - t) * np.asarray(scene.sky_horizon) + t * np.asarray(scene.sky_zenith)


def _sun_visibility(points: np.ndarray, normals: np.ndarray, owner: np.ndarray, scene: DemoScene,
                    poses: list[np.ndarray]) -> np.ndarray:
    """1 where the ray from each point towards the sun leaves the scene, 0 where a shadow-casting
    shape blocks it (exact ray–shape intervals; a bounding-sphere test culls first). Convex
    shapes cannot shadow themselves on their lit side, so a point's own object is skipped."""
    s = scene.sun_unit
    origin = points + 2e-3 * normals  # off the tessellated surface, which lies ≤ 0.5 mm inside
    # |c − o|² and (c − o)·s expanded so each object costs one matrix–vector product
    o_s = origin @ s
    o_o = np.einsum("ij,ij->i", origin, origin)
    vis = np.ones(points.shape[0])
    for k, obj in enumerate(scene.objects):
        if not obj.casts_shadow:
            continue
        centre, rot = poses[k][:3, 3], poses[k][:3, :3]
        along = centre @ s - o_s
        dist2 = centre @ centre - 2.0 * (origin @ centre) + o_o
        r = obj.shape.bounding_radius_m
        cand = np.flatnonzero((along > -r) & (dist2 - along * along < r * r) & (owner != k) & (vis > 0))
        if cand.size == 0:
            continue
        o_local = (origin[cand] - centre) @ rot  # R^T (P - t), row-vector form
        d_local = np.broadcast_to(s @ rot, o_local.shape)
        t_in, t_out = obj.shape.interval(o_local, d_local)
        hit = np.maximum(t_in, 0.0) <= t_out
        vis[cand[hit]] = 0.0
    return vis


def _lit_radiance(scene: DemoScene, p: np.ndarray, n: np.ndarray, owner: np.ndarray, local: np.ndarray,
                  width: np.ndarray, poses: list[np.ndarray]) -> np.ndarray:
    """Radiance (N×3) of non-emitting surface points: world positions ``p`` and normals ``n``
    (N×3) on objects ``owner`` (N), local coordinates ``local`` and texture footprint ``width``
    (N×3): albedo × (sun with shadows + hemispherical ambient + emitters); see :class:`DemoScene`."""
    s = scene.sun_unit
    cos_s = np.clip(n @ s, 0.0, None)
    sunlit = np.flatnonzero(cos_s > 0)
    vis = np.zeros(len(p))
    vis[sunlit] = _sun_visibility(p[sunlit], n[sunlit], owner[sunlit], scene, poses)
    irradiance = scene.sun_irradiance * cos_s * vis + scene.ambient * 0.5 * (1.0 + n[:, 2])
    irr_rgb = np.repeat(irradiance[:, None], 3, axis=1)
    if scene.emitter_lighting:
        # |c − p|² and n·(c − p) expanded so each emitter costs two matrix–vector products
        p_p = np.einsum("ij,ij->i", p, p)
        n_p = np.einsum("ij,ij->i", n, p)
        for k, obj in enumerate(scene.objects):
            if not obj.material.is_emitter:
                continue
            centre = poses[k][:3, 3]
            r = obj.shape.bounding_radius_m
            dist2 = np.maximum(centre @ centre - 2.0 * (p @ centre) + p_p, r * r)
            cos_e = np.clip(n @ centre - n_p, 0.0, None) / np.sqrt(dist2)
            power = math.pi * r * r * np.asarray(obj.material.emission)
            irr_rgb += (cos_e / dist2)[:, None] * power

    albedo = np.zeros((len(p), 3))
    order = np.argsort(owner, kind="stable")
    bounds = np.flatnonzero(np.r_[True, owner[order][1:] != owner[order][:-1], True])
    if len(p) == 0:  # only sky or emitters in view (a small sub-frustum): no albedo to look up
        bounds = bounds[:1]
    for a, b in zip(bounds[:-1], bounds[1:]):
        sel = order[a:b]
        k = int(owner[sel[0]])
        albedo[sel] = _albedo(scene.objects[k].material, local[sel], width[sel])
    return albedo * irr_rgb


def shade(scene: DemoScene, gbuf: GBuffer, f_px: float, c: tuple[float, float],
          cam_pose: np.ndarray, poses: list[np.ndarray], rays: np.ndarray | None = None) -> np.ndarray:
    """Linear HDR radiance (H×W×3, float64) of the G-buffer; see :class:`DemoScene` for the model.
    ``rays`` (H×W×3, unit Z) replaces the pinhole rays per pixel (renderer-side lens models:
    geometry distortion, image-based lens)."""
    h, w = gbuf.ids.shape
    rays = pixel_rays((w, h), f_px, c) if rays is None else rays
    rot_c, cen_c = cam_pose[:3, :3], cam_pose[:3, 3]
    dirs = rays @ rot_c.T
    color = _sky(dirs, scene)

    finite = np.isfinite(gbuf.depth)
    depth = np.where(finite, gbuf.depth, 0.0)
    points = (rays * depth[..., None]) @ rot_c.T + cen_c  # world positions (valid where finite)

    flat_pts = points.reshape(-1, 3)
    normals = np.zeros_like(flat_pts)
    local = np.zeros_like(flat_pts)
    for k, pix in _segments(gbuf.ids):
        rot, t = poses[k][:3, :3], poses[k][:3, 3]
        p = (flat_pts[pix] - t) @ rot
        local[pix] = p
        normals[pix] = scene.objects[k].shape.normal(p) @ rot.T
    width = _footprint(local.reshape(h, w, 3), gbuf.ids).reshape(-1, 3)

    ids = gbuf.ids.reshape(-1)
    lit = np.flatnonzero(ids >= 0)
    emissive = np.array([o.material.is_emitter for o in scene.objects] + [False])
    lit = lit[~emissive[ids[lit]]]
    out = color.reshape(-1, 3)
    out[lit] = _lit_radiance(scene, flat_pts[lit], normals[lit], ids[lit], local[lit], width[lit], poses)
    for k, pix in _segments(gbuf.ids):
        if scene.objects[k].material.is_emitter:
            out[pix] = scene.objects[k].material.emission
    return out.reshape(h, w, 3)


def surface_radiance(scene: DemoScene, k: int, local: np.ndarray, width: np.ndarray,
                     poses: list[np.ndarray]) -> np.ndarray:
    """Radiance (N×3) of object ``k`` at local points ``local`` (N×3, on its surface) with texture
    footprint ``width`` (N×3, m): what :func:`shade` gives a pixel that sees that point, for
    view-independent (baked) shading — the scene is Lambertian, so only the footprint depends
    on the view."""
    obj = scene.objects[k]
    if obj.material.is_emitter:
        return np.broadcast_to(np.asarray(obj.material.emission, np.float64), local.shape).copy()
    rot, t = poses[k][:3, :3], poses[k][:3, 3]
    return _lit_radiance(scene, local @ rot.T + t, obj.shape.normal(local) @ rot.T, np.full(len(local), k), local,
                         width, poses)


# ---------------------------------------------------------------------------------------------
# Velocity
# ---------------------------------------------------------------------------------------------


def velocity(scene: DemoScene, gbuf: GBuffer, f_px: float, c: tuple[float, float], frame: int,
             rays: np.ndarray | None = None, project_px=None) -> np.ndarray:
    """Forward screen-space motion (H×W×2, px per frame, +x right, +y down) by reprojection; see
    the module docstring for the formula. ``rays`` (H×W×3, unit Z) and ``project_px``
    (camera-space points …×3 → pixels …×2) replace the pinhole for renderer-side lens models."""
    h, w = gbuf.ids.shape
    rays = pixel_rays((w, h), f_px, c) if rays is None else rays
    cam0, cam1 = scene.camera_pose(frame), scene.camera_pose(frame + 1)
    finite = np.isfinite(gbuf.depth)
    depth = np.where(finite, gbuf.depth, 1.0)
    pts = ((rays * depth[..., None]) @ cam0[:3, :3].T + cam0[:3, 3]).reshape(-1, 3)
    for k, pix in _segments(gbuf.ids):
        motion = scene.objects[k].motion
        if motion.is_static:
            continue
        delta = scene.object_pose(k, frame + 1) @ np.linalg.inv(scene.object_pose(k, frame))
        pts[pix] = pts[pix] @ delta[:3, :3].T + delta[:3, 3]
    pts = pts.reshape(h, w, 3)
    # points: translate then rotate into the next camera; directions (background): rotate only
    dirs = rays @ cam0[:3, :3].T
    moved = np.where(finite[..., None], pts - cam1[:3, 3], dirs) @ cam1[:3, :3]
    # a point that passes behind the next camera has no image: clamp its Z so motion stays finite
    moved[..., 2] = np.maximum(moved[..., 2], 1e-6)
    xy = project(moved, f_px, c) if project_px is None else project_px(moved)
    base = np.stack(np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64)), -1)
    vel = np.clip(xy - base, -1e6, 1e6)
    if np.array_equal(cam0, cam1):
        # static camera: what does not move has exactly zero motion, not 1e-13 px of round-off
        moving = np.array([not o.motion.is_static for o in scene.objects] + [False])
        vel[~moving[gbuf.ids]] = 0.0
    return vel


# ---------------------------------------------------------------------------------------------
# The renderer
# ---------------------------------------------------------------------------------------------


class PyVistaRenderer:
    """Renders a :class:`DemoScene` to a :class:`~clpost.frame.Frame` (color, depth, velocity).

    The VTK scene is built once; :meth:`render` only moves actors and the camera, renders one
    unlit id + depth pass, then shades and reprojects in numpy. ``supersample`` (odd, ≥ 1)
    renders s×s samples per pixel and box-filters the colour (antialiasing); depth, velocity and
    ids come from the centre sample, which lies exactly on the pixel centre because s is odd.
    """

    def __init__(self, scene: DemoScene, supersample: int = 1) -> None:
        if not isinstance(scene, DemoScene):
            raise InputError(f"PyVistaRenderer needs a DemoScene, got {type(scene).__name__}")
        if int(supersample) != supersample or supersample < 1 or supersample % 2 == 0:
            raise InputError(f"PyVistaRenderer.supersample={supersample!r} must be an odd integer >= 1 "
                             "(odd keeps a sample on the pixel centre), e.g. 1 or 3")
        self.scene = scene
        self.supersample = int(supersample)
        self._pass = _IdDepthPass(scene)

    def gbuffer(self, size: tuple[int, int], f_px: float, frame_index: int,
                c: tuple[float, float] | None = None,
                offset_m: tuple[float, float] = (0.0, 0.0)) -> tuple[GBuffer, np.ndarray, list]:
        """Rasterize ids and planar depth at ``size`` with focal length ``f_px`` (principal point
        ``c``, default the image centre; the camera centre moved by ``offset_m`` along its x, y
        axes, or x, y, z with a third entry); returns the G-buffer, the camera pose and the object
        poses."""
        cam_pose = self.scene.camera_pose(frame_index)
        if any(offset_m):
            cam_pose = cam_pose.copy()
            # a third entry (image-based lens: a COP off the camera centre along the axis) moves along z
            cam_pose[:3, 3] += cam_pose[:3, :3] @ np.array([offset_m[0], offset_m[1], offset_m[2] if len(offset_m) > 2 else 0.0])
        poses = [self.scene.object_pose(k, frame_index) for k in range(len(self.scene.objects))]
        self._pass.set_camera(cam_pose, f_px, size[1], None if c is None else (c[0], c[1], size[0]))
        return self._pass.render(size, poses), cam_pose, poses

    def render(self, camera: Camera, size: tuple[int, int], frame_index: int,
               intrinsics: tuple[float, float, float, float] | None = None,
               aperture_offset_m: tuple[float, float] = (0.0, 0.0)) -> Frame:
        r"""Frame ``frame_index`` through ``camera``'s pinhole at ``size``.

        ``intrinsics`` (f, f, c_x, c_y) overrides ``camera.intrinsics(W, H)``, e.g. the extended
        frustum :func:`clpost.calibration.required_render` asks for (square pixels).

        ``aperture_offset_m`` = (a_x, a_y) (camera axes, metres, x right, y down; for the dof
        accumulation reference) moves the pinhole to a point of the lens aperture and shears the
        frustum so the focus plane stays put (Haeberli & Akeley 1990): centre
        :math:`C + R(a_x, a_y, 0)`, principal point :math:`c + f\,a/u`, so a point at depth S
        moves by :math:`f\,a\,(1/u - 1/S)` px. Such frames carry no velocity (None).
        """
        w, h = (int(v) for v in size)
        if w < 1 or h < 1 or (w, h) != tuple(size):
            raise InputError(f"render size {size!r} must be (width, height) in whole pixels >= 1")
        fx, fy, cx, cy = camera.intrinsics(w, h) if intrinsics is None else (float(t) for t in intrinsics)
        if fx != fy or (intrinsics is None and (abs(cx - (w - 1) / 2) > 1e-9 or abs(cy - (h - 1) / 2) > 1e-9)):
            raise InputError("PyVistaRenderer renders square pixels with the principal point at the image "
                             f"centre unless intrinsics are given; got intrinsics {(fx, fy, cx, cy)}")
        s = self.supersample
        ws, hs, fs = w * s, h * s, fx * s
        # pixel-centre convention: the image's edge −½ stays at −½ when pixels are split s×s
        cs = ((cx + 0.5) * s - 0.5, (cy + 0.5) * s - 0.5)
        ax, ay = (float(v) for v in aperture_offset_m)
        sheared = bool(ax or ay)
        if sheared and not math.isinf(camera.focus_distance_m):
            u = camera.focus_distance_m
            cs = (cs[0] + fs * ax / u, cs[1] + fs * ay / u)
        centred = abs(cs[0] - (ws - 1) / 2) < 1e-9 and abs(cs[1] - (hs - 1) / 2) < 1e-9
        gbuf, cam_pose, poses = self.gbuffer((ws, hs), fs, frame_index, None if centred else cs, (ax, ay))
        color = shade(self.scene, gbuf, fs, cs, cam_pose, poses)
        vel = None if sheared else velocity(self.scene, gbuf, fs, cs, frame_index)
        if s > 1:
            color = color.reshape(h, s, w, s, 3).mean(axis=(1, 3))
            centre = slice(s // 2, None, s)
            gbuf = GBuffer(ids=gbuf.ids[centre, centre], depth=gbuf.depth[centre, centre])
            vel = None if vel is None else vel[centre, centre] / s
        return Frame(
            color=color.astype(np.float32),
            depth=gbuf.depth.astype(np.float32),
            velocity=None if vel is None else vel.astype(np.float32),
            metadata={
                "renderer": "PyVistaRenderer",
                "frame_index": int(frame_index),
                "intrinsics": (fx, fy, cx, cy),
                "camera_pose": cam_pose,
                "object_id": gbuf.ids,
                "object_names": tuple(o.name for o in self.scene.objects),
            },
        )

    def render_cubemap(self, camera: Camera, spec, frame_index: int) -> Frame:
        """Frame ``frame_index`` as the cubemap atlas ``spec``
        (:class:`clpost.calibration.cubemap.CubemapSpec`): six square pinhole renders from the
        camera's centre, face i rotated by :func:`clpost.calibration.cubemap.face_rotation` (the
        scene's camera rotation times :math:`R_i`), side by side; ``metadata["cubemap"] = (face, pad)``.
        Colour only: depth and velocity are per face (planar along each face's axis, in each face's
        pixels) and have no meaning across the atlas, so they are left out."""
        from dataclasses import replace

        from ..calibration.cubemap import face_rotation

        scene, motion = self.scene, self.scene.camera_motion
        base = np.asarray(motion.base_rotation, dtype=np.float64)
        faces = []
        try:
            for i in range(6):
                rot = base @ face_rotation(i)
                self.scene = replace(scene, camera_motion=replace(
                    motion, base_rotation=tuple(tuple(float(v) for v in row) for row in rot)))
                faces.append(self.render(camera, (spec.size, spec.size), frame_index, spec.intrinsics()).color)
        finally:
            self.scene = scene
        return Frame(color=np.concatenate(faces, axis=1),
                     metadata={"renderer": "PyVistaRenderer", "frame_index": int(frame_index),
                               "cubemap": (spec.face, spec.pad)})

    def close(self) -> None:
        """Release the OpenGL context (also released when the renderer is garbage-collected)."""
        self._pass.close()


def render_demo_sequence(camera: Camera, size: tuple[int, int] = (960, 640), n_frames: int = 3,
                         camera_motion: bool = False, scene: DemoScene | None = None,
                         intrinsics: tuple[float, float, float, float] | None = None) -> list[Frame]:
    """Frames 0 … n_frames−1 of the demo scene (or ``scene``) through one reusable renderer
    (``intrinsics``: see :meth:`PyVistaRenderer.render`)."""
    if int(n_frames) != n_frames or n_frames < 1:
        raise InputError(f"n_frames={n_frames!r} must be an integer >= 1")
    renderer = PyVistaRenderer(scene if scene is not None else DemoScene.default(camera_motion=camera_motion))
    try:
        return [renderer.render(camera, size, i, intrinsics) for i in range(int(n_frames))]
    finally:
        renderer.close()

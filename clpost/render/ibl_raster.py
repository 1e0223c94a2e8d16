r"""The image-based lens's projections at rasterizer speed (Heidrich, Slusallek & Seidel 1997
render every projection with the graphics hardware; docs/image_based_lens.md, "Rasterizer path").

The scene is Lambertian, so a surface point's radiance does not depend on where it is seen from —
only the texture's filter footprint does. Per frame, the radiance of every object is therefore
**baked** once into a float texture by the renderer's own numpy shading
(:func:`clpost.render.pyvista_renderer.surface_radiance`: albedo × sun with shadows + ambient +
emitters, box-filtered over one texel), and every projection is then a plain VTK rasterisation of
unlit textured polygons into a **float32 framebuffer** (``vtkFramebufferPass``), read back without
clipping or quantisation. Background pixels (alpha 0) get the sky of their ray direction.

Baked region and texel. Per object, the bake covers the part of the object that the union of the
frame's projection frusta can see (the corner rays of each projection's render frustum intersected
with the object's plane, their bounding box clipped to the object), with a texel equal to the
smallest pixel footprint there (planar depth / focal length in px): magnified with bilinear
filtering, a texel then spans about one render pixel, as the numpy path's per-pixel box filter
does; farther parts are minified with mipmaps. A bake is reused while the object's pose, the
sun and the region and texel stay the same (a static scene: one bake for all frames).

Only :class:`~clpost.render.demo_scene.Plane` objects have a planar texture parametrisation here;
a scene with any other shape raises :class:`RasterUnavailable` with the reason, and callers fall
back to the numpy path (:func:`clpost.render.image_based_lens.rasterizer_render_fn`). So does a
VTK without offscreen float framebuffers.
"""
from __future__ import annotations

import math

import numpy as np

from .demo_scene import DemoScene, Plane
from .ibl_warp import WarpCell

MAX_TEXELS = 2048
"""Largest baked texture side (texels). A region that would need more gets a coarser texel (blur
where the footprint is finer than this allows; reported by :attr:`FloatRasterizer.coarsened`)."""


MIPMAP_SPREAD = 1.5
"""Mipmap a plane's texture when its pixel footprint varies by more than this factor over the
baked region; a fronto-parallel plane is read with bilinear filtering only."""


class RasterUnavailable(RuntimeError):
    """The rasterizer path cannot render this scene or on this VTK (the message says why)."""


def _frustum_rays(cell: WarpCell) -> np.ndarray:
    """Camera-space directions (unit Z) through the 4 corners of the cell's render (pixel edges)."""
    w, h = cell.render_size
    cx, cy = cell.render_c
    f = cell.render_f_px
    us = np.array([-0.5, w - 0.5, w - 0.5, -0.5])
    vs = np.array([-0.5, -0.5, h - 0.5, h - 0.5])
    return np.stack([(us - cx) / f, (vs - cy) / f, np.ones(4)], -1)


def bake_region(cells: list[WarpCell], cam_pose: np.ndarray, obj_pose: np.ndarray,
                half_size_m: float) -> tuple[np.ndarray, float, float] | None:
    """(xmin, xmax, ymin, ymax) in the plane's local metres, the smallest pixel footprint (m) of
    the projections of ``cells`` on the plane and the ratio of the largest to the smallest, or
    None when none of them sees the plane. A frustum that does not meet the plane in all four
    corners sees it up to its horizon: the whole plane, footprint from the corners that hit (or
    the plane's nearest point), ratio infinite."""
    rot_c, cen_c = cam_pose[:3, :3], cam_pose[:3, 3]
    rot, t = obj_pose[:3, :3], obj_pose[:3, 3]
    h = half_size_m
    corners = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]]) @ rot.T + t
    lo, hi = np.full(2, np.inf), np.full(2, -np.inf)
    texel, far = math.inf, 0.0
    seen = False
    for cell in cells:
        origin = rot_c @ np.asarray(cell.cop_camera_m) + cen_c
        if np.all((corners - origin) @ rot_c[:, 2] <= 0.0):
            continue  # the whole plane behind this projection's pinhole
        dirs = _frustum_rays(cell) @ rot_c.T
        o = (origin - t) @ rot
        d = dirs @ rot
        with np.errstate(divide="ignore", invalid="ignore"):
            s = -o[2] / d[:, 2]  # ray parameter = planar depth in the projection's camera (unit-Z rays)
        hit = np.isfinite(s) & (s > 0)
        if not hit.any():
            continue  # no corner ray meets the plane: neither does any ray of the frustum (their cone)
        if hit.all():
            pts = o[:2] + s[:, None] * d[:, :2]
            lo, hi = np.minimum(lo, pts.min(0)), np.maximum(hi, pts.max(0))
            # a fronto-parallel plane: one pixel spans depth / f; tilted planes are coarser than that
            texel = min(texel, float(s.min()) / cell.render_f_px)
            far = max(far, float(s.max()) / cell.render_f_px)
            seen = True
        else:
            lo, hi = np.full(2, -half_size_m), np.full(2, half_size_m)
            near = float(s[hit].min())
            texel = min(texel, max(near, 1e-3) / cell.render_f_px)
            far = math.inf
            seen = True
    if not seen:
        return None
    lo = np.maximum(lo, -half_size_m)
    hi = np.minimum(hi, half_size_m)
    if np.any(hi <= lo):
        return None
    return np.array([lo[0], hi[0], lo[1], hi[1]]), texel, far / texel


class FloatRasterizer:
    """One offscreen VTK window with a float32 framebuffer pass; the scene's planes as unlit
    actors carrying baked radiance textures (module docstring). :meth:`prepare` bakes for a
    frame's projections, :meth:`render` rasterises one projection."""

    def __init__(self, scene: DemoScene) -> None:
        others = [o.name for o in scene.objects if not isinstance(o.shape, Plane)]
        if others:
            names = ", ".join(others[:4]) + (", …" if len(others) > 4 else "")
            raise RasterUnavailable(f"the rasterizer path bakes planes only; {len(others)} of the scene's "
                                    f"{len(scene.objects)} objects are not planes ({names}); the numpy path "
                                    "renders any scene")
        try:
            import vtk
            from vtkmodules.vtkRenderingOpenGL2 import vtkFramebufferPass, vtkRenderStepsPass, vtkTextureObject

            from .pyvista_renderer import _offscreen_window
        except ImportError as e:  # a VTK build without the OpenGL2 render passes
            raise RasterUnavailable(f"VTK's OpenGL2 render passes are missing ({e})") from e
        self.vtk = vtk
        self.scene = scene
        self.window = _offscreen_window()
        self.window.SwapBuffersOff()  # the image is read from the pass's texture, never shown
        self.renderer = vtk.vtkRenderer()
        self.renderer.SetBackground(0.0, 0.0, 0.0)
        self.renderer.SetBackgroundAlpha(0.0)
        self.renderer.SetUseFXAA(False)
        self.window.AddRenderer(self.renderer)
        self.fb = vtkFramebufferPass()
        self.fb.SetColorFormat(vtkTextureObject.Float32)
        self.fb.SetDelegatePass(vtkRenderStepsPass())
        self.renderer.SetPass(self.fb)
        self.actors, self.sources, self.textures = [], [], []
        for _ in scene.objects:
            src = vtk.vtkPlaneSource()
            mapper = vtk.vtkPolyDataMapper()
            mapper.SetInputConnection(src.GetOutputPort())
            mapper.ScalarVisibilityOff()
            actor = vtk.vtkActor()
            actor.SetMapper(mapper)
            actor.GetProperty().LightingOff()  # the fragment is exactly the texel (colour 1, unlit)
            actor.GetProperty().SetColor(1.0, 1.0, 1.0)
            actor.VisibilityOff()
            tex = vtk.vtkTexture()
            tex.SetColorModeToDirectScalars()  # float scalars uploaded as they are, no lookup table
            tex.InterpolateOn()
            tex.MipmapOn()
            tex.EdgeClampOn()
            actor.SetTexture(tex)
            self.renderer.AddActor(actor)
            self.actors.append(actor)
            self.sources.append(src)
            self.textures.append(tex)
        self._baked: dict[int, tuple] = {}
        self._prepared_cells, self._prepared_state = None, b""
        self.size: tuple[int, int] | None = None
        self.cam_pose: np.ndarray | None = None
        self.bake_s = 0.0
        self.baked_texels = 0
        self.coarsened: set[str] = set()

    def prepare(self, cells: list[WarpCell], frame_index: int) -> None:
        """Bake every plane the frame's projections see (reusing an unchanged bake)."""
        import time

        from vtkmodules.util.numpy_support import numpy_to_vtk

        from .pyvista_renderer import _vtk_matrix, surface_radiance

        t0 = time.perf_counter()
        scene = self.scene
        cam_pose = scene.camera_pose(frame_index)
        poses = [scene.object_pose(k, frame_index) for k in range(len(scene.objects))]
        state = b"".join(p.tobytes() for p in [cam_pose] + poses)
        if cells is self._prepared_cells and state == self._prepared_state:  # the same frame again
            self.bake_s, self.baked_texels = 0.0, 0
            return
        self.cam_pose = cam_pose
        self.baked_texels = 0
        for k, obj in enumerate(scene.objects):
            actor = self.actors[k]
            actor.SetUserMatrix(_vtk_matrix(poses[k]))
            got = bake_region(cells, self.cam_pose, poses[k], obj.shape.half_size_m)
            if got is None:
                actor.VisibilityOff()
                continue
            region, footprint, spread = got
            # a texel box-filters the checker and is read bilinearly: box(t) ⊗ tent(t) has the
            # variance t²/4 of the numpy path's per-pixel box filter of one footprint p (p²/12)
            # at t = p/√3
            texel = footprint / math.sqrt(3.0)
            nx = int(math.ceil((region[1] - region[0]) / texel))
            ny = int(math.ceil((region[3] - region[2]) / texel))
            if max(nx, ny) > MAX_TEXELS:
                texel *= max(nx, ny) / MAX_TEXELS
                self.coarsened.add(obj.name)
            # whole texels over exactly the region (texel shrunk to fit): the polygon must end at
            # the plane's edge, not up to a texel beyond it
            nx = max(2, int(math.ceil((region[1] - region[0]) / texel)))
            ny = max(2, int(math.ceil((region[3] - region[2]) / texel)))
            tx, ty = (region[1] - region[0]) / nx, (region[3] - region[2]) / ny
            # every pose: shadows and emitter light depend on the other objects too
            key = (b"".join(p.tobytes() for p in poses), region.round(9).tobytes(), round(texel, 12))
            actor.VisibilityOn()
            # mipmaps only where the footprint varies across the plane (tilted, seen to the
            # horizon): trilinear filtering blurs a texel of p/√3 by its coarser level
            self.textures[k].SetMipmap(bool(spread > MIPMAP_SPREAD))
            if self._baked.get(k) == key:
                continue
            xs = region[0] + (np.arange(nx) + 0.5) * tx
            ys = region[2] + (np.arange(ny) + 0.5) * ty
            gx, gy = np.meshgrid(xs, ys)
            local = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], -1)
            width = np.zeros_like(local)
            width[:, 0], width[:, 1] = tx, ty  # the texel's box filter
            rad = surface_radiance(scene, k, local, width, poses).astype(np.float32)
            img = self.vtk.vtkImageData()
            img.SetDimensions(nx, ny, 1)
            img.GetPointData().SetScalars(numpy_to_vtk(rad, deep=True))
            self.textures[k].SetInputData(img)
            src = self.sources[k]
            src.SetOrigin(region[0], region[2], 0.0)
            src.SetPoint1(region[1], region[2], 0.0)
            src.SetPoint2(region[0], region[3], 0.0)
            self._baked[k] = key
            self.baked_texels += nx * ny
        self._prepared_cells, self._prepared_state = cells, state
        self.bake_s = time.perf_counter() - t0

    def render(self, cop_m, f_px: float, c, size) -> np.ndarray:
        """Radiance (h×w×3 float32) of the projection: a pinhole at camera-space ``cop_m`` of the
        prepared frame's camera, focal length ``f_px``, principal point ``c``, ``size`` = (w, h)."""
        out = np.empty((int(size[1]), int(size[0]), 4), np.float32)
        self.render_into(out, cop_m, f_px, c, size)
        return np.ascontiguousarray(out[::-1, :, :3])

    def render_into(self, out: np.ndarray, cop_m, f_px: float, c, size) -> None:
        """:meth:`render` into ``out`` (h×w×4 float32, C-contiguous): RGBA with the rows bottom-up,
        as OpenGL reads them back (the warp's buffer layout); alpha 0 marks sky pixels."""
        from .pyvista_renderer import _sky, set_vtk_camera

        vtk = self.vtk
        if self.cam_pose is None:
            raise RuntimeError("FloatRasterizer.render before prepare()")
        w, h = int(size[0]), int(size[1])
        if out.shape != (h, w, 4) or out.dtype != np.float32 or not out.flags.c_contiguous:
            raise ValueError(f"render_into needs a C-contiguous {h}x{w}x4 float32 array, got {out.shape} {out.dtype}")
        if self.size != (w, h):
            self.window.SetSize(w, h)
            self.size = (w, h)
        pose = self.cam_pose.copy()
        pose[:3, 3] += pose[:3, :3] @ np.asarray(cop_m, np.float64)
        set_vtk_camera(self.renderer.GetActiveCamera(), pose, f_px, h, (float(c[0]), float(c[1]), w))
        self.window.Render()
        tex = self.fb.GetColorTexture()
        if tex.GetVTKDataType() != vtk.VTK_FLOAT or (tex.GetWidth(), tex.GetHeight()) != (w, h):
            raise RasterUnavailable(f"VTK's framebuffer pass gave a {tex.GetWidth()}x{tex.GetHeight()} texture of "
                                    f"VTK type {tex.GetVTKDataType()}, not {w}x{h} float32")
        if not tex.Download().Download2D(vtk.VTK_FLOAT, out, [w, h], 4, [0, 0]):
            raise RasterUnavailable("VTK could not read back the float framebuffer")
        sky = out[..., 3] <= 0.0
        if sky.any():
            jb, ii = np.nonzero(sky)
            jj = h - 1 - jb  # rows bottom-up
            rays = np.stack([(ii - c[0]) / f_px, (jj - c[1]) / f_px, np.ones(ii.size)], -1)
            out[jb, ii, :3] = _sky(rays @ pose[:3, :3].T, self.scene)

    def close(self) -> None:
        self.window.Finalize()

r"""The image-based lens's projections at rasterizer speed (Heidrich, Slusallek & Seidel 1997
render every projection with the graphics hardware; docs/image_based_lens.md, "Rasterizer path").

The scene is Lambertian, so a surface point's radiance does not depend on where it is seen from —
only the texture's filter footprint does. Per frame, the radiance of every object is therefore
**baked** once into a float texture by the renderer's own numpy shading
(:func:`clpost.render.pyvista_renderer.surface_radiance`: albedo × sun with shadows + ambient +
emitters, box-filtered over one texel), and every projection is then a plain VTK rasterisation of
unlit textured polygons into a **float32 framebuffer**, read back without clipping or
quantisation. Background pixels (alpha 0) get the sky of their ray direction.

One framebuffer for all of a frame's projections. The renders are packed as tiles of a page
(:func:`clpost.render.ibl_warp.pack_tiles`, ten 262² renders: one 262×2620 column); the window's
own render framebuffer is re-created at the page's size with a float32 (RGBA32F) colour
attachment, and one ``vtkRenderer`` per tile, its viewport the tile and its camera the
projection's, shares the scene's actors. One ``Render()`` rasterises the whole page and one
``glReadPixels`` reads it back straight into the warp's buffer (the page is laid out there as
OpenGL reads it): no per-projection blit, download buffer or round trip to Mesa's rasterizer
threads (why and how much: docs/image_based_lens.md, "Rasterizer path").

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
    """One offscreen VTK window whose render framebuffer is float32; the scene's planes as unlit
    actors carrying baked radiance textures, shared by one renderer per tile (module docstring).
    :meth:`prepare` bakes for a frame's projections, :meth:`render_pages` rasterises all of them
    as the tiles of a few pages, :meth:`render` one projection."""

    def __init__(self, scene: DemoScene) -> None:
        others = [o.name for o in scene.objects if not isinstance(o.shape, Plane)]
        if others:
            names = ", ".join(others[:4]) + (", …" if len(others) > 4 else "")
            raise RasterUnavailable(f"the rasterizer path bakes planes only; {len(others)} of the scene's "
                                    f"{len(scene.objects)} objects are not planes ({names}); the numpy path "
                                    "renders any scene")
        try:
            import vtk
            from vtkmodules.vtkRenderingOpenGL2 import vtkOpenGLFramebufferObject  # noqa: F401

            from .pyvista_renderer import _offscreen_window
        except ImportError as e:  # a VTK build without the OpenGL2 backend
            raise RasterUnavailable(f"VTK's OpenGL2 framebuffer objects are missing ({e})") from e
        self.vtk = vtk
        self.scene = scene
        self.window = _offscreen_window()
        self.window.SwapBuffersOff()  # the image is read from the render framebuffer, never shown
        self.renderers: list = []  # one per tile of a page, grown on demand; all share the actors
        self._float_size: tuple[int, int] | None = None  # the size the float framebuffer was made at
        self._tile_state = None  # the page size, camera and tiles the renderers are set up for
        self._read = vtk.vtkFloatArray()
        self._read.SetNumberOfComponents(4)
        self._spare = np.zeros(4, np.float32)
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
            self.actors.append(actor)
            self.sources.append(src)
            self.textures.append(tex)
        self._baked: dict[int, tuple] = {}
        self._prepared_cells, self._prepared_state = None, b""
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
        from .ibl_warp import TileLayout

        w, h = int(size[0]), int(size[1])
        self.render_pages([out], [(cop_m, f_px, c, (w, h))], TileLayout.separate([(w, h)]))

    def render_pages(self, pages: list[np.ndarray], views: list, layout, fill_sky: bool = True) -> None:
        """Render the projections ``views`` = [(cop_m, f_px, c, (w, h)), …] as the tiles of
        ``layout`` (:class:`~clpost.render.ibl_warp.TileLayout`) into ``pages`` (one h×w×4 float32
        C-contiguous array per page: RGBA, rows bottom-up): per page one ``Render()`` of one
        renderer per tile and one read-back (module docstring); alpha 0 marks sky pixels, which
        (``fill_sky``) get the sky of their direction here — or are left to the warp kernel,
        which computes it per texel from :meth:`sky` (no pass over the pixels in Python)."""
        if self.cam_pose is None:
            raise RuntimeError("FloatRasterizer.render before prepare()")
        if len(views) != len(layout.tiles) or len(pages) != len(layout.pages):
            raise ValueError(f"{len(views)} projections and {len(pages)} pages for a layout of "
                             f"{len(layout.tiles)} tiles on {len(layout.pages)} pages")
        by_page: list[list[int]] = [[] for _ in layout.pages]
        for k, (p, _, _) in enumerate(layout.tiles):
            by_page[p].append(k)
        rot = self.cam_pose[:3, :3]
        for p, (out, (pw, ph)) in enumerate(zip(pages, layout.pages)):
            if out.shape != (ph, pw, 4) or out.dtype != np.float32 or not out.flags.c_contiguous:
                raise ValueError(f"render_pages needs a C-contiguous {ph}x{pw}x4 float32 array for page {p}, got "
                                 f"{out.shape} {out.dtype}")
            self._float_framebuffer(pw, ph)
            tiles = [(layout.tiles[k][1:], tuple(map(float, views[k][0])), float(views[k][1]),
                      tuple(map(float, views[k][2])), tuple(map(int, views[k][3]))) for k in by_page[p]]
            state = (pw, ph, self.cam_pose.tobytes(), tiles)
            if state != self._tile_state:  # a static scene and model: the same cameras every frame
                self._set_tiles(tiles, pw, ph)
                self._tile_state = state
            self.window.Render()
            self._read_page(out)
            for k in by_page[p] if fill_sky else ():
                _, x, y = layout.tiles[k]
                cop_m, f_px, c, (w, h) = views[k]
                self._fill_sky(out[y:y + h, x:x + w], rot, f_px, c)

    def _set_tiles(self, tiles: list, pw: int, ph: int) -> None:
        """One renderer per tile: its viewport (in [0, 1] of the page; VTK rounds it back to exactly
        the tile's pixels) and the projection's camera; the renderers left over draw nothing."""
        from .pyvista_renderer import set_vtk_camera

        while len(self.renderers) < len(tiles):
            self._add_renderer()
        rot = self.cam_pose[:3, :3]
        for r, ((x, y), cop_m, f_px, c, (w, h)) in zip(self.renderers, tiles):
            r.SetViewport(x / pw, y / ph, (x + w) / pw, (y + h) / ph)
            pose = self.cam_pose.copy()
            pose[:3, 3] += rot @ np.asarray(cop_m, np.float64)
            set_vtk_camera(r.GetActiveCamera(), pose, f_px, h, (c[0], c[1], w))
            r.DrawOn()
        for r in self.renderers[len(tiles):]:
            r.DrawOff()

    def sky(self, cells) -> tuple:
        """What the warp kernel needs to fill the sky of ``cells`` ' renders (the prepared
        frame's camera): (:func:`~clpost.render.ibl_warp.sky_table`, horizon, zenith colours)."""
        from .ibl_warp import sky_table

        if self.cam_pose is None:
            raise RuntimeError("FloatRasterizer.sky before prepare()")
        return sky_table(self.cam_pose[:3, :3], cells), self.scene.sky_horizon, self.scene.sky_zenith

    def _add_renderer(self) -> None:
        r = self.vtk.vtkRenderer()
        r.SetBackground(0.0, 0.0, 0.0)
        r.SetBackgroundAlpha(0.0)
        r.SetUseFXAA(False)
        for actor in self.actors:
            r.AddActor(actor)
        self.window.AddRenderer(r)
        self.renderers.append(r)

    def _float_framebuffer(self, w: int, h: int) -> None:
        """Make the window ``w``×``h`` with a float32 RGBA colour attachment on its render
        framebuffer (what VTK draws into; its own is 8-bit), re-created when the size changes."""
        vtk = self.vtk
        if self._float_size == (w, h):
            return
        self.window.SetSize(w, h)
        self.window.Render()  # the context and VTK's framebuffers at this size
        self.window.MakeCurrent()
        fbo = self.window.GetRenderFramebuffer()
        if not fbo.PopulateFramebuffer(w, h, True, 1, vtk.VTK_FLOAT, True, 32, 0, False):
            raise RasterUnavailable(f"VTK could not make a {w}x{h} float32 framebuffer")
        tex = fbo.GetColorAttachmentAsTextureObject(0)
        if tex is None or tex.GetVTKDataType() != vtk.VTK_FLOAT or (tex.GetWidth(), tex.GetHeight()) != (w, h):
            got = "none" if tex is None else f"{tex.GetWidth()}x{tex.GetHeight()} of VTK type {tex.GetVTKDataType()}"
            raise RasterUnavailable(f"VTK's render framebuffer has a colour attachment {got}, not {w}x{h} float32")
        self._float_size = (w, h)

    def _read_page(self, out: np.ndarray) -> None:
        """glReadPixels of the whole render framebuffer (float RGBA, rows bottom-up) into ``out``:
        VTK reads into the float array ``_read``, which wraps ``out``'s memory (no copy)."""
        ph, pw = out.shape[:2]
        flat = out.reshape(-1)
        self._read.SetArray(flat, flat.size, 1)  # 1: VTK never frees numpy's memory
        if not self.window.GetRGBAPixelData(0, 0, pw - 1, ph - 1, 0, self._read, 0):
            raise RasterUnavailable("VTK could not read back the float framebuffer")
        if self._read.GetNumberOfValues() != flat.size:
            raise RasterUnavailable(f"VTK read back {self._read.GetNumberOfValues()} floats, not {flat.size}")
        from vtkmodules.util.numpy_support import vtk_to_numpy

        got = vtk_to_numpy(self._read)
        if got.ctypes.data != out.ctypes.data:  # VTK re-allocated instead of reading in place: copy
            flat[:] = got
        self._read.SetArray(self._spare, self._spare.size, 1)  # let go of ``out`` (never freed by VTK)

    def _fill_sky(self, tile: np.ndarray, rot: np.ndarray, f_px: float, c) -> None:
        """The sky radiance of their direction in a tile's pixels of alpha 0 (rows bottom-up)."""
        from .pyvista_renderer import _sky

        alpha = tile[..., 3]
        if alpha.min() > 0.0:  # no sky in view (a reduction, no mask: the usual case)
            return
        sky = alpha <= 0.0
        h = tile.shape[0]
        jb, ii = np.nonzero(sky)
        jj = h - 1 - jb  # rows bottom-up
        rays = np.stack([(ii - c[0]) / f_px, (jj - c[1]) / f_px, np.ones(ii.size)], -1)
        tile[jb, ii, :3] = _sky(rays @ rot.T, self.scene)

    def close(self) -> None:
        self.window.Finalize()

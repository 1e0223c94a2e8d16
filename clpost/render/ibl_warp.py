r"""The quad-tree warp of the image-based lens model (Heidrich, Slusallek & Seidel, sec. 3.5):
each projection's pinhole render warped onto its film cell with the weight W and accumulated
(``kernels/ibl_warp.cl``, its float64 numpy reference :func:`warp_reference`).

Film ↔ pixels. The lens inverts the image; the output is shown upright, as a camera shows it:
the centre of pixel (i, j) is the film point (lens frame, mm)

.. math:: x' = -(i - c_x)\,p,\quad y' = (j - c_y)\,p,\quad c = \left(\tfrac{W-1}{2}, \tfrac{H-1}{2}\right),\quad
          p = \text{sensor width} / W

(a scene point to the right, camera X > 0, images at lens-frame x' < 0 and shows at i > c_x).
Camera space (X right, Y down, Z forward, metres) has its origin at the lens's entrance pupil
on the axis — the perspective centre of the chief rays, and of the pinhole render the
post-process pipeline starts from — so the depth buffers of both paths agree.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..optics import get_lens
from .ibl_build import ImageBasedLens, Projection
from .ibl_rays import focus_plane_z_mm, image_plane_tex, mirrored_table, trace_back


def pixel_to_film(i, j, size: tuple[int, int], sensor_w_mm: float):
    """Film point (lens frame, mm) of pixel coordinates (i, j) (module docstring)."""
    w, h = size
    p = sensor_w_mm / w
    return -(np.asarray(i, np.float64) - (w - 1) / 2.0) * p, (np.asarray(j, np.float64) - (h - 1) / 2.0) * p


def lens_to_camera_m(points_mm: np.ndarray, z_origin_mm: float) -> np.ndarray:
    """Lens-frame points (mm) → camera space (m) with the origin on the axis at ``z_origin_mm``."""
    pts = np.asarray(points_mm, np.float64)
    return np.stack([pts[..., 0], -pts[..., 1], -(pts[..., 2] - z_origin_mm)], -1) / 1000.0


@dataclass(frozen=True)
class WarpCell:
    """What the warp kernel needs for one projection at one output size: the projection's render
    (size, focal length, principal point, camera-space COP) and the film node grid."""

    pupil_index: int
    box: tuple[int, int, int, int]  # output pixels i0, i1, j0, j1 (half-open) owned by the cell
    nodes: np.ndarray  # (gy, gx, 4) float64: u, v (render px), W (1/mm²), 0
    node_origin: tuple[float, float]  # output pixel coordinates of node (0, 0)
    node_step: tuple[float, float]  # output pixels between nodes
    render_size: tuple[int, int]
    render_f_px: float
    render_c: tuple[float, float]
    cop_camera_m: np.ndarray


def _owned(coord: np.ndarray, lo: float, hi: float, last: bool) -> tuple[int, int]:
    """Half-open range of indices whose coordinate lies in [lo, hi) ([lo, hi] for the last cell),
    so cells that share an edge never both own a pixel."""
    m = (coord >= lo) & ((coord <= hi) if last else (coord < hi))
    idx = np.flatnonzero(m)
    return (int(idx[0]), int(idx[-1]) + 1) if idx.size else (0, 0)


def warp_cells(model: ImageBasedLens, size: tuple[int, int], node_spacing_px: float = 16.0,
               supersample: float = 1.0, margin_px: int = 2) -> tuple[list[WarpCell], float]:
    r"""The warp data of every projection for an output of ``size`` pixels, and the
    normalisation :math:`\sum_i W_i(0)` (the axial film point's weight over all pupil samples).

    Nodes: a regular grid over the cell's film rectangle (at least the model's ``grid`` per side,
    at most ``node_spacing_px`` apart so the vignetting border and the distortion are resolved
    at the output's resolution), each traced back through its pupil sample exactly as in
    preprocessing: u, v = the render pixel where the projection's image plane meets the ray's
    approximation q − e, W as in :mod:`clpost.render.ibl_build`. Vignetted nodes get W = 0 and the
    affine extrapolation of the passing nodes' (u, v), so interpolation across the border stays
    smooth. Render: focal length ``supersample`` × the film's (v / p), the frustum = the
    bounding box of the passing nodes' texture coordinates plus ``margin_px``. Cached on the model
    per arguments (the warp data of a model and size never change; a frame re-uses them)."""
    key = (tuple(size), float(node_spacing_px), float(supersample), int(margin_px))
    if key in model.warp_cache:
        return model.warp_cache[key]
    w, h = (int(v) for v in size)
    if w < 2 or h < 2 or (w, h) != tuple(size):
        raise InputError(f"image-based lens: size={size!r} must be (width, height) in whole pixels >= 2")
    if not (math.isfinite(node_spacing_px) and node_spacing_px >= 1):
        raise InputError(f"node_spacing_px={node_spacing_px!r} must be >= 1 output pixel, e.g. 16")
    if not (math.isfinite(supersample) and 0.25 <= supersample <= 8):
        raise InputError(f"supersample={supersample!r} must be in [0.25, 8] (render px per film px)")
    L = get_lens(model.lens)
    dist_mm = model.focus_distance_m * 1000.0 if math.isfinite(model.focus_distance_m) else math.inf
    pres = L.focused(dist_mm, model.f_number)
    table, zf = mirrored_table(pres, L.stop_radius_mm(model.f_number))
    z_e = L.paraxial.z_entrance_pupil_mm
    z_plane = focus_plane_z_mm(model.focus_distance_m, zf)
    pitch = model.sensor_mm[0] / w
    f_px = supersample * L.focus(dist_mm, model.f_number).image_distance_mm / pitch
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    xs, ys = pixel_to_film(np.arange(w), np.arange(h), (w, h), model.sensor_mm[0])
    hw, hh = 0.5 * model.sensor_mm[0], 0.5 * model.sensor_mm[1]
    cells = []
    for proj in model.projections:
        x0, x1, y0, y1 = proj.cell_mm
        p = model.pupil_samples_mm[proj.pupil_index]
        # film x is mirrored: the cell [x0, x1) is the pixel interval (c_x − x1/p, c_x − x0/p]
        i0, i1 = _owned(-xs, -x1, -x0, last=x0 <= -hw + 1e-9)
        j0, j1 = _owned(ys, y0, y1, last=y1 >= hh - 1e-9)
        if i1 <= i0 or j1 <= j0:
            continue
        a_x, b_x = cx - x1 / pitch, cx - x0 / pitch
        a_y, b_y = cy + y0 / pitch, cy + y1 / pitch
        gx = max(int(model_grid(proj)), int(math.ceil((b_x - a_x) / node_spacing_px)) + 1)
        gy = max(int(model_grid(proj)), int(math.ceil((b_y - a_y) / node_spacing_px)) + 1)
        nx, ny = np.meshgrid(np.linspace(a_x, b_x, gx), np.linspace(a_y, b_y, gy))
        fx, fy = pixel_to_film(nx, ny, (w, h), model.sensor_mm[0])
        film = np.stack([fx.ravel(), fy.ravel()], -1)
        q, d, ok = trace_back(table, zf, film, p)
        if ok.sum() < 3:
            continue
        tex = image_plane_tex(q, d, proj.cop_mm, z_plane)
        ok &= np.all(np.isfinite(tex), axis=1)
        if ok.sum() < 3:
            continue
        # vignetted nodes: affine extrapolation of the passing nodes' texture coordinates
        design = np.concatenate([film, np.ones((len(film), 1))], 1)
        coef = np.linalg.lstsq(design[ok], tex[ok], rcond=None)[0]
        tex = np.where(ok[:, None], tex, design @ coef)
        ray = np.concatenate([p[None, :2] - film, np.full((len(film), 1), p[2] - zf)], 1)
        dist2 = np.einsum("ij,ij->i", ray, ray)
        cos = np.abs(ray[:, 2]) / np.sqrt(dist2)
        wgt = np.where(ok, cos * cos / dist2, 0.0)
        t_ok = tex[ok]
        lo, hi = t_ok.min(0), t_ok.max(0)
        rw = int(math.ceil((hi[0] - lo[0]) * f_px)) + 2 * margin_px + 1
        rh = int(math.ceil((hi[1] - lo[1]) * f_px)) + 2 * margin_px + 1
        rc = (margin_px - lo[0] * f_px, margin_px - lo[1] * f_px)
        uv = tex * f_px + np.array(rc)
        nodes = np.zeros((gy, gx, 4))
        nodes[..., 0] = uv[:, 0].reshape(gy, gx)
        nodes[..., 1] = uv[:, 1].reshape(gy, gx)
        nodes[..., 2] = wgt.reshape(gy, gx)
        step = ((b_x - a_x) / (gx - 1), (b_y - a_y) / (gy - 1))
        cells.append(WarpCell(proj.pupil_index, (i0, i1, j0, j1), nodes, (a_x, a_y), step, (rw, rh), f_px, rc,
                              lens_to_camera_m(proj.cop_mm, z_e)))
    # normalisation: the axial film point's irradiance for unit radiance (all samples pass there)
    axial = 0.0
    for p in model.pupil_samples_mm:
        dz = p[2] - zf
        d2 = p[0] ** 2 + p[1] ** 2 + dz * dz
        axial += dz * dz / d2 / d2
    model.warp_cache[key] = (cells, axial)
    return cells, axial


def model_grid(proj: Projection) -> int:
    """Rays per cell side the projection was fitted with."""
    return int(proj.film_mm.shape[0])


def warp_reference(acc: np.ndarray, src: np.ndarray, cell: WarpCell) -> None:
    """float64 numpy reference of ``kernels/ibl_warp.cl``: adds the cell's weighted, warped
    render ``src`` (h×w×3) into ``acc`` (H×W×3) in place."""
    i0, i1, j0, j1 = cell.box
    gy_n, gx_n = cell.nodes.shape[:2]
    xx, yy = np.meshgrid(np.arange(i0, i1, dtype=np.float64), np.arange(j0, j1, dtype=np.float64))
    gx = np.clip((xx - cell.node_origin[0]) / cell.node_step[0], 0, gx_n - 1)
    gy = np.clip((yy - cell.node_origin[1]) / cell.node_step[1], 0, gy_n - 1)
    ix = np.minimum(gx.astype(int), gx_n - 2)
    iy = np.minimum(gy.astype(int), gy_n - 2)
    fx, fy = (gx - ix)[..., None], (gy - iy)[..., None]
    nd = cell.nodes
    n = ((nd[iy, ix] * (1 - fx) + nd[iy, ix + 1] * fx) * (1 - fy)
         + (nd[iy + 1, ix] * (1 - fx) + nd[iy + 1, ix + 1] * fx) * fy)
    sh, sw = src.shape[:2]
    u = np.clip(n[..., 0], 0, sw - 1)
    v = np.clip(n[..., 1], 0, sh - 1)
    iu = np.minimum(u.astype(int), sw - 2)
    iv = np.minimum(v.astype(int), sh - 2)
    fu, fv = (u - iu)[..., None], (v - iv)[..., None]
    s = src.astype(np.float64)
    val = ((s[iv, iu] * (1 - fu) + s[iv, iu + 1] * fu) * (1 - fv)
           + (s[iv + 1, iu] * (1 - fu) + s[iv + 1, iu + 1] * fu) * fv)
    wgt = np.where(n[..., 2] > 0, n[..., 2], 0.0)[..., None]
    acc[j0:j1, i0:i1] += wgt * val


PAGE_MAX_PX = 4096
"""Largest side of a page of tiled renders (:func:`pack_tiles`); OpenGL implementations render
at least 8192² (llvmpipe 16384²), and a page holds every projection of a usual frame."""


@dataclass(frozen=True)
class TileLayout:
    """Where the renders of a frame's cells lie in the warp's source buffer: ``pages`` (w, h)
    stored one after another, each RGBA float32 with the rows bottom-up (OpenGL's order); cell k's
    render is the tile at pixel (x, y) of page p, ``tiles[k] = (p, x, y)``, y counted from the
    page's bottom row."""

    pages: tuple[tuple[int, int], ...]
    tiles: tuple[tuple[int, int, int], ...]

    @staticmethod
    def separate(sizes) -> "TileLayout":
        """Every render a page of its own (the layout of :meth:`Warper.map_cells`)."""
        return TileLayout(tuple(tuple(s) for s in sizes), tuple((k, 0, 0) for k in range(len(sizes))))


def _shelves(sizes, width: int, max_side: int) -> TileLayout:
    """Shelf packing in the given order: tiles left to right along a shelf as long as they fit in
    ``width``, shelves bottom to top, a new page where a shelf would pass ``max_side``."""
    pages, tiles = [], []
    page_w = x = y = shelf_h = 0
    for w, h in sizes:
        if x + w > width:  # next shelf
            x, y, shelf_h = 0, y + shelf_h, 0
        if y + h > max_side and (x, y) != (0, 0):  # next page
            pages.append((page_w, y + shelf_h if x else y))
            page_w = x = y = shelf_h = 0
        tiles.append((len(pages), x, y))
        x += w
        shelf_h = max(shelf_h, h)
        page_w = max(page_w, x)
    pages.append((page_w, y + shelf_h))
    return TileLayout(tuple(pages), tuple(tiles))


def pack_tiles(sizes, max_side: int = PAGE_MAX_PX) -> TileLayout:
    """A :class:`TileLayout` for renders of ``sizes`` (w, h): shelf packing (:func:`_shelves`) at
    the page width, among multiples of the widest render up to ``max_side``, that needs the
    fewest page pixels in all (what a rasterizer reads back), then the fewest pages. Ten equal
    renders stack into one column: no pixel wasted."""
    sizes = [(int(w), int(h)) for w, h in sizes]
    if not sizes:
        return TileLayout((), ())
    widest = max(w for w, _ in sizes)
    if widest > max_side or max(h for _, h in sizes) > max_side:
        raise InputError(f"image-based lens: a projection's render of {widest}x{max(h for _, h in sizes)} px "
                         f"exceeds the {max_side}-px page of tiled renders; use a smaller output size")
    best = None
    for m in range(1, max_side // widest + 1):
        layout = _shelves(sizes, m * widest, max_side)
        cost = (sum(w * h for w, h in layout.pages), len(layout.pages), m)
        if best is None or cost < best[0]:
            best = (cost, layout)
        if len(layout.pages) == 1 and layout.tiles[-1][2] == 0:
            break  # every tile on one shelf: wider pages change nothing
    return best[1]


def _float4(v):
    from pyopencl import cltypes

    x, y, z = (float(t) for t in np.asarray(v, np.float64).reshape(-1)[:3])
    return cltypes.make_float4(x, y, z, 0.0)


def sky_table(cam_rotation: np.ndarray, cells: list[WarpCell]) -> np.ndarray:
    """Per cell the rows of the camera-to-world rotation with w = 1 / f, c_x, c_y: what
    ``ibl_warp_cells`` needs to compute the sky of a texel's direction (kernels/ibl_warp.cl,
    ``texel``). A projection's camera is the frame's camera moved to the COP, axes unchanged."""
    table = np.zeros((len(cells), 3, 4), np.float32)
    table[:, :, :3] = np.asarray(cam_rotation, np.float64)
    for k, cell in enumerate(cells):
        table[k, :, 3] = (1.0 / cell.render_f_px, cell.render_c[0], cell.render_c[1])
    return table


class Warper:
    """The OpenCL side: a planar accumulator of the output size and :meth:`add` per projection."""

    def __init__(self, size: tuple[int, int], device: str | None = None) -> None:
        import pyopencl as cl

        from ..runtime import get_runtime, kernel_source

        self.cl = cl
        self.rt = get_runtime(device)
        self.size = (int(size[0]), int(size[1]))
        w, h = self.size
        self.kernel = self.rt.kernel(kernel_source("ibl_warp"), "ibl_warp")
        self.kernel_cells = self.rt.kernel(kernel_source("ibl_warp"), "ibl_warp_cells")
        self.acc = cl.Buffer(self.rt.context, cl.mem_flags.READ_WRITE, size=3 * w * h * 4)
        cl.enqueue_fill_buffer(self.rt.queue, self.acc, np.float32(0), 0, 3 * w * h * 4)
        self.events = []
        self._meta = None
        self._src_buf = None
        self._mapped = None

    def add(self, src: np.ndarray, cell: WarpCell) -> None:
        cl = self.cl
        i0, i1, j0, j1 = cell.box
        if i1 <= i0 or j1 <= j0:
            return
        planar = np.ascontiguousarray(np.moveaxis(np.asarray(src, np.float32), -1, 0))
        sh, sw = src.shape[:2]
        if sw < 2 or sh < 2:
            raise InputError(f"image-based lens: a projection's render of {sw}x{sh} px is too small to sample")
        mf = cl.mem_flags
        src_buf = cl.Buffer(self.rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=planar)
        nodes = np.ascontiguousarray(cell.nodes, np.float32)
        node_buf = cl.Buffer(self.rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=nodes)
        gy, gx = nodes.shape[:2]
        w, h = self.size
        ev = self.kernel(self.rt.queue, (i1 - i0, j1 - j0), None, src_buf, np.int32(sw), np.int32(sh),
                         node_buf, np.int32(gx), np.int32(gy), np.float32(cell.node_origin[0]),
                         np.float32(cell.node_origin[1]), np.float32(1.0 / cell.node_step[0]),
                         np.float32(1.0 / cell.node_step[1]), self.acc, np.int32(w), np.int32(h),
                         np.int32(i0), np.int32(j0))
        self.events.append(ev)

    def reset(self) -> None:
        """Zero the accumulator for the next frame (the buffers are kept)."""
        w, h = self.size
        self.cl.enqueue_fill_buffer(self.rt.queue, self.acc, np.float32(0), 0, 3 * w * h * 4)
        self.events = []

    def _cells_meta(self, cells: list[WarpCell], tiled: bool = False):
        """Per-cell metadata and nodes on the device and the source buffer's :class:`TileLayout`
        (``tiled``: :func:`pack_tiles`; else every render alone, one after another), kept for the
        last cell list (a model's warp data is cached, so every frame of a sequence passes the same
        list)."""
        if self._meta is not None and self._meta[0] is cells and self._meta[1] == tiled:
            return self._meta
        cl = self.cl
        for cell in cells:
            sw, sh = cell.render_size
            if sw < 2 or sh < 2:
                raise InputError(f"image-based lens: a projection's render of {sw}x{sh} px is too small to sample")
        sizes = [tuple(int(v) for v in c.render_size) for c in cells]
        layout = pack_tiles(sizes) if tiled else TileLayout.separate(sizes)
        page_off = np.concatenate([[0], np.cumsum([4 * pw * ph for pw, ph in layout.pages])]).astype(np.int64)
        cell_i = np.zeros((len(cells), 11), np.int32)
        cell_f = np.zeros((len(cells), 4), np.float32)
        nodes = []
        n_off = 0
        for k, (cell, (page, x, y)) in enumerate(zip(cells, layout.tiles)):
            sw, sh = cell.render_size
            gy, gx = cell.nodes.shape[:2]
            pw = layout.pages[page][0]
            s_off = int(page_off[page]) + 4 * (y * pw + x)  # RGBA floats to the tile's bottom-left pixel
            cell_i[k] = (*cell.box, s_off, sw, sh, n_off, gx, gy, pw)
            cell_f[k] = (cell.node_origin[0], cell.node_origin[1], 1.0 / cell.node_step[0], 1.0 / cell.node_step[1])
            nodes.append(np.asarray(cell.nodes, np.float32).reshape(-1, 4))
            n_off += gx * gy
        if int(page_off[-1]) >= 2 ** 31:
            raise InputError(f"image-based lens: the frame's renders hold {page_off[-1] // 4} pixels, more than the "
                             "warp's 32-bit offsets address; use a smaller output or fewer pupil samples")
        mf = cl.mem_flags
        bufs = [cl.Buffer(self.rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a))
                for a in (np.concatenate(nodes), cell_i, cell_f)]
        self._meta = (cells, tiled, bufs, layout, page_off)
        return self._meta

    def _map(self, cells: list[WarpCell], tiled: bool):
        cl = self.cl
        if self._mapped is not None:
            raise RuntimeError("Warper.map_cells twice without launch_cells")
        _, _, _, layout, page_off = self._cells_meta(cells, tiled)
        total = int(page_off[-1])
        if self._src_buf is None or self._src_buf.size < 4 * total:
            self._src_buf = cl.Buffer(self.rt.context, cl.mem_flags.READ_ONLY | cl.mem_flags.ALLOC_HOST_PTR,
                                      size=4 * max(total, 1))
        stage, _ = cl.enqueue_map_buffer(self.rt.queue, self._src_buf, cl.map_flags.WRITE_INVALIDATE_REGION, 0,
                                         (max(total, 1),), np.float32)
        self._mapped = (cells, tiled, stage)
        return layout, [stage[off:off + 4 * pw * ph].reshape(ph, pw, 4)
                        for (pw, ph), off in zip(layout.pages, page_off)]

    def map_cells(self, cells: list[WarpCell]) -> list[np.ndarray]:
        """Writable (h, w, 4) float32 views, one per cell, into one mapped host-allocated buffer
        (pinned on a GPU; on a CPU device the kernel reads it in place, no upload): RGBA pixels
        with the rows bottom-up, as OpenGL reads a framebuffer back, so a rasterizer can download
        straight into them (alpha is not read). Fill them, then :meth:`launch_cells`."""
        return self._map(cells, False)[1]

    def map_pages(self, cells: list[WarpCell]) -> tuple[TileLayout, list[np.ndarray]]:
        """:meth:`map_cells` with the renders packed as tiles of a few pages (:func:`pack_tiles`):
        the layout and one writable (h, w, 4) view per page (RGBA, rows bottom-up), so a rasterizer
        renders all the frame's projections into one framebuffer per page and reads each page back
        in one piece. Fill them, then :meth:`launch_cells`."""
        return self._map(cells, True)

    def launch_cells(self, run: bool = True, sky=None) -> None:
        """Unmap the buffer of :meth:`map_cells` and (``run``) add all its cells in one launch of
        ``ibl_warp_cells``: the same sum as :meth:`add` per cell, in the same order. ``sky`` =
        (rotation, f, c) per cell and the scene's (horizon, zenith) colours, from
        :func:`sky_table`: texels of alpha 0 (nothing drawn) are then the sky of their direction,
        computed by the kernel, instead of the render's RGB."""
        cells, tiled, stage = self._mapped
        self._mapped = None
        stage.base.release(self.rt.queue)
        if not run or not cells:
            return
        _, _, (node_buf, ci_buf, cf_buf), _, _ = self._cells_meta(cells, tiled)
        cl = self.cl
        if sky is None:
            table, horizon, zenith = np.zeros(4, np.float32), np.zeros(4, np.float32), np.zeros(4, np.float32)
        else:
            table, horizon, zenith = sky
            if table.shape != (len(cells), 3, 4):
                raise ValueError(f"a sky table of shape {table.shape} for {len(cells)} cells")
        sky_buf = cl.Buffer(self.rt.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                            hostbuf=np.ascontiguousarray(table, np.float32))
        w, h = self.size
        self.events.append(self.kernel_cells(self.rt.queue, (w, h), None, self._src_buf, node_buf, ci_buf, cf_buf,
                                             np.int32(len(cells)), self.acc, np.int32(w), np.int32(h), sky_buf,
                                             np.int32(sky is not None), _float4(horizon), _float4(zenith)))

    def add_cells(self, srcs: list[np.ndarray], cells: list[WarpCell]) -> None:
        """:meth:`map_cells`, each render (h×w×3, rows top-down) copied in, :meth:`launch_cells`."""
        if len(srcs) != len(cells):
            raise ValueError(f"{len(srcs)} renders for {len(cells)} cells")
        for src, cell in zip(srcs, cells):
            sw, sh = cell.render_size
            if np.shape(src) != (sh, sw, 3):
                raise InputError(f"image-based lens: a render of shape {np.shape(src)} for a {sw}x{sh} projection")
        views = self.map_cells(cells)
        try:
            for src, view in zip(srcs, views):
                view[::-1, :, :3] = src
        except BaseException:
            self.launch_cells(run=False)
            raise
        self.launch_cells()

    def result(self) -> np.ndarray:
        w, h = self.size
        out = np.empty((3, h, w), np.float32)
        self.cl.enqueue_copy(self.rt.queue, out, self.acc)
        self.rt.queue.finish()
        return np.ascontiguousarray(np.moveaxis(out, 0, -1))

    def device_ms(self) -> float:
        from ..runtime import event_ms

        self.rt.queue.finish()
        return float(sum(event_ms(e) for e in self.events))

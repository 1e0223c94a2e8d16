r"""Rendering through the image-based lens model of Heidrich, Slusallek & Seidel ("An
Image-Based Model for Realistic Lens Systems in Interactive Computer Graphics", Graphics
Interface 1997): one pinhole render per projection, warped onto the film and accumulated.

One module per job, every public name importable from here:

* :mod:`clpost.render.ibl_rays` — backward tracing through the mirrored prescription, pupil
  sampling, the virtual-centre-of-projection fit, texture coordinates;
* :mod:`clpost.render.ibl_build` — the model: the quad tree of projections per pupil sample
  (:func:`build`, cached per lens, focus, aperture and sampling);
* :mod:`clpost.render.ibl_warp` — film ↔ pixels and the warp of each projection's render
  (:func:`warp_cells`, :class:`Warper`, :func:`warp_reference`);
* this module — driving a renderer: :func:`render_image_based`, :func:`render_image_based_sequence`.
"""
from __future__ import annotations

import threading
import time

import numpy as np

from ..errors import InputError
from .ibl_build import THRESHOLD_DEG, ImageBasedLens, Projection, build, model_for_camera
from .ibl_rays import (angle_errors_deg, fit_cop, focus_plane_z_mm, image_plane_tex, mirrored_table, pupil_samples,
                       trace_back)
from .ibl_warp import (Warper, WarpCell, lens_to_camera_m, model_grid, pixel_to_film, warp_cells,
                       warp_reference)

__all__ = ["THRESHOLD_DEG", "ImageBasedLens", "Projection", "WarpCell", "Warper", "angle_errors_deg", "build",
           "fit_cop", "focus_plane_z_mm", "image_plane_tex", "lens_to_camera_m", "mirrored_table", "model_for_camera",
           "model_grid", "open_rasterizer", "pixel_to_film", "pupil_samples", "pyvista_render_fn",
           "rasterizer_render_fn", "render_image_based", "render_image_based_sequence", "trace_back", "warp_cells",
           "warp_reference"]


_WARPERS: dict = {}


def _warper(size: tuple[int, int], device: str | None) -> Warper:
    """A zeroed :class:`Warper` for ``size``, kept between frames (its buffers and the cells'
    metadata are re-used; the last few sizes are kept), one per thread: a Warper holds a frame's
    accumulator."""
    key = (tuple(int(v) for v in size), device, threading.get_ident())
    warper = _WARPERS.pop(key, None)
    if warper is None:
        warper = Warper(size, device)
    else:
        warper.reset()
    _WARPERS[key] = warper
    while len(_WARPERS) > 4:
        _WARPERS.pop(next(iter(_WARPERS)))
    return warper


def render_image_based(model: ImageBasedLens, size: tuple[int, int], render_fn, *, node_spacing_px: float = 16.0,
                       supersample: float = 1.0, device: str | None = None) -> tuple[np.ndarray, dict]:
    r"""The image of ``model`` at ``size`` (sec. 3.5): every projection rendered by
    ``render_fn(cop_camera_m, f_px, c, (w, h)) -> h×w×3 radiance`` (a pinhole at the COP with an
    off-axis frustum; ``render_fn.prepare(cells)``, if there is one, is called first with all the
    frame's :class:`WarpCell` s — the rasterizer path bakes its textures there; a
    ``render_fn.render_into(view, cop, f, c, size)`` writes straight into the warp's RGBA buffer
    with rows bottom-up instead of returning; a ``render_fn.render_pages(pages, cells, layout)``
    renders all of them at once as the tiles of :meth:`Warper.map_pages`, leaving pixels of alpha 0
    to the warp kernel's sky if it has ``render_fn.warp_sky(cells)``), warped onto its
    film cell with weight W by the ``ibl_warp_cells`` kernel (all projections in one launch) and
    summed over pupil samples, then normalised by the axial point's weight,

    .. math:: I(x') = \frac{\sum_i W_i(x')\,L_i(x')}{\sum_i W_i(0)},

    so a uniform scene of radiance L gives L × the lens's relative illumination RI(x'), 1 on
    the axis. Photometry: this is scene radiance times RI — what the exposure stage expects as
    input, with the lens's fall-off (natural and optical vignetting) already applied; the
    ``vignetting`` stage must then not run (nor ``dof`` and ``distortion``, which the model
    also contains). Returns (H×W×3 float32, stats: projections, render_s (prepare + renders),
    prepare_s, warp_device_ms)."""
    cells, axial = warp_cells(model, size, node_spacing_px, supersample)
    warper = _warper(size, device)
    t0 = time.perf_counter()
    prepare = getattr(render_fn, "prepare", None)
    if prepare is not None:
        prepare(cells)
    t_prepare = time.perf_counter() - t0
    pages = getattr(render_fn, "render_pages", None)
    into = getattr(render_fn, "render_into", None)
    if pages is not None:  # all projections as the tiles of a few pages, one render + read-back per page
        layout, views = warper.map_pages(cells)
    else:
        views = warper.map_cells(cells)
    try:
        if pages is not None:
            pages(views, cells, layout)
        else:
            for cell, view in zip(cells, views):
                if into is not None:  # straight into the warp's buffer (RGBA, rows bottom-up)
                    into(view, cell.cop_camera_m, cell.render_f_px, cell.render_c, cell.render_size)
                    continue
                src = np.asarray(render_fn(cell.cop_camera_m, cell.render_f_px, cell.render_c, cell.render_size))
                if src.shape != (cell.render_size[1], cell.render_size[0], 3):
                    raise InputError(f"image-based lens: render_fn returned shape {src.shape}, expected "
                                     f"{(cell.render_size[1], cell.render_size[0], 3)} (h, w, 3)")
                view[::-1, :, :3] = src
    except BaseException:
        warper.launch_cells(run=False)
        raise
    t_render = time.perf_counter() - t0
    warp_sky = getattr(render_fn, "warp_sky", None) if pages is not None else None
    warper.launch_cells(sky=warp_sky(cells) if warp_sky is not None else None)
    out = warper.result() / np.float32(axial)
    return out.astype(np.float32), {"projections": len(cells), "render_s": t_render, "prepare_s": t_prepare,
                                     "warp_device_ms": warper.device_ms()}


def pyvista_render_fn(renderer, frame_index: int = 0):
    """``render_fn`` for :func:`render_image_based` from a :class:`PyVistaRenderer`: the scene
    camera moved to the COP (camera axes unchanged) with the projection's off-axis frustum."""
    from .pyvista_renderer import shade

    def fn(cop_m, f_px, c, size):
        gbuf, cam_pose, poses = renderer.gbuffer(tuple(size), f_px, frame_index, tuple(c), tuple(cop_m))
        return shade(renderer.scene, gbuf, f_px, tuple(c), cam_pose, poses)

    return fn


class _RasterRenderFn:
    """``render_fn`` of the rasterizer path (:func:`rasterizer_render_fn`)."""

    def __init__(self, raster, frame_index: int) -> None:
        self.raster, self.frame_index = raster, frame_index

    def prepare(self, cells) -> None:
        self.raster.prepare(cells, self.frame_index)

    def __call__(self, cop_m, f_px, c, size):
        return self.raster.render(cop_m, f_px, c, size)

    def render_into(self, view, cop_m, f_px, c, size) -> None:
        self.raster.render_into(view, cop_m, f_px, c, size)

    def render_pages(self, pages, cells, layout) -> None:
        self.raster.render_pages(pages, [(c.cop_camera_m, c.render_f_px, c.render_c, c.render_size) for c in cells],
                                 layout, fill_sky=False)  # the warp kernel fills the sky (warp_sky)

    def warp_sky(self, cells):
        return self.raster.sky(cells)


def rasterizer_render_fn(raster, frame_index: int = 0):
    """``render_fn`` for :func:`render_image_based` from a
    :class:`~clpost.render.ibl_raster.FloatRasterizer`: per frame the scene's radiance baked into
    float textures, then every projection a VTK rasterisation into a float framebuffer
    (docs/image_based_lens.md, "Rasterizer path")."""
    return _RasterRenderFn(raster, frame_index)


def open_rasterizer(scene, log=None):
    """A :class:`~clpost.render.ibl_raster.FloatRasterizer` for ``scene``, or None with the reason
    passed to ``log`` (default: a warning) when the rasterizer path cannot render it here."""
    from .ibl_raster import FloatRasterizer, RasterUnavailable

    try:
        return FloatRasterizer(scene)
    except RasterUnavailable as e:
        _fallback_note(f"image-based lens: rasterizer path unavailable, using the numpy path: {e}", log)
        return None


def _fallback_note(msg: str, log=None) -> None:
    """``msg`` to ``log``, or a warning without one."""
    import warnings

    if log is not None:
        log(msg)
    else:
        warnings.warn(msg, stacklevel=3)


def render_image_based_sequence(camera, size: tuple[int, int], n_frames: int = 1, camera_motion: bool = False,
                                 scene=None, *, pupil_n: int = 3, threshold_deg: float = THRESHOLD_DEG,
                                 max_depth: int = 4, device: str | None = None, log=None,
                                 pupil_pattern: str = "grid", rasterizer: bool = False) -> list:
    """Frames 0 … n_frames−1 through the image-based model of ``camera``'s lens: colour from
    :func:`render_image_based`, depth and velocity from the pinhole at the entrance pupil
    (the centre of the chief rays; what the post-process path renders). Metadata records the
    projections per frame and the timings. ``rasterizer``: the projections through the
    rasterizer path where it can render the scene (else the numpy path, with the reason logged)."""
    from .demo_scene import DemoScene
    from .ibl_raster import RasterUnavailable
    from .pyvista_renderer import PyVistaRenderer

    if int(n_frames) != n_frames or n_frames < 1:
        raise InputError(f"n_frames={n_frames!r} must be an integer >= 1")
    model = model_for_camera(camera, pupil_n=pupil_n, threshold_deg=threshold_deg, max_depth=max_depth,
                             pupil_pattern=pupil_pattern)
    renderer = PyVistaRenderer(scene if scene is not None else DemoScene.default(camera_motion=camera_motion))
    raster = open_rasterizer(renderer.scene, log) if rasterizer else None
    try:
        frames = []
        for i in range(int(n_frames)):
            t0 = time.perf_counter()
            if raster is not None:
                try:
                    color, stats = render_image_based(model, size, rasterizer_render_fn(raster, i), device=device)
                except RasterUnavailable as e:  # found at the first render (e.g. no float framebuffer)
                    _fallback_note(f"image-based lens: rasterizer path unavailable, using the numpy path: {e}", log)
                    raster.close()
                    raster = None
            if raster is None:
                color, stats = render_image_based(model, size, pyvista_render_fn(renderer, i), device=device)
            elif raster.coarsened:  # a plane whose bake hit the texture cap: blurrier than its footprint
                stats["coarsened"] = sorted(raster.coarsened)
            stats["frame_s"] = time.perf_counter() - t0
            pin = renderer.render(camera, size, i)
            meta = dict(pin.metadata)
            meta["image_based_lens"] = dict(stats, max_angle_deg=model.max_angle_deg,
                                            pupil_samples=len(model.pupil_samples_mm),
                                            projection_path="numpy" if raster is None else "raster")
            frames.append(pin.replace(color=color, metadata=meta))
            if log is not None:
                log(f"image-based lens frame {i}: {stats['projections']} projections, "
                    f"{stats['frame_s']:.2f} s ({stats['render_s']:.2f} s rendering, warp "
                    f"{stats['warp_device_ms']:.1f} ms device)")
        return frames
    finally:
        renderer.close()
        if raster is not None:
            raster.close()

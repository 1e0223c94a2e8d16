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
           "model_grid", "pixel_to_film", "pupil_samples", "pyvista_render_fn", "render_image_based",
           "render_image_based_sequence", "trace_back", "warp_cells", "warp_reference"]


def render_image_based(model: ImageBasedLens, size: tuple[int, int], render_fn, *, node_spacing_px: float = 16.0,
                       supersample: float = 1.0, device: str | None = None) -> tuple[np.ndarray, dict]:
    r"""The image of ``model`` at ``size`` (sec. 3.5): every projection rendered by
    ``render_fn(cop_camera_m, f_px, c, (w, h)) -> h×w×3 radiance`` (a pinhole at the COP with an
    off-axis frustum), warped onto its film cell by the ``ibl_warp`` kernel with weight W and
    summed over pupil samples, then normalised by the axial point's weight,

    .. math:: I(x') = \frac{\sum_i W_i(x')\,L_i(x')}{\sum_i W_i(0)},

    so a uniform scene of radiance L gives L × the lens's relative illumination RI(x'), 1 on
    the axis. Photometry: this is scene radiance times RI — what the exposure stage expects as
    input, with the lens's fall-off (natural and optical vignetting) already applied; the
    ``vignetting`` stage must then not run (nor ``dof`` and ``distortion``, which the model
    also contains). Returns (H×W×3 float32, stats: projections, render_s, warp_device_ms)."""
    cells, axial = warp_cells(model, size, node_spacing_px, supersample)
    warper = Warper(size, device)
    t_render = 0.0
    for cell in cells:
        t0 = time.perf_counter()
        src = np.asarray(render_fn(cell.cop_camera_m, cell.render_f_px, cell.render_c, cell.render_size))
        t_render += time.perf_counter() - t0
        if src.shape != (cell.render_size[1], cell.render_size[0], 3):
            raise InputError(f"image-based lens: render_fn returned shape {src.shape}, expected "
                             f"{(cell.render_size[1], cell.render_size[0], 3)} (h, w, 3)")
        warper.add(src, cell)
    out = warper.result() / np.float32(axial)
    return out.astype(np.float32), {"projections": len(cells), "render_s": t_render,
                                     "warp_device_ms": warper.device_ms()}


def pyvista_render_fn(renderer, frame_index: int = 0):
    """``render_fn`` for :func:`render_image_based` from a :class:`PyVistaRenderer`: the scene
    camera moved to the COP (camera axes unchanged) with the projection's off-axis frustum."""
    from .pyvista_renderer import shade

    def fn(cop_m, f_px, c, size):
        gbuf, cam_pose, poses = renderer.gbuffer(tuple(size), f_px, frame_index, tuple(c), tuple(cop_m))
        return shade(renderer.scene, gbuf, f_px, tuple(c), cam_pose, poses)

    return fn


def render_image_based_sequence(camera, size: tuple[int, int], n_frames: int = 1, camera_motion: bool = False,
                                 scene=None, *, pupil_n: int = 3, threshold_deg: float = THRESHOLD_DEG,
                                 max_depth: int = 4, device: str | None = None, log=None,
                                 pupil_pattern: str = "grid") -> list:
    """Frames 0 … n_frames−1 through the image-based model of ``camera``'s lens: colour from
    :func:`render_image_based`, depth and velocity from the pinhole at the entrance pupil
    (the centre of the chief rays; what the post-process path renders). Metadata records the
    projections per frame and the timings."""
    from .demo_scene import DemoScene
    from .pyvista_renderer import PyVistaRenderer

    if int(n_frames) != n_frames or n_frames < 1:
        raise InputError(f"n_frames={n_frames!r} must be an integer >= 1")
    model = model_for_camera(camera, pupil_n=pupil_n, threshold_deg=threshold_deg, max_depth=max_depth,
                             pupil_pattern=pupil_pattern)
    renderer = PyVistaRenderer(scene if scene is not None else DemoScene.default(camera_motion=camera_motion))
    try:
        frames = []
        for i in range(int(n_frames)):
            t0 = time.perf_counter()
            color, stats = render_image_based(model, size, pyvista_render_fn(renderer, i), device=device)
            stats["frame_s"] = time.perf_counter() - t0
            pin = renderer.render(camera, size, i)
            meta = dict(pin.metadata)
            meta["image_based_lens"] = dict(stats, max_angle_deg=model.max_angle_deg,
                                            pupil_samples=len(model.pupil_samples_mm))
            frames.append(pin.replace(color=color, metadata=meta))
            if log is not None:
                log(f"image-based lens frame {i}: {stats['projections']} projections, "
                    f"{stats['frame_s']:.2f} s ({stats['render_s']:.2f} s rendering, warp "
                    f"{stats['warp_device_ms']:.1f} ms device)")
        return frames
    finally:
        renderer.close()

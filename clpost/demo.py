"""``clpost demo``: render the built-in scene, process it with the default camera, write EXRs and
PNG previews — the first thing a new user runs.

Layout of the output directory::

    render/demo.####.exr      the renderer's pinhole buffers (color, Z, velocity): input for
                              `clpost process`
    clpost.####.exr           the camera's output (linear sensor signal, camera in the header)
    preview/clpost.####.png   sRGB previews of the output

The demo camera meters the scene (aperture priority at f/2 unless --shutter is given) so the image
is exposed as a camera would expose it. Its defaults (:data:`DEMO_CAMERA_DEFAULTS`) differ from
``clpost process``'s (a passthrough thin lens): ``--help`` shows them and the demo prints them as
``process`` flags (:func:`process_flags`). The scene's sunlit diffuse white (Y ≈ 1) is taken as
1000 cd/m² (``luminance_scale``), white paper outdoors on an overcast day. Its small lamps
(0.2 % of the pixels at 250–1000× diffuse white) pull an averaging meter down by about 1.4 stops,
so the demo dials in +1 EV as a photographer would; the meter then picks about 1/1250 s at f/2,
ISO 100.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

from . import exr
from .atomic import write_png
from .batch import output_header
from .camera import Camera
from .pipeline import Pipeline

DEMO_CAMERA_DEFAULTS = dict(lens="zeiss-planar-50-f1.4", depth_of_field=True, vignetting="lens", f_number=2.0, shutter_s=None, focus_distance_m=3.0,
                            luminance_scale=1000.0, exposure_compensation_ev=1.0,
                            blades=6)
DEMO_WIDTH = 960
# --lens-model image-based: the pupil sampling and the stages whose effect the model's image
# already contains. 36 samples on a Vogel spiral at quad-tree depth limit 1 (144 projections, as
# many as 9 samples at depth 2; the ray-angle error this leaves is logged) turn the 3×3 ghost
# copies of defocused highlights into a filled blur disc; cells meet without a step at the focus
# plane at any depth (image_based_lens.image_plane_tex). Measured in docs/image_based_lens.md
# (tools/ibl_bench.py pupil).
IBL_DEMO_PUPIL = dict(pupil_n=6, pupil_pattern="spiral", max_depth=1)
IBL_CONTAINS = ("dof", "distortion", "vignetting", "astigmatism", "coma")


def process_flags(camera: Camera) -> str:
    """The ``clpost process`` options that give ``camera`` (every value that differs from
    ``clpost.Camera``'s default), so a demo camera is reproducible on any plate."""
    plain = Camera()
    out = []
    for s in Camera.param_specs():
        if s.meta.flag is None or s.meta.input_only:
            continue
        value = getattr(camera, s.name)
        if value != getattr(plain, s.name):
            shown = s.help_default(value)
            out.append(f"{s.meta.flag} {'+' if s.name == 'exposure_compensation_ev' and value > 0 else ''}{shown}")
    return " ".join(out) or "(none: clpost.Camera's defaults)"


def run_demo(outdir: Path, camera: Camera | None = None, *, size: tuple[int, int] | None = None,
             n_frames: int = 3, quality: str = "final", stages: list[str] | None = None,
             device: str | None = None, camera_motion: bool = True, overwrite: bool = False,
             log: Callable[[str], None] = print, reference_subframes: int = 0,
             display: str = "srgb", lens_model: str = "post") -> dict:
    """Render, process and write the demo; returns a summary (paths, timings, plan).
    ``lens_model``: ``post`` (the pipeline's stages) or ``geometry-distortion`` (the camera's
    calibration applied to the vertices, :mod:`clpost.render.geometry_distortion`; the
    distortion stage is then left out) or ``image-based`` (the lens_data prescription as
    projections per pupil sample, :mod:`clpost.render.image_based_lens`; dof, distortion,
    vignetting and the aberration stages are then left out)."""
    from .render import render_demo_sequence

    camera = camera or Camera(**DEMO_CAMERA_DEFAULTS)
    log(f"camera, as `clpost process` flags (the demo's defaults differ from process's): {process_flags(camera)}")
    size = size or camera.default_resolution(DEMO_WIDTH)
    outdir = Path(outdir)
    out_paths = [outdir / f"clpost.{i:04d}.exr" for i in range(1, n_frames + 1)]
    existing = [p for p in out_paths if p.exists()]
    if existing and not overwrite:
        from .errors import InputError

        raise InputError(f"{existing[0]} exists; choose a new OUTDIR or pass --overwrite")

    t0 = time.perf_counter()
    render_size, intrinsics = size, None
    if camera.distortion is None and lens_model == "post":
        # a lens_data lens distorts by its traced curve: fix the model at the output size, so the
        # render below covers its extended frustum (Pipeline.camera_for would fit the render's size)
        from .calibration import lens_distortion_model

        model = lens_distortion_model(camera, size)
        if model is not None:
            camera = camera.with_(distortion=model)
    if camera.distortion is not None:
        # distortion stage: render the extended frustum so barrel distortion leaves no hole
        from .calibration import required_render

        spec = required_render(camera.distortion)
        render_size, intrinsics = (spec.width, spec.height), spec.intrinsics()
    if lens_model == "geometry-distortion":
        # renderer-side lens model: distorted geometry, so the distortion stage must not run again
        from .errors import InputError
        from .render.geometry_distortion import render_geometry_distorted_sequence
        from .stages import stage_names

        if camera.distortion is None:
            raise InputError("--lens-model geometry-distortion needs a calibration (--calibration FILE)")
        frames = render_geometry_distorted_sequence(camera.distortion, size, n_frames, camera_motion)
        stages = [s for s in (stages or stage_names()) if s != "distortion"]
    elif lens_model == "image-based":
        # renderer-side lens model: the image already has the lens's defocus, distortion,
        # aberrations and fall-off (natural + optical vignetting), so those stages must not run again
        from .render.image_based_lens import render_image_based_sequence
        from .stages import stage_names

        frames = render_image_based_sequence(camera, size, n_frames, camera_motion, device=device, log=log,
                                             **IBL_DEMO_PUPIL)
        stages = [s for s in (stages or stage_names()) if s not in IBL_CONTAINS]
    elif lens_model != "post":
        from .errors import InputError

        raise InputError(f"lens_model={lens_model!r} must be 'post', 'geometry-distortion' or 'image-based'")
    else:
        frames = render_demo_sequence(camera, size=render_size, n_frames=n_frames, camera_motion=camera_motion,
                                      intrinsics=intrinsics)
    t_render = time.perf_counter() - t0
    log(f"rendered {n_frames} frame(s) of the demo scene at {size[0]}x{size[1]} "
        f"in {t_render:.2f} s (pyvista/VTK offscreen: HDR color, planar depth, velocity)")

    pipe = Pipeline(camera, quality=quality, stages=stages, device=device)
    log(f"OpenCL device: {pipe.runtime.name}")
    t_proc, written = [], []
    for i, frame in enumerate(frames, start=1):
        exr.write_frame(outdir / "render" / f"demo.{i:04d}.exr", frame)
        t1 = time.perf_counter()
        out = pipe.run(frame)
        t_proc.append(time.perf_counter() - t1)
        exr.write_frame(out_paths[i - 1], out, header=output_header(out))
        write_png(outdir / "preview" / f"clpost.{i:04d}.png", out.color, display=display,
                  working_space=camera.working_space)
        written.append(out_paths[i - 1])
        if i == 1:
            for e in pipe.explain(frame):
                log(f"  {e}")
    cam = pipe.camera_for(frames[0])
    log(f"camera: {camera.lens} f/{cam.f_number:.3g} {cam.shutter_s:.4g} s ISO {cam.iso:g} "
        f"focus {cam.focus_distance_m:g} m")
    log(f"processed {n_frames} frame(s): first {t_proc[0] * 1e3:.0f} ms (one-time setup: kernel build, "
        f"colour-science import), "
        f"then {min(t_proc[1:] or t_proc) * 1e3:.1f} ms/frame")
    log(f"wrote {outdir}/render/demo.####.exr, {outdir}/clpost.####.exr and {outdir}/preview/clpost.####.png")
    if reference_subframes:
        # motion_blur: the ground truth the velocity-buffer blur is measured against
        from .render.motion import render_motion_blur_reference

        from .stages import stage_names

        t2 = time.perf_counter()
        # the reference is already blurred: process it with every stage but motion_blur
        ref_pipe = Pipeline(cam, quality=quality, device=device,
                            stages=[s for s in (stages or stage_names()) if s != "motion_blur"])
        for i in range(1, n_frames + 1):
            ref = render_motion_blur_reference(cam, size, frame_index=i - 1, subframes=reference_subframes,
                                               camera_motion=camera_motion)
            exr.write_frame(outdir / "render" / f"reference_blur.{i:04d}.exr", ref)
            out = ref_pipe.run(ref)
            write_png(outdir / "preview" / f"reference_blur.{i:04d}.png", out.color)
        log(f"rendered {n_frames} motion-blur reference frame(s) from {reference_subframes} sub-frames each "
            f"in {time.perf_counter() - t2:.1f} s: {outdir}/render/reference_blur.####.exr and "
            f"{outdir}/preview/reference_blur.####.png (the same camera minus motion_blur)")
    return {"outputs": written, "render_s": t_render, "process_s": t_proc, "size": size,
            "plan": pipe.plan(frames[0])}

"""Process a frame sequence: read → plan → run → write, frames in order.

The one loop behind ``clpost process`` (and the demo). Each output is written atomically, so an
interrupted run leaves only complete frames; existing outputs are skipped unless ``overwrite``,
so a rerun resumes. Frames of a sequence must share one size: a frame that differs stops the run
with an error naming it (the outputs already written are complete and stay).

Overlap (:func:`process_sequence`): frame k+1 is read by a reader thread and frame k−1 written by
a writer thread while frame k runs on the device, so a sequence costs about the slowest of read,
process and write per frame instead of their sum (OpenEXR's decoding and encoding, numpy copies
and OpenCL waits release the GIL; OpenEXR also gets one thread per CPU, :func:`exr_threads`). At
most one read ahead and one write behind: three frames in memory. An output image whose file is
written becomes the array a later frame's image is downloaded into (:meth:`Pipeline.run`'s
``out``), so a sequence does not allocate — and page-fault — a fresh image per frame. Errors keep
the serial loop's order: frame k's error is raised only after every earlier frame's output is
complete.
"""
from __future__ import annotations

import contextlib
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from . import exr
from .display_image import output_format, write_image
from .errors import InputError
from .frame import Frame, Windows
from .pipeline import Pipeline


@dataclass
class FrameJob:
    frame: int
    src: Path
    dst: Path
    front: Path | None = None
    """The foreground layer rendered apart (``clpost process --front``), read into
    ``Frame.front`` (:func:`read_front`); None for a one-layer frame."""


@dataclass
class BatchReport:
    done: list[int] = field(default_factory=list)
    skipped: list[int] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    """Wall time per processed frame: read + process + write."""
    failed: dict[int, str] = field(default_factory=dict)
    """Frames that could not be processed (distributed runs go on past them), with the error."""
    user_errors: list[int] = field(default_factory=list)
    """The failed frames whose error is the input's (:class:`~clpost.errors.ClpostError`: a bad
    file or parameter, never retried), as opposed to a crash or a lost worker."""


def output_header(frame: Frame) -> dict[str, str]:
    """String header attributes recording what the camera did (written into output EXRs)."""
    hdr = dict(frame.metadata.get("camera", {}))
    cam = frame.metadata.get("resolved_camera")
    if cam is not None:  # the same values under the OpenEXR standard names (focus, aperture, ...)
        from .camera_sources import standard_attributes

        hdr.update(standard_attributes(cam))
    hdr["clpost.plan"] = ",".join(frame.metadata.get("plan", [])) or "(identity)"
    src = frame.metadata.get("path")
    if src:
        hdr["clpost.source"] = str(src)
    return hdr


def read_input(pipeline: Pipeline, path: Path, layout: str | None = None, camera=None) -> Frame:
    """Read one input frame; radial depth (Arnold's Z, see :mod:`clpost.exr`) is converted to
    planar with the camera's own focal length in pixels at the frame's resolution (``camera``:
    this frame's, default the pipeline's); its ``labels`` picks the label channels read
    (:mod:`clpost.labels.channels`)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", exr.DepthConventionWarning)
        frame = exr.read_frame(path, layout, labels=getattr(camera or pipeline.camera, "labels", "auto"))
    if frame.metadata.get("depth_kind") == "radial" and frame.depth is not None:
        fx, fy, _, _ = (camera or pipeline.camera).intrinsics(frame.width, frame.height)
        meta = dict(frame.metadata, depth_kind="planar (converted from radial with the camera's focal length)")
        frame = frame.replace(depth=exr.radial_to_planar(frame.depth, (fx, fy)), metadata=meta)
    return frame


def frame_resolved(sources, job: FrameJob):
    """This job's :class:`~clpost.camera_sources.Resolved` camera (and each value's source) from
    ``sources`` and the input's standard attributes (header only: the camera is needed before the
    pixels, to convert radial depth)."""
    # a missing input is read_frame's error to report (it names the frame)
    attrs = exr.read_attributes(job.src)[0] if sources.use_exr and job.src.is_file() else {}
    try:
        return sources.resolve(job.frame, attrs)
    except InputError as exc:
        raise InputError(f"{job.src}: {exc}") from None


def frame_camera(sources, job: FrameJob):
    """This job's camera from ``sources`` (:class:`~clpost.camera_sources.CameraSources`; None:
    the pipeline's camera, constant)."""
    return None if sources is None else frame_resolved(sources, job).camera


def process_one(pipeline: Pipeline, job: FrameJob, layout: str | None = None,
                half: bool = False, expect_size: tuple[int, int] | None = None,
                compression: str = "zip", display="srgb", preview_dir: Path | None = None,
                sources=None, aovs: tuple[str, ...] = (), camera_files: bool = False) -> Frame:
    """Read, process and write one frame; returns the processed frame. An output named .png, .jpg
    or .tif is written display-encoded for ``display`` (:mod:`clpost.display_image`), an .exr
    linear with the camera in its header; ``preview_dir`` also gets ``<output stem>.png``.
    ``sources``: an animated camera (:class:`~clpost.camera_sources.CameraSources`), resolved for
    this frame. ``aovs``: diagnostic passes written as extra channels of an .exr output
    (:mod:`clpost.aovs`). The output's effective camera (:mod:`clpost.labels.camera_files`) goes
    into an .exr's header, and with ``camera_files`` beside the output in OpenCV, Kalibr and COLMAP
    form."""
    cam, frame = load_job(pipeline, job, layout, expect_size, sources)
    out, store = run_job(pipeline, job, cam, frame, display, aovs)
    store_job(job, out, store, half, compression, display, preview_dir, camera_files)
    return out


def load_job(pipeline: Pipeline, job: FrameJob, layout: str | None = None,
             expect_size: tuple[int, int] | None = None, sources=None) -> tuple:
    """Read step of :func:`process_one`: (this frame's camera or None, the input frame with its
    frame index) — checked against the sequence's size."""
    cam = frame_camera(sources, job)
    frame = read_input(pipeline, job.src, layout, cam)
    # the image size is the display window's (a data window may change per frame, as a render's
    # bounding box does)
    size = frame.windows.display_size
    if expect_size is not None and size != expect_size:
        raise InputError(
            f"{job.src}: size {size[0]}x{size[1]} differs from the sequence's "
            f"{expect_size[0]}x{expect_size[1]}; all frames of a sequence must have one size"
        )
    # The frame number seeds grain/sensor noise (CONVENTIONS "Randomness"): frames differ, reruns agree.
    frame = frame.replace(metadata=dict(frame.metadata, frame_index=int(job.frame)), validate=False)
    if job.front is not None:
        frame = frame.with_front(read_front(pipeline, job, frame, layout, cam), copy=False)
    return cam, frame


def read_front(pipeline: Pipeline, job: FrameJob, frame: Frame, layout: str | None = None, camera=None) -> np.ndarray:
    """The ``Frame.front`` array of ``job.front`` for the input ``frame``: read like an input
    (:func:`read_input`: same layout rule, radial depth made planar), its colour taken as
    premultiplied (the EXR convention, what a transparent film writes), its alpha and depth
    required, its arrays those of the input: one display window and one extent (the data window
    may be a crop inside it) (:func:`clpost.frame.front_of`)."""
    from .frame import front_of

    path = job.front
    fg = read_input(pipeline, path, layout, camera)
    # the arrays line up when both cover one extent of one display window (a front cropped to
    # its data window inside it is fine: no data there is alpha 0)
    wf, wi = fg.windows, frame.windows
    if fg.size != frame.size or wf.display != wi.display or wf.extent != wi.extent:
        def shown(f):
            w = f.windows
            if w == Windows.full(*f.size):
                return f"{f.width}x{f.height}"
            return f"{f.width}x{f.height} (data {exr.window_str(w.data)}, display {exr.window_str(w.display)})"
        raise InputError(f"--front {path}: size {shown(fg)} differs from the input's {shown(frame)} ({job.src}); "
                         "render the front layer with the input's resolution and windows")
    return front_of(fg, f"--front {path}")


def run_job(pipeline: Pipeline, job: FrameJob, cam, frame: Frame, display="srgb",
            aovs: tuple[str, ...] = (), out: np.ndarray | None = None) -> tuple[Frame, tuple]:
    """Device step of :func:`process_one` (the pipeline's thread): the processed frame and what
    :func:`store_job` needs (working space, input chromaticities, AOV channels, the camera used
    and the effective camera). ``out``: an array to put the image in (:meth:`Pipeline.run`)."""
    out = pipeline.run(frame, cam, out)
    ws = (cam or pipeline.camera).working_space
    chroma = input_chromaticities(display, job.src, frame.metadata)
    extra = None
    if aovs:
        from .aovs import compute

        extra = compute(pipeline.runtime, out.metadata.get("resolved_camera") or cam or pipeline.camera, out, aovs)
    from .labels.camera_files import effective_camera

    used = out.metadata.get("resolved_camera") or cam or pipeline.camera
    eff = effective_camera(used, frame, out.metadata.get("plan", ()), pipeline.quality)
    return out, (ws, chroma, extra, used, eff)


def store_job(job: FrameJob, out: Frame, store: tuple, half: bool = False, compression: str = "zip",
              display="srgb", preview_dir: Path | None = None, camera_files: bool = False) -> None:
    """Write step of :func:`process_one`: the output (atomically), its camera files and preview."""
    from .labels.camera_files import camera_header, write_camera_files

    ws, chroma, extra, used, eff = store
    header = {**output_header(out), **camera_header(eff)}
    write_output(job.dst, out, header, display=display, working_space=ws, half=half,
                 compression=compression, chroma=chroma, extra=extra, camera=used)
    if camera_files:
        write_camera_files(eff, job.dst)
    if preview_dir is not None and used.isp:  # already display-encoded by the camera's ISP
        from .raw_io import write_developed

        write_developed(preview_path(job.dst, preview_dir), display_window(out).color, used)
    elif preview_dir is not None:
        write_image(preview_path(job.dst, preview_dir), display_window(out).color, display=display,
                    working_space=ws, option="--preview", chroma=chroma)


def input_chromaticities(display, src: Path | None, metadata: dict | None = None):
    """The input file's chromaticities where an OCIO view takes its input space from them
    (:mod:`clpost.ocio`), else None. ``metadata``: the read frame's, whose ``"chromaticities"``
    the EXR reader already took from the header (else the header is read here)."""
    from .ocio import OcioView, file_chromaticities

    if not (isinstance(display, OcioView) and display.input_colorspace is None):
        return None
    if metadata is not None:
        return metadata.get("chromaticities")
    return file_chromaticities(src)


def write_output(path: Path, frame: Frame, header: dict, *, display="srgb", working_space: str = "rec709",
                 half: bool = False, compression: str = "zip", chroma=None, extra=None, camera=None) -> None:
    """Write ``frame`` as its name says: an .exr linear with ``header``, a .png/.jpg/.tif
    display-encoded for ``display`` (a clpost encoding or an OCIO view; ``chroma``: the input's
    chromaticities) with its ICC profile (:mod:`clpost.display_image`); ``extra``: further EXR
    channels (:mod:`clpost.aovs`). A raw ``camera``'s .png/.tif/.jpg: :mod:`clpost.raw_io`
    (16-bit mosaic with a sidecar, or the ISP's image as it is)."""
    from . import raw_io

    if raw_io.write(path, display_window(frame).color, camera, int(frame.metadata.get("frame_index", 0))):
        return
    if output_format(path) == "EXR":
        exr.write_frame(path, frame, header=header, half=half, compression=compression, extra=extra)
    else:
        write_image(path, display_window(frame).color, display=display, working_space=working_space, chroma=chroma)


def display_window(frame: Frame) -> Frame:
    """The frame's display window alone (a picture shows the image, not the overscan or the data
    beyond it); pixels of the display window without data are black."""
    win = frame.windows
    (x0, y0), (w, h) = win.display_offset, win.display_size
    if (x0, y0, w, h) == (0, 0, frame.width, frame.height):
        return frame
    return frame.replace(color=np.ascontiguousarray(frame.color[y0:y0 + h, x0:x0 + w]), depth=None, velocity=None,
                         alpha=None, validate=False)


def preview_path(dst: Path, preview_dir: Path) -> Path:
    """The preview of output ``dst``: ``<preview_dir>/<dst stem>.png``."""
    return Path(preview_dir) / f"{Path(dst).stem}.png"


def pending(jobs: list[FrameJob], overwrite: bool, report: BatchReport,
            progress: Callable[[FrameJob, float | None], None] | None = None) -> list[FrameJob]:
    """The jobs to run: those whose output exists are recorded as skipped (resume) unless
    ``overwrite``. Shared by the serial and the distributed loop; the CLI calls it while holding
    the output lock (:mod:`clpost.outputs`), so no other run writes these outputs meanwhile."""
    todo = []
    for job in jobs:
        if job.dst.exists() and not overwrite:
            report.skipped.append(job.frame)
            if progress:
                progress(job, None)
        else:
            todo.append(job)
    return todo


def first_size(jobs: list[FrameJob]) -> tuple[int, int] | None:
    """(width, height) of the first input frame whose output will be written: every task checks
    its frame against it, so a mismatched frame fails by itself instead of stopping the run."""
    for job in jobs:
        if job.src.is_file():
            return exr.display_size(job.src)
    return None


def exr_threads() -> None:
    """Let OpenEXR (de)compress a file's line blocks on its own threads, one per CPU (its default is
    none): only where nobody set a count before (a caller's choice stays)."""
    import os

    import OpenEXR

    if hasattr(OpenEXR, "set_global_thread_count") and OpenEXR.global_thread_count() == 0:
        OpenEXR.set_global_thread_count(os.cpu_count() or 1)


def process_sequence(pipeline: Pipeline, jobs: list[FrameJob], *, layout: str | None = None,
                     overwrite: bool = False, half: bool = False, compression: str = "zip",
                     progress: Callable[[FrameJob, float | None], None] | None = None,
                     display="srgb", preview_dir: Path | None = None, sources=None,
                     aovs: tuple[str, ...] = (), camera_files: bool = False) -> BatchReport:
    """Process ``jobs`` in order, reading ahead and writing behind (module docstring);
    ``progress(job, seconds or None if skipped)`` after each output is complete, seconds = the
    time since the previous frame completed (the sequence's pace per frame); ``sources``: an
    animated camera (per-frame, :mod:`clpost.camera_sources`)."""
    report = BatchReport()
    todo = pending(jobs, overwrite, report, progress)
    size = first_size(todo)  # the inputs' size (an output may differ: a calibration's own size)
    if not todo:
        return report
    exr_threads()
    t_last = time.perf_counter()
    spare: list[np.ndarray] = []  # images whose output is written: the next frames download into them

    def finished(job: FrameJob, write, image: np.ndarray) -> None:
        nonlocal t_last
        write.result()  # a failed write raises here, before any later frame's error
        spare.append(image)
        now = time.perf_counter()
        report.done.append(job.frame)
        report.seconds.append(now - t_last)
        t_last = now
        if progress:
            progress(job, report.seconds[-1])

    with ThreadPoolExecutor(1, thread_name_prefix="clpost-read") as reader, \
            ThreadPoolExecutor(1, thread_name_prefix="clpost-write") as writer:
        ahead = reader.submit(load_job, pipeline, todo[0], layout, size, sources)
        behind = None  # (job, future, image) of the write in flight
        try:
            for k, job in enumerate(todo):
                cam, frame = ahead.result()
                if k + 1 < len(todo):
                    ahead = reader.submit(load_job, pipeline, todo[k + 1], layout, size, sources)
                out, store = run_job(pipeline, job, cam, frame, display, aovs, spare.pop() if spare else None)
                if behind is not None:
                    done, behind = behind, None
                    finished(*done)
                behind = (job, writer.submit(store_job, job, out, store, half, compression, display,
                                                    preview_dir, camera_files), out.color)
            done, behind = behind, None
            finished(*done)
        except Exception:
            ahead.cancel()
            if behind is not None:  # frame k failed: frame k-1's output completes first (its own
                finished(*behind)   # write error, if any, is raised instead, as the serial loop would)
            raise
        except BaseException:
            # SIGTERM (Terminated) or Ctrl-C: the signal handler has already removed the temporary
            # file the writer is filling, so its write fails; the interruption is what to report
            ahead.cancel()
            if behind is not None:
                with contextlib.suppress(Exception):
                    behind[1].result()
            raise
    return report

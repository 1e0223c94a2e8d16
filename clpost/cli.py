"""The ``clpost`` command line. It holds no image logic: parse → Camera/Frame → plan → run → write.

User errors print one line (``clpost: error: …``) and exit with status 2; ``--debug`` shows the
traceback instead.
"""
from __future__ import annotations

import argparse
import os
import json
import math
import re
import sys
from pathlib import Path

from .camera import Camera
from . import exr
from .exr import COMPRESSIONS
from .errors import ClpostError, InputError
from .params import parse_fraction, parse_on_off, parse_wxh_mm
from .stages import QUALITIES


_positive_float = parse_fraction  # a number, a fraction like 1/50, or inf
_sensor = parse_wxh_mm


def _one_line(msg: str) -> str:
    """A message as one line: a multi-line one (a YAML parser's dump) keeps its first line and
    the first "line N, column M" it names."""
    lines = [ln.strip() for ln in str(msg).splitlines() if ln.strip()]
    if len(lines) <= 1:
        return lines[0] if lines else str(msg)
    m = re.search(r"line (\d+), column (\d+)", str(msg))
    head = lines[0] + (f" at line {m[1]}, column {m[2]}" if m else "")
    if head.count("(") > head.count(")"):
        head += ")"
    return head


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line plus where to look, not the whole usage block."""

    def error(self, message: str):  # noqa: D401 - argparse's signature
        self.exit(2, f"{self.prog}: error: {_one_line(message)}; see {self.prog} --help\n")


def _count(flag: str, minimum: int):
    """An integer option of at least ``minimum`` (``--workers 0`` is refused, not ignored)."""
    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
        if n < minimum:
            raise argparse.ArgumentTypeError(f"{n} is below {minimum}; {flag} takes {minimum} or more")
        return n
    return parse


def _aovs(text: str) -> tuple[str, ...]:
    from .aovs import parse_aovs

    try:
        return parse_aovs(text)
    except InputError as e:
        raise argparse.ArgumentTypeError(str(e).split(": ", 1)[-1]) from None


def _frames_spec(text: str) -> str:
    if not text.strip():
        raise argparse.ArgumentTypeError("empty frame range; give e.g. 1-100, 1-100x2 or 1,5,9")
    return text


def _stage_list(text: str) -> list[str]:
    """Comma-separated stage names; an empty selection is [] (cmd_process refuses it unless
    --explain, where it shows every stage as not selected)."""
    return [x.strip() for x in text.split(",") if x.strip()]


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = text.lower().split("x")
        w, h = int(w), int(h)
        if w < 1 or h < 1:
            raise ValueError
        return w, h
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not WIDTHxHEIGHT in pixels (e.g. 1280x720)") from None


def camera_options(camera_cls=None, defaults=None) -> list[tuple[str, str, object, str]]:
    """``(flag, Camera field, parser, help with the default)`` of every declared camera
    parameter that has a flag (:meth:`clpost.camera.Camera.param_specs`); ``defaults`` replaces
    Camera's own defaults in the help (the demo camera's)."""
    out = []
    for s in (camera_cls or Camera).param_specs():
        if s.meta.flag is not None:
            shown = s.help_default(*([defaults[s.name]] if defaults and s.name in defaults else []))
            help_ = f"{s.meta.help} (default: {shown})".replace("%", "%%")
            out.append((s.meta.flag, s.name, s.meta.parse or str, help_))
    return out


def _add_camera_options(p: argparse.ArgumentParser, camera_cls=None, defaults=None) -> None:
    g = p.add_argument_group("camera (defaults: the demo camera's)" if defaults
                             else "camera (defaults: clpost.Camera's)")
    for flag, dest, typ, help_ in camera_options(camera_cls, defaults):
        g.add_argument(flag, dest=f"cam_{dest}", type=typ, default=argparse.SUPPRESS, help=help_)


def camera_from_args(args: argparse.Namespace, camera_cls=None, /, **defaults) -> Camera:
    """Camera from the options given; ``defaults`` overrides Camera's own defaults (demo). The
    rules about given options (e.g. --metering only in auto-exposure) are the declarations' own
    (:meth:`clpost.camera.Camera.from_options`)."""
    given = {k[4:]: v for k, v in vars(args).items() if k.startswith("cam_")}
    return (camera_cls or Camera).from_options(given, defaults)


def _add_display_option(p: argparse.ArgumentParser, what: str) -> None:
    from .colorspace import DISPLAYS

    g = p.add_argument_group("display (clpost's encodings, or an OpenColorIO config's display/view: README "
                             "\"Colour-managed workflow\")")
    g.add_argument("--display", default=None, metavar="NAME",
                   help=f"{what}: without an OCIO config one of {', '.join(DISPLAYS)} (default srgb); with one, "
                        "a display of the config (default: its default display)")
    g.add_argument("--ocio-config", default=None, metavar="CONFIG",
                   help="OpenColorIO config for --display: a config.ocio file or a built-in URI such as "
                        "ocio://studio-config-latest (default: $OCIO if set; 'none': clpost's encodings)")
    g.add_argument("--ocio-view", default=None, metavar="VIEW",
                   help="the OCIO view of --display (default: the display's default view)")
    g.add_argument("--look", default=None, metavar="LOOK[,LOOK]", help="OCIO looks applied before the view")
    g.add_argument("--input-colorspace", default=None, metavar="NAME",
                   help="the OCIO colour space of the images (default: the input EXR's chromaticities, else "
                        "the working space)")


def display_from_args(args: argparse.Namespace):
    """What ``--display`` means: a :data:`clpost.colorspace.DISPLAYS` name, or a
    :class:`clpost.ocio.OcioView` when an OCIO config is in use (``--ocio-config`` or ``$OCIO``)."""
    from .colorspace import DISPLAYS
    from .ocio import OcioView, config_spec

    spec = config_spec(getattr(args, "ocio_config", None))
    if spec is None:
        for flag, value in (("--ocio-view", args.ocio_view), ("--look", args.look),
                            ("--input-colorspace", args.input_colorspace)):
            if value is not None:
                raise InputError(f"{flag} {value!r} needs an OpenColorIO config: give --ocio-config (e.g. "
                                 "ocio://studio-config-latest) or set $OCIO")
        display = args.display or "srgb"
        if display not in DISPLAYS:
            raise InputError(f"--display {display!r} is not one of clpost's encodings ({', '.join(DISPLAYS)}); "
                             "for an OpenColorIO display give --ocio-config (e.g. ocio://studio-config-latest)")
        return display
    return OcioView.resolve(spec, args.display, args.ocio_view, args.look, args.input_colorspace)


def _set_help(p: argparse.ArgumentParser, dest: str, text: str) -> None:
    """Reword one generated option's help where a subcommand gives it another meaning."""
    for action in p._actions:
        if action.dest == dest:
            action.help = text.replace("%", "%%")


def camera_sources_from_args(args: argparse.Namespace):
    """The animated camera of ``process``: flags > --camera-from > --camera-track > the inputs'
    OpenEXR attributes > defaults (:mod:`clpost.camera_sources`)."""
    from .camera_sources import CameraSources, camera_from_file
    from .camera_track import load_track

    flags = {k[4:]: v for k, v in vars(args).items() if k.startswith("cam_")}
    src = getattr(args, "camera_from", None)
    track = getattr(args, "camera_track", None)
    return CameraSources(flags=flags, camera_from=camera_from_file(src) if src else {},
                         camera_from_path=src, track=load_track(track) if track else None,
                         use_exr=getattr(args, "exr_camera", True))


def _add_source_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("animated camera (docs/camera-tracks.md; priority: flags > --camera-from > "
                             "--camera-track > the inputs' OpenEXR attributes > defaults)")
    g.add_argument("--camera-track", default=None, metavar="FILE",
                   help="keyframed camera parameters per frame number (JSON or CSV; linear or step)")
    g.add_argument("--camera-from", default=None, metavar="OUT.exr",
                   help="reuse the camera recorded in an output's header (its clpost.* keys)")
    g.add_argument("--exr-camera", type=parse_on_off, default=True, metavar="on/off",
                   help="read focus, aperture, expTime, isoSpeed, nominalFocalLength, tStop, shutterAngle "
                        "and captureRate from each input's header (default: on)")


def _add_pipeline_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quality", choices=QUALITIES, default="final", help="speed/accuracy level")
    p.add_argument("--stages", type=_stage_list, default=None,
                   help="only these stages, comma separated (e.g. exposure)")
    # Also accepted after the subcommand (`clpost bench --device nvidia`); SUPPRESS keeps the
    # top-level value when it is not given here.
    p.add_argument("--device", default=argparse.SUPPRESS,
                   help="OpenCL device: substring of platform/device name or version (e.g. pocl, nvidia)")


# -- commands ---------------------------------------------------------------------------------

def cmd_demo(args) -> int:
    from .demo import DEMO_CAMERA_DEFAULTS, run_demo

    camera = camera_from_args(args, **DEMO_CAMERA_DEFAULTS)
    run_demo(Path(args.outdir), camera, size=args.size, n_frames=args.frames, quality=args.quality,
             stages=args.stages, device=args.device, camera_motion=not args.static_camera,
             overwrite=args.overwrite, log=print, reference_subframes=args.reference_subframes,
             display=display_from_args(args), lens_model=args.lens_model)
    return 0


def _jobs(args):
    from .batch import FrameJob
    from .outputs import check_input, check_paths
    from .sequence import expand, find_frames, has_pattern, parse_frames

    src, dst = args.input, args.output
    if has_pattern(src):
        if not has_pattern(dst):
            raise InputError(f"-o {dst!r}: the input is a sequence, so the output needs a frame "
                             "pattern too (e.g. out.####.exr)")
        frames = parse_frames(args.frames) if args.frames else find_frames(src)
        jobs = [FrameJob(f, Path(expand(src, f)), Path(expand(dst, f))) for f in frames]
    elif args.frames:
        raise InputError(f"--frames given but the input {src!r} has no frame pattern (####, %04d or @)")
    else:
        check_input(Path(src))
        jobs = [FrameJob(0, Path(src), Path(dst))]
    check_paths([(j.src, j.dst) for j in jobs], dst)
    if args.front is not None:
        _front_paths(args, jobs)
    if args.preview is not None:
        from .batch import preview_path

        if Path(args.preview).exists() and not Path(args.preview).is_dir():
            raise InputError(f"--preview {args.preview}: is a file; give a directory for the PNG previews")
        check_paths([(j.src, preview_path(j.dst, Path(args.preview))) for j in jobs], args.preview)
    return jobs


def _front_paths(args, jobs) -> None:
    """Each job's ``--front`` file (the pattern expanded with the job's frame number), checked
    before anything is read or written: it exists, it is neither an input nor an output, and its
    image has the input's size (headers only)."""
    from .outputs import path_keys
    from .sequence import expand, has_pattern

    pattern = args.front
    if has_pattern(pattern) and not has_pattern(args.input):
        raise InputError(f"--front {pattern}: has a frame pattern but the input {args.input} is one file; give "
                         "the front layer's file (or a pattern for both)")
    for j in jobs:
        j.front = Path(expand(pattern, j.frame)) if has_pattern(pattern) else Path(pattern)

    inputs = {k: j.src for j in jobs for k in path_keys(j.src)}
    outputs = {k: j.dst for j in jobs for k in path_keys(j.dst)}
    for j in sorted({j.front: j for j in jobs}.values(), key=lambda j: j.frame):
        name = f"--front {pattern}" + (f": {j.front}" if str(j.front) != pattern else "")
        for k in path_keys(j.front):
            if k in inputs:
                raise InputError(f"{name} is the input {inputs[k]}; --front names the "
                                 "foreground layer rendered apart, the input the background (e.g. --front fg.####.exr)")
            if k in outputs:
                raise InputError(f"{name} is the output {outputs[k]}; writing it would destroy "
                                 "the front layer — choose another -o")
        if j.front.is_dir():
            raise InputError(f"{name} is a directory; give the front layer's EXR file or "
                             "frame pattern (e.g. fg.####.exr)")
        if not j.front.is_file():
            which = f" (frame {j.frame}, input {j.src})" if has_pattern(args.input) else ""
            raise InputError(f"{name} does not exist{which}; render the front layer for every input frame"
                             + (", or narrow --frames" if which else ""))
        src_size, front_size = exr.display_size(j.src), exr.display_size(j.front)
        if front_size != src_size:
            raise InputError(f"{name} is {front_size[0]}x{front_size[1]} but the input {j.src} "
                             f"is {src_size[0]}x{src_size[1]}; render both layers at one resolution")


def _front_summary(front) -> str:
    """What ``--explain`` says of a front layer: its coverage and depth range."""
    import numpy as np

    cov = front[..., 3] > 0
    d = front[..., 4][cov & np.isfinite(front[..., 4])]
    depth = f"depth {d.min():.3g}-{d.max():.3g} m" if d.size else "no finite depth"
    return (f"premultiplied RGB, alpha, depth; covers {int(cov.sum())} of {cov.size} px, "
            f"{int((front[..., 3] >= 1).sum())} opaque; {depth}")


def cmd_process(args) -> int:
    from .batch import load_job, process_sequence
    from .pipeline import Pipeline

    if args.stages == [] and not args.explain:
        raise InputError("--stages names no stage, so every output would be its input unchanged; give "
                         "stages (e.g. --stages exposure,dof; --explain lists them) or leave --stages out")
    from .batch import frame_camera
    from .display_image import output_format

    output_format(args.output)  # an unknown extension is refused before anything is read
    display = display_from_args(args)
    if args.aovs and output_format(args.output) != "EXR":
        raise InputError(f"--aovs {','.join(args.aovs)}: the passes are written as EXR channels; name an .exr "
                         f"output (-o {Path(args.output).with_suffix('.exr')})")
    if args.view is not None:
        args.channels = exr.ReadSpec(args.channels, args.view)  # travels where a layout name does
    if not (args.camera_from or args.camera_track):
        camera_from_args(args)  # the flags' own errors first, as before (with these, lower sources may complete them)
    sources = camera_sources_from_args(args)
    jobs = _jobs(args)
    if not jobs:
        raise InputError(f"{args.input}: no input frames")
    camera = frame_camera(sources, jobs[0])
    from .raw_io import output_kind

    output_kind(camera, args.output)  # a raw mosaic named .jpg is refused before anything is read
    pipe = Pipeline(camera, quality=args.quality, stages=args.stages, device=args.device)
    if args.explain:
        _explain_sources(sources, jobs)
        first = load_job(pipe, jobs[0], args.channels)[1]
        cam = pipe.camera_for(first)
        win = first.windows
        print(f"plan for {jobs[0].src} ({first.width}x{first.height}, quality {args.quality}):")
        if first.front is not None:
            print(f"front layer: {jobs[0].front} ({_front_summary(first.front)})")
        if win.data != win.display or win.origin != (0, 0):
            print(f"windows: display {exr.window_str(win.display)}, data {exr.window_str(win.data)} "
                  f"(overscan left/top/right/bottom {'/'.join(map(str, win.overscan))} px)")
        for e in pipe.explain(first):
            print(f"  {e}")
        plan = pipe.plan_for(first, cam)
        print(f"kernels: {', '.join(plan.kernel_names) or '(none)'}")
        print(f"label channels (--labels {cam.labels}): {', '.join(first.labels) or '(none)'}"
              + (" — nearest through the geometry, never blended" if first.labels else ""))
        print(f"principal point: ({plan.principal_point[0]:.6g}, {plan.principal_point[1]:.6g}) px")
        print(cam.focus_summary(first.width))
        if plan.output_size != plan.size:
            print(f"output size: {plan.output_size[0]}x{plan.output_size[1]} (resampled by "
                  f"{', '.join(L.name for L in plan.launches if L.out_size != L.in_size)})")
        if "distortion" in plan.stage_names:
            from .stages.distortion import Distortion

            print(f"distortion fill: {Distortion(args.quality).coverage(cam, first)} (clpost render-size says how)")
        if cam != camera:
            print(f"auto-exposure: f/{cam.f_number:.3g}, {cam.shutter_s:.4g} s")
        from .ocio import OcioView

        if isinstance(display, OcioView):
            from .batch import input_chromaticities

            src = display.source_space(cam.working_space, input_chromaticities(display, jobs[0].src))
            how = "" if src.matrix is None else " via a matrix from the chromaticities"
            print(f"display-referred outputs: {display.label}; input colour space {src.name!r}{how} "
                  f"(from {src.source})")
        return 0
    if args.front is not None:
        _check_first_front(args, pipe, jobs, sources)
    from tqdm import tqdm

    # A bar on a terminal; in logs (no TTY) one line per frame instead of bar redraws.
    use_bar = not args.quiet and sys.stderr.isatty()
    bar = tqdm(total=len(jobs), unit="frame", disable=not use_bar, file=sys.stderr, leave=False)

    def progress(job, seconds):
        what = ("exists, skipped" if seconds is None else "FAILED" if seconds != seconds
                else f"{seconds * 1e3:.0f} ms")
        if use_bar:
            bar.set_postfix_str(f"frame {job.frame}: {what}")
            bar.update(1)
        elif not args.quiet:
            print(f"frame {job.frame}: {what} -> {job.dst}")

    from .outputs import writing

    try:
        # The lock is held for the whole run: each frame's "exists, skip" check is made under it.
        previews = [] if args.preview is None else [Path(args.preview) / f"{j.dst.stem}.png" for j in jobs]
        if args.camera_files:  # their stale temporary files are cleaned like the outputs'
            from .labels.camera_files import camera_paths

            previews += [p for j in jobs for p in camera_paths(j.dst).values()]
        with writing(args.output, [j.dst for j in jobs] + previews):
            if args.workers or args.scheduler:
                rep = _process_distributed(args, camera, jobs, progress, sources, display)
            else:
                rep = process_sequence(pipe, jobs, layout=args.channels, overwrite=args.overwrite,
                                       half=args.half, compression=args.compression, progress=progress,
                                       display=display,
                                       preview_dir=None if args.preview is None else Path(args.preview),
                                       sources=sources, aovs=tuple(args.aovs or ()),
                                       camera_files=args.camera_files)
    finally:
        bar.close()
    for frame, err in sorted(rep.failed.items()):
        print(f"clpost: frame {frame} failed: {_one_line(err)}", file=sys.stderr)
    if rep.seconds:
        ms = sorted(rep.seconds)[len(rep.seconds) // 2] * 1e3
        print(f"processed {len(rep.done)} frame(s), median {ms:.1f} ms/frame (read+process+write); "
              f"skipped {len(rep.skipped)} existing (use --overwrite)")
    elif not rep.failed:
        print(f"nothing to do: all {len(rep.skipped)} output frame(s) exist (use --overwrite)")
    if rep.failed:
        print(f"clpost: {len(rep.failed)} of {len(jobs)} frame(s) failed; the others are complete", file=sys.stderr)
        # Bad input frames are the user's to fix (exit 2, as the serial loop); anything else is 1.
        return 2 if set(rep.failed) <= set(rep.user_errors) else 1
    return 0


def _check_first_front(args, pipe, jobs, sources) -> None:
    """The first frame to write read with its front layer and planned, before anything is written:
    a front without alpha or depth, or a --stages that drops it, stops the run here (one line,
    whether the frames then run here or on Dask workers)."""
    from .batch import BatchReport, load_job, pending

    todo = pending(jobs, args.overwrite, BatchReport())
    if not todo:
        return
    cam, frame = load_job(pipe, todo[0], args.channels, None, sources)
    pipe.explain(frame, pipe.camera_for(frame, cam), reasons=False)
    if frame.front is not None and (frame.front[..., 3] >= 1).all():
        import warnings

        warnings.warn(f"--front {todo[0].front}: alpha is 1 everywhere, so no pixel of the input shows through; "
                      "render the front layer over a transparent film (Blender: Film > Transparent) with the "
                      "rest of the scene hidden from the camera")


def _explain_sources(sources, jobs) -> None:
    """The camera per parameter: its value (range over the frames) and which source set it."""
    from .batch import frame_resolved
    from .camera_sources import explain_sources

    resolved = [(job.frame, frame_resolved(sources, job)) for job in jobs]
    print(f"camera over {len(jobs)} frame(s) (value [source: flag / camera-from / track / EXR attribute / default]):")
    for line in explain_sources(resolved):
        print(f"  {line}")


def _process_distributed(args, camera, jobs, progress, sources=None, display="srgb"):
    from .distributed import PipelineSpec, connect, disconnect, first_size, process_sequence_dask

    spec = PipelineSpec(camera, args.quality, None if args.stages is None else tuple(args.stages), args.device,
                        display, args.preview, tuple(args.aovs or ()), args.camera_files)
    client = connect(args.scheduler, args.workers)
    try:
        return process_sequence_dask(client, spec, jobs, layout=args.channels, overwrite=args.overwrite,
                                     half=args.half, compression=args.compression, retries=args.retries,
                                     expect_size=first_size(jobs), progress=progress, sources=sources)
    finally:
        disconnect(client)
def cmd_expose(args) -> int:
    from .expose import as_time, capture_rate, frames_needed, parse_instant
    from .outputs import check_paths, writing
    from .sequence import expand, find_frames, has_pattern, parse_frames

    if not has_pattern(args.input):
        if Path(args.input).is_dir():
            raise InputError(f"{args.input}: is a directory; expose needs a frame sequence pattern such as "
                             f"{Path(args.input) / 'render.####.exr'}")
        raise InputError(f"{args.input!r}: expose needs a frame sequence pattern (in.####.exr, in.%04d.exr)")
    on_disk = find_frames(args.input)
    if not on_disk:
        raise InputError(f"{args.input}: no frames of this pattern exist; check the path and the #### padding")
    first = min(on_disk)  # the time origin: seconds count from the start of the first frame on disk
    fps = getattr(args, "cam_frame_rate_fps", None) or capture_rate(expand(args.input, first))
    if fps is None:
        raise InputError(f"{expand(args.input, first)} has no captureRate attribute, so the sequence's frame "
                         "rate is unknown; give it with --fps (e.g. --fps 24)")
    t_open = parse_instant(args.open, fps, first, "--open")
    shutter = getattr(args, "cam_shutter_s", None)
    if (args.close is None) == (shutter is None):
        raise InputError("give the end of the exposure with --close (a time or frame) or its length with "
                         "--shutter SECONDS, one of them")
    t_close = parse_instant(args.close, fps, first, "--close") if args.close is not None else t_open + as_time(
        shutter, "--shutter", "a time in seconds (e.g. 2 or 1/2)")
    if not t_close > t_open:
        raise InputError(f"--close {args.close or ''} ({float(t_close):g} s) must be later than --open {args.open} "
                         f"({float(t_open):g} s); times count from the start of frame {first}")
    from .display_image import output_format

    out = Path(args.output)
    output_format(out)  # an unknown extension is refused before anything is read
    args.display = display_from_args(args)
    if args.png and output_format(args.png, "--png") == "EXR":
        raise InputError(f"--png {args.png}: a preview is display-encoded; name a .png (or .jpg/.tif) file")
    found = parse_frames(args.frames) if args.frames else on_disk
    want = set(frames_needed(fps, t_open, t_close, first))
    frames = [n for n in found if n in want]
    sources = [Path(expand(args.input, n)) for n in (frames or found)]
    check_paths([(src, out) for src in sources], args.output)
    if args.png:
        check_paths([(src, Path(args.png)) for src in sources], args.png)
    if out.exists() and not args.overwrite:
        raise InputError(f"{out} exists; choose another -o or pass --overwrite")
    plain = args.average or args.sum
    if plain and args.motion_blur:
        raise InputError("--motion-blur acts through the camera; leave out --average/--sum")
    camera = None if plain else _expose_camera(args)
    with writing(out, [out] + ([Path(args.png)] if args.png else [])):
        return _expose(args, out, frames, found, fps, first, t_open, t_close, camera)


def _expose_camera(args) -> Camera:
    """The camera options of an exposure: those of ``process`` less the shutter (the open
    interval) and the frame rate (the sequence's)."""
    given = {k[4:]: v for k, v in vars(args).items() if k.startswith("cam_")}
    for key, flag in (("shutter_angle_deg", "--shutter-angle"), ("readout_time_s", "--readout")):
        if key in given:
            raise InputError(f"{flag} does not apply to a long exposure: its shutter is open from --open to "
                             "--close; leave it out")
    given.pop("frame_rate_fps", None)
    given.pop("shutter_s", None)
    return Camera.from_options(given)


def _expose(args, out, frames, found, fps, first, t_open, t_close, camera) -> int:
    from . import exr
    from .batch import output_header, read_input, write_output
    from .display_image import write_image
    from .expose import expose, expose_camera_frames
    from .pipeline import Pipeline
    from .sequence import expand

    def progress(n, w):
        if not args.quiet:
            print(f"frame {n}: {float(w):.6g} s of the exposure")

    header = {"clpost.expose.open": str(args.open),
              "clpost.expose.close": str(args.close) if args.close is not None else f"{float(t_close):.9g}",
              "clpost.expose.open_s": f"{float(t_open):.9g}", "clpost.expose.close_s": f"{float(t_close):.9g}",
              "clpost.expose.firstFrame": str(first), "clpost.expose.fps": f"{float(fps):.9g}",
              "clpost.expose.seconds": f"{float(t_close - t_open):.9g}"}
    if camera is not None:
        reader = Pipeline(camera)  # radial depth → planar with the camera's focal length

        def read(n):
            return read_input(reader, Path(expand(args.input, n)), args.channels)

        if args.workers or args.scheduler:
            ex = _expose_camera_dask(args, read, frames or found, fps, first, t_open, t_close, camera)
        else:
            ex = expose_camera_frames(read, frames or found, fps, t_open, t_close, camera, first=first,
                                      quality=args.quality, stages=args.stages, device=args.device,
                                      progress=progress, motion_blur=args.motion_blur)
        result, count = ex.frame, len(ex.weights)
        header.update(output_header(result))
        header.update({"clpost.expose.frames": str(count), "clpost.expose.output": "camera",
                       "clpost.expose.perFrame": ",".join(ex.per_frame), "clpost.expose.once": ",".join(ex.once)})
    else:
        def read(n):
            return exr.read_frame(expand(args.input, n), args.channels)

        if args.workers or args.scheduler:
            from .distributed import connect, disconnect, expose_dask

            client = connect(args.scheduler, args.workers)
            try:
                part = expose_dask(client, args.input, frames or found, fps, t_open, t_close,
                                   layout=args.channels, device=args.device, first=first)
            finally:
                disconnect(client)
        else:
            part = expose(read, frames or found, fps, t_open, t_close, device=args.device,
                          progress=progress, first=first)
        from .frame import Frame

        result, count = Frame(part.exposure() if args.sum else part.mean()), part.count
        header.update({"clpost.expose.frames": str(count),
                       "clpost.expose.output": "exposure (input x seconds)" if args.sum else "time average (input units)"})
    ws = camera.working_space if camera is not None else "rec709"
    from .batch import input_chromaticities

    chroma = input_chromaticities(args.display, Path(expand(args.input, (frames or found)[0])))
    write_output(out, result, header, display=args.display, working_space=ws, chroma=chroma, camera=camera)
    if args.png:
        write_image(args.png, result.color * (args.png_gain or 1.0), display=args.display, working_space=ws,
                    option="--png", chroma=chroma)
    print(f"exposed {count} frame(s) for {float(t_close - t_open):.6g} s -> {out}")
    return 0


def _expose_camera_dask(args, read, frames, fps, first, t_open, t_close, camera):
    """The exposure through the camera with its per-frame optics on Dask workers (chunks reduced
    in a tree), then the once-stages here."""
    from .distributed import connect, disconnect, expose_dask
    from .expose import Exposed, exposure_plan, finish, prepare

    weights = exposure_plan(frames, fps, t_open, t_close, first)
    if not weights:
        raise InputError("no frame lies inside the shutter interval")
    seconds = t_close - t_open
    frame0 = read(weights[0][0])
    setup = prepare(frame0, camera, seconds, fps, quality=args.quality, stages=args.stages, device=args.device,
                    motion_blur=args.motion_blur)
    client = connect(args.scheduler, args.workers)
    try:
        part = expose_dask(client, args.input, frames, fps, t_open, t_close, layout=args.channels,
                           device=args.device, first=first, setup=setup)
    finally:
        disconnect(client)
    result = finish(part, setup, weights[0][0], frame0.metadata)
    return Exposed(result, setup.camera, seconds, weights, list(setup.per_frame), list(setup.once))


def cmd_info(args) -> int:
    from . import exr

    for path in args.files:
        d = exr.info(path)
        if args.json:
            print(json.dumps(d, default=str))
        else:
            print(exr.format_info(d))
    return 0


def cmd_bench(args) -> int:
    from .bench import DEFAULT_SIZES, SCENES, format_markdown, format_table, run, update_markdown
    from .demo import DEMO_CAMERA_DEFAULTS

    if getattr(args, "dof", False):
        from .dof_bench import DOF_BENCH_SIZES, format_dof_table, run_dof_bench
        from .runtime import get_runtime

        sizes = args.sizes or list(DOF_BENCH_SIZES)
        rows, conv = run_dof_bench(sizes=sizes, samples=args.dof_samples[:len(sizes)], repeats=args.repeats,
                                   device=args.device)
        print(format_dof_table(rows, conv, get_runtime(args.device).name))
        return 0

    scenes = args.scenes.split(",") if args.scenes else ["demo", "worst", "no_defocus", "full"]
    unknown = [s for s in scenes if s not in SCENES]
    if unknown:
        raise InputError(f"--scenes: unknown scene(s) {', '.join(unknown)}; known: {', '.join(SCENES)}")
    qualities = args.qualities.split(",") if args.qualities else [args.quality]
    if args.against:
        from .bench_ab import compare, format_rows

        rows = compare(args.against, scenes, args.sizes or list(DEFAULT_SIZES), qualities, device=args.device,
                       repeats=args.repeats, warmup=args.warmup, log=lambda m: print(m, file=sys.stderr))
        print(json.dumps(rows, indent=2) if args.json else format_rows(rows, args.against))
        return 0
    # the demo scene uses the demo camera with the command line's camera options on top
    base = camera_from_args(args, **DEMO_CAMERA_DEFAULTS)
    doc = run(scenes, args.sizes or list(DEFAULT_SIZES), qualities, device=args.device,
              repeats=args.repeats, warmup=args.warmup, numpy_max_pixels=args.numpy_max_pixels,
              base_camera=base, cache_dir=args.cache, log=lambda m: print(m, file=sys.stderr))
    if args.markdown:
        cmd = "clpost bench " + " ".join(a for a in sys.argv[2:] if a) if len(sys.argv) > 2 else "clpost bench"
        update_markdown(args.markdown, format_markdown(doc, cmd))
    print(json.dumps(doc, indent=2) if args.json else format_table(doc))
    return 0


def cmd_render_size(args) -> int:
    from .calibration import lens_distortion_model
    from .render_size import report

    cam = camera_from_args(args)
    if cam.distortion is not None:
        if args.size is not None:
            raise InputError("render-size: --size is the calibration's own with --calibration; leave --size out")
        model, what = cam.distortion, f"calibration {cam.distortion.source or ''}".strip()
    else:
        if cam.optics is None:
            raise InputError("render-size: give --calibration FILE, or --lens NAME (a lens_data lens: "
                             "`clpost lens list`) with --size WxH")
        if args.size is None:
            raise InputError("render-size: --lens needs the image size, --size WxH (e.g. --size 1920x1080)")
        model = lens_distortion_model(cam, args.size)
        what = f"{cam.lens} at {args.size[0]}x{args.size[1]}, focus {cam.focus_distance_m:g} m"
        if model is None:
            print(f"{what}: no distortion to 0.001 %: render at {args.size[0]}x{args.size[1]}, no overscan needed")
            return 0
    print(report(model, what, cam.sensor_mm[0] if cam.distortion is None else None))
    return 0


def cmd_stages(args) -> int:
    from .stages import order_table

    print(order_table())
    return 0


def _lens_focus_scale_m(args) -> float:
    """`clpost lens`'s focus as the lens-scale distance (m from the film) its reports take: --focus
    is a depth from the entrance pupil, as everywhere (docs/conventions.md "Focus")."""
    if args.focus is not None and args.focus_scale is not None:
        raise InputError("--focus (depth from the entrance pupil) and --focus-scale (distance from the film plane) "
                         "set the same focus; give one of them")
    cam = Camera(lens=args.name, f_number=getattr(args, "f_number", None), shutter_s=1 / 50,
                 **({"focus_scale_m": args.focus_scale} if args.focus_scale is not None
                    else {"focus_distance_m": math.inf if args.focus is None else args.focus}))
    return cam.focus_from_film_m


def cmd_lens(args) -> int:
    # Real lenses: list / info / plot of lens_data prescriptions.
    from .optics import available_lenses, get_lens
    from .optics.report import format_info, lens_info, plot_lens

    if args.lens_command == "list":
        for name in available_lenses():
            lens = get_lens(name)
            print(f"{name:24s} EFL {lens.efl_mm:7.2f} mm  f/{lens.max_aperture:.3g}  {lens.prescription.description}")
        return 0
    scale = _lens_focus_scale_m(args)
    if args.lens_command == "info":
        d = lens_info(args.name, sensor_mm=args.sensor, focus_distance_m=scale, f_number=args.f_number)
        print(json.dumps(d, indent=2, default=str) if args.json else format_info(d))
        return 0
    plot_lens(args.name, args.output, sensor_mm=args.sensor, focus_distance_m=scale)
    print(f"wrote {args.output}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    from .demo import DEMO_CAMERA_DEFAULTS  # the demo and bench cameras' defaults, shown in their --help

    p = _Parser(prog="clpost", description="A realistic camera for rendered images.")
    p.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    p.add_argument("--device", default=None,
                   help="OpenCL device: substring of platform/device name (default: $CLPOST_DEVICE, else GPU, else PoCL CPU)")
    sub = p.add_subparsers(dest="command", required=True)

    d = sub.add_parser("demo", help="render the built-in scene and process it (EXR + PNG previews)")
    d.add_argument("outdir", help="output directory")
    d.add_argument("--frames", type=_count("--frames", 1), default=3, help="number of frames (default 3)")
    d.add_argument("--size", type=_size, default=None, help="WIDTHxHEIGHT (default 960 wide, sensor aspect)")
    d.add_argument("--static-camera", action="store_true", help="no camera motion")
    d.add_argument("--overwrite", action="store_true", help="replace existing outputs")
    d.add_argument("--reference-subframes", type=int, default=0, metavar="K",
                   help="also render a reference motion-blurred frame from K sub-frames per frame "
                        "(needs --fps and --shutter or --shutter-angle)")
    _add_display_option(d, "preview PNG encoding")
    d.add_argument("--lens-model", choices=("post", "geometry-distortion", "image-based"), default="post",
                   help="post: lens effects as post-process stages (default); geometry-distortion: the "
                        "--calibration's distortion applied to the vertices before rasterisation "
                        "(Lambers et al. 3.2; docs/geometry_distortion.md); image-based: the --lens "
                        "prescription as perspective projections per pupil sample (Heidrich et al.; "
                        "docs/image_based_lens.md)")
    _add_camera_options(d, defaults=DEMO_CAMERA_DEFAULTS)
    _add_pipeline_options(d)
    d.set_defaults(func=cmd_demo)

    pr = sub.add_parser("process", help="process an EXR sequence")
    pr.add_argument("input", help="input EXR or pattern (in.####.exr, in.%%04d.exr, in.@@@@.exr)")
    pr.add_argument("-o", "--output", required=True,
                    help="output or pattern: .exr (linear, the camera in its header), or a viewable "
                         ".png/.jpg/.tif (display-encoded for --display, ICC profile embedded)")
    pr.add_argument("--front", default=None, metavar="FG_INPUT",
                    help="a foreground rendered as its own layer: EXR or pattern like the input's (each frame's "
                         "own number), with alpha and depth (any layout --channels reads); its colour is taken as "
                         "premultiplied (the EXR convention). Defocused by its own depth and composited over the "
                         "input (stage front_layer, after dof); docs/conventions.md \"Front layer\"")
    pr.add_argument("--preview", default=None, metavar="DIR",
                    help="also write a display-encoded PNG of each frame into DIR (<output stem>.png)")
    _add_display_option(pr, "encoding of .png/.jpg/.tif outputs and previews")
    pr.add_argument("--frames", type=_frames_spec, default=None,
                    help="frame range, e.g. 1-100, 1-100x2, 1,5,9 (default: all found)")
    pr.add_argument("--channels", default=None, help="input channel layout: clpost, blender, nuke, arnold (default: detect)")
    pr.add_argument("--view", default=None,
                    help="view of multi-view EXRs, e.g. left (default: the file's default view, the first it lists)")
    pr.add_argument("--explain", action="store_true", help="print the plan for the first frame and why each stage is in or out, then exit")
    pr.add_argument("--overwrite", action="store_true", help="replace existing outputs (default: skip them)")
    pr.add_argument("--half", action="store_true", help="write half-float EXRs")
    pr.add_argument("--aovs", type=_aovs, default=None, metavar="coc,focus,blur",
                    help="also write diagnostic passes as EXR channels: coc.Y (signed CoC diameter px, near < 0), "
                         "focus.A (depth-of-field matte), blur.Y (motion-blur length px); docs/conventions.md")
    pr.add_argument("--camera-files", action="store_true",
                    help="also write each output's effective camera beside it: <stem>.camera.yaml (OpenCV "
                         "FileStorage), <stem>.kalibr.yaml, <stem>.cameras.txt (always in an .exr's header: "
                         "clpost.camera.opencv/kalibr/colmap)")
    pr.add_argument("--compression", default="zip", choices=list(COMPRESSIONS),
                    help="lossless EXR compression of outputs (default zip; none writes fastest, largest files)")
    pr.add_argument("--quiet", action="store_true", help="no progress bar")
    dist = pr.add_argument_group("distributed (Dask)")
    dist.add_argument("--workers", type=_count("--workers", 1), default=None,
                      help="run on a local Dask cluster of N worker processes")
    dist.add_argument("--scheduler", default=None, help="run on an existing Dask cluster, e.g. tcp://HOST:8786")
    dist.add_argument("--retries", type=_count("--retries", 0), default=2, help="retries of a failing frame before it is reported (default 2)")
    _add_camera_options(pr)
    _add_source_options(pr)
    _add_pipeline_options(pr)
    pr.set_defaults(func=cmd_process)

    e = sub.add_parser(
        "expose", help="long exposure through the camera: the sequence integrated over the open shutter",
        description="One photograph of a sequence with the shutter open from --open to --close. Frame n "
                    "stands for the scene during [(n - first)/fps, (n - first + 1)/fps) seconds, where first is "
                    "the sequence's first frame on disk (box filter: a frame cut by the shutter counts for the "
                    "part it overlaps). Times are seconds from the start of the first frame (0.5, 1/48) or "
                    "frame numbers as timeline positions: f1001 (or 1001f) is the start of frame 1001, f1001.5 "
                    "its middle; --open f1001 --close f1025 exposes frames 1001-1024. The camera options are "
                    "process's: the optics (dof, aberrations, distortion, vignetting, the exposure gain) run on "
                    "each frame, film/sensor/grain/print once on the summed exposure, so a static scene gives the "
                    "frame processed with --shutter close-open. Alpha is the time-averaged coverage, depth the "
                    "nearest depth seen.")
    e.add_argument("input", help="input EXR pattern (in.####.exr, in.%%04d.exr)")
    e.add_argument("-o", "--output", required=True,
                   help="output: .exr (linear, the camera in the header) or .png/.jpg/.tif (display-encoded "
                        "for --display, ICC profile embedded); written atomically")
    e.add_argument("--open", required=True, help="the shutter opens: seconds (0.5, 1/48) or a frame (f1001, 1001f)")
    e.add_argument("--close", default=None,
                   help="the shutter closes: seconds or a frame (f1025 = the end of frame 1024); or give --shutter")
    e.add_argument("--frames", type=_frames_spec, default=None, help="frame range to consider (default: all found)")
    e.add_argument("--channels", default=None, help="input channel layout (default: detect)")
    e.add_argument("--motion-blur", action="store_true",
                   help="blur each frame along its velocity pass over the part of its interval the shutter "
                        "sees: continuous trails instead of one copy per frame (needs velocity)")
    e.add_argument("--average", action="store_true",
                   help="no camera: write the time-averaged input (input units)")
    e.add_argument("--sum", action="store_true", help="no camera: write H = ∫E dt (input × seconds)")
    e.add_argument("--png", default=None, help="also write a display-encoded preview (.png/.jpg/.tif) here")
    _add_display_option(e, "encoding of image outputs and --png")
    e.add_argument("--png-gain", type=_positive_float, default=None, help="scale before the PNG encoding")
    e.add_argument("--overwrite", action="store_true", help="replace an existing output")
    e.add_argument("--quiet", action="store_true")
    e.add_argument("--workers", type=_count("--workers", 1), default=None,
                   help="run the frames on a local Dask cluster of N worker processes (a tree reduction)")
    e.add_argument("--scheduler", default=None,
                   help="run the frames on an existing Dask cluster, e.g. tcp://HOST:8786")
    _add_camera_options(e)
    _set_help(e, "cam_frame_rate_fps", "frame rate of the sequence (24, 24000/1001); default: the first "
                                       "frame's EXR captureRate attribute")
    _set_help(e, "cam_shutter_s", "the exposure's length in seconds, instead of --close")
    for dest in ("cam_shutter_angle_deg", "cam_readout_time_s"):
        _set_help(e, dest, "not for a long exposure (its shutter is --open to --close)")
    _add_pipeline_options(e)
    e.set_defaults(func=cmd_expose)

    i = sub.add_parser("info", help="channels, size, depth and velocity ranges of EXR files")
    i.add_argument("files", nargs="+")
    i.add_argument("--json", action="store_true")
    i.set_defaults(func=cmd_info)

    b = sub.add_parser("bench", help="per-resolution benchmark of a plan (OpenCL events, median)")
    b.add_argument("--sizes", type=lambda s: [_size(x) for x in s.split(",")], default=None,
                   help="comma-separated WxH (default 640x360,1280x720,1920x1080,3840x2160)")
    b.add_argument("--repeats", type=int, default=10)
    b.add_argument("--json", action="store_true")
    b.add_argument("--dof", action="store_true",
                   help="dof speed/accuracy per quality against the thin-lens accumulation reference (demo scene)")
    b.add_argument("--dof-samples", type=lambda s: [int(x) for x in s.split(",")], default=[128, 64],
                   help="reference aperture samples per size for --dof (default 128,64)")
    # scenes, quality levels, baselines, docs/benchmarks.md
    b.add_argument("--scenes", default=None,
                   help="comma-separated: demo, worst, no_defocus, full (default: all)")
    b.add_argument("--qualities", default=None, help="comma-separated quality levels (default: --quality)")
    b.add_argument("--warmup", type=int, default=2, help="runs before timing (default 2)")
    b.add_argument("--numpy-max-pixels", type=int, default=1280 * 720,
                   help="time the numpy reference only up to this many pixels (default 921600)")
    b.add_argument("--cache", default=None, help="where the rendered demo frames are cached (EXR)")
    b.add_argument("--markdown", default=None,
                   help="also regenerate the generated section of this file (docs/benchmarks.md)")
    b.add_argument("--against", default=None, metavar="REV",
                   help="also run git revision REV of clpost in this process, interleaved, and print "
                        "per-kernel ms of both and new/old (run from a clpost checkout)")
    _add_camera_options(b, defaults=DEMO_CAMERA_DEFAULTS)
    _add_pipeline_options(b)
    b.set_defaults(func=cmd_bench)

    sub.add_parser("stages", help="every stage in physical order: order, domains, why it sits there"
                   ).set_defaults(func=cmd_stages)

    rs = sub.add_parser("render-size", help="the overscan (EXR data window) or larger render a calibration or "
                        "lens needs so distortion leaves no pixel unfilled")
    rs.add_argument("--size", type=_size, default=None,
                    help="image size WxH for --lens (a calibration has its own)")
    _add_camera_options(rs)
    rs.set_defaults(func=cmd_render_size)

    ln = sub.add_parser("lens", help="real lens prescriptions in lens_data/: list, info, datasheet plot")
    lsub = ln.add_subparsers(dest="lens_command", required=True)
    lsub.add_parser("list", help="the lenses in lens_data/").set_defaults(func=cmd_lens)
    for cmd, help_ in (("info", "EFL, BFL, pupils, f-numbers, FOV, corner distortion and illumination"),
                       ("plot", "datasheet-style plots (needs the 'plot' extra: matplotlib)")):
        q = lsub.add_parser(cmd, help=help_)
        q.add_argument("name", help="lens name (see `clpost lens list`)")
        q.add_argument("--sensor", type=_sensor, default=(36.0, 24.0), help="sensor WxH in mm (default 36x24)")
        q.add_argument("--focus", type=_positive_float, default=None,
                       help="depth in metres that is sharp, from the entrance pupil (the depth pass's camera "
                            "centre; default inf)")
        q.add_argument("--focus-scale", type=_positive_float, default=None,
                       help="focus by the lens's distance scale instead: metres from the film plane (not with --focus)")
        if cmd == "info":
            q.add_argument("--f-number", type=_positive_float, default=None, help="f-number (default: wide open)")
            q.add_argument("--json", action="store_true")
        else:
            q.add_argument("-o", "--output", required=True, help="output PNG")
        q.set_defaults(func=cmd_lens)

    from .calibration.command import add_parser as add_calibration_parser
    from .stmap import add_parser as add_stmap_parser

    from .view.command import VIEW_CAMERA_DEFAULTS
    from .view.command import add_parser as add_view_parser

    add_stmap_parser(sub, _size, camera_options())
    add_view_parser(sub, _size, camera_options(defaults=VIEW_CAMERA_DEFAULTS))
    add_calibration_parser(sub, _size, camera_options())
    from .labels.command import add_parser as add_labels_parser

    add_labels_parser(sub, _size, camera_options())
    return p


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings as one line each, ``clpost: warning: …`` — never a source path (``--debug`` keeps
    Python's own format)."""
    print(f"clpost: warning: {_one_line(str(message))}", file=file or sys.stderr)


def main(argv: list[str] | None = None) -> int:
    import warnings

    parser = build_parser()
    args = parser.parse_args(argv)
    shown = warnings.showwarning
    if not args.debug:
        warnings.showwarning = _show_warning
    try:
        return _run(args)
    finally:
        warnings.showwarning = shown


def _run(args) -> int:
    from .atomic import Terminated, signal_cleanup

    try:
        # SIGTERM removes the temporary file being written and unwinds (releasing the output lock).
        with signal_cleanup():
            return args.func(args)
    except BrokenPipeError:
        # the reader went away (`clpost stages | head`): nothing to report; keep Python's final
        # flush of stdout from raising again
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except (ClpostError, ValueError, OSError) as exc:
        if args.debug:
            raise
        msg = str(exc) if isinstance(exc, ClpostError) else f"{type(exc).__name__}: {exc}"
        print(f"clpost: error: {_one_line(msg)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("clpost: interrupted; complete outputs are kept, rerun to resume", file=sys.stderr)
        return 130
    except Terminated:
        print("clpost: terminated; complete outputs are kept, rerun to resume", file=sys.stderr)
        return 143
    except MemoryError:
        if args.debug:
            raise
        print("clpost: error: out of memory; process smaller frames or free memory", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

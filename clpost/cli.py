"""The ``clpost`` command line. It holds no image logic: parse → Camera/Frame → plan → run → write.

User errors print one line (``clpost: error: …``) and exit with status 2; ``--debug`` shows the
traceback instead.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .camera import METERING_MODES, Camera
from .exr import COMPRESSIONS
from .errors import ClpostError, InputError
from .stages import QUALITIES


def _positive_float(text: str) -> float:
    """A number, a fraction like ``1/50``, or ``inf``."""
    try:
        if "/" in text:
            num, den = text.split("/", 1)
            return float(num) / float(den)
        return float(text)
    except (ValueError, ZeroDivisionError):
        raise argparse.ArgumentTypeError(f"{text!r} is not a number (e.g. 2.8, 1/50, inf)") from None


def _auto_or_float(text: str):
    return None if text.lower() == "auto" else _positive_float(text)


def _sensor(text: str) -> tuple[float, float]:
    try:
        w, h = text.lower().split("x")
        return float(w), float(h)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not WxH in mm (e.g. 36x24)") from None


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = text.lower().split("x")
        w, h = int(w), int(h)
        if w < 1 or h < 1:
            raise ValueError
        return w, h
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not WIDTHxHEIGHT in pixels (e.g. 1280x720)") from None


CAMERA_OPTIONS = {
    # flag: (Camera field, type, help)
    "--lens": ("lens", str, "lens name: thin:<focal mm> (e.g. thin:50)"),
    "--f-number": ("f_number", _auto_or_float, "f-number N, or 'auto' (shutter priority)"),
    "--focus": ("focus_distance_m", _positive_float, "focus distance in metres ('inf' for infinity)"),
    "--shutter": ("shutter_s", _auto_or_float, "shutter time in seconds (1/50 works), or 'auto' (aperture priority)"),
    "--iso": ("iso", _positive_float, "ISO 12232 saturation-based speed"),
    "--transmittance": ("transmittance", _positive_float, "lens transmittance T in (0, 1]"),
    "--sensor": ("sensor_mm", _sensor, "sensor WxH in mm (e.g. 36x24)"),
    "--luminance-scale": ("luminance_scale", _positive_float, "cd/m² of input luminance Y = 1"),
    "--blades": ("blades", int, "aperture blades (0 = round)"),
    "--blade-rotation": ("blade_rotation_deg", _positive_float, "aperture blade rotation in degrees"),
    "--metering": ("metering", str, f"metering pattern for auto-exposure: {', '.join(METERING_MODES)}"),
    "--ev": ("exposure_compensation_ev", _positive_float, "exposure compensation in EV (+1 = one stop brighter)"),
    # dof stage
    "--depth-of-field": ("depth_of_field", lambda t: t.lower() in ("1", "on", "true", "yes"),
                         "thin-lens defocus from the depth buffer: on/off (default off: pinhole)"),
    "--roundness": ("aperture_roundness", float, "aperture blade roundness 0 (polygon) … 1 (circle)"),
    "--spherical-aberration": ("spherical_aberration", float, "bokeh texture -1 … 1 (> 0: undercorrected)"),
    "--cats-eye": ("optical_vignetting", float, "optical vignetting (cat's-eye bokeh) strength 0 … 1"),
}


def _add_camera_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("camera (defaults: clpost.Camera's)")
    for flag, (dest, typ, help_) in CAMERA_OPTIONS.items():
        g.add_argument(flag, dest=f"cam_{dest}", type=typ, default=argparse.SUPPRESS, help=help_)


def camera_from_args(args: argparse.Namespace, **defaults) -> Camera:
    """Camera from the options given; ``defaults`` overrides Camera's own defaults (demo)."""
    kw = dict(defaults)
    kw.update({k[4:]: v for k, v in vars(args).items() if k.startswith("cam_")})
    return Camera(**kw)


def _add_pipeline_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quality", choices=QUALITIES, default="final", help="speed/accuracy level")
    p.add_argument("--stages", type=lambda s: [x.strip() for x in s.split(",") if x.strip()],
                   default=None, help="only these stages, comma separated (e.g. exposure)")


# -- commands ---------------------------------------------------------------------------------

def cmd_demo(args) -> int:
    from .demo import DEMO_CAMERA_DEFAULTS, run_demo

    camera = camera_from_args(args, **DEMO_CAMERA_DEFAULTS)
    run_demo(Path(args.outdir), camera, size=args.size, n_frames=args.frames, quality=args.quality,
             stages=args.stages, device=args.device, camera_motion=not args.static_camera,
             overwrite=args.overwrite, log=print)
    return 0


def _jobs(args):
    from .batch import FrameJob
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
        jobs = [FrameJob(0, Path(src), Path(dst))]
    for j in jobs:
        if not j.src.is_file():
            raise InputError(f"{j.src}: input frame does not exist; check the path, pattern and --frames")
    return jobs


def cmd_process(args) -> int:
    from .batch import process_sequence, read_input
    from .pipeline import Pipeline

    camera = camera_from_args(args)
    pipe = Pipeline(camera, quality=args.quality, stages=args.stages, device=args.device)
    jobs = _jobs(args)
    if not jobs:
        raise InputError(f"{args.input}: no input frames")
    if args.explain:
        first = read_input(pipe, jobs[0].src, args.channels)
        cam = pipe.camera_for(first)
        print(f"plan for {jobs[0].src} ({first.width}x{first.height}, quality {args.quality}):")
        for e in pipe.explain(first):
            print(f"  {e}")
        print(f"kernels: {', '.join(pipe.kernels(first)) or '(none)'}")
        if cam != camera:
            print(f"auto-exposure: f/{cam.f_number:.3g}, {cam.shutter_s:.4g} s")
        return 0
    from tqdm import tqdm

    # A bar on a terminal; in logs (no TTY) one line per frame instead of bar redraws.
    use_bar = not args.quiet and sys.stderr.isatty()
    bar = tqdm(total=len(jobs), unit="frame", disable=not use_bar, file=sys.stderr, leave=False)

    def progress(job, seconds):
        what = "exists, skipped" if seconds is None else f"{seconds * 1e3:.0f} ms"
        if use_bar:
            bar.set_postfix_str(f"frame {job.frame}: {what}")
            bar.update(1)
        elif not args.quiet:
            print(f"frame {job.frame}: {what} -> {job.dst}")

    try:
        rep = process_sequence(pipe, jobs, layout=args.channels, overwrite=args.overwrite,
                               half=args.half, compression=args.compression, progress=progress)
    finally:
        bar.close()
    if rep.seconds:
        ms = sorted(rep.seconds)[len(rep.seconds) // 2] * 1e3
        print(f"processed {len(rep.done)} frame(s), median {ms:.1f} ms/frame (read+process+write); "
              f"skipped {len(rep.skipped)} existing (use --overwrite)")
    else:
        print(f"nothing to do: all {len(rep.skipped)} output frame(s) exist (use --overwrite)")
    return 0


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
    from .bench import DEFAULT_SIZES, bench_size, format_table

    if getattr(args, "dof", False):
        from .dof_bench import DOF_BENCH_SIZES, format_dof_table, run_dof_bench
        from .runtime import get_runtime

        sizes = args.sizes or list(DOF_BENCH_SIZES)
        rows, conv = run_dof_bench(sizes=sizes, samples=args.dof_samples[:len(sizes)], repeats=args.repeats,
                                   device=args.device)
        print(format_dof_table(rows, conv, get_runtime(args.device).name))
        return 0

    camera = camera_from_args(args)
    sizes = args.sizes or list(DEFAULT_SIZES)
    rows = [bench_size(camera, w, h, quality=args.quality, stages=args.stages, device=args.device,
                       repeats=args.repeats) for w, h in sizes]
    from .runtime import get_runtime

    name = get_runtime(args.device).name
    if args.json:
        print(json.dumps({"device": name, "rows": [r.as_dict() for r in rows]}, indent=2))
    else:
        print(format_table(rows, name))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="clpost", description="A realistic camera for rendered images.")
    p.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    p.add_argument("--device", default=None,
                   help="OpenCL device: substring of platform/device name (default: $CLPOST_DEVICE, else GPU, else PoCL CPU)")
    sub = p.add_subparsers(dest="command", required=True)

    d = sub.add_parser("demo", help="render the built-in scene and process it (EXR + PNG previews)")
    d.add_argument("outdir", help="output directory")
    d.add_argument("--frames", type=int, default=3, help="number of frames (default 3)")
    d.add_argument("--size", type=_size, default=None, help="WIDTHxHEIGHT (default 960 wide, sensor aspect)")
    d.add_argument("--static-camera", action="store_true", help="no camera motion")
    d.add_argument("--overwrite", action="store_true", help="replace existing outputs")
    _add_camera_options(d)
    _add_pipeline_options(d)
    d.set_defaults(func=cmd_demo)

    pr = sub.add_parser("process", help="process an EXR sequence")
    pr.add_argument("input", help="input EXR or pattern (in.####.exr, in.%%04d.exr, in.@@@@.exr)")
    pr.add_argument("-o", "--output", required=True, help="output EXR or pattern")
    pr.add_argument("--frames", default=None, help="frame range, e.g. 1-100, 1-100x2, 1,5,9 (default: all found)")
    pr.add_argument("--channels", default=None, help="input channel layout: clpost, blender, nuke, arnold (default: detect)")
    pr.add_argument("--explain", action="store_true", help="print the plan for the first frame and why each stage is in or out, then exit")
    pr.add_argument("--overwrite", action="store_true", help="replace existing outputs (default: skip them)")
    pr.add_argument("--half", action="store_true", help="write half-float EXRs")
    pr.add_argument("--compression", default="zip", choices=list(COMPRESSIONS),
                    help="lossless EXR compression of outputs (default zip; none is ~10x faster to write)")
    pr.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_camera_options(pr)
    _add_pipeline_options(pr)
    pr.set_defaults(func=cmd_process)

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
    _add_camera_options(b)
    _add_pipeline_options(b)
    b.set_defaults(func=cmd_bench)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (ClpostError, ValueError, OSError) as exc:
        if args.debug:
            raise
        msg = str(exc) if isinstance(exc, ClpostError) else f"{type(exc).__name__}: {exc}"
        print(f"clpost: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("clpost: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

"""``clpost calibration``: show a camera's distortion model, or write it in another format.

``clpost calibration convert IN -o OUT [--format F]`` reads any format
:func:`~clpost.calibration.load_calibration` reads — or the effective camera recorded in an
output EXR's header (``clpost.distortion``), or a ``--lens``'s traced distortion — and writes it
with :func:`~clpost.calibration.write_calibration` (format from ``--format`` or OUT's extension).
``clpost calibration show IN`` prints the model's named fields, its fold radius and the render
size that covers it.
"""
from __future__ import annotations

import math
from pathlib import Path

from ..errors import InputError
from .model import OpenCVModel


def model_from_source(args) -> OpenCVModel:
    """IN (a calibration file or a clpost output EXR) or the --calibration/--lens options."""
    from ..stmap import model_from_args

    src = getattr(args, "input", None)
    if src is None:
        return model_from_args(args, getattr(args, "size", None))
    if any(k in vars(args) for k in ("cam_distortion", "cam_lens")):
        raise InputError(f"clpost calibration: give IN ({src}) or --calibration/--lens, not both")
    if src.lower().endswith(".exr"):
        from .. import exr
        from .header import model_from_header

        if not Path(src).is_file():
            raise InputError(f"{src}: no such file")
        _, strings = exr.read_attributes(src)
        text = strings.get("clpost.distortion")
        if text is None:
            raise InputError(f"{src}: its header has no clpost.distortion (written without --calibration, or "
                             "a lens's traced model, which --lens gives at any size)")
        return model_from_header(text, source=f"{src} header")
    from .formats import load_calibration

    m = load_calibration(src)
    size = getattr(args, "size", None)
    return m if size is None or tuple(size) == (m.width, m.height) else m.scaled_to(*size)


def cmd_calibration(args) -> int:
    from .frustum import required_render
    from .header import header_text
    from .writers import FORMATS, write_calibration

    model = model_from_source(args)
    if args.calibration_command == "show":
        from .cubemap import required_cubemap
        from .frustum import PINHOLE_LIMIT_DEG, max_ray_angle_deg

        print(f"{model.source or 'model'}: {header_text(model)}")
        rf = model.fold_radius()
        theta = max_ray_angle_deg(model)
        if theta > PINHOLE_LIMIT_DEG:
            cube = required_cubemap(model)
            cover = (f"{theta:.1f}° off axis, beyond a pinhole render: a cubemap of six {cube.face} px faces "
                     f"({cube.width}x{cube.height} atlas)")
        else:
            spec = required_render(model)
            cover = f"{spec.width}x{spec.height} (f={spec.f:.6g}, c=({spec.cx:.6g}, {spec.cy:.6g}))"
        print(f"fold radius: {'none' if math.isinf(rf) else f'{rf:.6g} (normalised)'}; render that covers it: {cover}")
        return 0
    from ..outputs import check_paths

    out = Path(args.output)
    src = getattr(args, "input", None)
    if src is not None:
        check_paths([(Path(src.split("#")[0]), out)], args.output)
    if out.exists() and not args.overwrite:
        raise InputError(f"-o {args.output}: exists; pass --overwrite to replace it")
    fmt = write_calibration(model, out, args.format)
    print(f"wrote {out} ({FORMATS[fmt][1]})")
    return 0


def add_parser(sub, size, options) -> None:
    """Register ``clpost calibration {show,convert}`` on the CLI's subparsers (``size`` and ``options``:
    :func:`clpost.stmap.add_parser`'s)."""
    from ..stmap import add_source_options
    from .writers import FORMATS

    c = sub.add_parser("calibration", help="show a calibration, or write it (or an output's camera) in another "
                                           "format: OpenCV YAML/XML/JSON, ROS, COLMAP, Kalibr")
    csub = c.add_subparsers(dest="calibration_command", required=True)
    for name, help_ in (("show", "the model's named fields, fold radius and the render size that covers it"),
                        ("convert", "write the model in another format")):
        q = csub.add_parser(name, help=help_)
        q.add_argument("input", nargs="?", default=None,
                       help="calibration file (OpenCV YAML/XML/JSON, ROS, COLMAP cameras.txt[#ID], Kalibr "
                            "camchain[#camN]) or an output EXR of clpost (its clpost.distortion); or use --lens")
        if name == "convert":
            q.add_argument("-o", "--output", required=True, help="output file (.yaml, .xml, .json, .txt)")
            q.add_argument("--format", choices=list(FORMATS), default=None,
                           help="default from the extension: .yaml/.yml opencv-yaml, .xml opencv-xml, "
                                ".json opencv-json, .txt colmap")
            q.add_argument("--overwrite", action="store_true", help="replace an existing output")
        q.add_argument("--size", type=size, default=None,
                       help="WIDTHxHEIGHT: scale the calibration to this size (same aspect), or the traced lens's")
        add_source_options(q, options)
        q.set_defaults(func=cmd_calibration)


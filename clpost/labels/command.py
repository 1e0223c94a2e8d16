"""``clpost labels map``: a COCO annotation file of renders → the same dataset in the distorted image.

``clpost labels map IN.json -o OUT.json --calibration CAM.yaml`` maps every image's keypoints,
boxes and polygons with the camera's exact forward model (:mod:`clpost.labels.coco`). Each image's
render intrinsics come from its size as the distortion stage takes them — the calibration's own K
at the calibration's size, :func:`clpost.calibration.required_render`'s frustum at that size
(``clpost render-size``) — or from ``--render-intrinsics fx,fy,cx,cy``. ``--fill crop`` applies the
same magnification as ``clpost process --fill crop``. ``--camera-files`` also writes the effective
camera beside OUT (:mod:`clpost.labels.camera_files`). OUT is written atomically; a bad input is
one line, exit 2, nothing written.
"""
from __future__ import annotations

import json
from pathlib import Path

from ..errors import InputError


def _intrinsics(text: str) -> tuple[float, float, float, float]:
    import argparse
    import math

    try:
        k = tuple(float(t) for t in text.split(","))
    except ValueError:
        k = ()
    if len(k) != 4 or not all(math.isfinite(t) for t in k) or k[0] <= 0 or k[1] <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: give fx,fy,cx,cy in render pixels (fx, fy > 0), e.g. "
                                         "1000,1000,959.5,539.5")
    return k


def mapping_factory(model, fill: str = "overscan", intrinsics=None):
    """``mapping_for(width, height)`` of :func:`clpost.labels.coco.map_coco` for a calibration."""
    from ..stages import _field as fld
    from ..stages.distortion import _scaled, crop_scale
    from .coco import Mapping

    def mapping_for(w: int, h: int) -> Mapping:
        k = fld.render_intrinsics_px(model, w, h, intrinsics)
        if k is None:
            from ..calibration import required_render

            spec = required_render(model)
            raise InputError(f"render size {w}x{h} is neither the calibration{model._where()}'s "
                             f"{model.width}x{model.height} (its K) nor {spec.width}x{spec.height} (clpost "
                             "render-size); give the render's --render-intrinsics fx,fy,cx,cy")
        m = _scaled(model, crop_scale(model, (w, h), k)) if fill == "crop" else model
        return Mapping(m, k)

    return mapping_for


def cmd_labels(args) -> int:
    from ..atomic import atomic_path
    from ..outputs import check_paths
    from ..stmap import model_from_args
    from .coco import map_coco

    src, out = Path(args.input), Path(args.output)
    check_paths([(src, out)], args.output)
    if out.exists() and not args.overwrite:
        raise InputError(f"-o {args.output}: exists; pass --overwrite to replace it")
    try:
        data = json.loads(src.read_text())
    except UnicodeDecodeError:
        raise InputError(f"{src}: not a text file; give a COCO .json") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{src}: not valid JSON ({exc.msg} at line {exc.lineno}); give a COCO .json") from None
    model = model_from_args(args, args.size)
    mapping_for = mapping_factory(model, args.fill, args.render_intrinsics)
    mapped, rep = map_coco(data, mapping_for, str(src))
    eff = None
    if args.camera_files:  # checked before anything is written
        from .camera_files import camera_paths

        sizes = {(int(im["width"]), int(im["height"])) for im in data["images"]}
        if len(sizes) != 1:
            raise InputError(f"--camera-files: the images of {src} have {len(sizes)} render sizes; one camera file "
                             "describes one; map each size separately")
        eff = mapping_for(*sizes.pop()).model
        for p in camera_paths(out).values():
            if p.exists() and not args.overwrite:
                raise InputError(f"{p}: exists; pass --overwrite to replace it")
    with atomic_path(out) as tmp:
        Path(tmp).write_text(json.dumps(mapped))
    written = []
    if eff is not None:
        from .camera_files import write_camera_files

        written = write_camera_files(eff, out)
    print(f"wrote {out}: {rep}" + (f"; camera: {', '.join(str(p) for p in written)}" if written else ""))
    return 0


def add_parser(sub, size, options) -> None:
    """Register ``clpost labels map`` (``size`` and ``options``: :func:`clpost.stmap.add_parser`'s)."""
    from ..stages.distortion import FILLS
    from ..stmap import add_source_options

    p = sub.add_parser("labels", help="map COCO keypoints/boxes/polygons of renders into the distorted image")
    lsub = p.add_subparsers(dest="labels_command", required=True)
    q = lsub.add_parser("map", help="COCO JSON of undistorted renders -> COCO JSON of the distorted images, by the "
                                    "exact forward model (docs/labels.md)")
    q.add_argument("input", help="COCO annotation JSON of the renders")
    q.add_argument("-o", "--output", required=True, help="output COCO JSON")
    q.add_argument("--fill", choices=FILLS, default="overscan",
                   help="as clpost process --fill: crop magnifies the image (and so the labels)")
    q.add_argument("--render-intrinsics", type=_intrinsics, default=None, metavar="FX,FY,CX,CY",
                   help="the renders' pinhole intrinsics in px (default: from the image size, as the distortion "
                        "stage takes them)")
    q.add_argument("--size", type=size, default=None,
                   help="WIDTHxHEIGHT: the calibration scaled to this size, or the traced lens's image size")
    q.add_argument("--camera-files", action="store_true",
                   help="also write the effective camera beside OUT: <stem>.camera.yaml (OpenCV), "
                        "<stem>.kalibr.yaml, <stem>.cameras.txt")
    q.add_argument("--overwrite", action="store_true", help="replace existing outputs")
    add_source_options(q, options)
    q.set_defaults(func=cmd_labels)

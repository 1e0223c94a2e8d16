r"""An :class:`~clpost.calibration.model.OpenCVModel` written back out in the formats
:mod:`clpost.calibration.formats` reads, as the tools that own them write them:

========== ==================================================================================
format     what is written
========== ==================================================================================
opencv     OpenCV FileStorage YAML (``%YAML:1.0``, ``!!opencv-matrix``), XML or JSON, with the
           keys of OpenCV's calibration tutorial: ``image_width``, ``image_height``,
           ``camera_matrix``, ``distortion_coefficients`` (the shortest OpenCV vector of 5, 8,
           12 or 14 entries that holds every coefficient; a fisheye model's 4 with
           ``fisheye_model: 1``)
ros        ``camera_calibration_parsers`` YAML: ``plumb_bob`` (5), ``rational_polynomial`` (8)
           or ``equidistant`` (4); rectification identity, projection [K | 0]
colmap     ``cameras.txt``: ``PINHOLE``, ``OPENCV``, ``FULL_OPENCV`` or ``OPENCV_FISHEYE``, the
           principal point + 0.5 (:data:`~clpost.calibration.formats.COLMAP_PIXEL_OFFSET`)
kalibr     camchain YAML, ``cam0``: ``pinhole`` with ``radtan`` (k1, k2, p1, p2) or
           ``equidistant`` (k1…k4)
========== ==================================================================================

A model a format cannot express (thin prism or tilt for ROS and COLMAP, k3…k6 for Kalibr's radtan)
is refused in one line naming what is missing, never written approximately. Numbers are written
so they read back as the same float64 (17 significant digits where needed).
"""
from __future__ import annotations

import json
from pathlib import Path

from ..errors import InputError
from .formats import COLMAP_PIXEL_OFFSET
from .model import COEFF_NAMES, OpenCVModel

FORMATS = {
    # name: (default extension, description)
    "opencv-yaml": (".yaml", "OpenCV FileStorage YAML"),
    "opencv-xml": (".xml", "OpenCV FileStorage XML"),
    "opencv-json": (".json", "OpenCV FileStorage JSON"),
    "ros": (".yaml", "ROS camera_info YAML"),
    "colmap": (".txt", "COLMAP cameras.txt"),
    "kalibr": (".yaml", "Kalibr camchain YAML"),
}
"""Formats :func:`write_calibration` writes."""

_BY_SUFFIX = {".xml": "opencv-xml", ".json": "opencv-json", ".txt": "colmap", ".yaml": "opencv-yaml",
              ".yml": "opencv-yaml"}


def format_for(path: str | Path, fmt: str | None = None) -> str:
    """``fmt`` checked, or the format a file name implies (.yaml/.yml → opencv-yaml, .xml, .json, .txt → colmap)."""
    if fmt is not None:
        if fmt not in FORMATS:
            raise InputError(f"--format {fmt}: unknown; use one of {', '.join(FORMATS)}")
        return fmt
    suffix = Path(path).suffix.lower()
    if suffix not in _BY_SUFFIX:
        raise InputError(f"-o {path}: cannot tell the format from {suffix or 'no extension'}; use .yaml, .xml, "
                         f".json or .txt, or give --format ({', '.join(FORMATS)})")
    return _BY_SUFFIX[suffix]


def _num(v: float) -> str:
    """Shortest text that reads back as the same float, always with a '.' (YAML 1.1 reads 1e-05 as a string)."""
    t = repr(float(v))
    if "e" in t and "." not in t.split("e")[0]:
        m, e = t.split("e")
        t = f"{m}.0e{e}"
    return t


def _standard_vector(m: OpenCVModel) -> list[float]:
    """The shortest OpenCV vector (5, 8, 12, 14 entries) holding every non-zero coefficient."""
    v = m.vector()
    last = max([i for i, x in enumerate(v) if x] + [0])
    n = next(n for n in (5, 8, 12, 14) if n > last)
    return v[:n].tolist()


SCALARS = ("xi", "alpha", "omega")
"""Parameters of the other families written as keys of their own in FileStorage files."""


def _coefficients(m: OpenCVModel) -> list[float]:
    if m.distortion_model == "opencv":
        return _standard_vector(m)
    return [getattr(m, n) for n in m.coeff_names if n not in SCALARS]


def _family_keys(m: OpenCVModel) -> dict:
    """FileStorage keys beyond OpenCV's for the families other than opencv and fisheye:
    ``distortion_model`` and the scalars (what :mod:`.formats` reads back)."""
    if m.distortion_model in ("opencv", "fisheye"):
        return {}
    out = {"distortion_model": m.distortion_model}
    out.update({n: getattr(m, n) for n in m.coeff_names if n in SCALARS})
    return out


def _refuse(m: OpenCVModel, fmt: str, names) -> None:
    bad = [n for n in names if getattr(m, n)]
    if bad:
        raise InputError(f"{fmt} cannot express {', '.join(f'{n}={getattr(m, n):g}' for n in bad)}"
                         f"{m._where()}; write opencv-yaml, opencv-xml or opencv-json instead")


def _opencv_yaml(m: OpenCVModel) -> str:
    def mat(name, rows, cols, data):
        return (f"{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n"
                f"   data: [ {', '.join(_num(x) for x in data)} ]\n")

    d = _coefficients(m)
    out = f"%YAML:1.0\n---\nimage_width: {m.width}\nimage_height: {m.height}\n"
    if m.is_fisheye:
        out += "fisheye_model: 1\n"
    for k, v in _family_keys(m).items():
        out += f"{k}: {v if isinstance(v, str) else _num(v)}\n"
    return out + mat("camera_matrix", 3, 3, m.matrix().ravel()) + (
        mat("distortion_coefficients", 1, len(d), d) if d else "")


def _opencv_xml(m: OpenCVModel) -> str:
    def mat(name, rows, cols, data):
        return (f'<{name} type_id="opencv-matrix">\n  <rows>{rows}</rows>\n  <cols>{cols}</cols>\n  <dt>d</dt>\n'
                f"  <data>\n    {' '.join(_num(x) for x in data)}</data></{name}>\n")

    d = _coefficients(m)
    out = (f'<?xml version="1.0"?>\n<opencv_storage>\n<image_width>{m.width}</image_width>\n'
           f"<image_height>{m.height}</image_height>\n")
    if m.is_fisheye:
        out += "<fisheye_model>1</fisheye_model>\n"
    for k, v in _family_keys(m).items():
        out += f"<{k}>{v if isinstance(v, str) else _num(v)}</{k}>\n"
    return (out + mat("camera_matrix", 3, 3, m.matrix().ravel())
            + (mat("distortion_coefficients", 1, len(d), d) if d else "") + "</opencv_storage>\n")


def _opencv_json(m: OpenCVModel) -> str:
    def mat(rows, cols, data):
        return {"type_id": "opencv-matrix", "rows": rows, "cols": cols, "dt": "d", "data": [float(x) for x in data]}

    d = _coefficients(m)
    out: dict = {"image_width": m.width, "image_height": m.height}
    if m.is_fisheye:
        out["fisheye_model"] = 1
    out.update(_family_keys(m))
    out["camera_matrix"] = mat(3, 3, m.matrix().ravel())
    if d:
        out["distortion_coefficients"] = mat(1, len(d), d)
    return json.dumps(out, indent=4) + "\n"


def _family_only(m: OpenCVModel, fmt: str, families, instead: str) -> None:
    if m.distortion_model not in families:
        raise InputError(f"{fmt} cannot express the {m.distortion_model} model{m._where()}; write {instead} instead")


def _ros(m: OpenCVModel) -> str:
    _family_only(m, "ROS camera_info", ("opencv", "fisheye"), "opencv-yaml")
    _refuse(m, "ROS camera_info", COEFF_NAMES[8:])
    if m.is_fisheye:
        name, d = "equidistant", m.coefficients().tolist()
    else:
        d = m.vector()[:8].tolist()
        name, d = ("plumb_bob", d[:5]) if not any(d[5:]) else ("rational_polynomial", d)

    def mat(key, rows, cols, data):
        return f"{key}:\n  rows: {rows}\n  cols: {cols}\n  data: [{', '.join(_num(x) for x in data)}]\n"

    p = [m.fx, 0.0, m.cx, 0.0, 0.0, m.fy, m.cy, 0.0, 0.0, 0.0, 1.0, 0.0]
    return (f"image_width: {m.width}\nimage_height: {m.height}\ncamera_name: camera\n"
            + mat("camera_matrix", 3, 3, m.matrix().ravel()) + f"distortion_model: {name}\n"
            + mat("distortion_coefficients", 1, len(d), d)
            + mat("rectification_matrix", 3, 3, [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0]) + mat("projection_matrix", 3, 4, p))


def _colmap(m: OpenCVModel) -> str:
    cx, cy = m.cx + COLMAP_PIXEL_OFFSET, m.cy + COLMAP_PIXEL_OFFSET
    _family_only(m, "COLMAP", ("opencv", "fisheye", "fov", "thinprism"), "opencv-yaml")
    if m.distortion_model in ("fisheye", "fov", "thinprism"):
        name = {"fisheye": "OPENCV_FISHEYE", "fov": "FOV", "thinprism": "THIN_PRISM_FISHEYE"}[m.distortion_model]
        params = [m.fx, m.fy, cx, cy, *m.coefficients().tolist()]
    else:
        _refuse(m, "COLMAP", COEFF_NAMES[8:])
        v = m.vector()
        if m.is_identity:
            name, params = "PINHOLE", [m.fx, m.fy, cx, cy]
        elif not any(v[4:8]):
            name, params = "OPENCV", [m.fx, m.fy, cx, cy, *v[:4].tolist()]
        else:
            name, params = "FULL_OPENCV", [m.fx, m.fy, cx, cy, *v[:8].tolist()]
    return ("# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
            f"# Number of cameras: 1\n1 {name} {m.width} {m.height} {' '.join(repr(float(x)) for x in params)}\n")


def _kalibr(m: OpenCVModel) -> str:
    _family_only(m, "Kalibr", ("opencv", "fisheye", "fov", "ucm", "ds"), "opencv-yaml")
    cam, intr = "pinhole", [m.fx, m.fy, m.cx, m.cy]
    if m.is_fisheye:
        name, d = "equidistant", m.coefficients().tolist()
    elif m.distortion_model == "fov":
        name, d = "fov", [m.omega]
    elif m.distortion_model == "ds":
        cam, intr, name, d = "ds", [m.xi, m.alpha, *intr], "none", []
    elif m.distortion_model == "ucm":
        d = [m.k1, m.k2, m.p1, m.p2]
        cam, intr, name = "omni", [m.xi, *intr], ("radtan" if any(d) else "none")
        d = d if any(d) else []
    else:
        _refuse(m, "Kalibr radtan (k1, k2, p1, p2)", COEFF_NAMES[4:])
        name, d = "radtan", m.vector()[:4].tolist()
    return (f"cam0:\n  camera_model: {cam}\n"
            f"  intrinsics: [{', '.join(_num(x) for x in intr)}]\n"
            f"  distortion_model: {name}\n  distortion_coeffs: [{', '.join(_num(x) for x in d)}]\n"
            f"  resolution: [{m.width}, {m.height}]\n")


_WRITERS = {"opencv-yaml": _opencv_yaml, "opencv-xml": _opencv_xml, "opencv-json": _opencv_json, "ros": _ros,
            "colmap": _colmap, "kalibr": _kalibr}


def calibration_text(model: OpenCVModel, fmt: str) -> str:
    """The file ``fmt`` (:data:`FORMATS`) holds for ``model``."""
    return _WRITERS[format_for("", fmt)](model)


def write_calibration(model: OpenCVModel, path: str | Path, fmt: str | None = None) -> str:
    """Write ``model`` to ``path`` atomically (format from ``fmt`` or the extension); returns the format."""
    from ..atomic import atomic_path

    fmt = format_for(path, fmt)
    text = calibration_text(model, fmt)  # refusals happen before anything is written
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text)
    return fmt

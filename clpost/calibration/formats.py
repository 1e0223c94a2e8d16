r"""Calibration files → :class:`~clpost.calibration.model.OpenCVModel`.

:func:`load_calibration` reads OpenCV FileStorage YAML or JSON
(``camera_matrix``, ``distortion_coefficients``, ``image_width``/``image_height``), ROS
``camera_info`` YAML (``camera_matrix``, ``distortion_model: plumb_bob|rational_polynomial``,
``distortion_coefficients``, ``image_width``/``image_height``) and COLMAP ``cameras.txt``
(``SIMPLE_RADIAL``, ``RADIAL``, ``OPENCV``, ``FULL_OPENCV``); the format is told from the content.
"""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from ..errors import InputError
from .model import COEFF_NAMES, OpenCVModel


def _read_opencv_yaml(text: str) -> dict:
    """The subset of OpenCV FileStorage YAML calibration files use: scalars and ``!!opencv-matrix``
    mappings (rows, cols, dt, data: [...]); also plain ROS YAML."""
    import yaml

    class _Loader(yaml.SafeLoader):
        pass

    def _matrix(loader, node):
        return loader.construct_mapping(node, deep=True)

    _Loader.add_constructor("tag:yaml.org,2002:opencv-matrix", _matrix)
    _Loader.add_multi_constructor("!", lambda loader, suffix, node: loader.construct_mapping(node, deep=True))
    # OpenCV writes a '%YAML:1.0' directive PyYAML rejects (it wants '%YAML 1.1')
    text = re.sub(r"^%YAML[: ]1\.0\s*$", "", text, flags=re.M).lstrip("\n")
    if text.startswith("---"):
        text = text.split("\n", 1)[1] if "\n" in text else ""
    return yaml.load(text, Loader=_Loader) or {}


def _matrix_value(node, name: str, path: str) -> np.ndarray:
    if isinstance(node, dict) and "data" in node:
        data = np.asarray(node["data"], dtype=np.float64)
        rows, cols = int(node.get("rows", 1)), int(node.get("cols", data.size))
        if rows * cols != data.size:
            raise InputError(f"{path}: {name} says {rows}×{cols} but has {data.size} values")
        return data.reshape(rows, cols)
    if isinstance(node, (list, tuple)):
        return np.asarray(node, dtype=np.float64)
    raise InputError(f"{path}: {name} must be a matrix (rows/cols/data) or a list of numbers")


def _size_from(d: dict, path: str) -> tuple[int, int]:
    w = d.get("image_width", d.get("width"))
    h = d.get("image_height", d.get("height"))
    if w is None or h is None:
        raise InputError(f"{path}: no image size; add image_width and image_height (pixels) — "
                         "the intrinsics are only meaningful for the resolution they were calibrated at")
    return int(w), int(h)


def _from_mapping(d: dict, path: str) -> OpenCVModel:
    if not isinstance(d, dict) or "camera_matrix" not in d:
        raise InputError(f"{path}: no camera_matrix; expected an OpenCV FileStorage or ROS camera_info "
                         "file with camera_matrix and distortion_coefficients")
    k = _matrix_value(d["camera_matrix"], "camera_matrix", path).reshape(-1)
    if k.size != 9:
        raise InputError(f"{path}: camera_matrix must have 9 values, has {k.size}")
    dist_node = d.get("distortion_coefficients", d.get("dist_coeffs", d.get("D")))
    if dist_node is None:
        raise InputError(f"{path}: no distortion_coefficients; add them (OpenCV order {', '.join(COEFF_NAMES[:5])}, …)")
    dist = _matrix_value(dist_node, "distortion_coefficients", path).reshape(-1)
    model_name = d.get("distortion_model")
    if model_name is not None and model_name not in ("plumb_bob", "rational_polynomial"):
        raise InputError(f"{path}: distortion_model {model_name!r} is not the OpenCV standard model; "
                         "clpost reads plumb_bob and rational_polynomial (fisheye/equidistant are other models)")
    w, h = _size_from(d, path)
    return OpenCVModel.from_vector(w, h, k.reshape(3, 3), dist, source=path)


COLMAP_MODELS = {
    # name: parameter names (COLMAP src/colmap/sensor/models.h)
    "SIMPLE_RADIAL": ("f", "cx", "cy", "k1"),
    "RADIAL": ("f", "cx", "cy", "k1", "k2"),
    "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
    "FULL_OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
}


def _read_colmap(text: str, path: str, camera_id: int | None) -> OpenCVModel:
    r"""COLMAP ``cameras.txt``: ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS…``. COLMAP's pixel
    convention puts the image's top-left *corner* at (0, 0) (pixel centres at i + 0.5), so
    :math:`c_{\text{OpenCV}} = c_{\text{COLMAP}} - 0.5`."""
    rows = [ln.split() for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not rows:
        raise InputError(f"{path}: no camera lines (CAMERA_ID MODEL WIDTH HEIGHT PARAMS…)")
    if camera_id is None and len(rows) > 1:
        raise InputError(f"{path}: {len(rows)} cameras; say which with {path}#<CAMERA_ID>")
    row = rows[0] if camera_id is None else next((r for r in rows if r[0] == str(camera_id)), None)
    if row is None:
        raise InputError(f"{path}: no camera with id {camera_id}")
    name = row[1]
    if name not in COLMAP_MODELS:
        raise InputError(f"{path}: COLMAP model {name} is not supported; use one of {', '.join(COLMAP_MODELS)}")
    names = COLMAP_MODELS[name]
    vals = [float(t) for t in row[4:]]
    if len(vals) != len(names):
        raise InputError(f"{path}: {name} needs {len(names)} parameters ({' '.join(names)}), got {len(vals)}")
    p = dict(zip(names, vals))
    if "f" in p:
        p["fx"] = p["fy"] = p.pop("f")
    p["cx"] -= 0.5
    p["cy"] -= 0.5
    return OpenCVModel(int(row[2]), int(row[3]), source=path, **p)


def load_calibration(path: str | Path) -> OpenCVModel:
    """Read a calibration file (format from its content: OpenCV YAML/JSON, ROS YAML, COLMAP txt);
    ``cameras.txt#2`` picks COLMAP camera 2."""
    spec = str(path)
    camera_id = None
    if "#" in spec and spec.rsplit("#", 1)[1].isdigit():
        spec, cid = spec.rsplit("#", 1)
        camera_id = int(cid)
    p = Path(spec)
    try:
        text = p.read_text()
    except FileNotFoundError:
        raise InputError(f"--calibration {spec}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"--calibration {spec}: cannot read it as text ({exc})") from None
    stripped = text.lstrip()
    if stripped.startswith("{"):
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(f"{spec}: invalid JSON ({exc})") from None
        d = d.get("opencv_storage", d) if isinstance(d, dict) else d
        return _from_mapping(d, spec)
    if re.match(r"^(#.*\n|\s*\n)*\s*\d+\s+[A-Z_]+\s+\d+\s+\d+", text) or p.name == "cameras.txt":
        return _read_colmap(text, spec, camera_id)
    try:
        d = _read_opencv_yaml(text)
    except Exception as exc:  # yaml.YAMLError and friends: report as a file problem
        raise InputError(f"{spec}: not a readable OpenCV/ROS YAML, JSON or COLMAP cameras.txt ({exc})") from None
    return _from_mapping(d, spec)

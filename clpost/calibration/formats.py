r"""Calibration files → :class:`~clpost.calibration.model.OpenCVModel` (readers; the writers are
:mod:`clpost.calibration.writers`).

:func:`load_calibration` tells the format from the content:

* **OpenCV FileStorage** YAML, XML or JSON (what ``cv::FileStorage`` writes; OpenCV's
  ``samples/cpp/tutorial_code/calib3d/camera_calibration`` writes ``camera_matrix``,
  ``distortion_coefficients``, ``image_width``, ``image_height`` and ``fisheye_model``), with the
  key aliases other tools and scripts use (:data:`MATRIX_KEYS`, :data:`DISTORTION_KEYS`,
  :data:`SIZE_KEYS`);
* **ROS camera_info** YAML (``camera_calibration_parsers``: ``camera_matrix``,
  ``distortion_model`` ``plumb_bob`` | ``rational_polynomial`` | ``equidistant``,
  ``distortion_coefficients``, ``image_width``/``image_height``), and the ``sensor_msgs/CameraInfo``
  message as ``rostopic echo`` / ``ros2 topic echo`` print it (``K``/``k``, ``D``/``d``,
  ``width``/``height``);
* **COLMAP** ``cameras.txt`` (``CAMERA_ID MODEL WIDTH HEIGHT PARAMS…``, the models of
  :data:`COLMAP_MODELS`; ``cameras.txt#2`` picks camera 2);
* **Kalibr** camchain YAML (``cam0: {camera_model: pinhole, intrinsics: [fu, fv, pu, pv],
  distortion_model: radtan | equidistant | fov, distortion_coeffs, resolution: [w, h]}``, and
  ``camera_model: omni`` (+ ``radtan``/``none``) and ``ds`` (:data:`KALIBR_CAMERAS`);
  ``camchain.yaml#cam1`` picks cam1).

Pixel conventions: OpenCV, ROS and Kalibr (whose corners come from OpenCV's detector) put the centre of
the top-left pixel at (0, 0), as clpost does; COLMAP puts the top-left *corner* there
(:func:`_read_colmap`).
"""
from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..errors import InputError
from .model import COEFF_NAMES, FAMILY_PARAMS, FISHEYE_COEFF_NAMES, OpenCVModel

MATRIX_KEYS = ("camera_matrix", "cameraMatrix", "K", "k", "mtx", "intrinsic_matrix", "intrinsics_matrix")
"""Keys of the 3×3 camera matrix, in the order they are looked for."""
DISTORTION_KEYS = ("distortion_coefficients", "distCoeffs", "dist_coeffs", "D", "d", "dist",
                   "distortion_coeffs", "distortion")
"""Keys of the distortion vector."""
SIZE_KEYS = (("image_width", "image_height"), ("width", "height"), ("imageWidth", "imageHeight"))
"""Keys of the image size (pairs); a two-entry ``image_size``/``imageSize``/``resolution`` also works."""

FISHEYE_NAMES = ("equidistant", "fisheye", "opencv_fisheye", "kannala_brandt")
"""``distortion_model`` values meaning OpenCV's fisheye model (ROS, Kalibr and others)."""
STANDARD_NAMES = ("plumb_bob", "rational_polynomial", "radtan", "opencv", "pinhole", "none")
"""``distortion_model`` values meaning the standard OpenCV model."""
OTHER_NAMES = {"ucm": "ucm", "omni": "ucm", "omnidir": "ucm", "unified": "ucm", "mei": "ucm",
               "ds": "ds", "double_sphere": "ds", "ftheta": "ftheta", "f-theta": "ftheta", "fov": "fov",
               "thinprism": "thinprism", "thin_prism_fisheye": "thinprism"}
"""``distortion_model`` values of a FileStorage file (as clpost writes them) meaning the other
families; their scalars ``xi``, ``alpha``, ``omega`` are keys of their own (``xi`` alone, as
``cv::omnidir::calibrate``'s output has it, means the unified model with radtan)."""


def _read_opencv_yaml(text: str) -> dict:
    """The subset of OpenCV FileStorage YAML calibration files use: scalars and ``!!opencv-matrix``
    mappings (rows, cols, dt, data: [...]); also plain ROS and Kalibr YAML."""
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
    text = re.sub(r"\n---\s*$", "\n", text)  # `ros2 topic echo` ends each message with a separator
    return yaml.load(text, Loader=_Loader) or {}


def _xml_value(el: ET.Element):
    """An OpenCV FileStorage XML node: a matrix (rows/cols/dt/data children), a mapping, or text
    (one number, several numbers, or a string)."""
    children = list(el)
    if children:
        if el.get("type_id") == "opencv-matrix" or {c.tag for c in children} >= {"rows", "cols", "data"}:
            d = {c.tag: (c.text or "").strip() for c in children}
            return {"rows": int(d["rows"]), "cols": int(d["cols"]), "dt": d.get("dt", "d"),
                    "data": [float(t) for t in d["data"].split()]}
        if all(c.tag == "_" for c in children):
            return [_xml_value(c) for c in children]
        return {c.tag: _xml_value(c) for c in children}
    text = (el.text or "").strip().strip('"')
    tokens = text.split()
    try:
        nums = [float(t) for t in tokens]
    except ValueError:
        return text
    if len(nums) == 1:
        return int(nums[0]) if re.fullmatch(r"[-+]?\d+", tokens[0]) else nums[0]
    return nums


def _read_opencv_xml(text: str, path: str) -> dict:
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise InputError(f"{path}: invalid XML ({exc})") from None
    if root.tag != "opencv_storage":
        raise InputError(f"{path}: XML root is <{root.tag}>, not an OpenCV FileStorage <opencv_storage>")
    return {c.tag: _xml_value(c) for c in root}


def _matrix_value(node, name: str, path: str) -> np.ndarray:
    if isinstance(node, dict) and "data" in node:
        try:
            data = np.asarray(node["data"], dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(f"{path}: {name}'s data must be numbers") from None
        rows, cols = int(node.get("rows", 1)), int(node.get("cols", data.size))
        if rows * cols != data.size:
            raise InputError(f"{path}: {name} says {rows}×{cols} but has {data.size} values")
        return data.reshape(rows, cols)
    if isinstance(node, (list, tuple)):
        try:
            return np.asarray(node, dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(f"{path}: {name} must be a list of numbers") from None
    raise InputError(f"{path}: {name} must be a matrix (rows/cols/data) or a list of numbers")


def _lookup(d: dict, keys, what: str, path: str):
    """The value of the first of ``keys`` present; two different values under two aliases is an error."""
    found = [(k, d[k]) for k in keys if k in d]
    if len(found) > 1 and any(str(v) != str(found[0][1]) for _, v in found[1:]):
        raise InputError(f"{path}: {what} given twice with different values ({found[0][0]} and {found[1][0]}); "
                         "keep one")
    return found[0] if found else (None, None)


def _size_from(d: dict, path: str) -> tuple[int, int]:
    for kw, kh in SIZE_KEYS:
        if kw in d and kh in d:
            return int(d[kw]), int(d[kh])
    for k in ("image_size", "imageSize", "resolution"):
        v = d.get(k)
        if isinstance(v, (list, tuple)) and len(v) == 2:
            return int(v[0]), int(v[1])
    raise InputError(f"{path}: no image size; add image_width and image_height (pixels) — "
                     "the intrinsics are only meaningful for the resolution they were calibrated at")


def _family(name, path: str, where: str = "distortion_model") -> str:
    if name is None:
        return "opencv"
    n = str(name).strip().lower()
    if n in FISHEYE_NAMES:
        return "fisheye"
    if n in STANDARD_NAMES:
        return "opencv"
    if n in OTHER_NAMES:
        return OTHER_NAMES[n]
    raise InputError(f"{path}: {where} {name!r} is not a model clpost has; it reads "
                     f"{', '.join(STANDARD_NAMES[:3])} (OpenCV standard), {', '.join(FISHEYE_NAMES[:2])} "
                     f"(OpenCV fisheye) and {', '.join(sorted(set(OTHER_NAMES.values())))}")


def _from_mapping(d: dict, path: str) -> OpenCVModel:
    """OpenCV FileStorage (YAML/XML/JSON) or ROS camera_info as a mapping."""
    if not isinstance(d, dict):
        raise InputError(f"{path}: not a calibration (a mapping with camera_matrix and distortion_coefficients)")
    kkey, knode = _lookup(d, MATRIX_KEYS, "the camera matrix", path)
    if knode is None:
        raise InputError(f"{path}: no camera matrix (looked for {', '.join(MATRIX_KEYS)}); expected an OpenCV "
                         "FileStorage, ROS camera_info, Kalibr camchain or COLMAP cameras.txt file")
    k = _matrix_value(knode, kkey, path).reshape(-1)
    if k.size != 9:
        raise InputError(f"{path}: {kkey} must have 9 values, has {k.size}")
    family = _family(d.get("distortion_model"), path)
    if family == "opencv" and "distortion_model" not in d and "xi" in d:
        family = "ucm"  # cv::omnidir (Mei's model): K, D (k1, k2, p1, p2), xi
    scalars = {}
    for name in ("xi", "alpha", "omega"):
        if name in FAMILY_PARAMS[family]:
            if name not in d:
                raise InputError(f"{path}: the {family} model needs {name}; add it as a number")
            try:
                scalars[name] = float(_matrix_value(d[name], name, path).reshape(-1)[0]
                                      if isinstance(d[name], (dict, list)) else d[name])
            except (TypeError, ValueError):
                raise InputError(f"{path}: {name} must be a number") from None
    dkey, dnode = _lookup(d, DISTORTION_KEYS, "the distortion coefficients", path)
    if dnode is None and family in ("ds", "fov"):
        dkey, dnode = "distortion_coefficients", []
    if dnode is None:
        raise InputError(f"{path}: no distortion coefficients (looked for {', '.join(DISTORTION_KEYS[:6])}); add "
                         f"them (OpenCV order {', '.join(COEFF_NAMES[:5])}, …)")
    dist = _matrix_value(dnode, dkey, path).reshape(-1)
    if family == "opencv" and str(d.get("fisheye_model", 0)).strip().lower() in ("1", "true"):
        family = "fisheye"  # OpenCV's calibration tutorial's flag
    w, h = _size_from(d, path)
    return OpenCVModel.from_vector(w, h, k.reshape(3, 3), dist, source=path, distortion_model=family, **scalars)


COLMAP_MODELS = {
    # name: (parameter names, clpost family) — COLMAP src/colmap/sensor/models.h
    "SIMPLE_PINHOLE": (("f", "cx", "cy"), "opencv"),
    "PINHOLE": (("fx", "fy", "cx", "cy"), "opencv"),
    "SIMPLE_RADIAL": (("f", "cx", "cy", "k1"), "opencv"),
    "RADIAL": (("f", "cx", "cy", "k1", "k2"), "opencv"),
    "OPENCV": (("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"), "opencv"),
    "FULL_OPENCV": (("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"), "opencv"),
    "OPENCV_FISHEYE": (("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"), "fisheye"),
    # θ_d = θ(1 + k θ²) and θ(1 + k1 θ² + k2 θ⁴): truncations of OpenCV's fisheye model
    "SIMPLE_RADIAL_FISHEYE": (("f", "cx", "cy", "k1"), "fisheye"),
    "RADIAL_FISHEYE": (("f", "cx", "cy", "k1", "k2"), "fisheye"),
    "FOV": (("fx", "fy", "cx", "cy", "omega"), "fov"),
    "THIN_PRISM_FISHEYE": (("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "s1", "s3"), "thinprism"),
}
"""COLMAP camera models clpost's models express (THIN_PRISM_FISHEYE's sx1, sy1 are s1, s3;
RAD_TAN_THIN_PRISM_FISHEYE is another model and is refused)."""

COLMAP_PIXEL_OFFSET = 0.5
r"""COLMAP's principal point minus OpenCV's: COLMAP puts the image's top-left *corner* at (0, 0)
(pixel centres at i + 0.5), so :math:`c_{\text{OpenCV}} = c_{\text{COLMAP}} - 0.5`."""


def _read_colmap(text: str, path: str, camera_id: str | None) -> OpenCVModel:
    """COLMAP ``cameras.txt``: ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS…`` (:data:`COLMAP_PIXEL_OFFSET`)."""
    rows = [ln.split() for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not rows:
        raise InputError(f"{path}: no camera lines (CAMERA_ID MODEL WIDTH HEIGHT PARAMS…)")
    if camera_id is None and len(rows) > 1:
        raise InputError(f"{path}: {len(rows)} cameras; say which with {path}#<CAMERA_ID>")
    row = rows[0] if camera_id is None else next((r for r in rows if r[0] == str(camera_id)), None)
    if row is None:
        raise InputError(f"{path}: no camera with id {camera_id}")
    if len(row) < 4:
        raise InputError(f"{path}: camera line {' '.join(row)!r} needs CAMERA_ID MODEL WIDTH HEIGHT PARAMS…")
    name = row[1]
    if name not in COLMAP_MODELS:
        raise InputError(f"{path}: COLMAP model {name} is not supported (clpost's OpenCV and fisheye models cannot "
                         f"express it); use one of {', '.join(COLMAP_MODELS)}")
    names, family = COLMAP_MODELS[name]
    try:
        vals = [float(t) for t in row[4:]]
        width, height = int(row[2]), int(row[3])
    except ValueError:
        raise InputError(f"{path}: camera {row[0]}: WIDTH HEIGHT PARAMS must be numbers") from None
    if len(vals) != len(names):
        raise InputError(f"{path}: {name} needs {len(names)} parameters ({' '.join(names)}), got {len(vals)}")
    p = dict(zip(names, vals))
    if "f" in p:
        p["fx"] = p["fy"] = p.pop("f")
    p["cx"] -= COLMAP_PIXEL_OFFSET
    p["cy"] -= COLMAP_PIXEL_OFFSET
    return OpenCVModel(width, height, source=path, distortion_model=family, **p)


KALIBR_DISTORTIONS = {"radtan": ("opencv", ("k1", "k2", "p1", "p2")), "equidistant": ("fisheye", FISHEYE_COEFF_NAMES),
                      "fov": ("fov", ("omega",)), "none": ("opencv", ())}
"""Kalibr ``distortion_model`` of a ``pinhole`` camera → (clpost family, coefficient names)."""

KALIBR_CAMERAS = {"pinhole": ("fx", "fy", "cx", "cy"), "omni": ("xi", "fx", "fy", "cx", "cy"),
                  "ds": ("xi", "alpha", "fx", "fy", "cx", "cy")}
"""Kalibr ``camera_model`` → its ``intrinsics`` (Kalibr wiki, "Supported models"); ``omni`` is the
unified model (clpost ``ucm``) with ``radtan`` or ``none`` distortion, ``ds`` the double sphere
with ``none``."""


def _is_kalibr(d) -> bool:
    return isinstance(d, dict) and any(isinstance(v, dict) and "camera_model" in v and "intrinsics" in v
                                       for v in d.values())


def _read_kalibr(d: dict, path: str, cam: str | None) -> OpenCVModel:
    """Kalibr camchain: ``camN: {camera_model, intrinsics, distortion_model, distortion_coeffs,
    resolution}`` (Kalibr wiki, "Yaml formats")."""
    cams = [k for k, v in d.items() if isinstance(v, dict) and "camera_model" in v]
    if cam is None:
        if len(cams) > 1:
            raise InputError(f"{path}: {len(cams)} cameras ({', '.join(cams)}); say which with {path}#{cams[0]}")
        cam = cams[0]
    elif cam not in d and f"cam{cam}" in d:
        cam = f"cam{cam}"
    c = d.get(cam)
    if not isinstance(c, dict) or "camera_model" not in c:
        raise InputError(f"{path}: no camera {cam!r}; it has {', '.join(cams)}")
    where = f"{path}#{cam}"
    cm = c["camera_model"]
    if cm not in KALIBR_CAMERAS:
        raise InputError(f"{where}: Kalibr camera_model {cm!r} is not supported; clpost reads "
                         f"{', '.join(KALIBR_CAMERAS)} (fix camera_model or convert the calibration)")
    dm = c.get("distortion_model", "none")
    allowed = KALIBR_DISTORTIONS if cm == "pinhole" else ({"radtan", "none"} if cm == "omni" else {"none"})
    if dm not in allowed:
        raise InputError(f"{where}: Kalibr {cm}-{dm} is not supported; with camera_model {cm} clpost reads "
                         f"distortion_model {', '.join(sorted(allowed))}")
    family, names = KALIBR_DISTORTIONS[dm]
    family = {"omni": "ucm", "ds": "ds"}.get(cm, family)
    inames = KALIBR_CAMERAS[cm]
    intr = _matrix_value(c.get("intrinsics"), "intrinsics", where).reshape(-1)
    coeffs = _matrix_value(c.get("distortion_coeffs", []), "distortion_coeffs", where).reshape(-1)
    if intr.size != len(inames):
        raise InputError(f"{where}: {cm} intrinsics must be [{', '.join(inames)}], got {intr.size} values")
    if coeffs.size != len(names):
        raise InputError(f"{where}: {dm} needs {len(names)} distortion_coeffs ({', '.join(names) or 'none'}), "
                         f"got {coeffs.size}")
    res = c.get("resolution")
    if not (isinstance(res, (list, tuple)) and len(res) == 2):
        raise InputError(f"{where}: no resolution [width, height]; add it")
    p = dict(zip(inames, intr.tolist()))
    p.update(zip(names, coeffs.tolist()))
    return OpenCVModel(int(res[0]), int(res[1]), source=where, distortion_model=family, **p)


def load_calibration(path: str | Path) -> OpenCVModel:
    """Read a calibration file (format from its content, module docstring); ``cameras.txt#2``
    picks COLMAP camera 2, ``camchain.yaml#cam1`` Kalibr's cam1."""
    spec = str(path)
    selector = None
    if "#" in spec and re.fullmatch(r"[A-Za-z0-9_]+", spec.rsplit("#", 1)[1]):
        spec, selector = spec.rsplit("#", 1)
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
    if stripped.startswith("<"):
        return _from_mapping(_read_opencv_xml(text, spec), spec)
    if re.match(r"^(#.*\n|\s*\n)*\s*\d+\s+[A-Z_]+\s+\d+\s+\d+", text) or p.name == "cameras.txt":
        return _read_colmap(text, spec, selector)
    try:
        d = _read_opencv_yaml(text)
    except Exception as exc:  # yaml.YAMLError and friends: report as a file problem
        raise InputError(f"{spec}: not a readable OpenCV/ROS/Kalibr YAML, XML, JSON or COLMAP cameras.txt "
                         f"({exc})") from None
    if _is_kalibr(d):
        return _read_kalibr(d, spec, selector)
    return _from_mapping(d, spec)

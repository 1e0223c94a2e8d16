"""Outputs of a raw camera (the ``raw`` and ``isp`` stages), in forms computer-vision tools read.

- **Raw** (``raw`` stage, no ``isp``; output ``.png``, ``.tif``/``.tiff``): the mosaic as 16-bit
  single-channel digital numbers (DN, black level included, as the sensor's ADC gives them; a
  value v of the frame is ``round(v·(white − black) + black)``), plus a JSON sidecar beside it
  (``frame.0001.png`` → ``frame.0001.raw.json``, format :data:`RAW_FORMAT`): CFA pattern
  (read row by row from the top-left photosite), bits, black and white level, ISO, the white-balance
  gains and camera → sRGB colour matrix the ``isp`` stage would use, the working-space → camera
  matrix, the noise parameters at this ISO and the calibration's name. ``cv2.imread(path,
  cv2.IMREAD_UNCHANGED)``, ``imageio`` and Pillow read the image as uint16.
- **Developed** (``isp`` stage; ``.jpg``/``.jpeg``, ``.png``, ``.tif``): the ISP's display-encoded
  sRGB quantised to 8 bits as it is (it is already encoded: not encoded again), a JPEG at
  ``Camera.isp_jpeg_quality`` with 4:2:0 chroma subsampling as cameras write it, sRGB ICC profile
  embedded.

Every file is written atomically (:func:`clpost.atomic.atomic_path`); the image first, then its
sidecar. An ``.exr`` output keeps the usual path (linear values with the camera in the header).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .errors import InputError

RAW_FORMAT = "clpost-raw/1"
RAW_EXTENSIONS = {".png": "PNG", ".tif": "TIFF", ".tiff": "TIFF"}
DEVELOPED_EXTENSIONS = {".jpg": "JPEG", ".jpeg": "JPEG", ".png": "PNG", ".tif": "TIFF", ".tiff": "TIFF"}


def output_kind(camera, path) -> str | None:
    """``"raw"``, ``"developed"`` or None (the ordinary writer) for this camera and output path;
    InputError for a raw mosaic asked for as a JPEG."""
    if camera is None or getattr(camera, "raw_calibration", None) is None:
        return None
    ext = Path(str(path)).suffix.lower()
    if ext == ".exr":
        return None
    if camera.isp:
        return "developed" if ext in DEVELOPED_EXTENSIONS else None
    if ext in RAW_EXTENSIONS:
        return "raw"
    raise InputError(f"{path}: a raw mosaic is written as 16-bit .png or .tif (with a .json sidecar) or as .exr; "
                     "for a camera JPEG add --isp on")


def sidecar_path(path) -> Path:
    """``<stem>.raw.json`` beside the image (a name no other clpost output uses)."""
    p = Path(path)
    return p.with_name(p.stem + ".raw.json")


def raw_dn(frame_color, camera) -> np.ndarray:
    """(H, W) uint16 DN of the raw stage's normalised mosaic (channel 0)."""
    from . import sensor_calibration as calib

    c = calib.load(camera.raw_calibration)
    v = np.asarray(frame_color, np.float64)[..., 0]
    dn = np.round(v * (c.white_level_dn - c.black_level_dn) + c.black_level_dn)
    return np.clip(dn, 0, c.white_level_dn).astype(np.uint16)


def sidecar(camera, width: int, height: int, frame_index: int = 0) -> dict:
    from . import sensor_calibration as calib
    from .stages.isp import colour_matrix, white_balance_gains
    from .stages.raw import pattern

    c = calib.load(camera.raw_calibration)
    n = c.at_iso(camera.iso)
    pat = pattern(camera)  # the raw stage starts it at the display window's top-left
    return {
        "format": RAW_FORMAT, "width": width, "height": height, "cfa_pattern": pat,
        "gain_channels": ["R", "C" if "C" in pat else "G", "B"],
        "bits": c.bits, "black_level_dn": c.black_level_dn, "white_level_dn": c.white_level_dn,
        "iso": camera.iso, "frame_index": frame_index, "noise_seed": camera.noise_seed,
        "white_balance_gains": [float(g) for g in white_balance_gains(camera)],
        "camera_to_srgb": colour_matrix(camera).tolist(),
        "working_space": camera.working_space,
        "working_rgb_to_camera": c.rgb_to_camera(camera.working_space).tolist(),
        "noise": {"gain_dn_per_e": n.gain_dn_per_e, "read_noise_dn": n.read_noise_dn, "row_noise_dn": n.row_noise_dn,
                  "column_noise_dn": n.column_noise_dn, "dsnu_dn": n.dsnu_dn, "prnu": n.prnu,
                  "full_well_e": c.full_well_e},
        "calibration": c.name,
        "meaning": "DN = black_level_dn + signal * (white_level_dn - black_level_dn); develop: subtract black, divide "
                   "by (white - black), demosaic, multiply by white_balance_gains (channels R, G or C, B), "
                   "then camera_to_srgb (rows sum to 1) gives linear sRGB",
    }


def write_raw(path, color, camera, frame_index: int = 0) -> None:
    """16-bit single-channel mosaic (the display window) and its JSON sidecar (module docstring),
    atomically."""
    from PIL import Image

    from .atomic import atomic_path

    fmt = RAW_EXTENSIONS[Path(str(path)).suffix.lower()]
    dn = raw_dn(color, camera)
    img = Image.fromarray(dn)  # uint16 → Pillow's "I;16": a 16-bit greyscale PNG/TIFF
    extra = {"compression": "tiff_deflate"} if fmt == "TIFF" else {}
    with atomic_path(path) as tmp:
        img.save(tmp, format=fmt, **extra)
    meta = sidecar(camera, dn.shape[1], dn.shape[0], frame_index)
    with atomic_path(sidecar_path(path)) as tmp:
        Path(tmp).write_text(json.dumps(meta, indent=1) + "\n")


def write_developed(path, color, camera) -> None:
    """The ISP's display-encoded sRGB as an 8-bit image (JPEG at ``camera.isp_jpeg_quality``)."""
    from PIL import Image

    from .atomic import atomic_path
    from .display_image import icc_profile

    fmt = DEVELOPED_EXTENSIONS[Path(str(path)).suffix.lower()]
    codes = np.round(np.clip(np.asarray(color, np.float64)[..., :3], 0.0, 1.0) * 255.0).astype(np.uint8)
    img = Image.fromarray(np.ascontiguousarray(codes), mode="RGB")
    extra = {"icc_profile": icc_profile("srgb")}
    if fmt == "JPEG":
        extra.update(quality=int(camera.isp_jpeg_quality), subsampling=2)
    elif fmt == "TIFF":
        extra["compression"] = "tiff_deflate"
    with atomic_path(path) as tmp:
        img.save(tmp, format=fmt, **extra)


def write(path, color, camera, frame_index: int = 0) -> bool:
    """Write ``color`` as :func:`output_kind` says; False if it is the ordinary writer's."""
    kind = output_kind(camera, path)
    if kind == "raw":
        write_raw(path, color, camera, frame_index)
    elif kind == "developed":
        write_developed(path, color, camera)
    return kind is not None


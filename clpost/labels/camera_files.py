"""The effective camera of an output, in the forms computer-vision tools load directly.

The **effective camera** is the one whose image the output is: after the ``distortion`` stage the
calibration it rendered (magnified by ``--fill crop``'s factor when that applies: the same c and
coefficients, f·s), else the render's own pinhole — its recorded intrinsics
(``frame.metadata["intrinsics"]``) or ``Camera.intrinsics`` at the image (display window) size.
Pixel coordinates are OpenCV's, relative to the display window (``docs/conventions.md``).

It is written with the calibration writers (:mod:`clpost.calibration.writers`, the same files as
``clpost calibration convert``) in three forms (:data:`CAMERA_FILES`): OpenCV FileStorage YAML
(``cv2.FileStorage(path, cv2.FILE_STORAGE_READ)``), Kalibr camchain YAML and COLMAP
``cameras.txt``; into the output EXR's header as string attributes ``clpost.camera.opencv``,
``clpost.camera.kalibr`` and ``clpost.camera.colmap``, and with ``clpost process --camera-files``
beside each output as ``<output stem>.camera.yaml``, ``.kalibr.yaml`` and ``.cameras.txt``. A form
that cannot express the model (Kalibr's radtan has no k3…k6, COLMAP no thin prism or tilt) is left
out, never written approximately; the OpenCV form expresses every model.
"""
from __future__ import annotations

from pathlib import Path

from ..errors import InputError

CAMERA_FILES = {
    # writer format: (header attribute, file suffix)
    "opencv-yaml": ("clpost.camera.opencv", ".camera.yaml"),
    "kalibr": ("clpost.camera.kalibr", ".kalibr.yaml"),
    "colmap": ("clpost.camera.colmap", ".cameras.txt"),
}


def effective_camera(camera, frame, stage_names, quality: str = "final"):
    """The :class:`~clpost.calibration.OpenCVModel` of the image an output of ``camera`` on input
    ``frame`` is, when ``stage_names`` ran (module docstring)."""
    from ..calibration import OpenCVModel
    from ..stages._field import frame_intrinsics

    if "distortion" in stage_names:
        from ..stages.distortion import Distortion

        return Distortion(quality)._model(camera, frame)
    win = frame.windows
    w, h = win.display_size
    k = frame_intrinsics(frame)
    if k is not None:
        ox, oy = win.display_offset
        fx, fy, cx, cy = k[0], k[1], k[2] - ox, k[3] - oy
    else:
        fx, fy, cx, cy = camera.intrinsics(w, h)
    return OpenCVModel(w, h, fx, fy, cx, cy, source="effective camera")


def camera_texts(model) -> dict[str, str]:
    """Writer format → file text, for each of :data:`CAMERA_FILES` that can express ``model``."""
    from ..calibration import calibration_text

    out = {}
    for fmt in CAMERA_FILES:
        try:
            out[fmt] = calibration_text(model, fmt)
        except InputError:
            continue  # the format cannot express the model: left out, never approximated
    return out


def camera_header(model) -> dict[str, str]:
    """The EXR header attributes of the effective camera (module docstring)."""
    return {CAMERA_FILES[fmt][0]: text for fmt, text in camera_texts(model).items()}


def camera_paths(dst: str | Path) -> dict[str, Path]:
    """Writer format → the file beside output ``dst`` (``<stem>.camera.yaml`` …)."""
    dst = Path(dst)
    return {fmt: dst.with_name(dst.stem + suffix) for fmt, (_, suffix) in CAMERA_FILES.items()}


def write_camera_files(model, dst: str | Path) -> list[Path]:
    """Write the effective camera beside output ``dst`` atomically, each form that expresses it."""
    from ..atomic import atomic_path

    written = []
    paths = camera_paths(dst)
    for fmt, text in camera_texts(model).items():
        with atomic_path(paths[fmt]) as tmp:
            Path(tmp).write_text(text)
        written.append(paths[fmt])
    return written

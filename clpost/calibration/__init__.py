r"""The computer-vision standard camera model (OpenCV / Matlab) and calibration files.

One module per job:

* :mod:`~clpost.calibration.model` — :class:`OpenCVModel` (forward model, fold radius) and its
  inverses (:func:`undistort_newton`, :class:`HeikkilaInverse`, :func:`undistort`);
* :mod:`~clpost.calibration.frustum` — the render that covers a distorted image
  (:func:`required_render`, :class:`RenderSpec`, the overscan around the calibration's own K
  :func:`overscan_px`) and the intrinsics of a render of a given size
  (:func:`render_intrinsics`), cached per (model, size);
* :mod:`~clpost.calibration.traced` — a ``lens_data`` lens's traced distortion as an OpenCV model
  (:func:`lens_distortion_model`);
* :mod:`~clpost.calibration.formats` — reading OpenCV FileStorage YAML/XML/JSON, ROS camera_info,
  COLMAP ``cameras.txt`` and Kalibr camchain files (:func:`load_calibration`);
* :mod:`~clpost.calibration.writers` — writing a model back out in those formats
  (:func:`write_calibration`);
* :mod:`~clpost.calibration.header` — the model as the EXR header's named fields
  (:func:`header_text`, :func:`model_from_header`).

Every public name is importable from ``clpost.calibration``.
"""
from .formats import COLMAP_MODELS, load_calibration
from .frustum import RenderSpec, overscan_px, render_intrinsics, required_render, undistorted_bounds
from .header import header_text, model_from_header
from .model import (COEFF_NAMES, DISTORTION_MODELS, FISHEYE_COEFF_NAMES, HeikkilaInverse, OpenCVModel,
                    inverse_residual_px, undistort, undistort_newton)
from .traced import lens_distortion_model
from .writers import FORMATS, calibration_text, write_calibration

__all__ = ["COEFF_NAMES", "COLMAP_MODELS", "DISTORTION_MODELS", "FISHEYE_COEFF_NAMES", "FORMATS", "HeikkilaInverse",
           "OpenCVModel", "RenderSpec", "calibration_text", "header_text", "inverse_residual_px",
           "lens_distortion_model", "load_calibration", "model_from_header", "overscan_px", "render_intrinsics",
           "required_render", "undistort", "undistort_newton", "undistorted_bounds", "write_calibration"]

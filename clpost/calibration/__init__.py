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
* :mod:`~clpost.calibration.formats` — OpenCV/ROS YAML and JSON, COLMAP ``cameras.txt``
  (:func:`load_calibration`).

Every public name is importable from ``clpost.calibration``.
"""
from .formats import COLMAP_MODELS, load_calibration
from .frustum import RenderSpec, overscan_px, render_intrinsics, required_render, undistorted_bounds
from .model import COEFF_NAMES, HeikkilaInverse, OpenCVModel, inverse_residual_px, undistort, undistort_newton
from .traced import lens_distortion_model

__all__ = ["COEFF_NAMES", "COLMAP_MODELS", "HeikkilaInverse", "OpenCVModel", "RenderSpec", "inverse_residual_px",
           "lens_distortion_model", "load_calibration", "overscan_px", "render_intrinsics", "required_render",
           "undistort", "undistort_newton", "undistorted_bounds"]

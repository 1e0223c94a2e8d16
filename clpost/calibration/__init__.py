r"""The computer-vision standard camera model (OpenCV / Matlab) and calibration files.

One module per job:

* :mod:`~clpost.calibration.model` — :class:`OpenCVModel` (every family: ``project_rays`` /
  ``unproject``, D and K, fold radius) and its inverses (:func:`undistort_newton`,
  :class:`HeikkilaInverse`, :func:`undistort`, :func:`unproject_plane`);
* :mod:`~clpost.calibration.projections` — each family's central projection P and its exact inverse;
* :mod:`~clpost.calibration.cubemap` — the cubemap atlas a field of view beyond 150° is rendered to
  (:class:`CubemapSpec`, :func:`required_cubemap`);
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
from .cubemap import CubemapSpec, required_cubemap
from .formats import COLMAP_MODELS, load_calibration
from .frustum import RenderSpec, overscan_px, render_intrinsics, required_render, undistorted_bounds
from .header import header_text, model_from_header
from .frustum import PINHOLE_LIMIT_DEG, max_ray_angle_deg
from .model import (COEFF_NAMES, DISTORTION_MODELS, FAMILY_PARAMS, FISHEYE_COEFF_NAMES, HeikkilaInverse, OpenCVModel,
                    inverse_residual_px, undistort, undistort_newton, unproject_plane)
from .traced import lens_distortion_model
from .writers import FORMATS, calibration_text, write_calibration

__all__ = ["COEFF_NAMES", "COLMAP_MODELS", "CubemapSpec", "FAMILY_PARAMS", "PINHOLE_LIMIT_DEG", "max_ray_angle_deg",
           "required_cubemap", "unproject_plane", "DISTORTION_MODELS", "FISHEYE_COEFF_NAMES", "FORMATS", "HeikkilaInverse",
           "OpenCVModel", "RenderSpec", "calibration_text", "header_text", "inverse_residual_px",
           "lens_distortion_model", "load_calibration", "model_from_header", "overscan_px", "render_intrinsics",
           "required_render", "undistort", "undistort_newton", "undistorted_bounds", "write_calibration"]

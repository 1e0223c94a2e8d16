r"""Labels that follow the geometry: what a computer-vision user trains on, moved with the pixels.

One module per job:

* :mod:`~clpost.labels.channels` — which label channels (ids, segmentation, normals, any AOV) a
  frame carries (``Camera.labels`` / ``--labels``) and the nearest-sample rule that moves them
  through the geometric stages (never blended);
* :mod:`~clpost.labels.coco` — COCO keypoints, boxes and polygons mapped with the exact forward
  model of the camera (:func:`map_coco`);
* :mod:`~clpost.labels.camera_files` — the effective camera of an output (the calibration the
  distortion stage rendered, or the render's pinhole) in OpenCV FileStorage YAML, Kalibr camchain
  YAML and COLMAP ``cameras.txt`` forms, beside the output and in its EXR header;
* :mod:`~clpost.labels.command` — ``clpost labels map``.
"""
from .camera_files import CAMERA_FILES, camera_header, camera_texts, effective_camera, write_camera_files
from .channels import LABEL_FILL, auto_label, nearest_labels, parse_labels, select_labels
from .coco import map_coco, map_points

__all__ = ["CAMERA_FILES", "LABEL_FILL", "auto_label", "camera_header", "camera_texts", "effective_camera",
           "map_coco", "map_points", "nearest_labels", "parse_labels", "select_labels", "write_camera_files"]

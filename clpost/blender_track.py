"""Blender camera → clpost track keyframes: the conversion ``tools/blender_camera_track.py`` runs
inside Blender (plain Python on attribute values, no ``bpy`` import, no relative imports — the tool
loads this file by path because Blender's Python has no clpost installed; tests use fake objects).

Per frame (see the tool's docstring for the table): ``focus`` from the focus object's depth along
the camera's view axis (planar, like Blender's DoF and clpost's depth pass) or ``dof.focus_distance``,
in metres via ``unit_settings.scale_length``; ``f-number`` = ``dof.aperture_fstop``; ``depth-of-field``
= ``dof.use_dof``; ``lens`` = ``thin:<lens mm>``; ``sensor`` = the extent along the image width
(Blender's sensor fit; AUTO fits the larger side) × the matching height; ``shutter`` =
``motion_blur_shutter`` (frames) / fps; ``fps`` only with motion blur on.
"""
from __future__ import annotations

import math
from typing import Any, Sequence


def focus_from_object(cam_matrix: Sequence[Sequence[float]], target: Sequence[float]) -> float:
    """Depth (scene units) of ``target`` along the camera's view axis: ``(p − c) · (−z)`` with c
    the camera position and z its local +Z axis (Blender cameras look down −Z), both from the
    camera's 4×4 world matrix (rows, column 3 = translation)."""
    c = [cam_matrix[i][3] for i in range(3)]
    z = [cam_matrix[i][2] for i in range(3)]
    n = math.sqrt(sum(v * v for v in z)) or 1.0
    return -sum((p - q) * v / n for p, q, v in zip(target, c, z))


def sensor_mm(cam_data: Any, res_x: float, res_y: float) -> tuple[float, float]:
    """(width, height) mm of the sensor area imaged, with clpost's horizontal fit."""
    fit = getattr(cam_data, "sensor_fit", "AUTO")
    aspect = res_x / res_y
    if fit == "VERTICAL" or (fit == "AUTO" and res_y > res_x):
        h = cam_data.sensor_height if fit == "VERTICAL" else cam_data.sensor_width
        return h * aspect, h
    w = cam_data.sensor_width
    return w, w / aspect


def camera_keys(frame: int, cam_obj: Any, scene: Any) -> dict[str, Any]:
    """One keyframe of the track from a camera object and its scene at ``frame``."""
    data = cam_obj.data
    dof = data.dof
    scale = float(getattr(getattr(scene, "unit_settings", None), "scale_length", 1.0) or 1.0)
    if getattr(dof, "focus_object", None) is not None:
        target = dof.focus_object.matrix_world.translation
        focus = focus_from_object(cam_obj.matrix_world, [target[0], target[1], target[2]]) * scale
    else:
        focus = float(dof.focus_distance) * scale
    r = scene.render
    res_x = r.resolution_x * getattr(r, "pixel_aspect_x", 1.0)
    res_y = r.resolution_y * getattr(r, "pixel_aspect_y", 1.0)
    fps = r.fps / r.fps_base
    key: dict[str, Any] = {"frame": int(frame), "focus": round(focus, 9) if focus > 0 else "inf",
                           "f-number": round(float(dof.aperture_fstop), 6),
                           "depth-of-field": "on" if dof.use_dof else "off"}
    if getattr(data, "type", "PERSP") == "PERSP":
        key["lens"] = f"thin:{float(data.lens):.6g}"
    w, h = sensor_mm(data, res_x, res_y)
    key["sensor"] = f"{w:.6g}x{h:.6g}"
    key["shutter"] = float(r.motion_blur_shutter) / fps
    if getattr(r, "use_motion_blur", False):
        key["fps"] = fps
    return key


def export(scene: Any, cam_obj: Any, frames: Sequence[int], source: str) -> dict:
    """The track document: every frame of ``frames`` (the scene is stepped with frame_set)."""
    keys = []
    for f in frames:
        scene.frame_set(f)
        keys.append(camera_keys(f, cam_obj, scene))
    return {"format": "clpost camera track",
            "comment": f"{source}: camera {cam_obj.name!r}, frames {frames[0]}-{frames[-1]}, "
                       "by tools/blender_camera_track.py",
            "interpolation": {"lens": "step", "sensor": "step", "depth-of-field": "step"},
            "keys": keys}

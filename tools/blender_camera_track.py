"""Export a Blender scene camera's animation as a clpost camera track (``--camera-track``).

Run with a Python that has Blender as a module (an optional tool dependency, never a clpost one),
or inside Blender::

    python3 -m venv /tmp/bpyvenv && /tmp/bpyvenv/bin/pip install bpy==5.0.1
    /tmp/bpyvenv/bin/python tools/blender_camera_track.py shot.blend -o shot_track.json
    blender -b shot.blend --python tools/blender_camera_track.py -- -o shot_track.json

then ``clpost process render.####.exr -o out.####.exr --camera-track shot_track.json``.

Per frame of the scene's range (``--frames A-B`` to change it), from the active scene camera
(``--camera NAME`` for another):

=================  =================================================================  ==========
track key          from                                                               unit
=================  =================================================================  ==========
``focus``          ``dof.focus_object``: its origin's depth along the camera's view   m
                   axis (planar, as Blender's own DoF and clpost's depth pass);
                   else ``dof.focus_distance``
``f-number``       ``dof.aperture_fstop``
``depth-of-field`` ``dof.use_dof`` (on/off)
``lens``           ``thin:<lens>`` (perspective cameras; a focal-length change is a
                   zoom: one clpost plan per distinct value)                          mm
``sensor``         the sensor extent along the image width (Blender's sensor fit:     mm
                   AUTO fits the larger image side) × the matching height
``shutter``        ``render.motion_blur_shutter`` (frames) / fps                      s
``fps``            ``render.fps / render.fps_base``, only with motion blur on          1/s
=================  =================================================================  ==========

Scene units are converted to metres with ``unit_settings.scale_length``. The JSON lists every
frame (so the interpolation never matters between them); the format is ``docs/camera-tracks.md``.
The conversion (:func:`camera_keys`) is plain Python on attribute values, so it is tested without
Blender (``tests/test_blender_camera_track.py``).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
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


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--" in argv:  # blender -b x.blend --python this.py -- ARGS
        argv = argv[argv.index("--") + 1:]
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("blend", nargs="?", help=".blend file (omit inside Blender: the open file)")
    p.add_argument("-o", "--output", required=True, help="track JSON to write")
    p.add_argument("--camera", default=None, help="camera object name (default: the scene camera)")
    p.add_argument("--frames", default=None, help="A-B (default: the scene's frame range)")
    a = p.parse_args(argv)
    import bpy

    if a.blend:
        bpy.ops.wm.open_mainfile(filepath=a.blend)
    scene = bpy.context.scene
    cam = bpy.data.objects[a.camera] if a.camera else scene.camera
    if cam is None or cam.type != "CAMERA":
        print(f"blender_camera_track: error: no camera {'named ' + repr(a.camera) if a.camera else 'in the scene'}; "
              "set the scene camera or pass --camera NAME", file=sys.stderr)
        return 2
    if a.frames:
        lo, _, hi = a.frames.partition("-")
        frames = list(range(int(lo), int(hi or lo) + 1))
    else:
        frames = list(range(scene.frame_start, scene.frame_end + 1, scene.frame_step))
    doc = export(scene, cam, frames, a.blend or bpy.data.filepath or "(unsaved)")
    with open(a.output, "w") as fh:
        json.dump(doc, fh, indent=1)
    print(f"wrote {len(doc['keys'])} keyframes of camera {cam.name!r} to {a.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

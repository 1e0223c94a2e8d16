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
The conversion is :mod:`clpost.blender_track` (plain Python on attribute values), tested without
Blender (``tests/test_blender_camera_track.py``).
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from pathlib import Path
from typing import Sequence


def _conversion():
    """clpost/blender_track.py, loaded by path: Blender's Python has no clpost installed."""
    path = Path(__file__).resolve().parents[1] / "clpost" / "blender_track.py"
    spec = importlib.util.spec_from_file_location("clpost_blender_track", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


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
    doc = _conversion().export(scene, cam, frames, a.blend or bpy.data.filepath or "(unsaved)")
    with open(a.output, "w") as fh:
        json.dump(doc, fh, indent=1)
    print(f"wrote {len(doc['keys'])} keyframes of camera {cam.name!r} to {a.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

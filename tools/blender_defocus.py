"""Blender's compositor Defocus node on a clpost pinhole EXR — the peer the dof stage is measured
against (docs/benchmarks.md, "Blender Defocus").

Run with a Python that has Blender as a module (an optional tool dependency, never a clpost
one; keep it out of clpost's venv)::

    python3 -m venv /tmp/bpyvenv && /tmp/bpyvenv/bin/pip install bpy==5.0.1 numpy OpenEXR
    /tmp/bpyvenv/bin/python tools/blender_defocus.py pinhole.exr out.exr --f-number 2 \\
        --focal-mm 50 --sensor-mm 36 --focus-m 3 --blades 6 --max-blur 64 --threads 2 --json t.json

This script does not import clpost: data comes in and goes out as EXR files. Input: clpost's
native single-part layout (R, G, B float, Z planar metres, +inf for sky; CONVENTIONS.md).
Output: R, G, B float32, same size and orientation.

What it sets up (Blender 5.0 compositor, CPU, full float precision, ``--threads`` threads):
two float images made from the EXR's pixels (colour; depth in all three channels with +inf
replaced by ``--sky-depth``, Blender's own sky value 1e10 — Defocus computes the image distance
``f·S/(S−f)``, which is NaN for S = inf), ``Image → Defocus(Z = depth.Red) → Group Output``, and
a scene camera carrying the lens (Defocus takes focal length, sensor width (horizontal fit) and
focus distance from the scene camera, and f-stop, bokeh polygon, rotation and max blur from the
node). The scene itself is not rendered: a compositor tree without a Render Layers node only
composites.

Timing: wall time of ``bpy.ops.render.render()`` (median of ``--repeats`` after one warm-up),
minus the same for the tree without the Defocus node (image → output), so what is left is the
Defocus node's own time; both are reported.
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time

import numpy as np
import OpenEXR

import bpy

# Blender's polygon bokeh types by blade count (the node offers 3…8 and the circle only).
BOKEH = {0: "CIRCLE", 3: "TRIANGLE", 4: "SQUARE", 5: "PENTAGON", 6: "HEXAGON", 7: "HEPTAGON", 8: "OCTAGON"}


def read_clpost_exr(path: str) -> tuple[np.ndarray, np.ndarray]:
    """(color H×W×3 float32, depth H×W float32) from clpost's native layout, row 0 at the top."""
    f = OpenEXR.File(path, separate_channels=True)
    ch = f.parts[0].channels
    missing = [c for c in ("R", "G", "B", "Z") if c not in ch]
    if missing:
        sys.exit(f"{path}: channels {missing} missing; write it with clpost's native layout (R, G, B, Z)")
    color = np.stack([ch[c].pixels for c in "RGB"], -1).astype(np.float32)
    return color, ch["Z"].pixels.astype(np.float32)


def write_rgb_exr(path: str, rgb: np.ndarray) -> None:
    chans = {c: np.ascontiguousarray(rgb[..., i], dtype=np.float32) for i, c in enumerate("RGB")}
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, chans).write(path)


def blender_image(name: str, rgb: np.ndarray) -> "bpy.types.Image":
    """A float image holding ``rgb`` untouched: Non-Color, so no colour-space conversion; Blender
    stores rows bottom-up, hence the flip."""
    h, w, _ = rgb.shape
    img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True, is_data=True)
    img.colorspace_settings.name = "Non-Color"
    rgba = np.concatenate([rgb, np.ones((h, w, 1), np.float32)], -1)[::-1]
    img.pixels.foreach_set(np.ascontiguousarray(rgba, np.float32).ravel())
    img.pack()
    return img


def setup_scene(w: int, h: int, a) -> "bpy.types.Scene":
    scene = bpy.context.scene
    for ob in list(scene.objects):
        if ob.type != "CAMERA":
            bpy.data.objects.remove(ob)
    cam_ob = next((ob for ob in scene.objects if ob.type == "CAMERA"), None)
    if cam_ob is None:
        cam_ob = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
        scene.collection.objects.link(cam_ob)
    scene.camera = cam_ob
    cam = cam_ob.data
    cam.type = "PERSP"
    cam.lens = a.focal_mm
    cam.sensor_fit = "HORIZONTAL"  # clpost: the image spans the sensor width
    cam.sensor_width = a.sensor_mm
    cam.dof.use_dof = True
    cam.dof.focus_object = None
    cam.dof.focus_distance = a.focus_m
    cam.dof.aperture_fstop = a.f_number
    cam.dof.aperture_blades = a.blades
    cam.dof.aperture_rotation = math.radians(a.rotation_deg)

    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = w, h, 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0
    r.use_border = False
    r.engine = "BLENDER_WORKBENCH"  # never used: the tree has no Render Layers node
    r.threads_mode = "FIXED"
    r.threads = a.threads
    r.use_compositing = True
    r.use_sequencer = False
    r.compositor_device = "CPU"
    r.compositor_precision = "FULL"  # no half-float intermediates
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    r.image_settings.exr_codec = "ZIP"
    r.image_settings.color_mode = "RGB"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.display_settings.display_device = "sRGB"
    return scene


def build_tree(scene, color_img, depth_img, a, defocus: bool):
    tree = bpy.data.node_groups.new("clpost_defocus" if defocus else "clpost_passthrough", "CompositorNodeTree")
    tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    out = tree.nodes.new("NodeGroupOutput")
    col = tree.nodes.new("CompositorNodeImage")
    col.image = color_img
    if not defocus:
        tree.links.new(col.outputs["Image"], out.inputs[0])
        return tree, None
    dep = tree.nodes.new("CompositorNodeImage")
    dep.image = depth_img
    sep = tree.nodes.new("CompositorNodeSeparateColor")
    sep.mode = "RGB"
    dof = tree.nodes.new("CompositorNodeDefocus")
    dof.scene = scene
    dof.use_zbuffer = True  # Z is planar depth in metres, CoC from the camera's thin lens
    dof.f_stop = a.f_number
    dof.bokeh = BOKEH[a.blades]
    dof.angle = math.radians(a.angle_deg)
    dof.blur_max = a.max_blur
    tree.links.new(dep.outputs["Image"], sep.inputs["Image"])
    tree.links.new(col.outputs["Image"], dof.inputs["Image"])
    tree.links.new(sep.outputs["Red"], dof.inputs["Z"])
    tree.links.new(dof.outputs["Image"], out.inputs[0])
    return tree, dof


def timed_renders(scene, tree, repeats: int) -> list[float]:
    scene.compositing_node_group = tree
    times = []
    for i in range(repeats + 1):
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=False)
        if i:  # the first run loads images and builds the bokeh kernel: warm-up
            times.append(time.perf_counter() - t0)
    return times


def render_result(path: str) -> np.ndarray:
    bpy.data.images["Render Result"].save_render(path)
    f = OpenEXR.File(path, separate_channels=True)
    ch = f.parts[0].channels
    return np.stack([ch[c].pixels for c in "RGB"], -1).astype(np.float32)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("input", help="pinhole EXR in clpost's native layout (R, G, B, Z)")
    p.add_argument("output", help="Defocus result EXR (R, G, B float32)")
    p.add_argument("--f-number", type=float, default=2.0)
    p.add_argument("--focal-mm", type=float, default=50.0)
    p.add_argument("--sensor-mm", type=float, default=36.0, help="sensor width (horizontal fit)")
    p.add_argument("--focus-m", type=float, default=3.0)
    p.add_argument("--blades", type=int, default=6, choices=sorted(BOKEH))
    p.add_argument("--rotation-deg", type=float, default=0.0, help="camera aperture rotation (Cycles)")
    p.add_argument("--angle-deg", type=float, default=0.0,
                   help="Defocus node bokeh rotation (0…90°); see docs/benchmarks.md for the match")
    p.add_argument("--max-blur", type=float, default=64.0, help="Defocus 'Max Blur' (radius, px)")
    p.add_argument("--sky-depth", type=float, default=1e10, help="depth given to +inf (Blender's sky)")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--json", default=None, help="write timings and settings here")
    a = p.parse_args(argv)

    color, depth = read_clpost_exr(a.input)
    h, w, _ = color.shape
    z = np.where(np.isfinite(depth), depth, np.float32(a.sky_depth)).astype(np.float32)
    scene = setup_scene(w, h, a)
    color_img = blender_image("clpost_color", color)
    depth_img = blender_image("clpost_depth", np.repeat(z[..., None], 3, -1))

    tree_pass, _ = build_tree(scene, color_img, depth_img, a, defocus=False)
    t_pass = timed_renders(scene, tree_pass, a.repeats)
    passthrough = render_result(a.output)
    identity_err = float(np.max(np.abs(passthrough - color)))

    tree_dof, _ = build_tree(scene, color_img, depth_img, a, defocus=True)
    t_dof = timed_renders(scene, tree_dof, a.repeats)
    result = render_result(a.output)
    write_rgb_exr(a.output, result)

    report = {
        "blender": bpy.app.version_string, "size": [w, h], "threads": scene.render.threads,
        "settings": {k: v for k, v in vars(a).items() if k not in ("input", "output", "json")},
        "render_s": t_dof, "passthrough_s": t_pass,
        "render_median_s": statistics.median(t_dof), "passthrough_median_s": statistics.median(t_pass),
        "defocus_s": statistics.median(t_dof) - statistics.median(t_pass),
        "passthrough_max_abs_error": identity_err,
        "nonfinite": int(np.count_nonzero(~np.isfinite(result))),
    }
    print(json.dumps(report, indent=1))
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(report, fh, indent=1)
    if identity_err > 1e-6 * max(1.0, float(color.max())):
        print(f"passthrough differs from the input by {identity_err}: colour management is altering data",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

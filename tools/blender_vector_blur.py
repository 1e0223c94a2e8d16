"""Blender's compositor Vector Blur node on a Blender multilayer EXR (Combined, Depth, Vector) — the
motion-blur peer of docs/fidelity.md.

Run with a Python that has Blender as a module (never a clpost dependency)::

    /work/bpyvenv/bin/python tools/blender_vector_blur.py pinhole.exr out.exr --shutter 0.5 \\
        --samples 32 --threads 2 --json t.json

The EXR is loaded as Blender loads a render it wrote (an Image datablock of type MULTILAYER); its
Image node's Combined, Depth and Vector outputs feed ``Vector Blur(Image, Speed, Z)`` →
Group Output, exactly the tree an artist builds. ``--shutter`` is the node's Shutter in frames
(0.5 = 180°, Blender's default). The scene is not rendered (no Render Layers node): the tree only
composites. Timing as tools/blender_defocus.py: median wall time of ``bpy.ops.render.render()``
after one warm-up, minus the same for the tree without the node. Output: R, G, B float32.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys

import numpy as np
import OpenEXR

import bpy

from blender_defocus import render_result, timed_renders  # the same compositor timing and read-back


def setup(w: int, h: int, threads: int):
    scene = bpy.context.scene
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = w, h, 100
    r.engine = "BLENDER_WORKBENCH"  # never used: the tree has no Render Layers node
    r.threads_mode = "FIXED"
    r.threads = threads
    r.use_compositing = True
    r.use_sequencer = False
    r.compositor_device = "CPU"
    r.compositor_precision = "FULL"
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    r.image_settings.color_mode = "RGB"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    return scene


def build_tree(img, samples: int, shutter: float, blur: bool):
    tree = bpy.data.node_groups.new("vector_blur" if blur else "passthrough", "CompositorNodeTree")
    tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    out = tree.nodes.new("NodeGroupOutput")
    src = tree.nodes.new("CompositorNodeImage")
    src.image = img  # loads the file: its passes become the node's outputs
    passes = {o.name for o in src.outputs if o.enabled}
    if not {"Combined", "Depth", "Vector"} <= passes:
        sys.exit(f"{img.filepath}: passes {sorted(passes)}; Vector Blur needs a Blender multilayer EXR with "
                 "Combined, Depth and Vector (render with motion blur off and those passes on)")
    if not blur:
        tree.links.new(src.outputs["Combined"], out.inputs[0])
        return tree
    vb = tree.nodes.new("CompositorNodeVecBlur")
    vb.inputs["Samples"].default_value = samples
    vb.inputs["Shutter"].default_value = shutter
    tree.links.new(src.outputs["Combined"], vb.inputs["Image"])
    tree.links.new(src.outputs["Vector"], vb.inputs["Speed"])
    tree.links.new(src.outputs["Depth"], vb.inputs["Z"])
    tree.links.new(vb.outputs["Image"], out.inputs[0])
    return tree


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("input", help="Blender multilayer EXR with Combined, Depth and Vector passes")
    p.add_argument("output", help="result EXR (R, G, B float32)")
    p.add_argument("--shutter", type=float, default=0.5, help="shutter in frames (0.5 = 180°)")
    p.add_argument("--samples", type=int, default=32)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--json", default=None)
    a = p.parse_args(argv)
    img = bpy.data.images.load(a.input)
    tree_pass = build_tree(img, a.samples, a.shutter, False)  # loads the image
    h, w = next(iter(OpenEXR.File(a.input, separate_channels=True).parts[0].channels.values())).pixels.shape[:2]
    scene = setup(w, h, a.threads)
    t_pass = timed_renders(scene, tree_pass, a.repeats)
    t_vb = timed_renders(scene, build_tree(img, a.samples, a.shutter, True), a.repeats)
    res = render_result(a.output)
    chans = {c: np.ascontiguousarray(res[..., i]) for i, c in enumerate("RGB")}
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, chans).write(a.output)
    report = {"blender": bpy.app.version_string, "size": [w, h], "samples": a.samples, "shutter": a.shutter,
              "render_median_s": statistics.median(t_vb), "passthrough_median_s": statistics.median(t_pass),
              "vector_blur_s": statistics.median(t_vb) - statistics.median(t_pass),
              "nonfinite": int(np.count_nonzero(~np.isfinite(res)))}
    print(json.dumps(report))
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(report, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Render one scene of the Cycles ground-truth suite: the pinhole buffers an artist exports, or a
Cycles truth (thin-lens depth of field, motion blur, or both).

Run with a Python that has Blender as a module (never a clpost dependency)::

    /work/bpyvenv/bin/python tools/cycles_truth/render.py emitters pinhole out.exr --spp 256 --seed 0

Kinds:

- ``pinhole``: DoF and motion blur off; passes Combined, Depth (Z) and Vector, written the way
  Blender writes them by default — one multilayer OpenEXR ("OpenEXR MultiLayer", float, ZIP;
  one part per pass), default Blackman-Harris 1.5 px pixel filter, Depth from Cycles' depth pass
  (planar, 1e10 for the sky), Vector only exists with motion blur off. Every kind also writes the
  Emit pass (light seen directly from the emitters, nothing else): the lamps alone, for the
  per-emitter metrics; clpost's reader ignores it.
- ``dof``: the same camera with Cycles' thin lens (f-stop, blades, rotation, focus distance).
- ``motion``: motion blur on, shutter ``Shot.shutter_frames`` (0.5 frame = 180°), centred on the
  frame.
- ``dofmotion``: both.
- ``fg`` and ``bg`` (scenes of ``scenes.FOREGROUND`` only): the pinhole split into two layers, as
  an artist renders them separately. ``fg``: the foreground objects alone over a transparent film
  (premultiplied RGBA, Depth), everything else invisible to the camera; ``bg``: the rest with the
  foreground invisible to the camera. Invisible objects still cast their shadows, so
  ``fg + (1 − α) bg`` is the pinhole. ``fg``'s Depth pass has alpha threshold 0 (the layer's
  nearest surface however transparent; Blender's default 0.5 skips a pane of opacity 0.3).

Denoising off; adaptive sampling with ``--threshold`` (0 = off) and a minimum of spp/4 samples.
A JSON sidecar (out + ``.json``) records the camera, the lamps, the samples, the seed and the
render time.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import asdict

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import bpy  # noqa: E402

import scenes  # noqa: E402

KINDS = ("pinhole", "dof", "motion", "dofmotion", "fg", "bg")


def configure(kind: str, shot, a) -> None:
    scene = bpy.context.scene
    r = scene.render
    r.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    c.samples = a.spp
    c.seed = a.seed
    c.use_animated_seed = False
    c.use_denoising = False
    c.use_adaptive_sampling = a.threshold > 0
    c.adaptive_threshold = a.threshold
    c.adaptive_min_samples = max(16, a.spp // 4)
    c.max_bounces = 4
    c.diffuse_bounces = 0
    c.glossy_bounces = 1
    c.transmission_bounces = 2
    c.transparent_max_bounces = 16
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    r.threads_mode = "FIXED"
    r.threads = a.threads
    r.use_compositing = False
    r.use_sequencer = False
    r.film_transparent = kind == "fg"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.camera.data.dof.use_dof = kind in ("dof", "dofmotion")
    r.use_motion_blur = kind in ("motion", "dofmotion")
    r.motion_blur_shutter = shot.shutter_frames
    r.motion_blur_position = "CENTER"
    vl = scene.view_layers[0]
    vl.use_pass_combined = True
    vl.use_pass_emit = True  # the lamps alone (the sky is the Environment pass): per-emitter metrics
    vl.use_pass_z = kind in ("pinhole", "fg", "bg")
    vl.use_pass_vector = kind == "pinhole"  # Cycles writes vectors only with motion blur off
    if kind == "fg":  # the depth of the layer's nearest surface however transparent (default 0.5)
        vl.pass_alpha_threshold = 0.0
    im = r.image_settings
    im.media_type = "MULTI_LAYER_IMAGE"
    im.file_format = "OPEN_EXR_MULTILAYER"
    im.color_depth = "32"
    im.exr_codec = "ZIP"


def split_layers(scene_name: str, kind: str) -> None:
    """Hide from the camera what the ``fg`` / ``bg`` layer leaves out (shadows stay)."""
    if kind not in ("fg", "bg"):
        return
    if scene_name not in scenes.FOREGROUND:
        raise SystemExit(f"render.py: kind {kind} needs a scene of scenes.FOREGROUND "
                         f"({', '.join(sorted(scenes.FOREGROUND))}), not {scene_name}")
    for ob in bpy.context.scene.objects:
        if ob.type in ("MESH", "CURVE", "SURFACE", "META"):
            ob.visible_camera = scenes.is_foreground(scene_name, ob.name) == (kind == "fg")


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", choices=sorted(scenes.SCENES))
    p.add_argument("kind", choices=KINDS)
    p.add_argument("output", help="multilayer EXR to write")
    p.add_argument("--size", default="480x270")
    p.add_argument("--spp", type=int, default=256)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threshold", type=float, default=0.0, help="adaptive sampling noise threshold (0: off)")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--blend", default=None, help="also save the scene as this .blend")
    a = p.parse_args(argv)
    w, h = (int(v) for v in a.size.lower().split("x"))
    shot = scenes.build(a.scene, w, h)
    configure(a.kind, shot, a)
    split_layers(a.scene, a.kind)
    scene = bpy.context.scene
    scene.render.filepath = os.path.abspath(a.output)
    scene.render.use_file_extension = False
    if a.blend:
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(a.blend))
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    seconds = time.perf_counter() - t0
    info = {"scene": a.scene, "kind": a.kind, "size": [w, h], "spp": a.spp, "seed": a.seed,
            "adaptive_threshold": a.threshold, "threads": a.threads, "render_s": round(seconds, 2),
            "blender": bpy.app.version_string, "shot": asdict(shot)}
    with open(a.output + ".json", "w") as fh:
        json.dump(info, fh, indent=1)
    print(json.dumps({k: v for k, v in info.items() if k != "shot"}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Procedural Blender scenes for the Cycles ground-truth suite (tools/cycles_truth/render.py).

Each scene aims at one known failure of post-process depth of field or motion blur
(docs/fidelity.md). Runs inside a Python with Blender as a module (``bpy``); never imported by
clpost.

World and units: metres; the camera is at (0, 0, CAM_Z) above the ground plane z = 0, looking along +Y (Blender camera rotation (90°, 0, 0)), so a point's
planar depth is its y coordinate. Lighting is deliberately low-noise: two sun lamps (a key with
hard shadows, a shadowless fill), no diffuse bounces, a sky colour seen only by camera rays. The
noise that remains comes from what the truth is about: pixel-filter anti-aliasing, aperture and
shutter sampling, glossy highlights.

Emitters ("lamps") are small spheres with an Emission shader visible only to camera rays (they
light nothing, so they add no noise to the rest of the image). Their radiance is given in
multiples of a sunlit diffuse white (:data:`WHITE`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import bpy

CAM_Z = 1.5
SUN_KEY = 2.4  # W/m² (Cycles sun strength): diffuse albedo 0.8 under it ≈ 0.8·2.4/π·cos ≈ 0.5
SUN_FILL = 0.6
WHITE = 0.6  # linear value of sunlit diffuse white in these scenes (for emitter radiance)
SKY = (0.35, 0.5, 0.85)


@dataclass
class Shot:
    """The camera and timing of one scene, mirrored into the manifest for clpost's Camera."""
    focal_mm: float = 50.0
    sensor_mm: float = 36.0  # width; sensor fit horizontal
    f_number: float = 1.4
    focus_m: float = 2.0
    blades: int = 6
    rotation_deg: float = 0.0
    fps: float = 24.0
    shutter_frames: float = 0.5  # 180°
    frame: int = 1
    motion: bool = False  # scene has moving objects (vector pass matters, motion truths rendered)
    lamps: list = field(default_factory=list)  # [(name, (x, y, z) at the rendered frame, radius)]


# ----------------------------------------------------------------------------------------------
# materials
# ----------------------------------------------------------------------------------------------

def _mat(name):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nt = m.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    return m, nt, out


def diffuse(name, rgb):
    m, nt, out = _mat(name)
    d = nt.nodes.new("ShaderNodeBsdfDiffuse")
    d.inputs["Color"].default_value = (*rgb, 1)
    nt.links.new(d.outputs[0], out.inputs["Surface"])
    return m


def checker(name, rgb1, rgb2, scale):
    """Diffuse checkerboard in object coordinates (scale = squares per metre)."""
    m, nt, out = _mat(name)
    tc = nt.nodes.new("ShaderNodeTexCoord")
    ck = nt.nodes.new("ShaderNodeTexChecker")
    ck.inputs["Color1"].default_value = (*rgb1, 1)
    ck.inputs["Color2"].default_value = (*rgb2, 1)
    ck.inputs["Scale"].default_value = scale
    d = nt.nodes.new("ShaderNodeBsdfDiffuse")
    nt.links.new(tc.outputs["Object"], ck.inputs["Vector"])
    nt.links.new(ck.outputs["Color"], d.inputs["Color"])
    nt.links.new(d.outputs[0], out.inputs["Surface"])
    return m


def emission(name, strength, rgb=(1.0, 1.0, 1.0)):
    m, nt, out = _mat(name)
    e = nt.nodes.new("ShaderNodeEmission")
    e.inputs["Color"].default_value = (*rgb, 1)
    e.inputs["Strength"].default_value = strength
    nt.links.new(e.outputs[0], out.inputs["Surface"])
    m.cycles.emission_sampling = "NONE"  # seen by the camera only; lights nothing
    return m


def glossy(name, rgb, roughness):
    m, nt, out = _mat(name)
    p = nt.nodes.new("ShaderNodeBsdfPrincipled")
    p.inputs["Base Color"].default_value = (*rgb, 1)
    p.inputs["Roughness"].default_value = roughness
    p.inputs["Metallic"].default_value = 0.0
    nt.links.new(p.outputs[0], out.inputs["Surface"])
    return m


def see_through(name, rgb, opacity, pattern_scale=None):
    """Diffuse mixed with a Transparent BSDF: opacity in [0, 1]. With ``pattern_scale`` the
    opacity is modulated by a checker (opacity on one colour, opacity/3 on the other)."""
    m, nt, out = _mat(name)
    d = nt.nodes.new("ShaderNodeBsdfDiffuse")
    d.inputs["Color"].default_value = (*rgb, 1)
    t = nt.nodes.new("ShaderNodeBsdfTransparent")
    mix = nt.nodes.new("ShaderNodeMixShader")
    if pattern_scale is None:
        mix.inputs["Fac"].default_value = opacity
    else:
        tc = nt.nodes.new("ShaderNodeTexCoord")
        ck = nt.nodes.new("ShaderNodeTexChecker")
        ck.inputs["Color1"].default_value = (opacity,) * 3 + (1,)
        ck.inputs["Color2"].default_value = (opacity / 3,) * 3 + (1,)
        ck.inputs["Scale"].default_value = pattern_scale
        nt.links.new(tc.outputs["Object"], ck.inputs["Vector"])
        nt.links.new(ck.outputs["Color"], mix.inputs["Fac"])
    nt.links.new(t.outputs[0], mix.inputs[1])
    nt.links.new(d.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])
    return m


def bricks(name, rgb1, rgb2, mortar, scale):
    """Diffuse brick texture in object coordinates on a wall facing the camera (courses along x,
    stacked along z; a texture other than the suite's checkers)."""
    m, nt, out = _mat(name)
    tc = nt.nodes.new("ShaderNodeTexCoord")
    sep = nt.nodes.new("ShaderNodeSeparateXYZ")
    comb = nt.nodes.new("ShaderNodeCombineXYZ")
    nt.links.new(tc.outputs["Object"], sep.inputs[0])
    nt.links.new(sep.outputs["X"], comb.inputs["X"])
    nt.links.new(sep.outputs["Z"], comb.inputs["Y"])
    nt.links.new(sep.outputs["Y"], comb.inputs["Z"])
    br = nt.nodes.new("ShaderNodeTexBrick")
    br.inputs["Color1"].default_value = (*rgb1, 1)
    br.inputs["Color2"].default_value = (*rgb2, 1)
    br.inputs["Mortar"].default_value = (*mortar, 1)
    br.inputs["Scale"].default_value = scale
    d = nt.nodes.new("ShaderNodeBsdfDiffuse")
    nt.links.new(comb.outputs[0], br.inputs["Vector"])
    nt.links.new(br.outputs["Color"], d.inputs["Color"])
    nt.links.new(d.outputs[0], out.inputs["Surface"])
    return m


def foliage(name, rgb, scale):
    """Alpha-cut leaves: a Voronoi cell pattern thresholded to a binary mask (the alpha-textured
    foliage card of game and film assets)."""
    m, nt, out = _mat(name)
    tc = nt.nodes.new("ShaderNodeTexCoord")
    vor = nt.nodes.new("ShaderNodeTexVoronoi")
    vor.feature = "DISTANCE_TO_EDGE"
    vor.inputs["Scale"].default_value = scale
    ramp = nt.nodes.new("ShaderNodeMath")
    ramp.operation = "GREATER_THAN"
    ramp.inputs[1].default_value = 0.08
    d = nt.nodes.new("ShaderNodeBsdfDiffuse")
    d.inputs["Color"].default_value = (*rgb, 1)
    t = nt.nodes.new("ShaderNodeBsdfTransparent")
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(tc.outputs["Object"], vor.inputs["Vector"])
    nt.links.new(vor.outputs["Distance"], ramp.inputs[0])
    nt.links.new(ramp.outputs[0], mix.inputs["Fac"])
    nt.links.new(t.outputs[0], mix.inputs[1])
    nt.links.new(d.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])
    return m


# ----------------------------------------------------------------------------------------------
# objects
# ----------------------------------------------------------------------------------------------

def box(name, center, size, mat, rot_deg=(0, 0, 0)):
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=center, rotation=tuple(math.radians(r) for r in rot_deg))
    ob = bpy.context.active_object
    ob.name = name
    ob.scale = size
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)  # textures in metres
    ob.data.materials.append(mat)
    return ob


def plane(name, center, size, mat, rot_deg=(90, 0, 0)):
    """A rectangle (size = (w, h)); default rotation faces the camera (normal −Y)."""
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=center, rotation=tuple(math.radians(r) for r in rot_deg))
    ob = bpy.context.active_object
    ob.name = name
    ob.scale = (size[0], size[1], 1)
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    ob.data.materials.append(mat)
    return ob


def sphere(name, center, radius, mat, segments=32):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=center, segments=segments, ring_count=segments // 2)
    ob = bpy.context.active_object
    ob.name = name
    bpy.ops.object.shade_smooth()
    ob.data.materials.append(mat)
    return ob


def cylinder(name, p0, p1, radius, mat, vertices=16):
    """A cylinder from p0 to p1 (wires, poles, railing bars)."""
    import mathutils
    a, b = mathutils.Vector(p0), mathutils.Vector(p1)
    d = b - a
    bpy.ops.mesh.primitive_cylinder_add(radius=radius, depth=d.length, vertices=vertices, location=(a + b) / 2)
    ob = bpy.context.active_object
    ob.name = name
    ob.rotation_mode = "QUATERNION"
    ob.rotation_quaternion = mathutils.Vector((0, 0, 1)).rotation_difference(d.normalized())
    bpy.ops.object.shade_smooth()
    ob.data.materials.append(mat)
    return ob


def lamp(shot, name, center, px, times_white, f_px, rgb=(1.0, 1.0, 1.0)):
    """An emitter ``px`` pixels across at its depth (y), radiance ``times_white`` × WHITE (× ``rgb``)."""
    radius = px * center[1] / (2 * f_px)
    ob = sphere(name, center, radius, emission(name + "_mat", times_white * WHITE, rgb), segments=16)
    for attr in ("visible_diffuse", "visible_glossy", "visible_transmission", "visible_volume_scatter",
                 "visible_shadow"):
        setattr(ob, attr, False)
    shot.lamps.append((name, tuple(center), radius))
    return ob


def ground(mat=None):
    return plane("ground", (0, 30, 0), (80, 80), mat or checker("ground_mat", (0.45, 0.42, 0.38),
                                                                  (0.3, 0.28, 0.25), 0.5), rot_deg=(0, 0, 0))


def keyframes(ob, attr, values, frames):
    """Linear keyframes (constant velocity), so Cycles' motion and the vector pass agree."""
    for v, f in zip(values, frames):
        setattr(ob, attr, v)
        ob.keyframe_insert(attr, frame=f)
    ad = ob.animation_data
    act = ad.action
    curves = []
    if hasattr(act, "layers") and act.layers:
        for layer in act.layers:
            for strip in layer.strips:
                curves += list(strip.channelbag(ad.action_slot).fcurves)
    else:
        curves = list(act.fcurves)
    for fc in curves:
        for k in fc.keyframe_points:
            k.interpolation = "LINEAR"
        fc.extrapolation = "LINEAR"


# ----------------------------------------------------------------------------------------------
# scenes
# ----------------------------------------------------------------------------------------------

def f_px_of(shot, width):
    return shot.focal_mm * width / shot.sensor_mm


def scene_emitters(width):
    """Few-pixel emitters (1–4 px, 100–1000× white) at 2…12 m against the sky and in front of a near
    wall; focus 2 m, f/1.4: the 2 m ones are in focus (no halo allowed), the rest are bokeh discs."""
    shot = Shot(f_number=1.4, focus_m=2.0)
    f = f_px_of(shot, width)
    ground()
    # a wall on the left, 3.2 m away, with lamps just in front of it
    box("wall", (-1.2, 3.2, 1.2), (2.0, 0.1, 2.4), checker("wall_mat", (0.7, 0.68, 0.62), (0.5, 0.48, 0.44), 4.0))
    specs = [  # (x, y, z, px, × white)
        (0.25, 2.0, 1.65, 2, 300), (0.45, 2.0, 1.45, 1, 1000), (0.55, 2.0, 1.70, 3, 100),
        (0.9, 4.0, 2.0, 2, 500), (1.8, 6.0, 2.6, 3, 300), (3.0, 9.0, 3.1, 2, 1000), (4.2, 12.0, 3.6, 4, 200),
        (-0.8, 9.0, 3.3, 1, 1000), (2.4, 12.0, 2.7, 2, 500),
        (-0.75, 3.1, 1.5, 2, 500), (-0.55, 3.1, 0.9, 3, 200), (-0.4, 2.0, 1.2, 2, 300),
    ]
    for i, (x, y, z, px, k) in enumerate(specs):
        lamp(shot, f"lamp{i:02d}", (x, y, z), px, k, f)
    box("post", (0.4, 2.0, 0.6), (0.06, 0.06, 1.2), diffuse("post_mat", (0.3, 0.3, 0.32)))
    return shot


def scene_highlights(width):
    """In-focus highlights in front of a distant background: glossy spheres and tiny lamps at the
    focus distance (2.5 m) against buildings 40 m away and the sky; f/2."""
    shot = Shot(f_number=2.0, focus_m=2.5)
    f = f_px_of(shot, width)
    ground()
    for i, (x, h, w) in enumerate([(-12, 6, 8), (-3, 8, 7), (5, 4, 9), (14, 7, 6)]):
        box(f"bldg{i}", (x, 40 + 3 * i, h / 2), (w, 6, h),
            checker(f"bldg{i}_mat", (0.55, 0.5, 0.45), (0.25, 0.27, 0.3), 1.2))
    for i, (x, z, r, c) in enumerate([(-0.45, 1.4, 0.08, (0.8, 0.1, 0.1)), (0.0, 1.6, 0.05, (0.1, 0.2, 0.8)),
                                      (0.4, 1.35, 0.1, (0.9, 0.8, 0.2)), (0.15, 1.1, 0.04, (0.9, 0.9, 0.9))]):
        sphere(f"ball{i}", (x, 2.5, z), r, glossy(f"ball{i}_mat", c, 0.04))
    box("stand", (0.0, 2.55, 0.5), (1.2, 0.25, 1.0), diffuse("stand_mat", (0.35, 0.3, 0.25)))
    for i, (x, z, px, k) in enumerate([(-0.2, 1.75, 2, 400), (0.3, 1.8, 1, 1000), (-0.6, 1.2, 3, 150),
                                       (0.62, 1.55, 2, 600)]):
        lamp(shot, f"lamp{i:02d}", (x, 2.5, z), px, k, f)
    return shot


def scene_thin(width):
    """Thin geometry: power wires (1–6 mm), a railing in front of the focus plane, alpha-cut foliage
    cards; focus 4 m, f/2."""
    shot = Shot(f_number=2.0, focus_m=4.0)
    ground()
    box("backwall", (0, 16, 3), (30, 0.2, 6), checker("back_mat", (0.75, 0.72, 0.66), (0.4, 0.42, 0.45), 2.0))
    dark = diffuse("wire_mat", (0.04, 0.04, 0.04))
    for i, (y, z, r) in enumerate([(4.0, 2.4, 0.003), (4.0, 2.55, 0.006), (8.0, 3.0, 0.004), (2.5, 2.2, 0.002),
                                   (12.0, 3.6, 0.006)]):
        cylinder(f"wire{i}", (-10, y, z), (10, y + 1.0, z - 0.2), r, dark, vertices=8)
    metal = diffuse("rail_mat", (0.6, 0.6, 0.62))
    for i in range(14):  # railing at 1.6 m, bars 12 mm, spacing 10 cm
        x = -0.75 + 0.11 * i
        cylinder(f"bar{i}", (x, 1.6, 0), (x, 1.6, 1.4), 0.006, metal, vertices=8)
    cylinder("handrail", (-1.0, 1.6, 1.4), (1.0, 1.6, 1.4), 0.02, metal)
    leaf = foliage("leaf_mat", (0.2, 0.45, 0.12), 9.0)
    for i, (x, y, z, s) in enumerate([(-1.4, 4.0, 1.8, 1.2), (1.1, 3.0, 2.1, 1.0), (2.5, 7.0, 2.0, 2.0),
                                      (-0.3, 6.0, 2.8, 1.4)]):
        plane(f"card{i}", (x, y, z), (s, s), leaf, rot_deg=(90, 0, 15 * i - 20))
    box("crate", (0.3, 4.0, 0.35), (0.7, 0.7, 0.7), checker("crate_mat", (0.7, 0.5, 0.3), (0.45, 0.3, 0.18), 6.0))
    return shot


def scene_occluder(width):
    """Partial occlusion: blurred foreground (a pole and a ball at 0.6–0.9 m) over a sharp textured
    mid-ground at 3 m, far background behind; focus 3 m, f/2."""
    shot = Shot(f_number=2.0, focus_m=3.0)
    ground()
    box("mid", (0.2, 3.0, 1.2), (2.2, 0.05, 2.4), checker("mid_mat", (0.85, 0.85, 0.8), (0.08, 0.08, 0.1), 8.0))
    box("far", (0, 25, 4), (40, 0.5, 8), checker("far_mat", (0.5, 0.55, 0.6), (0.3, 0.32, 0.35), 0.5))
    cylinder("pole", (-0.12, 0.7, 0.0), (-0.12, 0.7, 3.0), 0.03, diffuse("pole_mat", (0.75, 0.12, 0.08)))
    sphere("ball", (0.18, 0.9, 1.35), 0.09, diffuse("ball_mat", (0.1, 0.3, 0.8)))
    cylinder("branch", (0.0, 1.2, 1.9), (0.9, 1.3, 1.6), 0.015, diffuse("branch_mat", (0.25, 0.15, 0.08)))
    f = f_px_of(shot, width)
    lamp(shot, "lamp00", (0.8, 2.9, 1.9), 2, 300, f)  # in focus, just in front of the wall
    return shot


def scene_transparent(width):
    """Semi-transparent surfaces: panes at 1.5 m with opacity 0.3 and 0.7 (below and above Cycles'
    0.5 alpha threshold for the depth pass), a patterned screen, a tinted sheet; focus 4 m, f/2."""
    shot = Shot(f_number=2.0, focus_m=4.0)
    ground()
    box("back", (-0.2, 4.0, 0.95), (1.6, 0.1, 1.9), checker("back_mat", (0.8, 0.8, 0.75), (0.15, 0.15, 0.2), 5.0))
    plane("pane_lo", (-0.2, 1.5, 1.55), (0.3, 0.4), see_through("pane_lo_mat", (0.9, 0.9, 0.95), 0.3))
    plane("pane_hi", (0.2, 1.5, 1.55), (0.3, 0.4), see_through("pane_hi_mat", (0.9, 0.9, 0.95), 0.7))
    plane("screen", (0.3, 2.6, 1.2), (0.6, 0.4), see_through("screen_mat", (0.8, 0.3, 0.2), 0.8, pattern_scale=30))
    plane("sheet", (-0.55, 3.0, 1.3), (0.5, 0.8), see_through("sheet_mat", (0.2, 0.7, 0.3), 0.5))
    f = f_px_of(shot, width)
    lamp(shot, "lamp00", (1.6, 6.0, 2.2), 3, 300, f)
    lamp(shot, "lamp01", (-2.0, 9.0, 2.6), 2, 600, f)
    return shot


def scene_macro(width):
    """Macro: focus 0.3 m, f/2.8 — CoC from 0 to ≈ 40 px at 480 wide (infinity) and large in front;
    a small textured object on a table, lamps far behind."""
    shot = Shot(f_number=2.8, focus_m=0.3)
    # camera at 1.5 m looking level: a table top just below the view centre
    box("table", (0, 0.6, CAM_Z - 0.08), (1.2, 1.2, 0.04), checker("table_mat", (0.6, 0.45, 0.3), (0.4, 0.28, 0.18), 20.0))
    box("cube", (0.0, 0.3, CAM_Z - 0.04), (0.04, 0.04, 0.04), checker("cube_mat", (0.9, 0.9, 0.9), (0.1, 0.1, 0.1), 150.0))
    sphere("berry", (-0.03, 0.22, CAM_Z - 0.045), 0.012, glossy("berry_mat", (0.7, 0.05, 0.1), 0.05))
    sphere("bead", (0.05, 0.45, CAM_Z - 0.03), 0.02, diffuse("bead_mat", (0.1, 0.5, 0.3)))
    cylinder("stalk", (-0.08, 0.26, CAM_Z - 0.06), (-0.06, 0.26, CAM_Z + 0.06), 0.0015, diffuse("stalk_mat", (0.2, 0.5, 0.1)))
    box("wall", (0, 6.0, 2.0), (8, 0.2, 4), checker("wall_mat", (0.7, 0.7, 0.72), (0.35, 0.38, 0.4), 2.0))
    f = f_px_of(shot, width)
    # lamp globes 6–12 px wide: a 2 px lamp spread over a 37 px disc is a 0.3 % target for aperture
    # samples, which would need thousands of samples per pixel for a 36 dB truth
    for i, (x, y, z, px, k) in enumerate([(0.6, 5.0, 2.2, 12, 100), (-0.9, 5.0, 1.9, 10, 60), (0.2, 2.0, 1.75, 6, 100)]):
        lamp(shot, f"lamp{i:02d}", (x, y, z), px, k, f)
    return shot


def scene_motion(width):
    """Motion: a cube sliding and spinning at 4 m, a ball crossing diagonally at 2.5 m in front of a
    static pillar, a moving lamp; 24 fps, 180° shutter; focus 4 m, f/2.8 for the DoF+motion truth."""
    shot = Shot(f_number=2.8, focus_m=4.0, motion=True, frame=1)
    ground()
    box("back", (0, 9.0, 2.0), (12, 0.2, 4), checker("back_mat", (0.75, 0.72, 0.66), (0.35, 0.38, 0.42), 3.0))
    box("pillar", (0.35, 2.0, 0.9), (0.15, 0.15, 1.8), diffuse("pillar_mat", (0.6, 0.2, 0.15)))
    cube = box("cube", (0, 4.0, 1.2), (0.5, 0.5, 0.5), checker("cube_mat", (0.9, 0.85, 0.2), (0.2, 0.2, 0.6), 6.0))
    # 20 px/frame at 480 wide and 4 m: 20·4/666.7 = 0.12 m per frame
    keyframes(cube, "location", [(-0.12, 4.0, 1.2), (0.12, 4.0, 1.2)], [0, 2])
    keyframes(cube, "rotation_euler", [(0, 0, math.radians(-8)), (0, 0, math.radians(8))], [0, 2])
    ball = sphere("ball", (0.2, 2.5, 1.2), 0.15, checker("ball_mat", (0.9, 0.9, 0.9), (0.8, 0.1, 0.1), 25.0))
    keyframes(ball, "location", [(0.45, 2.5, 1.29), (0.21, 2.5, 1.11)], [0, 2])
    f = f_px_of(shot, width)
    lp = lamp(shot, "lamp00", (-0.6, 6.0, 2.4), 3, 400, f)
    keyframes(lp, "location", [(-0.8, 6.0, 2.4), (-0.4, 6.0, 2.4)], [0, 2])
    return shot


SCENES = {
    "emitters": scene_emitters,
    "highlights": scene_highlights,
    "thin": scene_thin,
    "occluder": scene_occluder,
    "transparent": scene_transparent,
    "macro": scene_macro,
    "motion": scene_motion,
}


# ----------------------------------------------------------------------------------------------
# held-out scenes (tests/data/cycles_heldout/): the same failure classes as the suite's, with other
# geometry, colours, depths, textures and cameras; never used to tune clpost (docs/fidelity.md,
# "Held-out scenes")
# ----------------------------------------------------------------------------------------------

# The foreground of the partial-occlusion scenes, by object name prefix: what `render.py`'s ``fg``
# and ``bg`` kinds split the pinhole into (the layers an artist renders separately, which the
# one-layer input lacks; docs/fidelity.md, "Two layers").
FOREGROUND = {
    "thin": ("bar", "handrail", "wire3"),
    "occluder": ("pole", "ball", "branch"),
    "transparent": ("pane",),
    "h_fence": ("fw", "fence_top", "post"),
    "h_panes": ("pane", "sheet"),
}


def is_foreground(scene_name, object_name):
    return any(object_name.startswith(p) for p in FOREGROUND[scene_name])


def at_px(shot, width, u, v, y):
    """World (x, y, z) of the point at depth y seen at pixel (u·width, v·height), height = width·9/16."""
    f = f_px_of(shot, width)
    return ((u - 0.5) * width * y / f, y, CAM_Z - (v - 0.5) * width * 9 / 16 * y / f)


def scene_h_lamps(width):
    """Held-out emitters: an 85 mm lens at f/2, 8 blades, focus 3 m. Coloured lamps of 1–5 px,
    50–2000× white at 5–25 m against the sky and at 4.5 m in front of a brick wall (6 m) on the
    right; in-focus lamps at 3 m, one against the sky, one against the wall."""
    shot = Shot(focal_mm=85.0, f_number=2.0, focus_m=3.0, blades=8)
    f = f_px_of(shot, width)
    ground(checker("ground_mat", (0.35, 0.4, 0.3), (0.22, 0.26, 0.2), 1.5))
    box("wall", (1.3, 6.0, 0.925), (1.6, 0.2, 1.85),
        bricks("wall_mat", (0.6, 0.3, 0.2), (0.45, 0.22, 0.15), (0.8, 0.78, 0.75), 3.0))
    warm, cool, green, white = (1.0, 0.6, 0.25), (0.5, 0.8, 1.0), (0.5, 1.0, 0.5), (1.0, 1.0, 1.0)
    specs = [  # (u, v, depth, px, × white, rgb): pixel position as fractions of the frame
        (0.30, 0.15, 3.0, 2, 500, warm),     # in focus, against the sky
        (0.85, 0.55, 3.0, 1, 2000, white),   # in focus, against the wall (6 m)
        (0.10, 0.20, 5.0, 3, 400, cool), (0.45, 0.10, 8.0, 2, 800, white), (0.20, 0.40, 12.0, 4, 150, warm),
        (0.60, 0.25, 15.0, 1, 2000, green), (0.05, 0.08, 25.0, 5, 50, white), (0.35, 0.30, 8.0, 2, 1000, warm),
        (0.80, 0.40, 4.5, 2, 600, cool), (0.90, 0.75, 4.5, 3, 250, warm), (0.95, 0.35, 4.5, 1, 1500, white),
    ]
    for i, (u, v, y, px, k, rgb) in enumerate(specs):
        lamp(shot, f"lamp{i:02d}", at_px(shot, width, u, v, y), px, k, f, rgb)
    box("bollard", (-0.05, 3.0, 0.75), (0.05, 0.05, 1.5), diffuse("bollard_mat", (0.55, 0.5, 0.2)))
    return shot


def scene_h_panes(width):
    """Held-out semi-transparent surfaces: focus *on* the panes (1.2 m, f/1.8, 5 blades), so what
    is seen through them is defocused. Panes of opacity 0.2 (blue), 0.5 (amber), 0.85 (grey) side by
    side, straddling the top edge of a brick wall at 4 m; lamps behind each pane against the sky
    (6 m) and against the wall (3 m); an orange sheet of opacity 0.5 at 0.7 m in front of focus."""
    shot = Shot(focal_mm=50.0, f_number=1.8, focus_m=1.2, blades=5)
    f = f_px_of(shot, width)
    ground()
    box("wall", (0.0, 4.0, 0.75), (4.0, 0.1, 1.5),
        bricks("wall_mat", (0.75, 0.7, 0.6), (0.3, 0.32, 0.35), (0.15, 0.15, 0.15), 4.0))
    panes = [(-0.25, (0.3, 0.45, 0.9), 0.2), (0.0, (0.9, 0.6, 0.2), 0.5), (0.25, (0.8, 0.8, 0.8), 0.85)]
    for i, (x, rgb, op) in enumerate(panes):
        plane(f"pane{i}", (x, 1.2, 1.5), (0.2, 0.3), see_through(f"pane{i}_mat", rgb, op))
        # a lamp behind the pane's upper half against the sky, one behind its lower half before the wall
        lamp(shot, f"lamp{2 * i:02d}", (x * 6.0 / 1.2 + 0.1, 6.0, 1.5 + 0.07 * 6.0 / 1.2), 2, 600, f)
        lamp(shot, f"lamp{2 * i + 1:02d}", (x * 3.0 / 1.2 - 0.05, 3.0, 1.5 - 0.08 * 3.0 / 1.2), 3, 250, f)
    lamp(shot, "lamp06", (0.8 * 6.0 / 1.2 * 0.5, 6.0, 1.5 + 0.18 * 5.0), 2, 600, f)  # no pane: the control
    plane("sheet", (-0.12, 0.7, 1.42), (0.14, 0.12), see_through("sheet_mat", (0.95, 0.45, 0.1), 0.5))
    return shot


def scene_h_fence(width):
    """Held-out thin geometry and partial occlusion: a 35 mm lens at f/1.4, 7 blades, focus 5 m on a
    brick wall with a cable (3 mm) and a pipe in front of it; a wire fence (4 mm wires, 10 cm
    apart) at 0.8 m and a post (6 cm) at 0.6 m blurred over it; hills 30 m away, wires at 10 m."""
    shot = Shot(focal_mm=35.0, f_number=1.4, focus_m=5.0, blades=7)
    ground(checker("ground_mat", (0.4, 0.38, 0.3), (0.28, 0.3, 0.22), 1.0))
    box("wall", (0.4, 5.0, 1.1), (3.0, 0.2, 2.2),
        bricks("wall_mat", (0.8, 0.75, 0.65), (0.5, 0.25, 0.2), (0.1, 0.1, 0.1), 5.0))
    box("hills", (0, 30.0, 4.0), (60, 0.5, 8), checker("hills_mat", (0.3, 0.45, 0.3), (0.2, 0.3, 0.22), 0.7))
    dark = diffuse("cable_mat", (0.05, 0.04, 0.03))
    cylinder("cable", (-3, 4.8, 1.9), (3, 4.8, 1.6), 0.0015, dark, vertices=8)
    cylinder("pipe", (1.2, 4.85, 0.0), (1.2, 4.85, 2.2), 0.025, diffuse("pipe_mat", (0.2, 0.5, 0.7)))
    for i, (z, r) in enumerate([(3.2, 0.004), (3.6, 0.003)]):
        cylinder(f"wire{i}", (-12, 10.0, z), (12, 10.0, z + 0.4), r, dark, vertices=8)
    steel = diffuse("fence_mat", (0.7, 0.7, 0.72))
    for i in range(9):  # vertical wires of a fence at 0.8 m, 10 cm apart, slightly tilted
        x = -0.4 + 0.1 * i
        cylinder(f"fw{i}", (x, 0.8, 1.0), (x + 0.03, 0.8, 2.1), 0.002, steel, vertices=8)
    cylinder("fence_top", (-0.6, 0.8, 1.62), (0.6, 0.8, 1.66), 0.002, steel, vertices=8)
    cylinder("post", (0.25, 0.6, 0.0), (0.25, 0.6, 3.0), 0.03, diffuse("post_mat", (0.15, 0.3, 0.15)))
    return shot


def scene_h_spin(width):
    """Held-out motion: a checkered wheel spinning 20°/frame at 3 m and a ball falling 15 px/frame
    at 2 m in front of a brick wall (5 m); 24 fps, 180°; focus 3 m, f/2.4 for the DoF+motion truth."""
    shot = Shot(f_number=2.4, focus_m=3.0, motion=True, frame=1, blades=6)
    ground()
    box("back", (0, 5.0, 1.5), (6, 0.2, 3), bricks("back_mat", (0.7, 0.6, 0.5), (0.4, 0.35, 0.3), (0.9, 0.9, 0.9), 3.0))
    wheel = cylinder("wheel", (-0.25, 3.0, 1.5), (-0.25, 2.97, 1.5), 0.22,
                     checker("wheel_mat", (0.9, 0.9, 0.85), (0.1, 0.3, 0.6), 12.0), vertices=48)
    bpy.ops.object.shade_flat()
    wheel.rotation_mode = "XYZ"
    keyframes(wheel, "rotation_euler",
              [(math.radians(90), math.radians(-20), 0), (math.radians(90), math.radians(20), 0)], [0, 2])
    f = f_px_of(shot, width)
    # 15 px/frame at 2 m: 15·2/f metres per frame
    v = 15 * 2.0 / f
    ball = sphere("ball", (0.3, 2.0, 1.5), 0.08, checker("ball_mat", (0.95, 0.8, 0.1), (0.6, 0.1, 0.5), 30.0))
    keyframes(ball, "location", [(0.3, 2.0, 1.5 + v), (0.3, 2.0, 1.5 - v)], [0, 2])
    return shot


HELDOUT = {
    "h_lamps": scene_h_lamps,
    "h_panes": scene_h_panes,
    "h_fence": scene_h_fence,
    "h_spin": scene_h_spin,
}
SCENES.update(HELDOUT)


# ----------------------------------------------------------------------------------------------
# common setup
# ----------------------------------------------------------------------------------------------

def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def world_and_lights():
    scene = bpy.context.scene
    world = bpy.data.worlds.new("sky")
    scene.world = world
    world.use_nodes = True
    nt = world.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    bg = nt.nodes.new("ShaderNodeBackground")
    bg.inputs["Color"].default_value = (*SKY, 1)
    out = nt.nodes.new("ShaderNodeOutputWorld")
    nt.links.new(bg.outputs[0], out.inputs["Surface"])
    vis = world.cycles_visibility
    for attr in ("diffuse", "glossy", "transmission", "scatter"):
        setattr(vis, attr, False)  # the sky is seen, it lights nothing (no noise from it)
    for name, strength, rot, shadow in (("key", SUN_KEY, (50, 0, 30), True), ("fill", SUN_FILL, (60, 0, 200), False)):
        light = bpy.data.lights.new(name, "SUN")
        light.energy = strength
        light.angle = 0.0
        light.use_shadow = shadow
        ob = bpy.data.objects.new(name, light)
        ob.rotation_euler = tuple(math.radians(r) for r in rot)
        scene.collection.objects.link(ob)


def camera(shot, width, height):
    scene = bpy.context.scene
    cam = bpy.data.cameras.new("cam")
    ob = bpy.data.objects.new("cam", cam)
    scene.collection.objects.link(ob)
    scene.camera = ob
    ob.location = (0, 0, CAM_Z)
    ob.rotation_euler = (math.radians(90), 0, 0)  # looks along +Y: planar depth = y
    cam.type = "PERSP"
    cam.lens = shot.focal_mm
    cam.sensor_fit = "HORIZONTAL"
    cam.sensor_width = shot.sensor_mm
    cam.clip_start = 0.01
    cam.clip_end = 1000
    cam.dof.focus_object = None
    cam.dof.focus_distance = shot.focus_m
    cam.dof.aperture_fstop = shot.f_number
    cam.dof.aperture_blades = shot.blades
    cam.dof.aperture_rotation = math.radians(shot.rotation_deg)
    cam.dof.aperture_ratio = 1.0
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = width, height, 100
    r.fps = int(shot.fps)
    r.fps_base = 1.0
    scene.frame_set(shot.frame)
    return cam


def build(name, width, height):
    reset()
    shot = SCENES[name](width)
    world_and_lights()
    camera(shot, width, height)
    return shot

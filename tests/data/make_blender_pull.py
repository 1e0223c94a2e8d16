import bpy, math
scene = bpy.context.scene
cam = scene.camera
cam.location = (0, -5, 1); cam.rotation_euler = (math.radians(90), 0, 0)  # looks along +Y
d = cam.data
d.dof.use_dof = True
scene.frame_start, scene.frame_end = 1, 5
for f, u, n in [(1, 1.0, 2.8), (5, 4.0, 5.6)]:
    d.dof.focus_distance = u; d.dof.aperture_fstop = n
    d.dof.keyframe_insert("focus_distance", frame=f); d.dof.keyframe_insert("aperture_fstop", frame=f)
for fc in d.animation_data.action.layers[0].strips[0].channelbag(d.animation_data.action.slots[0]).fcurves if hasattr(d.animation_data.action, "layers") else d.animation_data.action.fcurves:
    for k in fc.keyframe_points: k.interpolation = "LINEAR"
d.lens = 35.0
scene.render.resolution_x, scene.render.resolution_y = 1920, 1080
scene.render.fps = 24; scene.render.motion_blur_shutter = 0.5
bpy.ops.wm.save_as_mainfile(filepath="/tmp/i18-anim/blender/pull.blend")
# a second file: focus on an object 3 m in front, 0.5 m off axis
bpy.ops.object.empty_add(location=(0.5, -2.0, 1.3))
d.dof.focus_object = bpy.context.active_object
bpy.ops.wm.save_as_mainfile(filepath="/tmp/i18-anim/blender/focus_object.blend")
print("ok")

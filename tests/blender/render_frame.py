"""Blender headless: render one frame of a glTF export with Cycles (CPU, 16 samples) from a
camera given in Blender coordinates (toolkit (x, y, z) read (-x, -y, z) in Blender).

    blender -b --factory-startup --python tests/blender/render_frame.py -- crowd.glb out.png FRAME EX EY EZ TX TY TZ
"""

import math
import sys

import bpy
import mathutils
import numpy

if "bool" not in vars(numpy):
    numpy.bool = bool
glb, png, frame, ex, ey, ez, tx, ty, tz = sys.argv[sys.argv.index("--") + 1 :]
for o in list(bpy.context.scene.objects):
    if o.type == "MESH":
        bpy.data.objects.remove(o)
sc = bpy.context.scene
sc.render.fps = 30
bpy.ops.import_scene.gltf(filepath=glb)
sc.frame_set(int(frame))
cam = sc.camera
cam.location = (float(ex), float(ey), float(ez))
d = mathutils.Vector((float(tx), float(ty), float(tz))) - cam.location
cam.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()
cam.data.sensor_fit = "VERTICAL"
cam.data.angle = math.radians(45)
bpy.ops.mesh.primitive_plane_add(size=40)
sun = bpy.data.lights.new("sun", "SUN")
sun.energy = 3.0
so = bpy.data.objects.new("sun", sun)
sc.collection.objects.link(so)
so.rotation_euler = (0.6, 0.3, 0.5)
sc.render.engine = "CYCLES"
sc.cycles.samples = 16
sc.cycles.device = "CPU"
sc.cycles.use_denoising = False
sc.render.resolution_x, sc.render.resolution_y = 1280, 720
sc.render.filepath = png
bpy.ops.render.render(write_still=True)

"""Blender headless: import a .glb and export it again as Blender writes glTF (its own node
layout, bone axes and armature object), to check that crowdstudy imports Blender's files.

    blender -b --factory-startup --python tests/blender/reexport.py -- in.glb out.glb [animations]

With ``animations`` the animations are exported too (Blender resamples them per frame).
"""

import sys

import bpy
import numpy

if "bool" not in vars(numpy):  # Debian's Blender 3.4 glTF add-on still uses np.bool
    numpy.bool = bool

src, dst, *flags = sys.argv[sys.argv.index("--") + 1 :]
for obj in list(bpy.context.scene.objects):  # the factory scene's cube, camera and light
    bpy.data.objects.remove(obj)
bpy.ops.import_scene.gltf(filepath=src)
bpy.ops.export_scene.gltf(filepath=dst, export_format="GLB", export_animations="animations" in flags)
print("REEXPORTED", dst)

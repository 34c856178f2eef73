"""Blender (``bpy``) imports a USD file: prints ``OK`` and how many armatures and meshes
it made, and the frame range.

    python-with-bpy tests/blender/usd_import_check.py FILE.usda x
"""

import os
import sys

import bpy

path = sys.argv[-2]
bpy.ops.wm.read_factory_settings(use_empty=True)
res = bpy.ops.wm.usd_import(filepath=path)
objs = bpy.context.scene.objects
arm = sum(1 for o in objs if o.type == "ARMATURE")
mesh = sum(1 for o in objs if o.type == "MESH")
print("OK" if res == {"FINISHED"} else f"FAILED {res}", f"armatures {arm} meshes {mesh}")
print("frames", bpy.context.scene.frame_start, bpy.context.scene.frame_end)

# bpy can crash while tearing down at exit; the work is done and printed
sys.stdout.flush()
os._exit(0)

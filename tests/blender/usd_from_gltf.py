"""Blender (the ``bpy`` module, 4.x) writes a glTF file's characters as USD with UsdSkel:
its own USD exporter, names, bind transforms and units, what a user's Blender file holds.

    python-with-bpy tests/blender/usd_from_gltf.py IN.glb OUT.usda [UNIT_SCALE]

``UNIT_SCALE`` (default 1) is the scene's unit scale: 0.01 writes the armatures and meshes
scaled by 100 in a centimetre scene (``metersPerUnit`` 0.01 where Blender writes it).
Prints ``OK`` and the exporter's options on success.
"""

import os
import sys

import bpy

src, out = sys.argv[-3], sys.argv[-2]
scale = float(sys.argv[-1])
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=src)
if scale != 1.0:
    bpy.context.scene.unit_settings.scale_length = scale
    for ob in bpy.context.scene.objects:
        if ob.parent is None:
            ob.scale = [s / scale for s in ob.scale]
            ob.location = [x / scale for x in ob.location]
scene = bpy.context.scene
frames = [int(a.frame_range[1]) for a in bpy.data.actions] or [1]
scene.frame_start, scene.frame_end = 0, max(frames)
props = set(bpy.ops.wm.usd_export.get_rna_type().properties.keys())
kwargs = {"filepath": out, "export_animation": True}
for key in ("export_armatures", "export_skins", "export_uvmaps", "export_normals"):
    if key in props:
        kwargs[key] = True
if "export_materials" in props:
    kwargs["export_materials"] = True
res = bpy.ops.wm.usd_export(**kwargs)
print("OK" if res == {"FINISHED"} else f"FAILED {res}", sorted(kwargs))

# bpy can crash while tearing down at exit; the work is done and printed
sys.stdout.flush()
os._exit(0)

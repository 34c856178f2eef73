"""Blender headless check of a crowdstudy glTF export (not part of pytest: Blender is optional).

    blender -b --factory-startup --python tests/blender/check_export.py -- crowd.glb expected.json out.json

expected.json: {"fps", "frame", "bones": {name: [x, y, z] toolkit world}, "vertices":
{mesh name: {index: [x, y, z]}}, "n_characters", "n_frames"}. Writes what Blender computed.
In Blender (Z up) the toolkit's (x, y, z) appear as (-x, -y, z): the glTF file maps them to
(-x, z, y), Blender's importer maps glTF (x, y, z) to (x, -z, y).
"""

import json
import sys

import bpy
import numpy

# Debian's Blender 3.4 glTF add-on still uses np.bool, removed in numpy 1.24
if "bool" not in vars(numpy):
    numpy.bool = bool

args = sys.argv[sys.argv.index("--") + 1 :]
glb, expected_path, out_path = args
exp = json.load(open(expected_path))
scene = bpy.context.scene
scene.render.fps = int(round(exp["fps"]))
bpy.ops.import_scene.gltf(filepath=glb)
arms = [o for o in scene.objects if o.type == "ARMATURE"]
meshes = [o for o in scene.objects if o.type == "MESH"]
actions = list(bpy.data.actions)
out = {
    "armatures": len(arms),
    "meshes": len(meshes),
    "actions": len(actions),
    "frame_ranges": sorted({tuple(a.frame_range) for a in actions}),
    "bones": sum(len(a.data.bones) for a in arms),
}
# keyframe k lies at frame k + first frame of the action
first = min(a.frame_range[0] for a in actions)
scene.frame_set(int(round(first + exp["frame"])))
dg = bpy.context.evaluated_depsgraph_get()
bones = {}
for arm in arms:
    for pb in arm.pose.bones:
        if pb.name in exp["bones"]:
            bones[pb.name] = list(arm.matrix_world @ pb.head)
out["bone_positions"] = bones
verts = {}
for m in meshes:
    want = exp["vertices"].get(m.name) or exp["vertices"].get(m.data.name)
    if not want:
        continue
    ev = m.evaluated_get(dg)
    me = ev.to_mesh()
    verts[m.name] = {k: list(ev.matrix_world @ me.vertices[int(k)].co) for k in want}
    ev.to_mesh_clear()
out["vertices"] = verts
json.dump(out, open(out_path, "w"), indent=1)
print("BLENDER-CHECK", json.dumps({k: v for k, v in out.items() if k not in ("bone_positions", "vertices")}))

"""Write a corrected crowd back into its glTF file's scene (``crowdstudy correct IN.glb OUT.glb``).

The output is the input's document with only the corrected motion changed: the same nodes,
meshes, materials, skins, images, accessors (their indices and bytes), ``extras`` and
extensions. Per character (:func:`crowdstudy.interchange.retarget.rewrite_rig`):

* every mapped joint gets a new rotation channel (the physics' rotation carried back
  through the rig's rest frames), the pelvis' source joint a new translation channel;
* joints between mapped ones and unmapped joints (fingers, twist bones, face) keep their
  channels, relative to their parents; a joint beside the mapped tree whose parts follow a
  physics joint (an IK foot target) gets new channels moving it with that joint;
* a channel that is replaced keeps its place in its animation; its sampler is re-pointed
  to new accessors (keys at the corrected frames' times, ``LINEAR``); a joint that had no
  channel gets one in the animation that moves the character.

New data are appended to the GLB's binary chunk (a ``.gltf``: a new buffer as a data URI;
buffers and images in files beside the input are referred to from the output's folder).
``asset.extras["crowdstudy_correct"]`` records the provenance. The same input gives the
same bytes.
"""

from __future__ import annotations

import base64
import copy
import json
import os
import struct
from pathlib import Path

import numpy as np

from crowdstudy.body.gltf_container import CHUNK_BIN, CHUNK_JSON, GLB_MAGIC
from crowdstudy.body.rotations import quat_align_signs
from crowdstudy.interchange.gltf_sampling import world_at_frames
from crowdstudy.interchange.retarget import RigMotion, rewrite_rig

__all__ = ["corrected_gltf_bytes", "rig_motion"]


def rig_motion(crowd, corrected, i: int) -> RigMotion:
    """The rewritten motion of character ``i`` of an :class:`~crowdstudy.interchange.gltf_crowd.ImportedCrowd`
    for the corrected animation ``corrected`` (its first frames are the import's)."""
    c = crowd.characters[i]
    t = corrected.n_frames
    times = crowd.times[:t]
    nodes = [int(n) for n in c.character.rig.nodes]
    world, local = world_at_frames(crowd.gltf.doc, crowd.parent, nodes, crowd.channels, times)
    loc = np.stack([local[n] for n in nodes], axis=1)
    pw = np.tile(np.eye(4), (t, len(nodes), 1, 1))
    for k, n in enumerate(nodes):
        p = int(crowd.parent[n])
        if c.character.rig.parents[k] < 0 and p >= 0:
            pw[:, k] = world[p]
    base = (crowd.anim.joint_rotations[:t, i], crowd.anim.root_translation[:t, i])
    new = (corrected.joint_rotations[:, i], corrected.root_translation[:, i])
    return rewrite_rig(loc, pw, base, new, c.frames)


class _Appender:
    """Appends arrays as buffer views and accessors to a copied document."""

    def __init__(self, doc: dict, buffer: int, data: bytearray):
        self.doc, self.buffer, self.data = doc, buffer, data

    def accessor(self, arr: np.ndarray, bounds: bool = False) -> int:
        arr = np.ascontiguousarray(arr, dtype=np.float32)
        self.data += b"\x00" * (-len(self.data) % 4)
        view = {"buffer": self.buffer, "byteOffset": len(self.data), "byteLength": arr.nbytes}
        self.data += arr.tobytes()
        self.doc.setdefault("bufferViews", []).append(view)
        width = 1 if arr.ndim == 1 else arr.shape[1]
        acc = {
            "bufferView": len(self.doc["bufferViews"]) - 1,
            "componentType": 5126,
            "count": int(len(arr)),
            "type": {1: "SCALAR", 3: "VEC3", 4: "VEC4"}[width],
        }
        if bounds:
            flat = arr.reshape(len(arr), -1)
            acc["min"] = [float(v) for v in flat.min(axis=0)]
            acc["max"] = [float(v) for v in flat.max(axis=0)]
        self.doc.setdefault("accessors", []).append(acc)
        return len(self.doc["accessors"]) - 1


def _home_animation(crowd, i: int) -> int:
    """The chosen animation with the most channels on character ``i``'s nodes."""
    own = {int(n) for n in crowd.characters[i].character.rig.nodes}
    counts = {a: 0 for a in crowd.animations}
    for ch in crowd.channels:
        if ch.node in own:
            counts[ch.animation] += 1
    return max(crowd.animations, key=lambda a: (counts[a], -a))


def _set_channels(doc: dict, crowd, app: _Appender, time_acc: int, i: int, motion: RigMotion) -> None:
    nodes = crowd.characters[i].character.rig.nodes
    existing = {(ch.node, ch.path): ch for ch in crowd.channels}
    users: dict[tuple[int, int], int] = {}
    for a in crowd.animations:
        for ch in doc["animations"][a].get("channels", []):
            users[(a, ch["sampler"])] = users.get((a, ch["sampler"]), 0) + 1
    home = _home_animation(crowd, i)
    for path, table in (("rotation", motion.rotation), ("translation", motion.translation)):
        for k, values in sorted(table.items()):
            node = int(nodes[k])
            if path == "rotation":
                values = quat_align_signs(values, axis=0)
            out = app.accessor(values)
            _untangle_matrix(doc["nodes"][node])
            old = existing.get((node, path))
            sampler = {"input": time_acc, "output": out, "interpolation": "LINEAR"}
            if old is not None and users[(old.animation, old.sampler)] == 1:
                doc["animations"][old.animation]["samplers"][old.sampler] = sampler
            elif old is not None:
                anim = doc["animations"][old.animation]
                anim["samplers"].append(sampler)
                anim["channels"][old.channel]["sampler"] = len(anim["samplers"]) - 1
            else:
                anim = doc["animations"][home]
                anim["samplers"].append(sampler)
                anim["channels"].append({"sampler": len(anim["samplers"]) - 1, "target": {"node": node, "path": path}})


def _untangle_matrix(node: dict) -> None:
    """A node given by ``matrix`` cannot be animated: give it translation, rotation, scale."""
    if "matrix" not in node:
        return
    from crowdstudy.body.rotations import matrix_to_quaternion

    m = np.asarray(node.pop("matrix"), dtype=np.float64).reshape(4, 4).T
    s = np.linalg.norm(m[:3, :3], axis=0)
    node["translation"] = [float(x) for x in m[:3, 3]]
    node["rotation"] = [float(x) for x in matrix_to_quaternion(m[:3, :3] / s)]
    node["scale"] = [float(x) for x in s]


def corrected_gltf_bytes(crowd, corrected, out_path: str | Path, provenance: dict) -> bytes:
    """The bytes of the corrected file (GLB or glTF JSON, as ``out_path``'s suffix says):
    ``crowd`` the imported :class:`~crowdstudy.interchange.gltf_crowd.ImportedCrowd`,
    ``corrected`` the corrected CrowdAnimation (the import's frames, or its first ones)."""
    out_path = Path(out_path)
    src = crowd.gltf
    doc = copy.deepcopy(src.doc)
    glb = out_path.suffix.lower() == ".glb"
    bufs = doc.setdefault("buffers", [])
    if glb and bufs and "uri" not in bufs[0]:
        buffer, data = 0, bytearray(src.buffers[0])
    else:
        bufs.append({"byteLength": 0})
        buffer, data = len(bufs) - 1, bytearray()
    app = _Appender(doc, buffer, data)
    time_acc = app.accessor(crowd.times[: corrected.n_frames], bounds=True)
    for i in range(len(crowd.characters)):
        _set_channels(doc, crowd, app, time_acc, i, rig_motion(crowd, corrected, i))
    data += b"\x00" * (-len(data) % 4)
    bufs[buffer]["byteLength"] = len(data)
    extras = doc["asset"].setdefault("extras", {})
    if isinstance(extras, dict):
        extras["crowdstudy_correct"] = provenance
    _relocate_uris(doc, Path(src.path).parent, out_path.parent)
    if not (glb and buffer == 0):
        bufs[buffer]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(bytes(data)).decode()
    if not glb:
        return json.dumps(doc, separators=(",", ":")).encode("utf-8")
    text = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<II", len(text), CHUNK_JSON) + text
    if buffer == 0:
        chunks += struct.pack("<II", len(data), CHUNK_BIN) + bytes(data)
    return struct.pack("<III", GLB_MAGIC, 2, 12 + len(chunks)) + chunks


def _relocate_uris(doc: dict, src_dir: Path, out_dir: Path) -> None:
    """Buffers and images in files beside the input, referred to from the output's folder."""
    if src_dir.resolve() == out_dir.resolve():
        return
    for item in [*doc.get("buffers", []), *doc.get("images", [])]:
        uri = item.get("uri")
        if isinstance(uri, str) and uri and not uri.startswith("data:") and "://" not in uri:
            item["uri"] = Path(os.path.relpath(src_dir.resolve() / uri, out_dir.resolve())).as_posix()

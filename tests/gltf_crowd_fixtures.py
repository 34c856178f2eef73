"""Crowds written as glTF from one character's file (tests only; no third-party file is
committed): copies of a scene's character placed on a grid, each turned and shifted in
time, all instancing the original meshes and inverse bind matrices.

:func:`crowd_of` reads a .glb, keeps one animation, copies the scene's root subtree N
times (nodes, skins with remapped joints, animation channels; a copy's key values are
rolled by its time shift, so every copy is keyed at the same times) and writes a .glb.
Variants: ``unnamed`` strips every node name; ``rigid`` drops the skinned meshes (a
rigid-parts character); ``weight_scale`` scales the first skinned mesh's WEIGHTS_0 (skin
weights that do not sum to one).
"""

from __future__ import annotations

import copy
import json
import math
import struct
from pathlib import Path

import numpy as np

from crowdstudy.body.gltf_container import read_gltf


class _Doc:
    """A glTF document and its binary buffer being extended."""

    def __init__(self, path: Path):
        g = read_gltf(path)
        self.src = g
        self.doc = copy.deepcopy(g.doc)
        self.bin = bytearray(g.buffers[0]) if g.buffers else bytearray()

    def add_accessor(self, arr: np.ndarray, like: dict) -> int:
        arr = np.ascontiguousarray(arr, dtype=np.float32)
        self.bin += b"\x00" * (-len(self.bin) % 4)
        self.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(self.bin), "byteLength": arr.nbytes})
        self.bin += arr.tobytes()
        acc = {"bufferView": len(self.doc["bufferViews"]) - 1, "componentType": 5126, "count": len(arr)}
        acc["type"] = like["type"]
        if "min" in like:
            flat = arr.reshape(len(arr), -1)
            acc["min"], acc["max"] = [float(v) for v in flat.min(0)], [float(v) for v in flat.max(0)]
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def write(self, path: Path) -> Path:
        doc = self.doc
        doc["buffers"] = [{"byteLength": len(self.bin)}]
        text = json.dumps(doc, separators=(",", ":")).encode()
        text += b" " * (-len(text) % 4)
        self.bin += b"\x00" * (-len(self.bin) % 4)
        body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(self.bin), 0x004E4942)
        body += bytes(self.bin)
        Path(path).write_bytes(struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body)
        return Path(path)


def _subtree(doc: dict, root: int) -> list[int]:
    out, stack = [], [root]
    while stack:
        k = stack.pop()
        out.append(k)
        stack.extend(doc["nodes"][k].get("children", []))
    return sorted(out)


def crowd_of(
    src: Path,
    out: Path,
    *,
    n: int,
    spacing: float,
    animation: str | int = 0,
    shift_keys: int = 5,
    unnamed: bool = False,
    rigid: bool = False,
    weight_scale: float | None = None,
    columns: int | None = None,
    seed: int = 0,
    last_rate: float | None = None,
    lift: float = 0.0,
) -> Path:
    """Write a crowd of ``n`` copies of ``src``'s scene (see the module docstring), copies
    ``spacing`` m apart on a grid of ``columns`` (default: a square), each turned by a
    random yaw within +-20 deg and its keys rolled by ``shift_keys * i``; ``last_rate``
    stretches the last copy's key times by that factor (a character keyed at another rate);
    ``lift`` raises every copy by that many metres (a file whose origin is the pelvis, not
    the floor)."""
    d = _Doc(Path(src))
    doc = d.doc
    anims = doc.get("animations", [])
    a_idx = animation if isinstance(animation, int) else [a.get("name") for a in anims].index(animation)
    anim = anims[a_idx]
    scene = doc["scenes"][doc.get("scene", 0)]
    roots = list(scene["nodes"])
    rng = np.random.default_rng(seed)
    cols = columns or math.ceil(math.sqrt(n))
    new_roots, channels, samplers = [], [], []
    base_nodes = sorted({k for r in roots for k in _subtree(doc, r)})
    n_nodes0, n_skins0 = len(doc["nodes"]), len(doc.get("skins", []))
    originals = [copy.deepcopy(doc["nodes"][k]) for k in range(n_nodes0)]
    skins0 = copy.deepcopy(doc.get("skins", []))
    doc["nodes"], doc["skins"] = [], []
    for i in range(n):
        remap = {k: len(doc["nodes"]) + j for j, k in enumerate(base_nodes)}
        skin_base = len(doc["skins"])
        for k in base_nodes:
            node = copy.deepcopy(originals[k])
            if "children" in node:
                node["children"] = [remap[c] for c in node["children"]]
            if "skin" in node:
                node["skin"] = skin_base + node["skin"]
            if unnamed:
                node.pop("name", None)
            doc["nodes"].append(node)
        for sk in skins0:
            sk = copy.deepcopy(sk)
            sk["joints"] = [remap[j] for j in sk["joints"]]
            if "skeleton" in sk:
                sk["skeleton"] = remap[sk["skeleton"]]
            doc["skins"].append(sk)
        yaw = float(rng.uniform(-0.35, 0.35))
        holder = {
            "translation": [spacing * (i % cols - (cols - 1) / 2), lift, spacing * (i // cols)],
            "rotation": [0.0, math.sin(yaw / 2), 0.0, math.cos(yaw / 2)],
            "children": [remap[r] for r in roots],
        }
        if not unnamed:
            holder["name"] = f"copy_{i:02d}"
        doc["nodes"].append(holder)
        new_roots.append(len(doc["nodes"]) - 1)
        for ch in anim["channels"]:
            if ch["target"].get("node") not in remap:
                continue
            smp = anim["samplers"][ch["sampler"]]
            out_acc = smp["output"]
            shift = (shift_keys * i) % max(1, doc["accessors"][smp["input"]]["count"])
            if shift:
                vals = d.src.accessor(out_acc)
                out_acc = d.add_accessor(np.roll(vals, -shift, axis=0), doc["accessors"][smp["output"]])
            in_acc = smp["input"]
            if last_rate is not None and i == n - 1:
                times = d.src.accessor(in_acc) * last_rate
                in_acc = d.add_accessor(times, doc["accessors"][smp["input"]])
            samplers.append({**smp, "input": in_acc, "output": out_acc})
            channels.append(
                {"sampler": len(samplers) - 1, "target": {**ch["target"], "node": remap[ch["target"]["node"]]}}
            )
    del n_nodes0, n_skins0
    doc["animations"] = [{"name": anim.get("name", "crowd"), "channels": channels, "samplers": samplers}]
    doc["scenes"] = [{"nodes": new_roots}]
    doc["scene"] = 0
    if rigid or not doc["skins"]:
        _drop_skins(doc)
    if weight_scale is not None:
        _scale_weights(d, weight_scale)
    return d.write(Path(out))


def _drop_skins(doc: dict) -> None:
    """Remove the skinned mesh nodes and the skins: only rigid parts remain."""
    for node in doc["nodes"]:
        if "skin" in node:
            node.pop("skin")
            node.pop("mesh", None)
    doc.pop("skins", None)


def _scale_weights(d: _Doc, factor: float) -> None:
    """WEIGHTS_0 of the first skinned mesh times ``factor`` (a new accessor)."""
    doc = d.doc
    node = next(n for n in doc["nodes"] if "skin" in n and "mesh" in n)
    prim = doc["meshes"][node["mesh"]]["primitives"][0]
    acc = prim["attributes"]["WEIGHTS_0"]
    w = d.src.accessor(acc).astype(np.float32) * factor
    prim["attributes"]["WEIGHTS_0"] = d.add_accessor(w, doc["accessors"][acc])

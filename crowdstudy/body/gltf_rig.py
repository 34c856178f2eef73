"""The characters of a glTF file and the rig of each, before any mapping to the 24 joints.

A character (:func:`find_characters`) is either

* a **skinned** character: one or more skins over one skeleton (skins that share joint
  nodes are one character: Blender and Ready Player Me write one skin per mesh), every
  mesh node bound to them, plus the meshes parented rigidly to its joints (a robot's
  armour next to its skinned hands); or
* a **rigid-parts** character: an animated node tree whose meshes hang rigidly under its
  nodes (no skin); its root is the top-most animated node above them.

Several mesh nodes may share one mesh (instancing): each skin over its own joints is its
own character. Nodes that share one skin pose identically (glTF poses a skinned mesh by
its joints only) and are one character.

:func:`read_rig` reads a character's joints (names, parents within the character, bind
pose in the file's world) and its mesh in the bind pose (file world, metres, Y up), with
per-vertex weights over the rig's joints. Skin weights that do not sum to one are
normalised and counted (:attr:`Rig.renormalised`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from crowdstudy.body.gltf_container import GltfFile
from crowdstudy.errors import InvalidInputError

__all__ = ["CharacterSpec", "Rig", "find_characters", "character_for_record", "read_rig", "animated_nodes", "weld"]

#: Skin weight sums further than this from 1 count as "not normalised".
WEIGHT_SUM_TOLERANCE = 1e-3


@dataclasses.dataclass(frozen=True)
class CharacterSpec:
    """Where one character lives in a glTF document.

    Attributes:
        skins: the skin indices of a skinned character (empty for rigid parts).
        root: the character's top node (the skeleton's top joint, or the rigid tree's root).
        joints: its rig joints (node indices, ascending): the skins' joints, or the rigid
            tree's nodes other than unanimated mesh leaves.
        skinned: mesh nodes bound to its skins; rigid: mesh nodes parented under its joints.
    """

    skins: tuple[int, ...]
    root: int
    joints: tuple[int, ...]
    skinned: tuple[int, ...]
    rigid: tuple[int, ...]

    @property
    def key(self) -> dict:
        """The body record fields that select this character: ``{"skin": s}`` or ``{"node": n}``."""
        return {"skin": self.skins[0]} if self.skins else {"node": self.root}


@dataclasses.dataclass
class Rig:
    """A character's rig and mesh in the bind pose, in the file's world (glTF axes, metres).

    Attributes:
        nodes: (K,) node index of every rig joint; names: (K,) their names ("" unnamed).
        parents: (K,) int64 parent within the rig (-1 for the top joints).
        bind: (K, 4, 4) float64 world matrix of every joint in the bind pose.
        vertices: (V, 3) float64; faces: (F, 3) int32; weights: (V, K) float64 rows summing to 1.
        uvs, images: per primitive, its TEXCOORD_0 (or None) and base-colour image (or None).
        renormalised: vertices whose skin weights did not sum to one (normalised here).
        weight_sum_range: (min, max) of those sums before normalising.
    """

    nodes: np.ndarray
    names: list[str]
    parents: np.ndarray
    bind: np.ndarray
    vertices: np.ndarray
    faces: np.ndarray
    weights: np.ndarray
    uvs: list
    images: list
    renormalised: int = 0
    weight_sum_range: tuple[float, float] = (1.0, 1.0)


def animated_nodes(doc: dict, animations: list[int] | None = None) -> set[int]:
    """Nodes targeted by a translation, rotation or scale channel of ``animations`` (all by default)."""
    anims = doc.get("animations", [])
    chosen = range(len(anims)) if animations is None else animations
    return {
        int(ch["target"]["node"])
        for a in chosen
        for ch in anims[a].get("channels", [])
        if "node" in ch.get("target", {}) and ch["target"].get("path") in ("translation", "rotation", "scale")
    }


def _ancestors(k: int, parent: np.ndarray) -> list[int]:
    out = []
    k = int(parent[k])
    while k >= 0:
        out.append(k)
        k = int(parent[k])
    return out


def find_characters(doc: dict, parent: np.ndarray) -> list[CharacterSpec]:
    """Every character of the document (see the module docstring), skinned ones first in
    skin order, then rigid-parts ones in node order. ``parent``: (nodes,) parent node."""
    nodes = doc.get("nodes", [])
    skins = doc.get("skins", [])
    group = list(range(len(skins)))

    def find(a: int) -> int:
        while group[a] != a:
            group[a] = group[group[a]]
            a = group[a]
        return a

    owner: dict[int, int] = {}
    for s, sk in enumerate(skins):
        for j in sk.get("joints", []):
            if int(j) in owner:
                group[find(s)] = find(owner[int(j)])
            else:
                owner[int(j)] = s
    members: dict[int, list[int]] = {}
    for s in range(len(skins)):
        members.setdefault(find(s), []).append(s)
    joint_of = {j: find(s) for j, s in owner.items()}
    skinned: dict[int, list[int]] = {g: [] for g in members}
    rigid: dict[int, list[int]] = {g: [] for g in members}
    loose = []
    for i, n in enumerate(nodes):
        if "mesh" not in n:
            continue
        if "skin" in n and 0 <= int(n["skin"]) < len(skins):
            skinned[find(int(n["skin"]))].append(i)
            continue
        hit = next((joint_of[a] for a in [i, *_ancestors(i, parent)] if a in joint_of), None)
        (rigid[hit] if hit is not None else loose).append(i)
    kids: dict[int, list[int]] = {}
    for c, p in enumerate(parent):
        kids.setdefault(int(p), []).append(c)
    out = []
    for g, ss in sorted(members.items(), key=lambda kv: min(kv[1])):
        skin_joints = {int(j) for s in ss for j in skins[s]["joints"]}
        joints = sorted(skin_joints | _bone_like_descendants(nodes, kids, skin_joints))
        top = next(j for j in joints if not any(a in joints for a in _ancestors(j, parent)))
        out.append(CharacterSpec(tuple(ss), top, tuple(joints), tuple(skinned[g]), tuple(rigid[g])))
    out += _rigid_characters(doc, parent, loose)
    return out


def _bone_like_descendants(nodes: list, kids: dict[int, list[int]], joints: set[int]) -> set[int]:
    """Nodes under a skeleton's joints that are neither skinned meshes nor mesh leaves: end
    bones (``LowerLeg_end``: where a shin ends) and the holders of rigid parts."""
    out: set[int] = set()
    stack = [c for j in joints for c in kids.get(j, [])]
    while stack:
        k = stack.pop()
        if k in joints or k in out:
            continue
        n = nodes[k]
        if "skin" in n or ("mesh" in n and not kids.get(k)):
            continue
        out.add(k)
        stack.extend(kids.get(k, []))
    return out


def _rigid_characters(doc: dict, parent: np.ndarray, meshes: list[int]) -> list[CharacterSpec]:
    """Rigid-parts characters: the loose mesh nodes grouped by their top-most animated ancestor."""
    moving = animated_nodes(doc)
    roots: dict[int, list[int]] = {}
    for m in meshes:
        chain = [m, *_ancestors(m, parent)]
        top = [a for a in chain if a in moving]
        if top:
            roots.setdefault(top[-1], []).append(m)
    kids: dict[int, list[int]] = {}
    for c, p in enumerate(parent):
        kids.setdefault(int(p), []).append(c)
    out = []
    for root, ms in sorted(roots.items()):
        sub, stack = [], [root]
        while stack:
            k = stack.pop()
            sub.append(k)
            stack.extend(kids.get(k, []))
        nodes = doc["nodes"]
        joints = sorted(k for k in sub if "mesh" not in nodes[k] or kids.get(k) or k in moving)
        out.append(CharacterSpec((), root, tuple(joints), (), tuple(sorted(ms))))
    return out


def character_for_record(doc: dict, parent: np.ndarray, path: Path, *, skin=None, node=None) -> CharacterSpec:
    """The character a body record selects: by ``skin`` (any of its skins) or ``node`` (its root)."""
    chars = find_characters(doc, parent)
    if node is not None:
        hit = [c for c in chars if c.root == node]
        if not hit:
            roots = ", ".join(str(c.root) for c in chars if not c.skins) or "none"
            raise InvalidInputError(f"node: glTF file {path} has no rigid-parts character at node {node} ({roots})")
        return hit[0]
    n_skins = len(doc.get("skins", []))
    if not n_skins:
        raise InvalidInputError(f"glTF file {path}: no skin (a rigged character needs a skinned mesh)")
    if isinstance(skin, bool) or not isinstance(skin, (int, np.integer)) or not 0 <= skin < n_skins:
        raise InvalidInputError(f"skin: expected an index in 0..{n_skins - 1} for {path}, got {skin!r}")
    return next(c for c in chars if skin in c.skins)


def read_rig(gltf: GltfFile, spec: CharacterSpec, parent: np.ndarray, world: np.ndarray, path: Path) -> Rig:
    """The rig and bind-pose mesh of ``spec`` (see :class:`Rig`); ``world``: (nodes, 4, 4)
    world matrices of the default pose. Skinned joints take their bind pose from the inverse
    bind matrices (carried to the world by the skeleton's top joint); rigid characters and
    joints outside every skin take the default pose."""
    doc = gltf.doc
    joints = list(spec.joints)
    index = {n: k for k, n in enumerate(joints)}
    parents = np.array([next((index[a] for a in _ancestors(n, parent) if a in index), -1) for n in joints])
    bind = world[joints].copy()
    ibms = {}
    for s in spec.skins:
        sk = doc["skins"][s]
        sj = [int(j) for j in sk["joints"]]
        ibm = (
            gltf.accessor(sk["inverseBindMatrices"]).astype(np.float64)
            if "inverseBindMatrices" in sk
            else np.tile(np.eye(4), (len(sj), 1, 1))
        )
        if len(ibm) != len(sj):
            raise InvalidInputError(
                f"glTF file {path}: skin {s} has {len(sj)} joints but {len(ibm)} inverse bind matrices"
            )
        ibms[s] = ibm
    to_world = {}
    for s in spec.skins:  # each skin's bind space -> the file's world, by its top joint
        sj = [int(j) for j in doc["skins"][s]["joints"]]
        r = (
            sj.index(spec.root)
            if spec.root in sj
            else next(i for i, j in enumerate(sj) if not any(a in sj for a in _ancestors(j, parent)))
        )
        to_world[s] = world[sj[r]] @ ibms[s][r]
    for s in reversed(spec.skins):  # a joint in several skins takes the first one's bind pose
        for j, m in zip(doc["skins"][s]["joints"], ibms[s], strict=True):
            bind[index[int(j)]] = to_world[s] @ np.linalg.inv(m)
    in_skin = {int(j) for s in spec.skins for j in doc["skins"][s]["joints"]}
    for n in sorted(joints, key=lambda n: len(_ancestors(n, parent))):  # parents first
        k = index[n]
        if spec.skins and n not in in_skin:
            a = next(a for a in _ancestors(n, parent) if a in index)
            bind[k] = bind[index[a]] @ np.linalg.inv(world[a]) @ world[n]
    names = [str(doc["nodes"][n].get("name", "")) for n in joints]
    mesh = _read_meshes(gltf, spec, index, parent, world, bind, to_world, path)
    return Rig(nodes=np.array(joints), names=names, parents=parents, bind=bind, **mesh)


def _read_meshes(gltf, spec, index, parent, world, bind, to_world, path) -> dict:
    """The character's triangles in the bind pose (file world) and their weights (V, K)."""
    doc = gltf.doc
    verts, faces, weights, uvs, images, sums = [], [], [], [], [], []
    offset = 0
    k_all = len(index)
    for m in (*spec.skinned, *spec.rigid):
        node = doc["nodes"][m]
        for prim in doc["meshes"][node["mesh"]]["primitives"]:
            if prim.get("mode", 4) != 4:
                continue
            attrs = prim["attributes"]
            p = gltf.accessor(attrs["POSITION"]).astype(np.float64)
            if "skin" in node:
                s = int(node["skin"])
                sj = [index[int(j)] for j in doc["skins"][s]["joints"]]
                to_bind = to_world[s]
                w, total = _skin_weights(gltf, attrs, np.array(sj), k_all, len(p), m, path)
                sums.append(total)
                p = p @ to_bind[:3, :3].T + to_bind[:3, 3]
            else:
                holder = next(a for a in [m, *_ancestors(m, parent)] if a in index)
                w = np.zeros((len(p), k_all))
                w[:, index[holder]] = 1.0
                # the part rides on its holder joint from the default pose to the bind pose
                place = bind[index[holder]] @ np.linalg.inv(world[holder]) @ world[m]
                p = p @ place[:3, :3].T + place[:3, 3]
            verts.append(p)
            weights.append(w)
            idx = gltf.accessor(prim["indices"]).astype(np.int64) if "indices" in prim else np.arange(len(p))
            faces.append(idx.reshape(-1, 3) + offset)
            offset += len(p)
            uvs.append(gltf.accessor(attrs["TEXCOORD_0"]).astype(np.float64) if "TEXCOORD_0" in attrs else None)
            images.append(_base_color_image(doc, prim))
    if not verts:
        raise InvalidInputError(f"glTF file {path}: no triangle mesh on the character at node {spec.root}")
    total = np.concatenate(sums) if sums else np.ones(1)
    off = np.abs(total - 1.0) > WEIGHT_SUM_TOLERANCE
    one_image = all(u is not None for u in uvs) and len(set(images)) == 1
    uv = np.concatenate(uvs) if one_image else None
    v, f, w, uv = weld(np.concatenate(verts), np.concatenate(faces), np.concatenate(weights), uv)
    return {
        "vertices": v,
        "faces": f,
        "weights": w,
        "uvs": [uv],
        "images": [images[0] if one_image else None],
        "renormalised": int(off.sum()),
        "weight_sum_range": (float(total.min()), float(total.max())),
    }


def weld(vertices: np.ndarray, faces: np.ndarray, weights: np.ndarray, uv: np.ndarray | None, tol: float = 1e-5):
    """Merge vertices closer than ``tol`` m with the same texture coordinate: flat shaded
    and split meshes (rigid parts cut along the bones) become closed, connected surfaces,
    which the overlap metric, the capsule fit and the renderer's level of detail need. The
    merged vertex takes the mean weights; faces that collapse are dropped. Returns
    ``(vertices, faces int32, weights, uv)``."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree  # pyright: ignore[reportAttributeAccessIssue]  # missing from scipy stubs

    pairs = cKDTree(vertices).query_pairs(tol, output_type="ndarray")
    if uv is not None and len(pairs):
        pairs = pairs[np.all(np.abs(uv[pairs[:, 0]] - uv[pairs[:, 1]]) < 1e-6, axis=1)]
    if not len(pairs):
        return vertices, faces.astype(np.int32), weights, uv
    n = len(vertices)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    _, first, inverse = np.unique(label, return_index=True, return_inverse=True)
    order = np.argsort(first)  # keep the first occurrence's order
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    new = rank[inverse.reshape(-1)]
    w = np.zeros((len(first), weights.shape[1]))
    np.add.at(w, new, weights)
    w /= w.sum(axis=1, keepdims=True)
    f = new[faces]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
    keep = np.sort(first)
    return vertices[keep], f.astype(np.int32), w, None if uv is None else uv[keep]


def _base_color_image(doc: dict, prim: dict) -> int | None:
    """The image index of a primitive's base-colour texture, or None."""
    if "material" not in prim:
        return None
    info = doc["materials"][prim["material"]].get("pbrMetallicRoughness", {}).get("baseColorTexture")
    return None if info is None else doc["textures"][info["index"]].get("source")


def _skin_weights(gltf, attrs, target, k_all, n, mesh, path) -> tuple[np.ndarray, np.ndarray]:
    """(n, K) weights over the rig joints from every JOINTS_k / WEIGHTS_k set, normalised,
    and the (n,) sums before normalising."""
    if "JOINTS_0" not in attrs or "WEIGHTS_0" not in attrs:
        raise InvalidInputError(f"glTF file {path}: skinned mesh node {mesh} has no JOINTS_0/WEIGHTS_0")
    w = np.zeros((n, k_all))
    k = 0
    while f"JOINTS_{k}" in attrs and f"WEIGHTS_{k}" in attrs:
        ji = gltf.accessor(attrs[f"JOINTS_{k}"]).astype(np.int64)
        wi = gltf.accessor(attrs[f"WEIGHTS_{k}"]).astype(np.float64)
        if ji.max(initial=0) >= len(target):
            raise InvalidInputError(f"glTF file {path}: JOINTS_{k} of mesh node {mesh} refers past its skin's joints")
        for c in range(ji.shape[1]):
            np.add.at(w, (np.arange(n), target[ji[:, c]]), wi[:, c])
        k += 1
    total = w.sum(axis=1)
    if np.any(total <= 0):
        raise InvalidInputError(f"glTF file {path}: vertices of mesh node {mesh} without skin weights")
    return w / total[:, None], total

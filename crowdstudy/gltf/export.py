"""Export a :class:`~crowdstudy.scene.CrowdAnimation` with its bodies to one binary glTF 2.0.

Layout of the file (``crowdstudy export-gltf anim.npz out.glb``):

* Scene roots: one node ``crowdstudy_world`` carrying the axis conversion, and one
  skinned-mesh node ``cNN_body`` per character (glTF ignores a skinned mesh node's own
  transform, so these sit at the root with none).
* ``crowdstudy_world`` has the rotation ``C`` that takes the toolkit's Z-up world to glTF's
  Y-up one: ``(x, y, z) -> (-x, z, y)`` (a half turn about the axis (0, 1, 1) / sqrt(2),
  quaternion ``(0, sqrt(1/2), sqrt(1/2), 0)``). A character that faces +y in the toolkit
  faces +Z in glTF, up is +Y and its right hand is -X: glTF's own convention for the front
  of an asset. Everything under it (joint translations, animation values) is in the
  toolkit's frame and units (metres), so the animation's quaternions are exactly the
  toolkit's axis-angle rotations.
* Per character, 24 joint nodes ``cNN_<joint>`` (names of ``crowdstudy.body.skeleton``)
  under ``crowdstudy_world``: the pelvis translated to the root position, every other joint
  at its rest offset from its parent. Their default transform is the bind pose (a T-pose
  at the first frame's pelvis position), so importers (Blender) see the rest pose as rest.
* Per character one mesh (one primitive): POSITION and NORMAL in the body's rest frame
  (pelvis at the origin), JOINTS_0 / WEIGHTS_0 (the four largest weights, renormalised),
  inverse bind matrices ``translate(-rest_joint)``; TEXCOORD_0 and a base-colour texture
  when the body has ``uv`` and ``texture`` (v flipped to glTF's top-left origin), else
  COLOR_0 with the renderer's clothing colours (linear RGB).
* One animation ``crowd``: for every joint a LINEAR rotation track (the axis-angle rotations
  as unit quaternions, scalar-last, sign kept continuous between frames) and for each pelvis
  a translation track, keyed at every frame ``t = k / fps``.

With ``J_j`` the world matrix of joint node j and ``IBM_j`` its inverse bind matrix,
``J_j IBM_j = C M_j`` where ``M_j`` is the toolkit's LBS matrix
(:func:`crowdstudy.body.model.skinning_matrices`), so a glTF viewer poses every vertex
exactly where the toolkit does, expressed in Y-up.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np

from crowdstudy.body.gltf_container import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GltfBuilder
from crowdstudy.body.rotations import axis_angle_to_quaternion, quat_align_signs
from crowdstudy.body.skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS
from crowdstudy.errors import InvalidInputError
from crowdstudy.render.bodies import region_scores, vertex_normals

__all__ = ["export_gltf", "build_gltf", "WORLD_ROTATION", "character_prefix", "add_skinned_mesh", "encode_png"]

#: ``Z_UP_TO_Y_UP`` (:mod:`crowdstudy.body.gltf_container`) as the quaternion ``(x, y, z, w)`` of the
#: ``crowdstudy_world`` node.
WORLD_ROTATION = (0.0, math.sqrt(0.5), math.sqrt(0.5), 0.0)
WORLD_NODE = "crowdstudy_world"


def character_prefix(index: int, n_characters: int) -> str:
    """Node-name prefix of character ``index``: ``c07_`` (zero-padded to the crowd size)."""
    return f"c{index:0{max(2, len(str(max(n_characters - 1, 0))))}d}_"


def encode_png(image: np.ndarray) -> bytes:
    """(H, W, 3|4) uint8 -> PNG bytes (Pillow; deterministic for the same pixels)."""
    from PIL import Image

    arr = np.ascontiguousarray(image, dtype=np.uint8)
    if arr.ndim != 3 or arr.shape[2] not in (3, 4):
        raise InvalidInputError(f"texture: expected an (H, W, 3) uint8 image, got shape {arr.shape}")
    buf = io.BytesIO()
    Image.fromarray(arr).save(buf, format="PNG", optimize=False, compress_level=6)
    return buf.getvalue()


def _normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit vertex normals for glTF (which requires unit length): the renderer's area-weighted
    normals, with +z for vertices no face gives a normal."""
    n = vertex_normals(vertices, faces)
    n[np.linalg.norm(n, axis=1) < 0.5] = (0.0, 0.0, 1.0)
    return n.astype(np.float32)


def add_skinned_mesh(
    builder: GltfBuilder,
    *,
    name: str,
    vertices: np.ndarray,
    faces: np.ndarray,
    joints: np.ndarray,
    weights: np.ndarray,
    joint_nodes: list[int],
    inverse_bind: np.ndarray,
    skeleton: int | None = None,
    uv: np.ndarray | None = None,
    texture: np.ndarray | None = None,
    colors: np.ndarray | None = None,
    normals: np.ndarray | None = None,
    indices: int | None = None,
) -> int:
    """Add a skinned mesh, its skin and material, and the (transform-free) node that binds
    them; returns that node's index (the caller puts it in a scene).

    Args:
        vertices: (V, 3) bind-pose positions; faces: (F, 3) vertex indices.
        joints: (V, 4) indices into ``joint_nodes``; weights: (V, 4), rows summing to 1.
        joint_nodes: node index of each skin joint; inverse_bind: (J, 4, 4) row-major.
        uv: (V, 2) with glTF's top-left origin, and texture (H, W, 3) uint8; or colors
            (V, 3) linear RGB in [0, 1]; or neither (a plain grey material).
        indices: an index accessor written before for the same faces (bodies of one
            template share it); by default a new one is written.
    """
    verts = np.asarray(vertices, dtype=np.float32)
    f = np.asarray(faces, dtype=np.int64)
    if f.size and (f.min() < 0 or f.max() >= len(verts)):
        raise InvalidInputError(f"{name}: face indices outside 0..{len(verts) - 1}")
    norm = _normals(verts, f) if normals is None else np.asarray(normals, dtype=np.float32)
    attrs = {
        "POSITION": builder.accessor(verts, target=ARRAY_BUFFER, bounds=True),
        "NORMAL": builder.accessor(norm, target=ARRAY_BUFFER),
    }
    jdtype = np.uint8 if len(joint_nodes) <= 256 else np.uint16
    w = np.asarray(weights, dtype=np.float32)
    j = np.where(w > 0, np.asarray(joints), 0).astype(jdtype)
    attrs["JOINTS_0"] = builder.accessor(j, target=ARRAY_BUFFER)
    attrs["WEIGHTS_0"] = builder.accessor(w, target=ARRAY_BUFFER)
    material = {"name": f"{name}_material", "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 0.85}}
    if uv is not None and texture is not None:
        attrs["TEXCOORD_0"] = builder.accessor(np.asarray(uv, dtype=np.float32), target=ARRAY_BUFFER)
        if "samplers" not in builder.doc:
            builder.add("samplers", {"magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071})
        image = builder.image(encode_png(texture))
        tex = builder.add("textures", {"sampler": 0, "source": image})
        material["pbrMetallicRoughness"]["baseColorTexture"] = {"index": tex, "texCoord": 0}
    elif colors is not None:
        attrs["COLOR_0"] = builder.accessor(
            np.clip(np.asarray(colors, dtype=np.float32), 0.0, 1.0), target=ARRAY_BUFFER
        )
    else:
        material["pbrMetallicRoughness"]["baseColorFactor"] = [0.7, 0.7, 0.7, 1.0]
    idx_dtype = np.uint16 if len(verts) < 65535 else np.uint32
    if indices is None:
        indices = builder.accessor(f.reshape(-1).astype(idx_dtype), target=ELEMENT_ARRAY_BUFFER)
    prim = {"attributes": attrs, "indices": indices, "material": builder.add("materials", material), "mode": 4}
    mesh = builder.add("meshes", {"name": name, "primitives": [prim]})
    skin = {
        "joints": list(joint_nodes),
        "inverseBindMatrices": builder.accessor(np.asarray(inverse_bind, dtype=np.float32), kind="MAT4"),
        "name": f"{name}_skin",
    }
    if skeleton is not None:
        skin["skeleton"] = skeleton
    return builder.add("nodes", {"name": name, "mesh": mesh, "skin": builder.add("skins", skin)})


def _vertex_colors(anim, bodies) -> list[np.ndarray]:
    """Per-vertex linear RGB of each body: the renderer's colour regions and palette
    (the same seed and frame-0 positions as ``crowdstudy render``)."""
    from crowdstudy.render.palette import assign_colors

    seed = int(anim.meta.get("seed", 0))
    pos = anim.root_translation[0, :, :2]
    period = anim.periodic_length
    if period:
        pos = pos.copy()
        pos[:, 0] -= period * np.floor(pos[:, 0] / period)
    colors, _ = assign_colors(pos, seed, period=period)
    out = []
    for i, body in enumerate(bodies):
        region = np.argmax(region_scores(body), axis=1)
        out.append(colors[i][region])
    return out


def build_gltf(anim, *, bodies=None, colors: bool = True, progress: bool = False) -> GltfBuilder:
    """The glTF document of ``anim`` (see the module docstring) as a :class:`GltfBuilder`.

    Args:
        anim: a CrowdAnimation on the 24-joint skeleton.
        bodies: N :class:`~crowdstudy.body.Body` (default ``load_body`` of ``anim.bodies``).
        colors: write the renderer's clothing colours as COLOR_0 for bodies without a texture.
        progress: show a progress bar over the characters.
    """
    from crowdstudy.provenance import provenance

    if tuple(anim.joint_names) != JOINT_NAMES or not np.array_equal(anim.parents, PARENTS):
        raise InvalidInputError("anim.joint_names: glTF export needs the 24-joint skeleton of crowdstudy.body.skeleton")
    n, t = anim.n_characters, anim.n_frames
    if bodies is None:
        from crowdstudy.body import load_body

        bodies = [load_body(rec) for rec in anim.bodies]
    bodies = list(bodies)
    if len(bodies) != n:
        raise InvalidInputError(f"bodies: expected {n} bodies (one per character), got {len(bodies)}")
    vcolors = _vertex_colors(anim, bodies) if colors else [None] * n
    b = GltfBuilder()
    b.doc["asset"]["extras"] = {
        "crowdstudy": provenance(
            seed=anim.meta.get("seed"),
            source="CrowdAnimation",
            n_characters=n,
            n_frames=t,
            fps=anim.fps,
            up_axis_conversion="glTF (x, y, z) = (-x_toolkit, z_toolkit, y_toolkit)",
        )
    }
    world = b.add("nodes", {"name": WORLD_NODE, "rotation": list(WORLD_ROTATION), "children": []})
    # signs continuous in time: glTF's LINEAR interpolation takes the short arc
    quats = quat_align_signs(axis_angle_to_quaternion(anim.joint_rotations), axis=0)  # (T, N, J, 4)
    roots = anim.root_translation
    times = (np.arange(t, dtype=np.float64) / anim.fps).astype(np.float32)
    anim_doc = {"name": "crowd", "channels": [], "samplers": []}
    time_acc = b.accessor(times, bounds=True)
    mesh_nodes = []
    index_accessors: dict[str, int] = {}  # bodies of one template share faces
    iterator = range(n)
    if progress:
        from crowdstudy.progress import progress_bar

        iterator = progress_bar(iterator, desc="glTF characters", unit="char")
    for i in iterator:
        body = bodies[i]
        prefix = character_prefix(i, n)
        rest = np.asarray(body.rest_joints, dtype=np.float64)
        nodes = []
        for jj, jname in enumerate(JOINT_NAMES):
            p = int(PARENTS[jj])
            offset = roots[0, i] if p < 0 else rest[jj] - rest[p]
            node = {"name": prefix + jname, "translation": [float(x) for x in offset]}
            nodes.append(b.add("nodes", node))
            if p < 0:
                b.doc["nodes"][world]["children"].append(nodes[-1])
            else:
                b.doc["nodes"][nodes[p]].setdefault("children", []).append(nodes[-1])
        ibm = np.tile(np.eye(4), (NUM_JOINTS, 1, 1))
        ibm[:, :3, 3] = -rest
        idx, val = body.top_weights(4)
        uv, tex = getattr(body, "uv", None), getattr(body, "texture", None)
        if uv is not None:
            uv = np.asarray(uv, dtype=np.float64)
            uv = np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1)
        mesh_nodes.append(
            add_skinned_mesh(
                b,
                name=prefix + "body",
                vertices=body.rest_vertices,
                faces=body.faces,
                joints=idx,
                weights=val,
                joint_nodes=nodes,
                inverse_bind=ibm,
                skeleton=nodes[0],
                uv=uv,
                texture=tex,
                colors=vcolors[i],
                indices=index_accessors.get(body.template_key),
            )
        )
        prim = b.doc["meshes"][b.doc["nodes"][mesh_nodes[-1]]["mesh"]]["primitives"][0]
        index_accessors.setdefault(body.template_key, prim["indices"])
        for jj in range(NUM_JOINTS):
            s = _add_sampler(anim_doc, time_acc, b.accessor(quats[:, i, jj].astype(np.float32)))
            anim_doc["channels"].append({"sampler": s, "target": {"node": nodes[jj], "path": "rotation"}})
        s = _add_sampler(anim_doc, time_acc, b.accessor(roots[:, i].astype(np.float32)))
        anim_doc["channels"].append({"sampler": s, "target": {"node": nodes[0], "path": "translation"}})
    b.add("animations", anim_doc)
    b.doc["scenes"] = [
        {
            "name": anim.meta.get("scenario", "crowd") if isinstance(anim.meta.get("scenario"), str) else "crowd",
            "nodes": [world, *mesh_nodes],
        }
    ]
    b.doc["scene"] = 0
    return b


def _add_sampler(anim_doc: dict, input_acc: int, output_acc: int) -> int:
    anim_doc["samplers"].append({"input": input_acc, "output": output_acc, "interpolation": "LINEAR"})
    return len(anim_doc["samplers"]) - 1


def export_gltf(anim, path: str | Path, *, bodies=None, colors: bool = True, progress: bool = False) -> Path:
    """Write ``anim`` as a binary glTF (.glb) at ``path``; returns the path.

    See :func:`build_gltf` for the arguments and the module docstring for the layout.
    """
    path = Path(path)
    if path.suffix.lower() != ".glb":
        raise InvalidInputError(f"path: expected a .glb output file, got {str(path)!r}")
    if path.exists() and path.is_dir():
        raise InvalidInputError(f"path: {path} is a directory")
    return build_gltf(anim, bodies=bodies, colors=colors, progress=progress).write(path)

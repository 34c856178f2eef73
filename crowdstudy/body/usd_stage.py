"""A USD stage's UsdSkel characters as an in-memory glTF document, so that every step after
reading (the characters, the joint mapping, the bodies, the sampling and retargeting of the
motion, the rewrite of the corrected motion) is the glTF side's, unchanged.

What is read (:func:`read_usd`), with Pixar's ``usd-core`` (``pip install 'crowdstudy[usd]'``):

* every skeleton binding of every ``SkelRoot`` (:class:`pxr.UsdSkel.Cache`, instance
  proxies included: a ``SkelRoot`` under an ``instanceable`` prim is a character per
  instance; several ``SkelRoot`` s binding one ``SkelAnimation`` are a character each)
  becomes a glTF skin: a node per joint (the skeleton's topology, rest transforms as the
  default pose, the joint's last path element as its name), inverse bind matrices from the
  skeleton's ``bindTransforms``, the skeleton prim's world transform above its joints;
* every skinned ``Mesh`` of the binding (``primvars:skel:jointIndices`` / ``jointWeights``,
  any number of influences, ``skel:joints`` subsets, ``primvars:skel:geomBindTransform``)
  becomes a glTF mesh bound to that skin, its points carried by the geom bind transform;
  rigidly bound meshes (constant joint influences: a part riding on one joint) get those
  influences on every point;
* every ``SkelAnimation`` becomes a glTF animation: per joint of each skeleton it drives, a
  translation, rotation and scale channel keyed at the animation's time samples (time
  codes / ``timeCodesPerSecond``, s), linear; unanimated joints keep their rest transform;
* the stage's axes and units become glTF's: a root node turns ``upAxis`` Z to Y and scales
  by ``metersPerUnit`` (a Z-up stage's x, y, z are the toolkit's; a Y-up stage's are
  glTF's, (x, y, z) -> toolkit (-x, z, y)). A stage without authored ``metersPerUnit`` whose characters are
  taller than :data:`CENTIMETRE_STATURE` units (a crowd in centimetres) is an error naming it.

:class:`UsdCrowdFile` keeps, per glTF node and skin, the USD prims it came from (what the
corrected motion is written back to: :mod:`crowdstudy.interchange.usd_write`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from crowdstudy.body.gltf_container import GltfBuilder, GltfFile
from crowdstudy.errors import InvalidInputError, MissingDependencyError

__all__ = ["USD_SUFFIXES", "UsdSkin", "UsdCrowdFile", "read_usd", "import_pxr", "CENTIMETRE_STATURE"]

USD_SUFFIXES = (".usd", ".usda", ".usdc")
#: Characters taller than this many stage units without an authored ``metersPerUnit`` are
#: taken for a crowd in centimetres (USD's fallback unit) and refused.
CENTIMETRE_STATURE = 20.0


def import_pxr():
    """The ``pxr`` modules (Usd, UsdGeom, UsdSkel, Gf, Vt, Sdf), or MissingDependencyError
    naming the extra."""
    try:
        from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt
    except ImportError:
        raise MissingDependencyError(
            "USD needs Pixar's usd-core: pip install 'crowdstudy[usd]' (or usd-core)"
        ) from None
    return Usd, UsdGeom, UsdSkel, Gf, Vt, Sdf


@dataclasses.dataclass(frozen=True)
class UsdSkin:
    """Where one glTF skin of a :class:`UsdCrowdFile` came from: the ``skel_root``,
    ``skeleton`` and ``animation`` prim paths (``animation`` "" when none), the skeleton's
    ``joints`` (its joint order, USD paths) and the glTF node of each joint (``nodes``)."""

    skel_root: str
    skeleton: str
    animation: str
    joints: tuple[str, ...]
    nodes: tuple[int, ...]
    meshes: tuple[str, ...]


@dataclasses.dataclass
class UsdCrowdFile:
    """A USD stage read as glTF: ``gltf`` (the document and its buffer, ``gltf.path`` the USD
    file), ``skins`` (one :class:`UsdSkin` per glTF skin), ``up_axis`` ("Y" or "Z"),
    ``meters_per_unit``, ``time_codes_per_second`` and ``animations`` (the SkelAnimation
    prim path of each glTF animation)."""

    gltf: GltfFile
    skins: list[UsdSkin]
    up_axis: str
    meters_per_unit: float
    time_codes_per_second: float
    animations: list[str]


def _np(m) -> np.ndarray:
    """(4, 4) float64 column-vector matrix of a Gf.Matrix4d (USD's are row-vector)."""
    return np.array(m, dtype=np.float64).reshape(4, 4).T


def _stage_root(up: str, mpu: float) -> dict:
    """The glTF root node: Z up -> Y up and the unit scale. A Z-up stage's axes become the
    toolkit's unchanged (the turn is ``Z_UP_TO_Y_UP``, half a turn about (0, 1, 1))."""
    node: dict = {"name": "usd_stage", "scale": [mpu, mpu, mpu], "children": []}
    if up == "Z":
        s = float(np.sqrt(0.5))
        node["rotation"] = [0.0, s, s, 0.0]
    return node


def read_usd(path: str | Path) -> UsdCrowdFile:
    """Read a USD file's skinned characters as a glTF document (see the module docstring).

    Raises InvalidInputError naming the file: not a USD stage, no ``SkelRoot`` with a bound
    skeleton and skinned meshes, a crowd in centimetres without ``metersPerUnit``.
    """
    usd, usd_geom, usd_skel, _, _, _ = import_pxr()
    path = Path(path)
    if not path.is_file():
        raise InvalidInputError(f"USD file {path}: no such file")
    try:
        stage = usd.Stage.Open(str(path), usd.Stage.LoadAll)
    except Exception as exc:  # pxr raises Tf.ErrorException
        raise InvalidInputError(f"USD file {path}: cannot be opened ({str(exc).strip().splitlines()[-1]})") from None
    if stage is None:
        raise InvalidInputError(f"USD file {path}: cannot be opened")
    up = str(usd_geom.GetStageUpAxis(stage))
    mpu = float(usd_geom.GetStageMetersPerUnit(stage))
    tcps = float(stage.GetTimeCodesPerSecond())
    pred = usd.TraverseInstanceProxies()
    cache = usd_skel.Cache()
    builder = GltfBuilder(generator="crowdstudy usd reader")
    builder.add("nodes", _stage_root(up, mpu))
    scene = [0]
    skins: list[UsdSkin] = []
    anims: dict[str, list[tuple[int, list]]] = {}
    n_roots = 0
    tallest = [0.0]
    for prim in stage.Traverse(pred):
        if not prim.IsA(usd_skel.Root):
            continue
        n_roots += 1
        root = usd_skel.Root(prim)
        cache.Populate(root, pred)
        for binding in cache.ComputeSkelBindings(root, pred):
            skin = _add_binding(builder, cache, binding, prim, scene, path, tallest)
            if skin is not None:
                skins.append(skin)
                anims.setdefault(skin.animation, []).append((len(skins) - 1, list(skin.nodes)))
    if not skins:
        what = "no SkelRoot" if not n_roots else "no SkelRoot binds a skeleton to a skinned mesh"
        raise InvalidInputError(f"USD file {path}: no character to import ({what})")
    if not stage.HasAuthoredMetadata("metersPerUnit") and tallest[0] > CENTIMETRE_STATURE:
        raise InvalidInputError(
            f"USD file {path}: metersPerUnit is not authored and the characters are {tallest[0]:.4g} units tall "
            "(centimetres?): author the stage's metersPerUnit (0.01 for centimetres)"
        )
    order = [a for a in sorted(anims) if a]
    for a in order:
        _add_animation(builder, stage, cache, a, anims[a], skins, tcps)
    builder.doc["scenes"] = [{"nodes": scene}]
    builder.doc["scene"] = 0
    doc = builder.doc
    doc["buffers"] = [{"byteLength": len(builder._bin)}]
    gltf = GltfFile(doc, [bytes(builder._bin)], path)
    return UsdCrowdFile(gltf, skins, up, mpu, tcps, order)


def _add_binding(builder, cache, binding, root_prim, scene: list, path: Path, tallest: list) -> UsdSkin | None:
    """One skeleton binding as glTF nodes, a skin and meshes; None when it skins no mesh.
    ``tallest[0]`` grows to the tallest mesh's extent in stage units (bind pose)."""
    _, usd_geom, _, _, _, _ = import_pxr()
    skel = binding.GetSkeleton()
    query = cache.GetSkelQuery(skel)
    targets = [t for t in binding.GetSkinningTargets() if t.GetPrim().IsA(usd_geom.Mesh) and t.HasJointInfluences()]
    if not targets or not query:
        return None
    joints = [str(j) for j in query.GetJointOrder()]
    parents = np.asarray(query.GetTopology().GetParentIndices(), dtype=np.int64)
    rest = query.ComputeJointLocalTransforms(0.0, True) if query.HasRestPose() else None
    bind = np.stack([_np(m) for m in query.GetJointWorldBindTransforms()]) if joints else np.zeros((0, 4, 4))
    if rest is None:  # rest from the bind pose: local = parent bind^-1 bind
        local = [bind[k] if parents[k] < 0 else np.linalg.inv(bind[parents[k]]) @ bind[k] for k in range(len(joints))]
    else:
        local = [_np(m) for m in rest]
    skel_world = _np(usd_geom.Xformable(skel.GetPrim()).ComputeLocalToWorldTransform(0.0))
    skel_node = builder.add(
        "nodes", {"name": skel.GetPrim().GetName(), "matrix": [float(x) for x in skel_world.T.reshape(-1)]}
    )
    builder.doc["nodes"][0]["children"].append(skel_node)
    first = len(builder.doc["nodes"])
    nodes = list(range(first, first + len(joints)))
    for name, trs in zip(joints, _trs(np.asarray(local).reshape(-1, 4, 4)), strict=True):
        builder.add("nodes", {"name": name.rsplit("/", 1)[-1], **trs})
    for k in range(len(joints)):
        holder = skel_node if parents[k] < 0 else nodes[parents[k]]
        builder.doc["nodes"][holder].setdefault("children", []).append(nodes[k])
    ibm = np.linalg.inv(bind).astype(np.float32)
    skin = builder.add(
        "skins", {"joints": nodes, "inverseBindMatrices": builder.accessor(ibm), "skeleton": nodes[0] if nodes else 0}
    )
    meshes = []
    for t in targets:
        mesh = _add_mesh(builder, t, joints, skin, path, skel_world, tallest)
        if mesh is not None:
            scene.append(mesh)
            meshes.append(str(t.GetPrim().GetPath()))
    if not meshes:
        return None
    anim = query.GetAnimQuery()
    return UsdSkin(
        skel_root=str(root_prim.GetPath()),
        skeleton=str(skel.GetPrim().GetPath()),
        animation=str(anim.GetPrim().GetPath()) if anim else "",
        joints=tuple(joints),
        nodes=tuple(nodes),
        meshes=tuple(meshes),
    )


def _trs(m: np.ndarray) -> list[dict]:
    """glTF translation/rotation/scale of (K, 4, 4) local matrices (a mirroring matrix
    takes a negative x scale)."""
    from crowdstudy.body.rotations import matrix_to_quaternion

    if not len(m):
        return []
    s = np.linalg.norm(m[:, :3, :3], axis=1)
    s[:, 0] *= np.where(np.linalg.det(m[:, :3, :3]) < 0, -1.0, 1.0)
    q = matrix_to_quaternion(m[:, :3, :3] / s[:, None, :])
    return [
        {
            "translation": [float(x) for x in m[k, :3, 3]],
            "rotation": [float(x) for x in q[k]],
            "scale": [float(x) for x in s[k]],
        }
        for k in range(len(m))
    ]


def _add_mesh(builder, query, joints: list[str], skin: int, path: Path, skel_world, tallest: list) -> int | None:
    """A skinned mesh prim as a glTF mesh node bound to ``skin``; None without triangles."""
    _, usd_geom, _, _, _, _ = import_pxr()
    prim = query.GetPrim()
    mesh = usd_geom.Mesh(prim)
    points = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64).reshape(-1, 3)
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
    index = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int64)
    if not len(points) or not len(counts):
        return None
    tris = _triangulate(counts, index)
    if not len(tris):
        return None
    influences = query.ComputeVaryingJointInfluences(len(points), 0.0)
    if not influences:
        raise InvalidInputError(f"USD file {path}: mesh {prim.GetPath()}: its joint influences cannot be read")
    ji, jw = (np.asarray(a) for a in influences)
    per = len(ji) // len(points)
    ji, jw = ji.reshape(len(points), per), jw.reshape(len(points), per).astype(np.float32)
    order = query.GetJointOrder()
    if order:  # skel:joints: the mesh's own joint order -> the skeleton's
        lookup = {j: k for k, j in enumerate(joints)}
        missing = [str(j) for j in order if str(j) not in lookup]
        if missing:
            raise InvalidInputError(
                f"USD file {path}: mesh {prim.GetPath()}: skel:joints names joints the skeleton lacks: {missing[:3]}"
            )
        remap = np.array([lookup[str(j)] for j in order], dtype=np.int64)
        ji = remap[np.clip(ji, 0, len(remap) - 1)]
    if ji.max(initial=0) >= len(joints) or ji.min(initial=0) < 0:
        raise InvalidInputError(f"USD file {path}: mesh {prim.GetPath()}: joint indices past the skeleton's joints")
    geom = _np(query.GetGeomBindTransform(0.0))
    p = points @ geom[:3, :3].T + geom[:3, 3]
    w = p @ skel_world[:3, :3].T
    tallest[0] = max(tallest[0], float(np.ptp(w, axis=0).max()))
    width = -(-per // 4) * 4
    ji = np.pad(ji, ((0, 0), (0, width - per))).astype(np.uint16)
    jw = np.pad(jw, ((0, 0), (0, width - per))).astype(np.float32)
    attrs = {"POSITION": builder.accessor(p.astype(np.float32), bounds=True)}
    for s in range(width // 4):
        attrs[f"JOINTS_{s}"] = builder.accessor(np.ascontiguousarray(ji[:, 4 * s : 4 * s + 4]))
        attrs[f"WEIGHTS_{s}"] = builder.accessor(np.ascontiguousarray(jw[:, 4 * s : 4 * s + 4]))
    prims = [{"attributes": attrs, "indices": builder.accessor(tris.reshape(-1).astype(np.uint32)), "mode": 4}]
    m = builder.add("meshes", {"name": str(prim.GetPath()), "primitives": prims})
    return builder.add("nodes", {"name": prim.GetName(), "mesh": m, "skin": skin})


def _triangulate(counts: np.ndarray, index: np.ndarray) -> np.ndarray:
    """(F, 3) triangles of polygons (fans), degenerate polygons dropped."""
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    out = []
    for n in np.unique(counts):
        if n < 3:
            continue
        s = starts[counts == n]
        for k in range(1, n - 1):
            out.append(np.stack([index[s], index[s + k], index[s + k + 1]], axis=1))
    return np.concatenate(out) if out else np.zeros((0, 3), dtype=np.int64)


def _add_animation(builder, stage, cache, anim_path: str, users: list, skins: list[UsdSkin], tcps: float) -> None:
    """One SkelAnimation as a glTF animation: translation and rotation channels (and scale
    where it is not one) on every joint it drives, for each skeleton bound to it; joints it
    does not drive keep their rest transform (the node's default)."""
    usd, _, _, _, _, _ = import_pxr()
    aq = cache.GetAnimQuery(stage.GetPrimAtPath(anim_path))
    times = sorted(float(t) for t in aq.GetJointTransformTimeSamples()) or [0.0]
    order = [str(j) for j in aq.GetJointOrder()]
    tr = np.empty((len(order), len(times), 3), dtype=np.float32)
    ro = np.empty((len(order), len(times), 4), dtype=np.float32)
    sc = np.empty((len(order), len(times), 3), dtype=np.float32)
    for t, code in enumerate(times):
        comps = aq.ComputeJointLocalTransformComponents(usd.TimeCode(code))
        if not comps or len(comps[0]) != len(order):
            raise InvalidInputError(
                f"USD file {stage.GetRootLayer().realPath}: SkelAnimation {anim_path}: "
                f"its translations, rotations and scales do not cover its {len(order)} joints"
            )
        tr[:, t], ro[:, t], sc[:, t] = np.array(comps[0]), np.array(comps[1]), np.array(comps[2])
    ro = _continuous(ro)
    scaled = ~np.all(np.abs(sc - 1.0) < 1e-6, axis=(1, 2))
    channels, samplers = [], []
    time_acc = builder.accessor(np.asarray(times, dtype=np.float32) / np.float32(tcps), bounds=True)
    outputs: dict[tuple[int, str], int] = {}
    for s, nodes in users:
        slot = {j: k for k, j in enumerate(skins[s].joints)}
        for a, joint in enumerate(order):
            if joint not in slot:
                continue
            for what, values in (("translation", tr), ("rotation", ro), ("scale", sc)):
                if what == "scale" and not scaled[a]:
                    continue
                if (a, what) not in outputs:  # skeletons bound to one animation share its data
                    outputs[(a, what)] = builder.accessor(np.ascontiguousarray(values[a]))
                samplers.append({"input": time_acc, "output": outputs[(a, what)], "interpolation": "LINEAR"})
                channels.append({"sampler": len(samplers) - 1, "target": {"node": nodes[slot[joint]], "path": what}})
    builder.add("animations", {"name": anim_path, "channels": channels, "samplers": samplers})


def _continuous(q: np.ndarray) -> np.ndarray:
    """(K, T, 4) quaternions with signs continuous in time (linear interpolation takes the short arc)."""
    from crowdstudy.body.rotations import quat_align_signs

    return quat_align_signs(q.astype(np.float64), axis=1).astype(np.float32)

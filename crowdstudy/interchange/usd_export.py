"""Skinned glTF characters as a UsdSkel stage (what ``crowdstudy export-usd`` writes, through
:func:`crowdstudy.gltf.export_usd.export_usd`, and what the USD tests are made from).

Every glTF skin is written as one UsdSkel character (:func:`gltf_to_usd`):

``/Crowd`` (an ``Xform`` carrying glTF's Y-up metres to the stage's ``upAxis`` and
``metersPerUnit``) / ``<character>`` (a ``SkelRoot``) with

* ``Skel`` (``Skeleton``): ``joints`` as paths down the skin's tree, ``bindTransforms``
  the inverse of the skin's inverse bind matrices, ``restTransforms`` the default pose;
  ``skel:animationSource`` -> ``Anim``;
* ``Anim`` (``SkelAnimation``): every joint's translation, rotation and scale sampled at
  the animation's key rate (time codes are frames: ``timeCodesPerSecond`` is the rate);
* ``Body`` (``Mesh``): the skin's triangles with ``primvars:skel:jointIndices`` /
  ``jointWeights`` (4 a point), ``primvars:displayColor`` from the vertex colours, bound to
  ``Skel``.

``customLayerData["crowdstudy"]`` records the provenance. The same input gives the same bytes.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from crowdstudy.body.gltf_container import GltfFile
from crowdstudy.body.usd_stage import import_pxr
from crowdstudy.errors import InvalidInputError

__all__ = ["gltf_to_usd", "usd_layer_bytes", "UP_AXES"]

#: The stage up axes export-usd writes.
UP_AXES = ("Y", "Z")


def _axes(up: str, mpu: float) -> np.ndarray:
    """(4, 4) glTF world (Y up, metres) -> stage (``up``, units of ``mpu`` metres)."""
    k = np.eye(4) / mpu
    k[3, 3] = 1.0
    if up == "Z":  # glTF -> toolkit axes (Z_UP_TO_Y_UP is its own inverse)
        from crowdstudy.body.gltf_container import Z_UP_TO_Y_UP

        r = np.eye(4)
        r[:3, :3] = Z_UP_TO_Y_UP
        k = r @ k
    return k


def _gf(m: np.ndarray):
    """Gf.Matrix4d of a (4, 4) column-vector matrix."""
    _, _, _, gf, _, _ = import_pxr()
    return gf.Matrix4d(*[float(x) for x in np.asarray(m, dtype=np.float64).T.reshape(-1)])


def _joint_paths(doc: dict, joints: list[int], parent: np.ndarray) -> tuple[list[int], list[str]]:
    """The skin's joints ordered parents first, and their UsdSkel paths (names joined)."""
    import re

    inside = set(joints)

    def up(n: int) -> int:
        p = int(parent[n])
        while p >= 0 and p not in inside:
            p = int(parent[p])
        return p

    def depth(n: int) -> int:
        d, p = 0, up(n)
        while p >= 0:
            d, p = d + 1, up(p)
        return d

    order = sorted(joints, key=lambda n: (depth(n), joints.index(n)))
    paths: dict[int, str] = {}
    for n in order:
        name = re.sub(r"[^A-Za-z0-9_]", "_", str(doc["nodes"][n].get("name", f"joint{n}"))) or f"joint{n}"
        if name[0].isdigit():
            name = "_" + name
        p = up(n)
        paths[n] = name if p < 0 else f"{paths[p]}/{name}"
    return order, [paths[n] for n in order]


def gltf_to_usd(gltf: GltfFile, *, up_axis: str = "Z", meters_per_unit: float = 1.0, custom: dict | None = None):
    """A UsdSkel stage (in memory) of a glTF document's skinned characters (see the module
    docstring); returns the ``Usd.Stage``."""
    from crowdstudy.body.gltf_model import node_parents, node_world_matrices
    from crowdstudy.interchange.gltf_sampling import channels_of, keyframe_rate, world_at_frames

    usd, usd_geom, usd_skel, _, vt, sdf = import_pxr()
    if up_axis not in UP_AXES:
        raise InvalidInputError(f"--up-axis: expected one of {', '.join(UP_AXES)}, got {up_axis!r}")
    if not (np.isfinite(meters_per_unit) and meters_per_unit > 0):
        raise InvalidInputError(f"--meters-per-unit: expected a positive number, got {meters_per_unit}")
    doc = gltf.doc
    parent = node_parents(doc)
    world = node_world_matrices(doc, parent)
    anims = list(range(len(doc.get("animations", []))))
    channels = channels_of(gltf, anims, Path(gltf.path)) if anims else []
    rate = keyframe_rate(channels) or 30.0
    t1 = max((float(c.times[-1]) for c in channels), default=0.0)
    times = np.arange(int(np.floor(t1 * rate + 1e-3)) + 1) / rate
    stage = usd.Stage.CreateInMemory()
    usd_geom.SetStageUpAxis(stage, usd_geom.Tokens.z if up_axis == "Z" else usd_geom.Tokens.y)
    usd_geom.SetStageMetersPerUnit(stage, float(meters_per_unit))
    stage.SetTimeCodesPerSecond(float(rate))
    stage.SetStartTimeCode(0.0)
    stage.SetEndTimeCode(float(len(times) - 1))
    crowd = usd_geom.Xform.Define(stage, "/Crowd")
    crowd.AddTransformOp().Set(_gf(_axes(up_axis, meters_per_unit)))
    stage.SetDefaultPrim(crowd.GetPrim())
    layer = stage.GetRootLayer()
    layer.customLayerData = {"crowdstudy": json.dumps(custom or {}, sort_keys=True)}
    skin_nodes = [[int(j) for j in sk["joints"]] for sk in doc.get("skins", [])]
    all_joints = sorted({n for js in skin_nodes for n in js})
    _, local = world_at_frames(doc, parent, all_joints, channels, times) if all_joints else (None, {})
    used: set[str] = set()
    for s, joints in enumerate(skin_nodes):
        meshes = [i for i, n in enumerate(doc.get("nodes", [])) if n.get("skin") == s and "mesh" in n]
        if meshes:
            name = _prim_name(doc, meshes[0], s)
            name = name if name not in used else f"{name}_{s}"
            used.add(name)
            _write_character(stage, gltf, s, joints, meshes, parent, world, local, len(times), name)
    return stage


def _write_character(stage, gltf, s, joints: list[int], meshes: list[int], parent, world, local, n_t: int, name: str):
    """One glTF skin as a SkelRoot with its Skeleton, SkelAnimation and Mesh prims."""
    usd, usd_geom, usd_skel, gf, vt, sdf = import_pxr()
    doc = gltf.doc
    order, paths = _joint_paths(doc, joints, parent)
    root = usd_skel.Root.Define(stage, f"/Crowd/{name}")
    base = root.GetPath()
    skel = usd_skel.Skeleton.Define(stage, base.AppendChild("Skel"))
    top = order[0]
    above = world[int(parent[top])] if parent[top] >= 0 else np.eye(4)
    usd_geom.Xformable(skel).AddTransformOp().Set(_gf(above))
    sk = doc["skins"][s]
    ibm = gltf.accessor(sk["inverseBindMatrices"]).astype(np.float64) if "inverseBindMatrices" in sk else None
    bind = {j: (np.linalg.inv(ibm[k]) if ibm is not None else world[j]) for k, j in enumerate(joints)}
    from crowdstudy.body.gltf_model import node_local_matrix

    skel.CreateJointsAttr(vt.TokenArray(paths))
    skel.CreateBindTransformsAttr(vt.Matrix4dArray([_gf(bind[j]) for j in order]))
    skel.CreateRestTransformsAttr(vt.Matrix4dArray([_gf(node_local_matrix(doc["nodes"][j])) for j in order]))
    anim = usd_skel.Animation.Define(stage, base.AppendChild("Anim"))
    anim.CreateJointsAttr(vt.TokenArray(paths))
    mats = np.stack([local[j] for j in order], axis=1)  # (T, K, 4, 4)
    tr_a, ro_a, sc_a = anim.CreateTranslationsAttr(), anim.CreateRotationsAttr(), anim.CreateScalesAttr()
    from crowdstudy.body.rotations import matrix_to_quaternion, quat_align_signs

    sc = np.linalg.norm(mats[..., :3, :3], axis=-2)
    quat = quat_align_signs(matrix_to_quaternion(mats[..., :3, :3] / sc[..., None, :]), axis=0)
    for t in range(n_t):
        tc = usd.TimeCode(float(t))
        tr_a.Set(vt.Vec3fArray.FromNumpy(mats[t, :, :3, 3].astype(np.float32)), tc)
        ro_a.Set(vt.QuatfArray.FromNumpy(quat[t].astype(np.float32)), tc)
        sc_a.Set(vt.Vec3hArray.FromNumpy(sc[t].astype(np.float16)), tc)
    usd_skel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    usd_skel.BindingAPI.Apply(root.GetPrim())
    slot = {j: k for k, j in enumerate(order)}
    sj = np.array([slot[j] for j in joints], dtype=np.int64)
    for m, node in enumerate(meshes):
        _write_mesh(stage, gltf, doc["nodes"][node], base.AppendChild("Body" if m == 0 else f"Body{m}"), sj, skel)


def _prim_name(doc: dict, mesh_node: int, s: int) -> str:
    import re

    raw = str(doc["nodes"][mesh_node].get("name", "")).removesuffix("body").rstrip("_")
    name = re.sub(r"[^A-Za-z0-9_]", "_", raw) or f"character_{s}"
    return name if not name[0].isdigit() else "c" + name


def _write_mesh(stage, gltf, node: dict, path, sj: np.ndarray, skel) -> None:
    """The triangle primitives of a glTF mesh node as one skinned UsdGeom.Mesh."""
    _, usd_geom, usd_skel, gf, vt, _ = import_pxr()
    pts, faces, ji, jw, cols = [], [], [], [], []
    off = 0
    for prim in gltf.doc["meshes"][node["mesh"]]["primitives"]:
        if prim.get("mode", 4) != 4:
            continue
        a = prim["attributes"]
        p = gltf.accessor(a["POSITION"]).astype(np.float32)
        idx = gltf.accessor(prim["indices"]).astype(np.int64) if "indices" in prim else np.arange(len(p))
        pts.append(p)
        faces.append(idx + off)
        off += len(p)
        ji.append(sj[gltf.accessor(a["JOINTS_0"]).astype(np.int64)])
        jw.append(gltf.accessor(a["WEIGHTS_0"]).astype(np.float32))
        if "COLOR_0" in a:
            c = gltf.accessor(a["COLOR_0"]).astype(np.float32)
            cols.append(c[:, :3] / 255.0 if c.max(initial=0) > 1.0 else c[:, :3])
    if not pts:
        return
    p, f = np.concatenate(pts), np.concatenate(faces)
    mesh = usd_geom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(vt.Vec3fArray.FromNumpy(p))
    mesh.CreateFaceVertexCountsAttr(vt.IntArray.FromNumpy(np.full(len(f) // 3, 3, dtype=np.int32)))
    mesh.CreateFaceVertexIndicesAttr(vt.IntArray.FromNumpy(f.astype(np.int32)))
    mesh.CreateExtentAttr(vt.Vec3fArray.FromNumpy(np.stack([p.min(axis=0), p.max(axis=0)])))
    mesh.CreateSubdivisionSchemeAttr(usd_geom.Tokens.none)
    if len(cols) == len(pts):
        dc = mesh.CreateDisplayColorPrimvar(usd_geom.Tokens.vertex)
        dc.Set(vt.Vec3fArray.FromNumpy(np.concatenate(cols).astype(np.float32)))
    binding = usd_skel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    binding.CreateJointIndicesPrimvar(False, 4).Set(
        vt.IntArray.FromNumpy(np.concatenate(ji).astype(np.int32).reshape(-1))
    )
    binding.CreateJointWeightsPrimvar(False, 4).Set(vt.FloatArray.FromNumpy(np.concatenate(jw).reshape(-1)))
    binding.CreateGeomBindTransformAttr(gf.Matrix4d(1.0))


def usd_layer_bytes(stage, out_path: str | Path) -> bytes:
    """The bytes of the stage's root layer as ``out_path``'s suffix says (.usda text, .usdc
    or .usd crate), written through a temporary file in the output's folder."""
    import os
    import tempfile

    out_path = Path(out_path)
    suffix = out_path.suffix.lower()
    if suffix == ".usda":
        return stage.GetRootLayer().ExportToString().encode("utf-8")
    fd, tmp = tempfile.mkstemp(suffix=".usdc", dir=out_path.parent if out_path.parent.exists() else None)
    os.close(fd)
    try:
        if not stage.GetRootLayer().Export(tmp):
            raise InvalidInputError(f"output: cannot write USD {str(out_path)!r}")
        return Path(tmp).read_bytes()
    finally:
        Path(tmp).unlink(missing_ok=True)

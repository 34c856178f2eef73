"""Write a corrected crowd back into its USD stage (``crowdstudy correct IN.usd OUT.usd``).

The output is the input's root layer opened and edited: the same prims, meshes,
materials, skinning, custom data and metadata; per character only its ``SkelAnimation``
changes (:func:`crowdstudy.interchange.retarget.rewrite_rig`, the glTF side's rewrite):

* the mapped joints' rotations and the pelvis source's translation are the corrected ones,
  joints beside the mapped tree that follow a physics joint move with it; every other
  joint keeps its own motion (sampled from the input at the same times);
* the animation is keyed at the corrected frames (time codes ``time * timeCodesPerSecond``),
  its earlier time samples replaced;
* a ``SkelAnimation`` shared by several characters (UsdSkel instancing) or inside a native
  instance is not edited: each character gets its own ``CorrectedAnim`` beside its
  skeleton under its ``SkelRoot`` (an ``instanceable`` ancestor is made editable), bound by
  ``skel:animationSource``.

``customLayerData["crowdstudy_correct"]`` records the provenance.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from crowdstudy.body.rotations import quat_align_signs
from crowdstudy.body.usd_stage import import_pxr
from crowdstudy.interchange.gltf_write import rig_motion
from crowdstudy.interchange.usd_export import usd_layer_bytes

__all__ = ["corrected_usd_bytes"]


def corrected_usd_bytes(crowd, corrected, out_path: str | Path, provenance: dict) -> bytes:
    """The bytes of the corrected USD file (``out_path``'s suffix: .usda text, else crate)."""
    usd, _, usd_skel, _, _, sdf = import_pxr()
    src = crowd.usd
    layer = sdf.Layer.FindOrOpen(str(src.gltf.path))
    edit = sdf.Layer.CreateAnonymous(".usda" if Path(out_path).suffix.lower() == ".usda" else ".usdc")
    edit.TransferContent(layer)
    stage = usd.Stage.Open(edit)
    codes = crowd.times[: corrected.n_frames] * src.time_codes_per_second
    users: dict[str, int] = {}
    for c in crowd.characters:
        users[src.skins[c.spec.skins[0]].animation] = users.get(src.skins[c.spec.skins[0]].animation, 0) + 1
    for i, c in enumerate(crowd.characters):
        skin = src.skins[c.spec.skins[0]]
        motion = rig_motion(crowd, corrected, i)
        node_of = {int(n): k for k, n in enumerate(c.character.rig.nodes)}
        joint_of = {node_of[n]: skin.joints[j] for j, n in enumerate(skin.nodes) if n in node_of}
        anim = _animation_to_edit(stage, skin, users[skin.animation] > 1, usd_skel)
        _write_motion(stage, anim, skin, motion, joint_of, codes, crowd, c)
    data = dict(stage.GetRootLayer().customLayerData)
    data["crowdstudy_correct"] = json.dumps(provenance, sort_keys=True)
    stage.GetRootLayer().customLayerData = data
    return usd_layer_bytes(stage, out_path)


def _animation_to_edit(stage, skin, shared: bool, usd_skel):
    """The SkelAnimation prim to write character ``skin``'s motion to (see the module docstring)."""
    sdf = import_pxr()[5]
    anim = stage.GetPrimAtPath(skin.animation)
    root = stage.GetPrimAtPath(skin.skel_root)
    if not shared and not anim.IsInstanceProxy():
        return anim
    p = root
    while p and p.IsInstanceProxy():
        p = p.GetParent()
        if p.IsInstance():
            p.SetInstanceable(False)
            p = stage.GetPrimAtPath(skin.skel_root)
    root = stage.GetPrimAtPath(skin.skel_root)
    new = usd_skel.Animation.Define(stage, root.GetPath().AppendChild("CorrectedAnim"))
    src = usd_skel.Animation(stage.GetPrimAtPath(skin.animation))
    new.CreateJointsAttr(src.GetJointsAttr().Get())
    for name in ("translations", "rotations", "scales"):
        a = src.GetPrim().GetAttribute(name)
        b = new.GetPrim().GetAttribute(name)
        for t in a.GetTimeSamples():
            b.Set(a.Get(t), t)
        if a.HasAuthoredValue() and a.Get() is not None and not a.GetTimeSamples():
            b.Set(a.Get())
    target = sdf.Path(str(new.GetPath()))
    usd_skel.BindingAPI.Apply(root).CreateAnimationSourceRel().SetTargets([target])
    skel = stage.GetPrimAtPath(skin.skeleton)
    if str(skel.GetPath()).startswith(str(root.GetPath()) + "/"):
        usd_skel.BindingAPI.Apply(skel).CreateAnimationSourceRel().SetTargets([target])
    return new.GetPrim()


def _write_motion(stage, anim_prim, skin, motion, joint_of: dict, codes: np.ndarray, crowd, c) -> None:
    """Replace the animation's samples by the input's motion at ``codes`` with the corrected joints."""
    usd, _, usd_skel, _, vt, _ = import_pxr()
    anim = usd_skel.Animation(anim_prim)
    joints = [str(j) for j in anim.GetJointsAttr().Get() or []]
    changed = {joint_of[k] for k in (*motion.rotation, *motion.translation) if k in joint_of}
    extra = [j for j in skin.joints if j in changed and j not in joints]
    order = joints + extra
    slot = {j: n for n, j in enumerate(order)}
    cache = usd_skel.Cache()
    aq = cache.GetAnimQuery(anim_prim)
    rest = _rest_components(crowd, skin, extra)
    tr = np.zeros((len(codes), len(order), 3), dtype=np.float32)
    ro = np.zeros((len(codes), len(order), 4), dtype=np.float32)
    sc = np.ones((len(codes), len(order), 3), dtype=np.float32)
    for t, code in enumerate(codes):
        if joints:
            comps = aq.ComputeJointLocalTransformComponents(usd.TimeCode(float(code)))
            tr[t, : len(joints)], ro[t, : len(joints)], sc[t, : len(joints)] = (np.array(c) for c in comps)
        for n, j in enumerate(extra):
            tr[t, len(joints) + n], ro[t, len(joints) + n], sc[t, len(joints) + n] = rest[j]
    for k, q in motion.rotation.items():
        if k in joint_of:
            ro[:, slot[joint_of[k]]] = q
    for k, v in motion.translation.items():
        if k in joint_of:
            tr[:, slot[joint_of[k]]] = v
    ro = quat_align_signs(ro.astype(np.float64), axis=0).astype(np.float32)
    if extra:
        anim.GetJointsAttr().Set(vt.TokenArray(order))
    attrs = (anim.GetTranslationsAttr(), anim.GetRotationsAttr(), anim.GetScalesAttr())
    for a in attrs:
        if a.IsValid():
            a.Clear()
    tr_a, ro_a, sc_a = anim.CreateTranslationsAttr(), anim.CreateRotationsAttr(), anim.CreateScalesAttr()
    for t, code in enumerate(codes):
        tc = usd.TimeCode(float(code))
        tr_a.Set(vt.Vec3fArray.FromNumpy(tr[t]), tc)
        ro_a.Set(vt.QuatfArray.FromNumpy(np.ascontiguousarray(ro[t])), tc)
        sc_a.Set(vt.Vec3hArray.FromNumpy(sc[t].astype(np.float16)), tc)


def _rest_components(crowd, skin, extra: list[str]) -> dict:
    """{joint: (translation, rotation xyzw, scale)} of the skeleton's rest transforms for
    joints the animation did not drive (their glTF nodes' default TRS)."""
    doc = crowd.gltf.doc
    out = {}
    for j in extra:
        node = doc["nodes"][skin.nodes[skin.joints.index(j)]]
        out[j] = (node["translation"], node["rotation"], node["scale"])
    return out

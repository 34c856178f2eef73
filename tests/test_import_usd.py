"""A user's own crowd from USD (UsdSkel): import, correction file to file, export-usd.

The USD files are written by the tests from the glTF test characters of
tests/rig_fixtures.py (a Blender-named rig in centimetres, a CesiumMan-like numbered rig)
crowded by tests/gltf_crowd_fixtures.py, converted by
:func:`crowdstudy.interchange.usd_export.gltf_to_usd` in centimetres/Z-up and
metres/Y-up: each USD import must give the glTF import's motion.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from gltf_crowd_fixtures import crowd_of
from rig_fixtures import write_rig_character

pytest.importorskip("pxr", reason="usd-core is not installed (pip install 'crowdstudy[usd]')")

from pxr import Sdf, Usd, UsdGeom, UsdSkel, UsdValidation  # noqa: E402

from crowdstudy.body import load_body  # noqa: E402
from crowdstudy.body.gltf_container import read_gltf  # noqa: E402
from crowdstudy.cli import main  # noqa: E402
from crowdstudy.errors import InvalidInputError  # noqa: E402
from crowdstudy.gltf.export_usd import export_usd  # noqa: E402
from crowdstudy.interchange.gltf_crowd import read_crowd  # noqa: E402
from crowdstudy.interchange.usd_export import gltf_to_usd, usd_layer_bytes  # noqa: E402
from crowdstudy.motion import load_clip  # noqa: E402
from crowdstudy.physics.correct_file import correct_gltf  # noqa: E402

FRAMES = 24
ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def glb_crowds(tmp_path_factory):
    clip = load_clip("cheer")
    body = load_body({"model": "open", "sex": "female", "height": 1.62})
    folder = tmp_path_factory.mktemp("usd_rigs")
    out = {}
    for naming in ("blender", "numbered"):
        one = folder / f"{naming}.glb"
        write_rig_character(
            one,
            body,
            clip.joint_rotations[:FRAMES],
            clip.root_translation[:FRAMES],
            clip.fps,
            naming=naming,
            seed=3,
            rigid=False,
        )
        out[naming] = crowd_of(one, folder / f"{naming}_crowd.glb", n=3, spacing=0.3, shift_keys=7, seed=1)
    return out


def _usd(glb: Path, out: Path, up: str, mpu: float) -> Path:
    out.write_bytes(usd_layer_bytes(gltf_to_usd(read_gltf(glb), up_axis=up, meters_per_unit=mpu), out))
    return out


def _validate(path: Path) -> list[str]:
    ctx = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    errors = ctx.Validate(Usd.Stage.Open(str(path)))
    return [e.GetMessage() for e in errors if e.GetType() == UsdValidation.ValidationErrorType.Error]


@pytest.mark.parametrize("naming", ["blender", "numbered"])
@pytest.mark.parametrize(("up", "mpu", "suffix"), [("Z", 0.01, ".usda"), ("Y", 1.0, ".usdc")])
def test_usd_import_is_the_gltf_import(glb_crowds, tmp_path, naming, up, mpu, suffix):
    glb = glb_crowds[naming]
    usd = _usd(glb, tmp_path / f"crowd{suffix}", up, mpu)
    a, b = read_crowd(glb), read_crowd(usd)
    assert b.anim.n_characters == a.anim.n_characters == 3
    assert b.anim.fps == pytest.approx(a.anim.fps)
    np.testing.assert_allclose(b.anim.joint_rotations, a.anim.joint_rotations, atol=1e-5)
    np.testing.assert_allclose(b.anim.root_translation, a.anim.root_translation, atol=1e-5)
    assert b.anim.bodies[0]["model"] == "usd"
    body = load_body(b.anim.bodies[1])  # the record reloads from the USD file
    np.testing.assert_allclose(body.rest_vertices, b.bodies[1].rest_vertices, atol=1e-6)
    assert b.anim.meta["imported"]["format"] == "usd"


def test_correct_usd_file_to_file(glb_crowds, tmp_path):
    usd = _usd(glb_crowds["blender"], tmp_path / "crowd.usda", "Z", 0.01)
    out = tmp_path / "out.usda"
    assert main(["correct", str(usd), str(out), "--frames", "10", "--no-progress"]) == 0
    report = json.loads((tmp_path / "out.overlap.json").read_text())
    assert report["overall"]["after_litres"] < report["overall"]["before_litres"]
    again = read_crowd(out)
    corrected = correct_gltf(usd, tmp_path / "x.usda", frames=10).corrected
    np.testing.assert_allclose(again.anim.joint_rotations[:10], corrected.joint_rotations, atol=1e-4)
    np.testing.assert_allclose(again.anim.root_translation[:10], corrected.root_translation, atol=1e-5)
    assert _validate(out) == []
    _same_prims_but_animation(usd, out)


def _same_prims_but_animation(a: Path, b: Path) -> None:
    sa, sb = Usd.Stage.Open(str(a)), Usd.Stage.Open(str(b))
    pa = [p.GetPath() for p in sa.Traverse()]
    assert pa == [p.GetPath() for p in sb.Traverse()]
    for path in pa:
        x, y = sa.GetPrimAtPath(path), sb.GetPrimAtPath(path)
        assert x.GetTypeName() == y.GetTypeName()
        if x.IsA(UsdSkel.Animation):
            continue
        for attr in x.GetAttributes():
            other = y.GetAttribute(attr.GetName())
            assert other.IsValid(), (path, attr.GetName())
            va, vb = attr.Get(), other.Get()
            assert (np.asarray(va) == np.asarray(vb)).all() if va is not None else vb is None, (path, attr.GetName())
    for key in ("upAxis", "metersPerUnit", "timeCodesPerSecond"):
        assert sa.GetMetadata(key) == sb.GetMetadata(key)


def test_export_usd_round_trip(glb_crowds, tmp_path):
    anim = read_crowd(glb_crowds["numbered"]).anim
    npz = tmp_path / "anim.npz"
    anim.save(npz)
    out = tmp_path / "crowd.usda"
    assert main(["export-usd", str(npz), str(out)]) == 0
    assert _validate(out) == []
    back = read_crowd(out)
    assert back.anim.n_characters == anim.n_characters
    np.testing.assert_allclose(back.anim.root_translation, anim.root_translation, atol=1e-4)
    g = back.anim.joint_rotations
    assert np.abs(g - anim.joint_rotations).max() < 1e-3
    assert out.read_bytes() == (export_usd(anim, tmp_path / "again.usda") and (tmp_path / "again.usda").read_bytes())


def test_usd_skel_instancing_shares_one_animation(glb_crowds, tmp_path):
    """Two SkelRoots whose skeletons bind one SkelAnimation are two characters; correcting
    them gives each its own CorrectedAnim."""
    usd = _usd(glb_crowds["numbered"], tmp_path / "crowd.usda", "Z", 1.0)
    stage = Usd.Stage.Open(str(usd))
    roots = [p for p in stage.Traverse() if p.IsA(UsdSkel.Root)]
    shared = roots[0].GetPath().AppendChild("Anim")
    for r in roots[1:]:
        UsdSkel.BindingAPI(r.GetChild("Skel")).GetAnimationSourceRel().SetTargets([shared])
    stage.GetRootLayer().Save()
    crowd = read_crowd(usd)
    assert crowd.anim.n_characters == 3
    assert crowd.usd.animations == [str(shared)]
    out = tmp_path / "out.usda"
    assert main(["correct", str(usd), str(out), "--frames", "6", "--no-progress"]) == 0
    text = out.read_text()
    assert text.count('def SkelAnimation "CorrectedAnim"') == 3
    assert read_crowd(out).anim.n_characters == 3


def test_native_instancing_each_instance_a_character(glb_crowds, tmp_path):
    usd = _usd(glb_crowds["numbered"], tmp_path / "one.usda", "Z", 1.0)
    stage = Usd.Stage.CreateNew(str(tmp_path / "instanced.usda"))
    UsdGeom.SetStageUpAxis(stage, "Z")
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(Usd.Stage.Open(str(usd)).GetTimeCodesPerSecond())
    for k in range(2):
        UsdGeom.Xform.Define(stage, f"/Place_{k}").AddTranslateOp().Set((3.0 * k, 0.0, 0.0))
        p = UsdGeom.Xform.Define(stage, f"/Place_{k}/Crowd")
        p.GetPrim().GetReferences().AddReference(usd.name, Sdf.Path("/Crowd"))
        p.GetPrim().SetInstanceable(True)
    stage.GetRootLayer().Save()
    crowd = read_crowd(tmp_path / "instanced.usda")
    assert crowd.anim.n_characters == 6
    x = crowd.anim.root_translation[0, :, 0]
    assert x[3:].mean() - x[:3].mean() == pytest.approx(3.0, abs=1e-3)


def test_usd_errors_are_named(glb_crowds, tmp_path, capsys):
    cm = _usd(glb_crowds["blender"], tmp_path / "cm.usda", "Z", 0.01)
    layer = Sdf.Layer.FindOrOpen(str(cm))
    layer.ClearMetersPerUnit() if hasattr(layer, "ClearMetersPerUnit") else None
    text = cm.read_text().replace("    metersPerUnit = 0.01\n", "")
    nounit = tmp_path / "nounit.usda"
    nounit.write_text(text)
    with pytest.raises(InvalidInputError, match="metersPerUnit"):
        read_crowd(nounit)
    still = tmp_path / "still.usda"
    still.write_text(
        text.replace("    metersPerUnit", "    metersPerUnit").replace("rel skel:animationSource", "rel x")
    )
    noanim = tmp_path / "noanim.usda"
    noanim.write_text(cm.read_text().replace("rel skel:animationSource", "rel notAnimationSource"))
    with pytest.raises(InvalidInputError, match="no SkelAnimation"):
        read_crowd(noanim)
    noskel = tmp_path / "noskel.usda"
    noskel.write_text(cm.read_text().replace("rel skel:skeleton", "rel notSkeleton"))
    with pytest.raises(InvalidInputError, match="no character"):
        read_crowd(noskel)
    out = tmp_path / "out.usdc"
    assert main(["correct", str(cm), str(out)]) == 2
    assert "must be a .usda file" in capsys.readouterr().err
    assert not out.exists()
    assert main(["import-crowd", str(nounit), "--out", str(tmp_path / "a.npz")]) == 2
    assert not (tmp_path / "a.npz").exists()


# ---------------------------------------------------------------------- Blender-written USD

BPY_PYTHON = os.environ.get("CROWDSTUDY_BPY_PYTHON") or str(ROOT / "build" / "bpy-venv" / "bin" / "python")
needs_bpy = pytest.mark.skipif(
    not Path(BPY_PYTHON).is_file(),
    reason="no Python with Blender's bpy module (scripts/setup_bpy.sh, or CROWDSTUDY_BPY_PYTHON)",
)


def _bpy(*args: str) -> str:
    res = subprocess.run([BPY_PYTHON, *args], capture_output=True, text=True, timeout=600)
    assert res.returncode == 0 and "OK" in res.stdout, (res.stdout + res.stderr)[-2000:]
    return res.stdout


@pytest.fixture(scope="module")
def blender_usd(glb_crowds, tmp_path_factory):
    """The Blender-named crowd written by Blender's own USD exporter, in metres and in a
    centimetre scene (armatures scaled by 100, metersPerUnit 0.01)."""
    if not Path(BPY_PYTHON).is_file():
        pytest.skip("no Python with bpy")
    folder = tmp_path_factory.mktemp("blender_usd")
    out = {}
    for unit, scale in (("m", "1"), ("cm", "0.01")):
        out[unit] = folder / f"crowd_{unit}.usda"
        _bpy(str(ROOT / "tests/blender/usd_from_gltf.py"), str(glb_crowds["blender"]), str(out[unit]), scale)
    return out


@pytest.mark.slow
@needs_bpy
@pytest.mark.parametrize("unit", ["m", "cm"])
def test_blender_usd_moves_as_the_gltf(glb_crowds, blender_usd, unit):
    """Blender's USD (its bone axes, names, unit scale, 24 fps) gives the glTF file's joint
    positions, turned half a turn about z (Blender's Z-up world is glTF's turned so)."""
    from crowdstudy.body.skeleton import forward_kinematics

    assert Usd.Stage.Open(str(blender_usd[unit])).GetMetadata("metersPerUnit") == pytest.approx(
        1.0 if unit == "m" else 0.01
    )
    a, b = read_crowd(glb_crowds["blender"], fps=24.0), read_crowd(blender_usd[unit], fps=24.0)
    assert b.anim.n_characters == a.anim.n_characters == 3
    n = min(a.anim.n_frames, b.anim.n_frames)
    turn = np.array([-1.0, -1.0, 1.0])
    for j in range(3):  # Blender orders its characters as it likes: match them by place
        i = int(np.argmin(np.linalg.norm(a.anim.root_translation[0] - b.anim.root_translation[0, j] * turn, axis=1)))
        _, pa = forward_kinematics(
            a.bodies[i].rest_joints, a.anim.joint_rotations[:n, i], a.anim.root_translation[:n, i]
        )
        _, pb = forward_kinematics(
            b.bodies[j].rest_joints, b.anim.joint_rotations[:n, j], b.anim.root_translation[:n, j]
        )
        np.testing.assert_allclose(pb * turn, pa, atol=3e-3)


@pytest.mark.slow
@needs_bpy
def test_blender_usd_corrected_file_to_file(blender_usd, tmp_path):
    src = blender_usd["cm"]
    out = tmp_path / "ours.usda"
    assert main(["correct", str(src), str(out), "--no-progress"]) == 0
    report = json.loads((tmp_path / "ours.overlap.json").read_text())
    assert report["overall"]["after_litres"] < 0.5 * report["overall"]["before_litres"]
    assert _validate(out) == []
    _same_prims_but_animation(src, out)
    assert read_crowd(out).anim.n_characters == 3
    text = _bpy(str(ROOT / "tests/blender/usd_import_check.py"), str(out), "x")
    assert "armatures 3" in text

"""Real character files made by others (tests/data/SOURCES.md): Debian's assimp test model
BCN_Epileptic (a skinned body of three meshes, a 54-bone rig whose legs hang from a lower
pelvis beside the spine, ``B_*_Left`` names) and Minetest's blocky player (one joint per
limb), converted to .glb by assimp's own glTF writer at test time into the cache folder.

BCN maps (the table is printed), imports, and a crowd of copies is corrected file to file
with its mesh overlap falling, then read back; Minetest's player gives the named error of a
rig too coarse for the physics skeleton. The tests skip where the Debian packages
(``assimp-utils``, ``assimp-testmodels``, ``minetest-data``: ``make setup`` installs them)
are absent.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from gltf_crowd_fixtures import crowd_of

from crowdstudy.body.gltf_container import read_gltf
from crowdstudy.body.skeleton import forward_kinematics
from crowdstudy.cli import main
from crowdstudy.interchange.gltf_crowd import read_crowd
from crowdstudy.physics.correct_file import correct_gltf, write_outputs

ROOT = Path(__file__).resolve().parent.parent
JS = ROOT / "tests" / "js"
BCN_X = Path("/usr/share/assimp/models/X/BCN_Epileptic.X")
MINETEST_B3D = Path("/usr/share/games/minetest/games/minetest_game/mods/player_api/models/character.b3d")


def _converted(src: Path, name: str) -> Path:
    """``src`` as .glb by ``assimp export -fglb2``, once, in $CROWDSTUDY_CACHE/real-files."""
    if shutil.which("assimp") is None:
        pytest.skip("Debian package assimp-utils absent (make setup installs it)")
    if not src.is_file():
        pytest.skip(f"{src} absent: its Debian package is not installed (make setup installs it)")
    cache = Path(os.environ.get("CROWDSTUDY_CACHE", ROOT / "build" / "cache")) / "real-files"
    cache.mkdir(parents=True, exist_ok=True)
    out = cache / name
    if not out.is_file() or out.stat().st_mtime < src.stat().st_mtime:
        tmp = cache / f".{name}.tmp.glb"
        subprocess.run(["assimp", "export", str(src), str(tmp), "-fglb2"], check=True, capture_output=True, timeout=120)
        tmp.replace(out)
    return out


@pytest.fixture(scope="module")
def bcn() -> Path:
    return _converted(BCN_X, "BCN_Epileptic.glb")


def test_bcn_maps_by_its_names_and_imports(bcn, tmp_path, capsys):
    out = tmp_path / "bcn.npz"
    assert main(["import-crowd", str(bcn), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    print(text)
    for ours, theirs in [
        ("pelvis", "B_Root_Pelvis_L"),
        ("left_hip", "B_Hip_Left"),
        ("right_knee", "B_Knee_Right"),
        ("left_collar", "B_Clavicle_Left"),
        ("right_shoulder", "B_UpperArm_Right"),
        ("left_elbow", "B_ForeArm_Left"),
        ("right_wrist", "B_Hand_Right"),
        ("head", "B_Neck"),
    ]:
        assert any(line.split()[:3] == [ours, theirs, "name"] for line in text.splitlines()), (ours, text)
    crowd = read_crowd(bcn)
    assert len(crowd.characters) == 1 and crowd.anim.joint_rotations.shape[0] == 100
    assert 1.4 < float(np.ptp(crowd.bodies[0].rest_joints[:, 2])) + 0.2 < 2.1  # a human's stature, metres


def test_bcn_maps_by_topology_without_names(bcn, tmp_path, capsys):
    """The same rig unnamed: its legs hang from a lower pelvis beside the spine and its arms
    hang down at rest; the topology still finds pelvis, legs, spine and arms."""
    path = crowd_of(bcn, tmp_path / "unnamed.glb", n=1, spacing=1.0, unnamed=True)
    assert main(["import-crowd", str(path), "--out", str(tmp_path / "u.npz")]) == 0
    text = capsys.readouterr().out
    print(text)
    assert "topology (legs and spine branch here)" in text and "required joints missing" not in text


@pytest.mark.slow
def test_bcn_crowd_corrected_file_to_file(bcn, tmp_path):
    # BCN's origin is its pelvis (its feet 0.99 m below): the copies stand on the floor
    crowd = crowd_of(bcn, tmp_path / "crowd.glb", n=4, spacing=0.35, shift_keys=17, seed=2, lift=0.99)
    dst = tmp_path / "ours.glb"
    res = correct_gltf(crowd, dst, device="cpu", overlap_every=0.2)
    write_outputs({dst: res.data})
    o = res.overlap["overall"]
    print(json.dumps(o))
    assert o["before_litres"] > 2.0 and o["after_litres"] < 0.25 * o["before_litres"], o  # 5.7 -> 0.14 litres
    a, b = read_gltf(crowd), read_gltf(dst)
    assert a.doc["meshes"] == b.doc["meshes"] and a.doc["skins"] == b.doc["skins"]
    back = read_crowd(dst)
    assert len(back.characters) == 4
    np.testing.assert_allclose(back.anim.root_translation, res.corrected.root_translation, atol=1e-5)
    if shutil.which("node") and (JS / "node_modules" / "gltf-validator").is_dir():
        # assimp's writer leaves skin weights that do not sum to one (the validator's
        # ACCESSOR_WEIGHTS_NON_NORMALIZED errors, in the input already): the output adds none
        cmd = ["node", str(JS / "validate.mjs"), str(crowd), str(dst)]
        reps = [
            json.loads(line)
            for line in subprocess.run(cmd, capture_output=True, text=True, timeout=120).stdout.splitlines()
        ]
        errors = [sorted((m["code"], m["pointer"]) for m in r["messages"] if m["severity"] == 0) for r in reps]
        assert {c for c, _ in errors[0]} <= {"ACCESSOR_WEIGHTS_NON_NORMALIZED"}, errors[0][:5]
        assert errors[1] == errors[0], errors[1][:5]


def test_minetest_player_is_too_coarse(tmp_path, capsys):
    path = _converted(MINETEST_B3D, "minetest_character.glb")
    out = tmp_path / "out"
    out.mkdir()
    assert main(["import-crowd", str(path), "--out", str(out / "a.npz")]) == 2
    err = capsys.readouterr().err
    assert "required joints missing: the knees, the elbows" in err and "Traceback" not in err, err
    assert "Arm_Left" in err and "Leg_Right" in err
    assert not any(out.iterdir())


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("blender") is None, reason="Blender not installed (optional: apt-get install blender)")
def test_bcn_written_by_blender_moves_as_assimps(bcn, tmp_path):
    """A second real writer: Blender's glTF exporter (its own node order, bone axes and
    per-frame keys at 24 fps) re-writes the assimp file; the import finds the same mapping
    and the same motion."""
    out = tmp_path / "blender.glb"
    cmd = ["blender", "-b", "--factory-startup", "--python", str(ROOT / "tests/blender/reexport.py")]
    res = subprocess.run([*cmd, "--", str(bcn), str(out), "animations"], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    ours, theirs = read_crowd(bcn, fps=30.0), read_crowd(out, fps=30.0)
    print(theirs.report())
    names = lambda c: {j: c.character.rig_map.names[m.source] for j, m in c.character.rig_map.joints.items()}  # noqa: E731
    assert names(theirs.characters[0]) == names(ours.characters[0])
    a, b = ours.anim, theirs.anim
    n = min(a.n_frames, b.n_frames)
    assert n >= a.n_frames - 4
    pa = forward_kinematics(ours.bodies[0].rest_joints, a.joint_rotations[:n], a.root_translation[:n])[1]
    pb = forward_kinematics(theirs.bodies[0].rest_joints, b.joint_rotations[:n], b.root_translation[:n])[1]
    err = np.linalg.norm(pa - pb, axis=-1)
    print(f"joint positions, Blender's file vs assimp's: median {np.median(err):.4f} m, max {err.max():.4f} m")
    assert np.median(err) < 0.005 and err.max() < 0.02  # 0.2 mm and 4.4 mm

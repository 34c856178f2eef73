"""A user's own crowd from glTF: the rig mapping (names, topology, --map), import of every
character of a file as a CrowdAnimation, correction file to file (the same scene with the
corrected motion), the Khronos validator, three.js, Blender where installed, and the
named errors of bad input.

The characters are written by the tests in the layouts of real third-party rigs
(tests/rig_fixtures.py: RobotExpressive's Blender-style names, rigid parts and centimetre
armature; CesiumMan's numbered joints; the same without names), from a toolkit body and a
motion-capture clip, so every import is checked against the motion it encodes. When
``CROWDSTUDY_GLTF_SAMPLES`` names a folder holding the real files (RobotExpressive.glb,
CesiumMan.glb: see tests/data/SOURCES.md), they are imported and corrected too.
"""

from __future__ import annotations

import functools
import http.server
import json
import os
import shutil
import subprocess
import threading
from pathlib import Path

import numpy as np
import pytest
from gltf_crowd_fixtures import crowd_of
from rig_fixtures import kept_joints, write_rig_character

from crowdstudy.body import load_body
from crowdstudy.body.gltf_container import Z_UP_TO_Y_UP, GltfBuilder, read_gltf
from crowdstudy.body.rig_map import map_rig, read_overrides, side_of_name
from crowdstudy.body.rotations import axis_angle_to_matrix
from crowdstudy.body.skeleton import DEFAULT_REST_JOINTS, JOINT_INDEX, JOINT_NAMES, PARENTS, forward_kinematics
from crowdstudy.cli import main
from crowdstudy.errors import InvalidInputError
from crowdstudy.interchange.gltf_crowd import read_crowd
from crowdstudy.motion import load_clip
from crowdstudy.physics.correct_file import correct_gltf, write_outputs

ROOT = Path(__file__).resolve().parent.parent
JS = ROOT / "tests" / "js"
NAMINGS = ("blender", "numbered", "unnamed")
FRAMES = 36
needs_validator = pytest.mark.skipif(
    shutil.which("node") is None or not (JS / "node_modules" / "gltf-validator").is_dir(),
    reason="node or tests/js/node_modules missing (make setup)",
)


@pytest.fixture(scope="module")
def motion():
    clip = load_clip("cheer")
    return clip.joint_rotations[:FRAMES], clip.root_translation[:FRAMES], clip.fps


@pytest.fixture(scope="module")
def body():
    return load_body({"model": "open", "sex": "female", "height": 1.62})


@pytest.fixture(scope="module")
def characters(tmp_path_factory, body, motion):
    folder = tmp_path_factory.mktemp("rigs")
    out = {}
    for naming in NAMINGS:
        path = folder / f"{naming}.glb"
        out[naming] = (path, write_rig_character(path, body, *motion, naming=naming, seed=3))
    return out


@pytest.fixture(scope="module")
def crowds(tmp_path_factory, characters):
    folder = tmp_path_factory.mktemp("crowds")
    return {
        n: crowd_of(p, folder / f"{n}_crowd.glb", n=4, spacing=0.3, shift_keys=9, seed=1)
        for n, (p, _) in characters.items()
    }


# ---------------------------------------------------------------------- mapping


@pytest.mark.parametrize("naming", NAMINGS)
def test_each_layout_maps_and_imports_the_motion_it_encodes(characters, naming):
    path, truth = characters[naming]
    crowd = read_crowd(path)
    print(crowd.report())  # the mapping table, in the test log
    ch = crowd.characters[0].character
    rm = ch.rig_map
    kept = kept_joints(naming)
    assert sorted(rm.joints) == sorted(kept) and sorted(rm.missing) == sorted(set(JOINT_NAMES) - set(kept))
    for j in kept:  # each physics joint found its own source joint
        if naming != "unnamed":
            assert rm.names[rm.joints[j].source] == truth["names"][j], j
        else:
            assert rm.names[rm.joints[j].source].startswith("#")
    hows = {j: m.how for j, m in rm.joints.items()}
    if naming == "blender":  # Hips is a spine joint here: the shape wins over the name table
        assert hows["pelvis"] == "topology" and hows["left_collar"] == "name" and hows["left_knee"] == "topology"
        assert ch.height == pytest.approx(1.62, abs=0.02)  # centimetre armature, metres out
        assert crowd.characters[0].spec.rigid and not crowd.characters[0].spec.skins
    else:
        assert set(hows.values()) == {"topology"}
    anim = crowd.anim
    assert anim.n_frames == FRAMES and anim.fps == pytest.approx(truth["rotations"].shape[0] and 60.0)
    g, p = forward_kinematics(crowd.bodies[0].rest_joints, anim.joint_rotations[:, 0], anim.root_translation[:, 0])
    idx = [JOINT_INDEX[j] for j in kept]
    np.testing.assert_allclose(g[:, idx], truth["global"][:, idx], atol=1e-5)
    np.testing.assert_allclose(p[:, idx], truth["positions"][:, idx], atol=1e-5)


def test_names_and_sides():
    assert [side_of_name(n) for n in ("UpperArm.L", "UpperArmR", "leg_joint_L_1", "LeftUpLeg", "lThigh")] == [
        -1,
        1,
        -1,
        -1,
        -1,
    ]
    assert [side_of_name(n) for n in ("Skeleton_arm_joint_R__2_", "Hips", "Palm2L", "Left_Right")] == [1, 0, -1, 0]


def test_map_overrides_and_named_errors(tmp_path):
    rest = DEFAULT_REST_JOINTS
    names = [f"j{k}" for k in range(24)]
    rm = map_rig(names, PARENTS, rest, forward=(0.0, 1.0, 0.0))
    assert rm.joints["left_knee"].source == JOINT_INDEX["left_knee"] and rm.joints["left_knee"].how == "topology"
    # --map: the physics joint takes the named joint (here a finger beside the hand), marked "map"
    names2 = [*names, "finger"]
    parents2 = np.append(PARENTS, JOINT_INDEX["left_wrist"])
    rest2 = np.vstack([rest, rest[JOINT_INDEX["left_wrist"]] + [-0.05, 0.03, 0.0]])
    rm2 = map_rig(names2, parents2, rest2, forward=(0.0, 1.0, 0.0), overrides={"left_hand": "finger"})
    assert rm2.joints["left_hand"].how == "map" and rm2.joints["left_hand"].source == 24
    assert rm2.weight_joint(JOINT_INDEX["left_hand"]) == "left_wrist"  # the old hand joint, now unmapped
    assert "finger" in rm2.table() and "map" in rm2.table()
    with pytest.raises(InvalidInputError, match="no joint named 'nope'"):
        map_rig(names, PARENTS, rest, forward=(0.0, 1.0, 0.0), overrides={"head": "nope"})
    # without names, toes that point forward or a forward direction, left and right are unknown
    flat = np.array(rest)
    for s in ("left", "right"):
        flat[JOINT_INDEX[f"{s}_foot"], :2] = flat[JOINT_INDEX[f"{s}_ankle"], :2]
    with pytest.raises(InvalidInputError, match="left from its right"):
        map_rig([""] * 24, PARENTS, flat)
    bad = tmp_path / "map.json"
    bad.write_text('{"left_kneee": "x"}')
    with pytest.raises(InvalidInputError, match="left_kneee"):
        read_overrides(bad)
    bad.write_text("[1, 2]")
    with pytest.raises(InvalidInputError, match="JSON object"):
        read_overrides(bad)


# ---------------------------------------------------------------------- import


def test_import_crowd_cli_prints_the_mapping_and_shares_bodies(crowds, tmp_path, capsys):
    out = tmp_path / "crowd.npz"
    assert main(["import-crowd", str(crowds["numbered"]), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "4 characters" in text and "leg_joint_L_2" in text and "topology (leg chain: middle joint)" in text
    assert "placed from its neighbours" in text and "mapping: as the character above" in text
    from crowdstudy.scene import CrowdAnimation

    anim = CrowdAnimation.load(out)
    assert anim.n_characters == 4 and anim.meta["imported"]["format"] == "gltf"
    assert [b["skin"] for b in anim.bodies] == [0, 1, 2, 3]  # instances: one mesh, four skins
    keys = {load_body(b).template_key for b in anim.bodies}
    assert len(keys) == 1
    crowd = read_crowd(crowds["numbered"])
    assert len({id(b) for b in crowd.bodies}) == 1  # one fit of the capsules for the four
    # the copies are shifted in time: their motions differ
    assert not np.allclose(anim.joint_rotations[:, 0], anim.joint_rotations[:, 1])


def test_weights_not_summing_to_one_are_normalised_and_reported(characters, tmp_path):
    path = crowd_of(characters["numbered"][0], tmp_path / "w.glb", n=2, spacing=1.0, weight_scale=0.8)
    crowd = read_crowd(path)
    rig = crowd.characters[0].character.rig
    assert rig.renormalised > 0 and rig.weight_sum_range[0] == pytest.approx(0.8, abs=1e-3)
    np.testing.assert_allclose(crowd.bodies[0].weights.sum(axis=1), 1.0, atol=1e-5)
    assert "did not sum to one" in crowd.report() and "normalised" in crowd.report()


def test_fps_resamples_and_different_rates_need_fps(characters, tmp_path):
    crowd = read_crowd(characters["numbered"][0], fps=30.0)
    assert crowd.anim.fps == 30.0 and crowd.anim.n_frames == (FRAMES - 1) // 2 + 1
    path = crowd_of(characters["numbered"][0], tmp_path / "rates.glb", n=2, spacing=1.0, last_rate=1.25)
    with pytest.raises(InvalidInputError, match="different rates"):
        read_crowd(path)
    assert read_crowd(path, fps=60.0).anim.n_characters == 2


# ---------------------------------------------------------------------- correct file to file


@pytest.fixture(scope="module")
def corrected(crowds, tmp_path_factory):
    folder = tmp_path_factory.mktemp("ours")
    out = {}
    for naming, path in crowds.items():
        doc = read_gltf(path).doc
        src = folder / f"{naming}_in.glb"
        _with_extras(path, src)
        dst = folder / f"{naming}_ours.glb"
        res = correct_gltf(src, dst, device="cpu", overlap_every=0.1)
        write_outputs({dst: res.data})
        out[naming] = (src, dst, res, doc)
    return out


def _with_extras(path: Path, out: Path) -> None:
    """The crowd with extras and an unknown extension (they must survive the correction)."""
    g = read_gltf(path)
    b = GltfBuilder()
    b.doc = json.loads(json.dumps(g.doc))
    b._bin = bytearray(g.buffers[0])
    b.doc["extras"] = {"author": "test", "take": 3}
    b.doc["nodes"][0]["extras"] = {"role": "first"}
    b.doc["nodes"][0]["extensions"] = {"EXT_crowdstudy_test": {"kept": True}}
    b.doc["extensionsUsed"] = [*b.doc.get("extensionsUsed", []), "EXT_crowdstudy_test"]
    b.doc.pop("buffers", None)
    b.write(out)


@pytest.mark.slow
@pytest.mark.parametrize("naming", NAMINGS)
def test_correct_file_to_file_keeps_the_scene_and_resolves_overlap(corrected, naming):
    src, dst, res, _ = corrected[naming]
    a, b = read_gltf(src), read_gltf(dst)
    for key in ("nodes", "meshes", "skins", "materials", "images", "textures", "scenes"):
        assert len(a.doc.get(key, [])) == len(b.doc.get(key, [])), key
    assert [m for m in a.doc["meshes"]] == [m for m in b.doc["meshes"]]
    assert a.doc.get("skins") == b.doc.get("skins")
    assert b.doc["extras"] == {"author": "test", "take": 3} and b.doc["nodes"][0]["extensions"]
    assert "crowdstudy_correct" in b.doc["asset"]["extras"]
    for i in range(len(a.doc["accessors"])):  # every accessor of the input, same index, same bytes
        np.testing.assert_array_equal(a.accessor(i), b.accessor(i))
    for k, (na, nb) in enumerate(zip(a.doc["nodes"], b.doc["nodes"], strict=True)):
        assert {x: v for x, v in na.items() if x not in ("rotation", "translation")} == {
            x: v for x, v in nb.items() if x not in ("rotation", "translation")
        }, k
    # imported again, the file moves as the corrected animation: every mapped joint's world
    # rotation and the root (a joint the rig lacks is carried by its mapped children)
    back = read_crowd(dst)
    ours = res.corrected
    mapped = [JOINT_INDEX[j] for j in back.characters[0].character.rig_map.joints]
    rest = back.bodies[0].rest_joints
    g_back, _ = forward_kinematics(rest, back.anim.joint_rotations, back.anim.root_translation)
    g_ours, _ = forward_kinematics(rest, ours.joint_rotations, ours.root_translation)
    np.testing.assert_allclose(g_back[:, :, mapped], g_ours[:, :, mapped], atol=2e-5)
    np.testing.assert_allclose(back.anim.root_translation, ours.root_translation, atol=1e-5)
    moved = np.abs(axis_angle_to_matrix(ours.joint_rotations) - axis_angle_to_matrix(res.crowd.anim.joint_rotations))
    assert moved.max() > 0.01  # the correction did change the motion
    o = res.overlap["overall"]
    assert o["before_litres"] > 0.5 and o["after_litres"] < 0.6 * o["before_litres"]
    assert len(res.overlap["characters"]) == 4


@pytest.mark.slow
@needs_validator
def test_corrected_files_pass_the_khronos_validator(corrected):
    paths = [str(dst) for _, dst, _, _ in corrected.values()]
    out = subprocess.run(["node", str(JS / "validate.mjs"), *paths], capture_output=True, text=True, timeout=120)
    for line in out.stdout.splitlines():
        rep = json.loads(line)
        assert rep["numErrors"] == 0, rep["messages"][:5]


@pytest.mark.slow
def test_correct_cli_writes_glb_report_and_timings(crowds, tmp_path, capsys):
    out = tmp_path / "o" / "ours.glb"
    out.parent.mkdir()
    code = main(["correct", str(crowds["unnamed"]), str(out), "--no-progress", "--device", "cpu", "--frames", "12"])
    assert code == 0
    text = capsys.readouterr().out
    assert "mesh overlap" in text and "overall" in text and "topology" in text
    report = json.loads((tmp_path / "o" / "ours.overlap.json").read_text())
    assert set(report["overall"]) == {"before_litres", "after_litres", "ratio"} and report["frames"] == 12
    assert (tmp_path / "o" / "ours.timings.json").is_file()
    assert sorted(p.name for p in out.parent.iterdir()) == ["ours.glb", "ours.overlap.json", "ours.timings.json"]


# ---------------------------------------------------------------------- three.js, Blender


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


@pytest.mark.browser
@pytest.mark.slow
def test_threejs_loads_and_poses_the_corrected_file(corrected, tmp_path):
    if not Path("/usr/bin/chromium").exists():
        pytest.skip("Debian chromium is not installed")
    if not (JS / "node_modules" / "three").is_dir():
        pytest.skip("tests/js/node_modules missing (make setup)")
    from playwright.sync_api import sync_playwright

    _, dst, res, _ = corrected["numbered"]
    (tmp_path / "node_modules").symlink_to(JS / "node_modules")
    shutil.copy(JS / "gltf_page.html", tmp_path / "index.html")
    shutil.copy(dst, tmp_path / "crowd.glb")
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Quiet, directory=str(tmp_path)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    frame = 20
    ours = res.corrected
    names = [res.crowd.characters[i].character.rig_map for i in range(ours.n_characters)]
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path="/usr/bin/chromium", args=["--no-sandbox", "--headless"])
            page = browser.new_page()
            page.goto(f"http://127.0.0.1:{server.server_address[1]}/index.html")
            page.wait_for_function("window.crowdReady === true", timeout=30000)
            info = page.evaluate("crowd.load('crowd.glb')")
            assert info["skinnedMeshes"] == 4 and info["animations"] == 1
            # node names repeat across copies: ask by joint names of copy 0 only
            bones = [names[0].names[m.source] for m in names[0].joints.values()]
            got = page.evaluate("([t, b]) => crowd.pose(t, b, [])", [frame / ours.fps, bones])
            browser.close()
    finally:
        server.shutdown()
    _, pos = forward_kinematics(
        res.crowd.bodies[0].rest_joints, ours.joint_rotations[frame, 0], ours.root_translation[frame, 0]
    )
    want = pos[[JOINT_INDEX[j] for j in names[0].joints]] @ Z_UP_TO_Y_UP.T
    np.testing.assert_allclose(np.array(got["bones"]), want, atol=2e-3)


@pytest.mark.slow
@pytest.mark.skipif(
    shutil.which("blender") is None,
    reason="Blender not installed (optional: apt-get install blender python3-numpy)",
)
def test_blender_imports_the_corrected_file(corrected, tmp_path):
    _, dst, _, _ = corrected["numbered"]
    res = subprocess.run(
        [
            "blender",
            "-b",
            "--factory-startup",
            "--python",
            str(ROOT / "tests/blender/reexport.py"),
            "--",
            str(dst),
            str(tmp_path / "re.glb"),
            "animations",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr[-2000:]
    # Blender's file (its own bone axes, keys resampled per frame) moves as the corrected one
    ours, back = read_crowd(dst, fps=30.0).anim, read_crowd(tmp_path / "re.glb", fps=30.0).anim
    assert back.n_characters == ours.n_characters == 4
    n = min(back.n_frames, ours.n_frames)
    assert n >= ours.n_frames - 1
    np.testing.assert_allclose(back.root_translation[:n], ours.root_translation[:n], atol=0.01)


# ---------------------------------------------------------------------- real files (optional)

SAMPLES = os.environ.get("CROWDSTUDY_GLTF_SAMPLES")


@pytest.mark.slow
@pytest.mark.skipif(
    not SAMPLES,
    reason="no registry package ships RobotExpressive/CesiumMan (tests/data/SOURCES.md): set CROWDSTUDY_GLTF_SAMPLES",
)
@pytest.mark.parametrize("name, animation", [("RobotExpressive.glb", "Walking"), ("CesiumMan.glb", None)])
def test_real_files_map_and_correct(tmp_path, name, animation):
    src = Path(SAMPLES) / name
    if not src.is_file():
        pytest.skip(f"{src} not present")
    path = crowd_of(
        src, tmp_path / "crowd.glb", n=4, spacing=0.5 if "Cesium" in name else 2.2, animation=animation or 0
    )
    res = correct_gltf(path, tmp_path / "ours.glb", device="cpu", overlap_every=0.2)
    print(res.crowd.report())
    assert res.overlap["overall"]["after_litres"] < res.overlap["overall"]["before_litres"]


# ---------------------------------------------------------------------- named errors


def _run_fails(args: list[str], folder: Path, match: str, capsys) -> None:
    assert main(args) == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err, err
    assert not any(folder.iterdir()), sorted(p.name for p in folder.iterdir())


def _static_mesh(path: Path) -> Path:
    b = GltfBuilder()
    pos = b.accessor(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), bounds=True)
    b.add("meshes", {"primitives": [{"attributes": {"POSITION": pos}}]})
    b.add("nodes", {"mesh": 0})
    b.doc["scenes"] = [{"nodes": [0]}]
    return b.write(path)


def _edit(src: Path, dst: Path, change) -> Path:
    g = read_gltf(src)
    b = GltfBuilder()
    b.doc = json.loads(json.dumps(g.doc))
    b._bin = bytearray(g.buffers[0])
    b.doc.pop("buffers", None)
    change(b.doc)
    return b.write(dst)


def test_bad_input_no_skin(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    path = _static_mesh(tmp_path / "static.glb")
    _run_fails(["import-crowd", str(path), "--out", str(out / "a.npz")], out, "no character to import (no skin", capsys)


def test_bad_input_no_animation(characters, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    path = _edit(characters["numbered"][0], tmp_path / "still.glb", lambda d: d.pop("animations"))
    _run_fails(["correct", str(path), str(out / "a.glb")], out, "no animation", capsys)


def test_bad_input_not_humanoid(characters, tmp_path, capsys):
    """A rig whose 'legs' run sideways: a creature lying down, not a humanoid."""
    out = tmp_path / "out"
    out.mkdir()

    def lie_down(doc):
        arm = next(n for n in doc["nodes"] if n.get("name") == "Armature")
        arm["rotation"] = [0.5, 0.5, 0.5, 0.5]

    path = _edit(characters["numbered"][0], tmp_path / "lying.glb", lie_down)
    _run_fails(["import-crowd", str(path), "--out", str(out / "a.npz")], out, "not a humanoid rig", capsys)


def test_bad_input_required_joints_missing(characters, tmp_path, capsys):
    """No knees: the shins' joints removed (the ankles hang from the hips)."""
    out = tmp_path / "out"
    out.mkdir()

    def no_knees(doc):
        for side in "LR":
            knee = next(i for i, n in enumerate(doc["nodes"]) if n.get("name") == f"leg_joint_{side}_2")
            hip = next(n for n in doc["nodes"] if knee in n.get("children", []))
            hip["children"] = [c for c in hip["children"] if c != knee] + doc["nodes"][knee].pop("children")
            doc["nodes"][knee]["name"] = f"loose_{side}"

    path = _edit(characters["numbered"][0], tmp_path / "coarse.glb", no_knees)
    _run_fails(
        ["import-crowd", str(path), "--out", str(out / "a.npz")], out, "required joints missing: the knees", capsys
    )


def test_bad_input_different_rates(characters, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    path = crowd_of(characters["numbered"][0], tmp_path / "rates.glb", n=2, spacing=1.0, last_rate=1.25)
    _run_fails(["correct", str(path), str(out / "a.glb")], out, "different rates", capsys)


def test_bad_input_output_extension(crowds, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    _run_fails(["correct", str(crowds["numbered"]), str(out / "a.gltf")], out, "must be a .glb file", capsys)
    _run_fails(["correct", str(crowds["numbered"]), str(out / "a.npz")], out, "must be a .glb file", capsys)
    _run_fails(["import-crowd", str(crowds["numbered"]), "--out", str(out / "a.glb")], out, "expected a .npz", capsys)

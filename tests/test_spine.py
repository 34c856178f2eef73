"""The package spine: scene containers, study design loader, CLI, kinematics."""

import subprocess
import sys
import tomllib

import numpy as np
import pytest

from crowdstudy.body.rotations import (
    axis_angle_to_matrix,
    matrix_to_axis_angle,
    matrix_to_quaternion,
    quaternion_to_matrix,
)
from crowdstudy.body.skeleton import DEFAULT_REST_JOINTS, JOINT_NAMES, PARENTS, forward_kinematics, joint_index
from crowdstudy.design import load_design, parse_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.scene import Crowd, CrowdAnimation


def _anim(t=4, n=3, seed=0):
    rng = np.random.default_rng(seed)
    return CrowdAnimation(
        joint_names=JOINT_NAMES,
        parents=PARENTS,
        root_translation=rng.normal(size=(t, n, 3)),
        joint_rotations=rng.normal(scale=0.3, size=(t, n, 24, 3)),
        fps=30,
        bodies=[{"model": "test", "sex": "female", "height": 1.6, "shape": [0.0]}] * n,
        clips=[{"clip": "dance_00", "phase": 0.0}] * n,
        meta={"seed": seed},
    )


def test_animation_roundtrip_is_byte_identical(tmp_path):
    a = _anim()
    p1, p2 = a.save(tmp_path / "a.npz"), _anim().save(tmp_path / "b.npz")
    assert p1.read_bytes() == p2.read_bytes()
    b = CrowdAnimation.load(p1)
    np.testing.assert_array_equal(b.joint_rotations, a.joint_rotations)
    assert b.bodies == a.bodies and b.meta == a.meta and b.fps == 30.0


@pytest.mark.parametrize(
    "field,value,needle",
    [
        ("root_translation", np.zeros((4, 2, 3)), "joint_rotations"),
        ("joint_rotations", np.zeros((4, 3, 23, 3)), "joint_rotations"),
        ("fps", 0, "fps"),
        ("parents", np.arange(24), "parents"),
        ("bodies", [{}], "bodies"),
    ],
)
def test_animation_validation_names_field(field, value, needle):
    with pytest.raises(InvalidInputError, match=needle):
        _anim().replace(**{field: value})


def test_animation_rejects_nan():
    rot = np.zeros((4, 3, 24, 3))
    rot[2, 1, 5, 0] = np.nan
    with pytest.raises(InvalidInputError, match=r"joint_rotations.*\(2, 1, 5, 0\)"):
        _anim().replace(joint_rotations=rot)


def test_load_errors_name_file(tmp_path):
    with pytest.raises(InvalidInputError, match="does not exist"):
        CrowdAnimation.load(tmp_path / "missing.npz")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(InvalidInputError, match="bad.npz"):
        CrowdAnimation.load(bad)
    crowd = Crowd(positions=np.zeros((1, 2, 2)) + [[0, 0], [1, 1]], radius=0.2)
    crowd.save(tmp_path / "crowd.npz")
    with pytest.raises(InvalidInputError, match="holds a 'Crowd'"):
        CrowdAnimation.load(tmp_path / "crowd.npz")
    assert Crowd.load(tmp_path / "crowd.npz").n_agents == 2


def test_design_matches_paper():
    d = load_design()
    assert [d.n_characters(k) for k in d.densities] == [20, 30, 40, 50, 60]
    stim = d.stimuli()
    assert sum(s.stage == 1 for s in stim) == 40 and sum(s.stage == 2 for s in stim) == 20
    assert len({s.stimulus_id for s in stim}) == 60
    assert [i.id for i in d.items if i.reverse] == ["Q2", "Q4", "Q6"]


@pytest.mark.parametrize(
    "edit,needle",
    [
        (lambda r: r["floor"].__setitem__("width", -1.0), "floor.width"),
        (lambda r: r["densities"].__setitem__("D3", "many"), "densities.D3"),
        (lambda r: r.__setitem__("colour", "red"), "colour"),
        (lambda r: r["viewpoints"]["V2"].__setitem__("fov", 400.0), "viewpoints.V2.fov"),
        (lambda r: r["stages"]["walking"].__setitem__("viewpoints", ["V9"]), "V9"),
        (lambda r: r["video"].__setitem__("fps", 2.5), "video.fps"),
        (lambda r: r["scenarios"]["corridor"].__setitem__("speed", 1.0), "scenarios.corridor.speed"),
        (lambda r: r["scenarios"]["corridor"].__setitem__("direction", "sideways"), "scenarios.corridor.direction"),
        (lambda r: r["scenarios"]["concert"].__setitem__("motion", "keyframes"), "scenarios.concert.motion"),
        (lambda r: r["scenarios"].__setitem__("stadium", {}), "scenarios.stadium"),
        (lambda r: r["stages"]["walking"].__setitem__("scenario", "stadium"), "stages.walking.scenario"),
        (lambda r: r["video"].__setitem__("width", 641), "video.width"),
        (lambda r: r["questionnaire"]["labels"].pop(), "questionnaire.labels"),
        (lambda r: r["questionnaire"]["items"][2].__setitem__("reverse", "yes"), r"questionnaire.items[2].reverse"),
        (lambda r: r["composites"].__setitem__("QXX", ["Q1", "Q9"]), "composites.QXX"),
    ],
)
def test_design_errors_name_key(edit, needle):
    from crowdstudy.design import default_design_path

    raw = tomllib.loads(default_design_path().read_text())
    edit(raw)
    with pytest.raises(InvalidInputError, match=needle.replace(".", r"\.").replace("[", r"\[")):
        parse_design(raw, "study.toml")


def test_design_corridor_direction_is_checked():
    from crowdstudy.design import default_design_path

    raw = tomllib.loads(default_design_path().read_text())
    raw["scenarios"]["corridor"]["direction"] = "sideways"
    with pytest.raises(InvalidInputError) as info:
        parse_design(raw, "study.toml")
    assert str(info.value) == (
        "study.toml: key 'scenarios.corridor.direction' must be 'unidirectional' or 'bidirectional', got 'sideways'"
    )
    raw["scenarios"]["corridor"]["direction"] = "bidirectional"
    assert parse_design(raw, "study.toml").scenarios["corridor"]["direction"] == "bidirectional"


def test_rotation_conversions_roundtrip():
    rng = np.random.default_rng(1)
    aa = rng.normal(size=(500, 3))
    aa *= (rng.uniform(0, np.pi - 1e-3, 500) / np.linalg.norm(aa, axis=1))[:, None]
    aa[:5] *= 1e-9
    R = axis_angle_to_matrix(aa)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(matrix_to_axis_angle(R), aa, atol=1e-9)
    np.testing.assert_allclose(quaternion_to_matrix(matrix_to_quaternion(R)), R, atol=1e-12)


def test_forward_kinematics_hand_case():
    rot = np.zeros((24, 3))
    rot[0] = [0, 0, np.pi / 2]  # root yaw 90 deg: facing +y -> facing -x
    rot[joint_index("left_elbow")] = [0, 0, np.pi / 2]
    glob, pos = forward_kinematics(DEFAULT_REST_JOINTS, rot, np.array([1.0, 2.0, 0.9]))
    assert np.allclose(pos[0], [1, 2, 0.9])
    # the left hip (rest x = -0.06) ends up at y = -0.06 after a +90 deg yaw
    hip = DEFAULT_REST_JOINTS[joint_index("left_hip")]
    assert np.allclose(pos[joint_index("left_hip")], [1 - hip[1], 2 + hip[0], 0.9 + hip[2]])
    # the forearm length is preserved
    e, w = joint_index("left_elbow"), joint_index("left_wrist")
    assert np.isclose(np.linalg.norm(pos[w] - pos[e]), np.linalg.norm(DEFAULT_REST_JOINTS[w] - DEFAULT_REST_JOINTS[e]))


def test_cli_help_lists_commands():
    out = subprocess.run([sys.executable, "-m", "crowdstudy", "--help"], capture_output=True, text=True, check=True)
    for cmd in ("layout", "navigate", "animate", "correct", "render", "serve", "analyze", "bench", "demo"):
        assert cmd in out.stdout

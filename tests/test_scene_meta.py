"""The schema of ``CrowdAnimation.meta`` (crowdstudy.scene_meta): every key the package
writes is documented and typed; a bad value is named by its path when an animation is
made, loaded or saved; the user's own keys pass."""

import json
import typing
import zipfile

import numpy as np
import pytest

import crowdstudy.scene_meta as scene_meta
from crowdstudy.errors import InvalidInputError
from crowdstudy.scene import CrowdAnimation
from crowdstudy.scene_meta import LOOP_MODES, LoopMode, PhysicsMeta, SceneMeta, check_meta, loop_mode, periodic_length


def _anim(meta: dict) -> CrowdAnimation:
    return CrowdAnimation(
        joint_names=("root", "child"),
        parents=np.array([-1, 0]),
        root_translation=np.zeros((2, 1, 3)),
        joint_rotations=np.zeros((2, 1, 2, 3)),
        fps=30.0,
        bodies=({},),
        clips=({},),
        meta=meta,
    )


GOOD = {
    "scenario": "corridor",
    "periodic": {"axis": 0, "length": 4.5},
    "floor": {"width": 4.5, "depth": 2.0},
    "obstacles": [[[-6.0, -1.0], [6.0, -1.0]]],
    "corridor_width": 2.0,
    "seed": 3,
    "density": 2.22,
    "loop": {"mode": "dissolve", "frames": 15, "video_frames": 30},
    "method": "Baseline",
    "tempo": None,
    "provenance": {"seed": 3},
    "my_own_key": {"anything": [1, "two"]},
}


def test_a_good_meta_and_the_users_own_keys_pass():
    anim = _anim(GOOD)
    assert anim.meta["my_own_key"] == {"anything": [1, "two"]}
    assert anim.periodic_length == 4.5 == periodic_length(anim.meta)
    assert loop_mode(anim.meta) == "dissolve" and loop_mode({}) == "none"
    assert periodic_length({"periodic": None}) is None
    assert typing.get_args(LoopMode) == LOOP_MODES


@pytest.mark.parametrize(
    "change, message",
    [
        ({"periodic": {"axis": 0, "length": 0.0}}, r"meta\.periodic\.length: expected a positive number, got 0\.0"),
        ({"periodic": {"axis": 0}}, r"meta\.periodic\.length: missing"),
        ({"periodic": {"axis": -1, "length": 4.5}}, r"meta\.periodic\.axis: expected an integer >= 0"),
        ({"loop": {"mode": "forever"}}, r"meta\.loop\.mode: expected one of 'periodic', 'dissolve', 'none'"),
        ({"loop": {"mode": "dissolve", "frames": 15}}, r"meta\.loop\.video_frames: missing"),
        ({"loop": {"mode": "periodic", "frames": 2.5}}, r"meta\.loop\.frames: expected an integer"),
        ({"floor": {"width": 3.0}}, r"meta\.floor\.depth: missing"),
        ({"floor": {"width": -3.0, "depth": 3.0}}, r"meta\.floor\.width: expected a positive number"),
        ({"obstacles": [[0.0, 1.0]]}, r"meta\.obstacles: expected \(M, 2, 2\) wall segments"),
        ({"seed": "three"}, r"meta\.seed: expected an integer"),
        ({"seed": True}, r"meta\.seed: expected an integer"),
        ({"density": float("nan")}, r"meta\.density: expected a number >= 0"),
        ({"scenario": 1}, r"meta\.scenario: expected a string"),
        ({"tempo": 0.0}, r"meta\.tempo: expected a positive number"),
        ({"physics": {"profile_weight": -0.5}}, r"meta\.physics\.profile_weight: expected a number >= 0"),
        ({"physics": {"config": [1, 2]}}, r"meta\.physics\.config: expected a dict"),
        ({"physics": {"steps": 1.5}}, r"meta\.physics\.steps: expected an integer"),
        ({"provenance": "git"}, r"meta\.provenance: expected a dict"),
    ],
)
def test_a_bad_key_is_named_by_its_path(change, message):
    with pytest.raises(InvalidInputError, match=r"CrowdAnimation: " + message):
        _anim({**GOOD, **change})
    with pytest.raises(InvalidInputError, match=message):
        check_meta({**GOOD, **change})


def test_load_and_save_check_the_meta(tmp_path):
    anim = _anim(GOOD)
    path = anim.save(tmp_path / "a.npz")
    assert CrowdAnimation.load(path).meta == json.loads(json.dumps(GOOD))
    # a file whose meta was broken outside crowdstudy: the file and the key are named
    with zipfile.ZipFile(path) as zf:
        members = {name: zf.read(name) for name in zf.namelist()}
    meta = json.loads(np.load(path)["__meta__"].item())
    meta["meta"]["periodic"]["length"] = -1.0
    import io

    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.array(json.dumps(meta)), allow_pickle=False)
    members["__meta__.npy"] = buf.getvalue()
    broken = tmp_path / "broken.npz"
    with zipfile.ZipFile(broken, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    with pytest.raises(InvalidInputError, match=r"broken\.npz.*meta\.periodic\.length: expected a positive number"):
        CrowdAnimation.load(broken)
    # a meta changed in place after the animation was made is checked before it is written
    anim.meta["loop"] = {"mode": "sometimes"}
    with pytest.raises(InvalidInputError, match=r"save.*meta\.loop\.mode"):
        anim.save(tmp_path / "b.npz")
    assert not (tmp_path / "b.npz").exists()


def test_the_module_docstring_documents_every_key():
    doc = scene_meta.__doc__
    for key in SceneMeta.__annotations__:
        assert f"``{key}``" in doc, key
    for key in PhysicsMeta.__annotations__:
        assert f"``{key}``" in PhysicsMeta.__doc__, key


def test_the_package_writes_only_documented_keys():
    """A Baseline of each scenario and a corrected one: every key of their meta is in the
    schema, and the schema's checks pass."""
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline
    from crowdstudy.physics.corrector import correct

    design = load_design()
    concert = build_baseline(design, "stationary", "D1", duration=1.0, body_model="open")
    corridor = build_baseline(design, "walking", "D1", duration=1.0, body_model="open")
    ours = correct(concert.frames(0, 3), progress=False, device="cpu")
    for anim in (concert, corridor, ours):
        check_meta(anim.meta)
        assert set(anim.meta) <= set(SceneMeta.__annotations__), set(anim.meta) - set(SceneMeta.__annotations__)
    assert set(ours.meta["physics"]) == set(PhysicsMeta.__annotations__)
    assert loop_mode(concert.meta) in LOOP_MODES and loop_mode(corridor.meta) == "dissolve"

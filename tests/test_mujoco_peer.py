"""The MuJoCo peer of the correction (crowdstudy.physics.mujoco_peer) is set up like Ours:
same inter-body geometry (radius + mesh skin + margin), same self pairs, same interpolated
targets, and the same conversion back to a CrowdAnimation; without mujoco it names the extra
to install."""

from __future__ import annotations

import dataclasses
import sys

import numpy as np
import pytest

from crowdstudy.errors import InvalidInputError, MissingDependencyError
from crowdstudy.physics.mujoco_peer import (
    MUJOCO_SETTINGS,
    MujocoScene,
    check_timeconsts,
    mujoco_peer,
    rigid_to_animation,
)

N_FRAMES = 10


@pytest.fixture
def mujoco():
    return pytest.importorskip("mujoco", reason="mujoco is not installed (pip install -e .[peers])")


def _tiny(kind: str, chars=(0, 1, 2), spread: float = 0.0):
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline

    stage = "stationary" if kind == "concert" else "walking"
    design = load_design()
    for sc in design.scenarios.values():  # the bars below were set on the procedural motion
        sc.params["motion"] = "procedural"
    anim = build_baseline(design, stage, "D1", duration=N_FRAMES / 30.0)
    sel = list(chars)
    root = anim.root_translation[:N_FRAMES, sel].copy()
    root[..., 0] += spread * np.arange(len(sel))  # spread > 0: characters far apart
    return anim.replace(
        root_translation=root,
        joint_rotations=anim.joint_rotations[:N_FRAMES, sel],
        bodies=tuple(anim.bodies[i] for i in sel),
        clips=tuple(anim.clips[i] for i in sel),
    )


def _ours(anim):
    """Ours as ``correct()`` sets it up: the configuration resolved for this crowd."""
    from crowdstudy.physics.corrector import CrowdCorrector, load_bodies
    from crowdstudy.physics.crowding import crowd_config

    config = crowd_config(anim)[0]
    corr = CrowdCorrector(load_bodies(anim.bodies), fps=anim.fps, n_frames=anim.n_frames, device="cpu", config=config)
    corr.control.set_frames(anim.joint_rotations, anim.root_translation)
    return corr


@pytest.mark.parametrize("kind", ["concert", "corridor"])
def test_same_geometry_and_self_pairs(mujoco, kind):
    anim = _tiny(kind)
    scene = MujocoScene(anim)
    corr = _ours(anim)
    m, cfg = corr.model, corr.config
    n, nj = anim.n_characters, anim.n_joints
    # inter-body (hull) capsules: radius + mesh skin, plus the contact margin, body by body
    ours = (m.cap_radius + m.cap_skin + cfg.contacts.margin).reshape(n, nj)
    np.testing.assert_allclose(scene.inter_body_radius(), ours, atol=1e-7)
    assert np.all(m.cap_skin.reshape(n, nj).max(1) > 0)  # the skin is really there
    np.testing.assert_allclose(scene.model.geom_margin[scene.hull_geom], cfg.contacts.margin)
    # ground and self contacts on the bare capsule, no margin; masses from the bare capsule
    np.testing.assert_allclose(scene.model.geom_size[scene.core_geom, 0], m.cap_radius.reshape(n, nj), atol=1e-7)
    assert np.all(scene.model.geom_margin[scene.core_geom] == 0)
    # (measured: the two toe capsules, the smallest, differ by up to 0.3 %)
    np.testing.assert_allclose(scene.model.body_mass[scene.body_id], m.body_mass.reshape(n, nj), rtol=4e-3)
    # self pairs that may collide: exactly our intra-body pair list
    intra = np.sort(m.intra_pairs, 1)
    intra = intra[np.lexsort((intra[:, 1], intra[:, 0]))]
    assert len(intra) > 0
    np.testing.assert_array_equal(scene.self_pairs(), intra)
    # walls (concert stage front, corridor walls) are there; the corridor gets periodic images
    walls = [
        i
        for i in range(scene.model.ngeom)
        if (mujoco.mj_id2name(scene.model, mujoco.mjtObj.mjOBJ_GEOM, i) or "").startswith("wall")
    ]
    assert len(walls) == (2 if kind == "corridor" else 1)
    assert len(scene.ghost_shift) == (2 if kind == "corridor" else 0)
    # each box's face is the wall and it lies behind it, away from the crowd (ours: one-sided
    # planes facing the roots): the roots' side of every box face is empty
    from crowdstudy.scene_meta import static_walls_from_meta

    roots = anim.root_translation[0, :, :2]
    for gid, ((x0, y0), (x1, y1)) in zip(walls, static_walls_from_meta(anim.meta), strict=True):
        centre = scene.model.geom_pos[gid, :2]
        half_depth = scene.model.geom_size[gid, 1]
        direction = np.array([x1 - x0, y1 - y0]) / np.hypot(x1 - x0, y1 - y0)
        normal = np.array([-direction[1], direction[0]])
        offset = (centre - [x0, y0]) @ normal  # box centre from the wall's line
        assert abs(abs(offset) - half_depth) < 1e-4 and half_depth >= 0.2
        assert np.all(np.sign((roots - [x0, y0]) @ normal) == -np.sign(offset))


def test_half_step_targets_equal_ours(mujoco):
    from crowdstudy.body.rotations import quaternion_to_matrix

    anim = _tiny("corridor")
    scene = MujocoScene(anim)
    corr = _ours(anim)
    m = corr.model
    n, nj = anim.n_characters, anim.n_joints
    for f0, f1 in ((3, 4), (8, 9)):
        scene.set_targets(f0, f1, 0.5)
        corr.control.advance(f0, f1, 0.5)
        q_mj = scene.data.mocap_quat[scene.mocap_id.ravel()][:, [1, 2, 3, 0]]
        q_ours = corr.control.t_glob.numpy().astype(np.float64)
        sign = np.where(np.sum(q_mj * q_ours, 1, keepdims=True) < 0, -1.0, 1.0)
        np.testing.assert_allclose(q_mj, sign * q_ours, atol=1e-6)
        # ours stores centres of mass; the joint is x + R anchor_child
        x = corr.control.t_x.numpy().astype(np.float64)
        joint = x + np.einsum("bij,bj->bi", quaternion_to_matrix(q_ours), m.anchor_child)
        np.testing.assert_allclose(scene.data.mocap_pos[scene.mocap_id.ravel()], joint, atol=1e-6)
    assert q_mj.shape == (n * nj, 4)


def test_conversion_back_same_as_ours_and_tracks(mujoco):
    from crowdstudy.metrics import tracking_error

    anim = _tiny("concert", spread=3.0)
    # the numpy conversion equals project_kernel on our rigid state
    corr = _ours(anim)
    corr.reset_to_frame(5)
    wp = corr.solver.wp
    rot = wp.zeros((1, corr.model.n_bodies), dtype=wp.vec3, device="cpu")
    root = wp.zeros((1, anim.n_characters), dtype=wp.vec3, device="cpu")
    corr.project(rot, root, 0)
    q = corr.state.q.numpy().astype(np.float64).reshape(anim.n_characters, anim.n_joints, 4)
    x = corr.state.x.numpy().astype(np.float64)
    from crowdstudy.body.rotations import quaternion_to_matrix

    pelvis = x + np.einsum("bij,bj->bi", quaternion_to_matrix(q.reshape(-1, 4)), corr.model.anchor_child)
    r_np, root_np = rigid_to_animation(q, pelvis.reshape(anim.n_characters, anim.n_joints, 3)[:, 0])
    np.testing.assert_allclose(r_np.reshape(-1, 3), rot.numpy()[0], atol=2e-5)
    np.testing.assert_allclose(root_np, root.numpy()[0], atol=2e-6)
    # an unperturbed MuJoCo run (characters 3 m apart) converted back tracks its input
    scene = MujocoScene(anim)
    r0, root0 = scene.read()
    np.testing.assert_allclose(root0, anim.root_translation[0], atol=1e-9)
    assert (
        tracking_error(
            anim.replace(
                joint_rotations=np.repeat(r0[None], N_FRAMES, 0), root_translation=np.repeat(root0[None], N_FRAMES, 0)
            ),
            anim.replace(
                joint_rotations=np.repeat(anim.joint_rotations[:1], N_FRAMES, 0),
                root_translation=np.repeat(anim.root_translation[:1], N_FRAMES, 0),
            ),
        )
        < 1e-6
    )
    mj, timing = mujoco_peer(anim)
    assert not timing["unstable"] and timing["steps_per_60th"] == 1.0
    assert mj.meta["method"] == "MuJoCo" and mj.n_frames == anim.n_frames
    assert tracking_error(mj, anim) < 3.0


def test_every_tuning_is_one_mujoco_runs_as_written(mujoco):
    """MuJoCo clamps a solref time constant under two steps to two steps without a word (a
    weld at 0.02 s and one at 0.03 s ran the same model at 1/60 s): every tuning of the
    peer keeps its welds and contacts at or above two of its steps, and one that does
    not is refused, naming the field."""
    assert len(MUJOCO_SETTINGS) == 4
    for st in MUJOCO_SETTINGS.values():
        check_timeconsts(st, 1.0 / (30.0 * st.substeps))
    too_stiff = dataclasses.replace(MUJOCO_SETTINGS["weld0.05"], weld_solref=(0.02, 1.0))
    with pytest.raises(InvalidInputError, match="weld_solref"):
        MujocoScene(_tiny("concert", chars=(0,)), setting=too_stiff)
    MujocoScene(_tiny("concert", chars=(0,)), setting=dataclasses.replace(too_stiff, substeps=4))  # 1/120 s: 2 steps
    with pytest.raises(InvalidInputError, match="setting"):
        MujocoScene(_tiny("concert", chars=(0,)), setting="weld0.07")


def test_without_mujoco_the_peer_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "mujoco", None)  # import mujoco raises ImportError
    with pytest.raises(MissingDependencyError, match=r"pip install 'crowdstudy\[peers\]'"):
        MujocoScene(_tiny("concert", chars=(0,)))

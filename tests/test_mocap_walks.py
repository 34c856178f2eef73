"""Walks from motion capture: looping in-place CMU walks blended by speed in animate_walking."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from crowdstudy.body.skeleton import JOINT_INDEX
from crowdstudy.motion import animate_walking, foot_skate
from crowdstudy.motion.clip import seam_discontinuity
from crowdstudy.motion.mocap_walks import WALK_FILES, build_walk_loops, gait_report, loop_foot_skate
from crowdstudy.motion.walk import procedural_contacts
from crowdstudy.scene import Crowd

J = JOINT_INDEX


MOCAP = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "mocap"


@pytest.fixture(scope="module")
def loops():
    mocap = MOCAP
    if not all((mocap / f).is_file() for f in WALK_FILES):
        pytest.skip("the CMU walk files are not in ../shared/data/mocap")
    return build_walk_loops(mocap)


def _straight(speed: float, n: int = 3, seconds: float = 5.0, fps: float = 30.0) -> Crowd:
    """n walkers side by side going along +y at a constant ``speed`` (m/s)."""
    t = np.arange(int(seconds * fps)) / fps
    pos = np.stack(
        [np.broadcast_to(np.linspace(-1.0, 1.0, n), (len(t), n)), np.broadcast_to(speed * t[:, None], (len(t), n))],
        axis=-1,
    )
    return Crowd(
        positions=pos,
        radius=0.2,
        fps=fps,
        velocities=np.broadcast_to([0.0, speed], pos.shape).copy(),
        headings=np.full(pos.shape[:2], np.pi / 2),
        meta={"scenario": "corridor"},
    )


def _left_strike_ok(clip) -> bool:
    """Phase 0 starts the left stance: the left foot is the front one, half a stride ahead of
    the right, and it stops: its ankle moves fast just before (late swing) and hardly just
    after (stance)."""
    from crowdstudy.body.skeleton import DEFAULT_REST_JOINTS, forward_kinematics

    cyc = clip.duration / clip.meta["cycles"]
    t = np.array([-0.12, -0.1, 0.0, 0.1, 0.12]) * cyc
    rot, root = clip.sample(t)
    pos = forward_kinematics(DEFAULT_REST_JOINTS, rot, root + clip.travel(t))[1]
    left, right = pos[:, J["left_ankle"]], pos[:, J["right_ankle"]]
    ahead = left[2, 1] - right[2, 1]
    v_before = np.linalg.norm(left[1, :2] - left[0, :2]) / (0.02 * cyc)
    v_after = np.linalg.norm(left[4, :2] - left[3, :2]) / (0.02 * cyc)
    return bool(ahead > 0.3 * clip.meta["stride_length"] and v_after < 0.3 * v_before)


def test_speeds_cover_the_corridor(loops):
    speeds = [c.speed for c in loops]
    assert speeds == sorted(speeds) and len(set(speeds)) == len(speeds) == len(WALK_FILES)
    assert speeds[0] <= 0.5 and speeds[-1] >= 1.7
    for c in loops:
        m = c.meta
        assert c.kind == "walk" and c.loop and m["cycles"] in (1, 2)
        assert m["stride_length"] == pytest.approx(c.speed * c.duration / m["cycles"], rel=1e-9)
        assert m["cadence"] == pytest.approx(120.0 * m["cycles"] / c.duration, rel=1e-9)
        assert 60 < m["cadence"] < 160 and m["source"] in WALK_FILES and m["trial"] in m["source"]
        for side in ("left", "right"):
            ev = m["contacts"][side]
            assert all(0.0 <= ev[k] < 1.0 for k in ("strike", "flat_end", "toe_off"))
            # heel strike -> heel rise -> toe-off, a stance of 45..80 % of the cycle
            flat, stance = (ev["flat_end"] - ev["strike"]) % 1.0, (ev["toe_off"] - ev["strike"]) % 1.0
            assert 0.1 < flat < stance and 0.45 < stance < 0.8
        assert min(m["contacts"]["left"]["strike"], 1 - m["contacts"]["left"]["strike"]) < 0.02
        assert abs(m["contacts"]["right"]["strike"] - 0.5) < 0.08


def test_loops_are_seamless(loops):
    for c in loops:
        seam = seam_discontinuity(c)
        assert seam["step_seam"] <= 1.5 * seam["step_max"], c.name
        assert seam["accel_seam"] <= 1.5 * seam["accel_max"], c.name


def test_phase_zero_is_a_left_heel_strike(loops):
    for c in loops:
        assert _left_strike_ok(c), c.name
    # mutation: a loop turned by a third of a cycle no longer starts at a left heel strike
    c = loops[2]
    shift = c.n_frames // (3 * c.meta["cycles"])
    turned = dataclasses.replace(
        c,
        joint_rotations=np.roll(c.joint_rotations, -shift, axis=0),
        root_translation=np.roll(c.root_translation, -shift, axis=0),
    )
    assert not _left_strike_ok(turned)


def test_loops_feet_are_planted_and_walk_like_walks(loops):
    for c in loops:
        skate = loop_foot_skate(c)
        assert skate.size >= 4 * 2 * c.meta["cycles"] and skate.max() < 0.02, c.name
        rep = gait_report(c)
        assert min(rep["left_wrist_swing"], rep["right_wrist_swing"]) > (0.08 if c.speed < 0.5 else 0.15), c.name
        assert 1.4 < rep["head_height"] < 1.65, c.name
        # the leg is longest (knee straightest) in the stance, bent in the swing
        pos = c.joint_positions()
        leg = np.linalg.norm(pos[:, J["left_hip"]] - pos[:, J["left_ankle"]], axis=-1)
        assert leg.max() - leg.min() > 0.04, c.name


@pytest.mark.parametrize("speed", [0.5, 0.6, 1.0, 1.6, 1.8])
def test_animate_walking_with_mocap_loops(loops, speed):
    crowd = _straight(speed)
    anim = animate_walking(crowd, seed=1, walks=loops)
    assert anim.clips[0]["clips"] == [c.name for c in loops]
    skate = foot_skate(anim)
    assert skate.size >= crowd.n_agents * 4 * 3 and skate.max() < 0.02, (speed, skate.max())
    # (the captured pelvis surges and sways about the trajectory by up to about 20 cm)
    assert np.linalg.norm(anim.root_translation[..., :2] - crowd.positions, axis=-1).max() < 0.25


def test_contact_meta_drives_the_foot_locks(loops):
    """Mutation check: with the contact timing of the clips broken (right foot's stance moved
    by a third of a cycle), the locks pin swinging feet and release planted ones."""
    crowd = _straight(1.0)
    broken = []
    for c in loops:
        contacts = {s: dict(v) for s, v in c.meta["contacts"].items()}
        contacts["right"] = {k: (v + 0.33) % 1.0 for k, v in contacts["right"].items()}
        broken.append(dataclasses.replace(c, meta={**c.meta, "contacts": contacts}))
    good = foot_skate(animate_walking(crowd, seed=1, walks=loops)).max()
    bad = foot_skate(animate_walking(crowd, seed=1, walks=broken)).max()
    assert good < 0.02 < bad


def test_procedural_clips_carry_their_contacts():
    from crowdstudy.motion.library import walk_clips

    meta = procedural_contacts()
    walks = walk_clips("procedural")
    for c in walks:
        assert c.meta["contacts"] == meta["contacts"] and c.meta["cycles"] == 1
    anim = animate_walking(_straight(1.2, n=2, seconds=3.0), seed=2, walks=walks)
    assert foot_skate(anim).max() < 0.02


def test_build_is_deterministic(loops):
    again = build_walk_loops(MOCAP, files=(loops[0].meta["source"],))[0]
    assert again.joint_rotations.tobytes() == loops[0].joint_rotations.tobytes()
    assert again.root_translation.tobytes() == loops[0].root_translation.tobytes()
    assert again.meta == loops[0].meta

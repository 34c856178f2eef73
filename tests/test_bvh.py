"""BVH and AMASS importers: the real CMU walk, round trips, rest-pose retargeting, bad files."""

import dataclasses

import numpy as np
import pytest

from crowdstudy.body.rotations import axis_angle_to_matrix, matrix_to_axis_angle, rot_y
from crowdstudy.body.skeleton import DEFAULT_REST_JOINTS, JOINT_INDEX, PARENTS, forward_kinematics
from crowdstudy.errors import InvalidInputError
from crowdstudy.motion import load_amass, load_bvh, load_clip, save_bvh
from crowdstudy.motion.bvh import parse_bvh
from crowdstudy.motion.rig import ANKLE_HEIGHT

J = JOINT_INDEX


def _cmu_path(shared_dir):
    path = shared_dir / "data" / "cmu_12_01_walk.bvh"
    if not path.is_file():
        pytest.skip("the CMU walk is not in ../shared/data")
    return path


def test_cmu_walk_retargets_to_a_plausible_walk(shared_dir):
    path = _cmu_path(shared_dir)
    clip = load_bvh(path)
    assert clip.n_frames == 524 and clip.fps == pytest.approx(120.0, rel=1e-4)
    assert clip.meta["skeleton"] == "cmu" and clip.kind == "mocap" and not clip.loop
    assert clip.meta["unit_scale"] == pytest.approx(0.0564, rel=0.05)  # CMU's inch-ish units
    root = clip.root_translation
    walk = slice(60, None)  # frame 0 is a calibration pose
    travel = root[-1, :2] - root[60, :2]
    speed = np.linalg.norm(travel) / ((clip.n_frames - 61) / clip.fps)
    assert 0.7 < speed < 1.6
    heading = travel / np.linalg.norm(travel)
    forward = axis_angle_to_matrix(clip.joint_rotations[walk, 0])[:, :2, 1]
    forward /= np.linalg.norm(forward, axis=1, keepdims=True)
    assert (forward @ heading).mean() > 0.9  # faces where it walks
    pos = clip.joint_positions()
    # bone lengths of the retargeted skeleton are those of the target skeleton, every frame
    bones = np.linalg.norm(pos[:, 1:] - pos[:, PARENTS[1:]], axis=-1)
    rest_bones = np.linalg.norm(DEFAULT_REST_JOINTS[1:] - DEFAULT_REST_JOINTS[PARENTS[1:]], axis=-1)
    assert np.abs(bones - rest_bones).max() < 1e-9
    # feet alternate: the leading foot changes at every step
    lead = (pos[walk, J["left_ankle"], :2] - pos[walk, J["right_ankle"], :2]) @ heading
    changes = np.count_nonzero(np.diff(np.sign(lead[np.abs(lead) > 0.1])) != 0)
    assert changes >= 4
    # standing on the floor, knees bending the right way, a human pelvis height
    ankles = pos[walk][:, [J["left_ankle"], J["right_ankle"]], 2]
    assert ankles.min() > ANKLE_HEIGHT - 0.03 and ankles.min(axis=1).max() < 0.35
    assert 0.8 < root[walk, 2].mean() < 1.1
    knees = np.degrees(clip.joint_rotations[walk][:, [J["left_knee"], J["right_knee"]]])
    assert knees[..., 0].max() < 10 and np.linalg.norm(knees, axis=-1).max() < 150
    with pytest.raises(InvalidInputError, match="cmu_12_01_walk.bvh"):
        load_bvh(path, skeleton="mixamo")
    # resampling the 120 fps capture to 30 fps keeps every 4th pose
    slow = clip.resample(30.0)
    assert slow.n_frames == 131 and slow.fps == 30.0
    assert np.abs(slow.joint_positions() - pos[::4]).max() < 1e-3  # frame time 0.0083333, not 1/120


@pytest.mark.parametrize("naming,order", [("mixamo", "ZXY"), ("cmu", "XYZ")])
def test_save_then_load_round_trip(tmp_path, naming, order):
    clip = load_clip("dance_clap_overhead")
    path = save_bvh(clip, tmp_path / f"clap_{naming}.bvh", naming=naming, order=order)
    back = load_bvh(path)
    assert back.meta["skeleton"] == naming and back.n_frames == clip.n_frames
    assert back.fps == pytest.approx(clip.fps, rel=1e-6)
    a, b = clip.joint_positions(), back.joint_positions()
    assert np.abs((a - a[:, :1]) - (b - b[:, :1])).max() < 1e-4
    assert np.abs(a[:, 0, :2] - b[:, 0, :2]).max() < 1e-4
    assert np.ptp(a[:, 0, 2] - b[:, 0, 2]) < 1e-5  # only a constant grounding shift


def test_a_pose_rest_is_aligned_to_our_t_pose(tmp_path):
    """A file whose rest pose has the arms 45 degrees down retargets to the same motion."""
    clip = load_clip("dance_hands_up_sway")
    rest_a = np.array(DEFAULT_REST_JOINTS)
    local = axis_angle_to_matrix(clip.joint_rotations)
    for side, angle in (("left", -np.pi / 4), ("right", np.pi / 4)):
        q = rot_y(np.array(angle))
        sh = J[f"{side}_shoulder"]
        for name in ("elbow", "wrist", "hand"):
            j = J[f"{side}_{name}"]
            rest_a[j] = rest_a[sh] + q @ (DEFAULT_REST_JOINTS[j] - DEFAULT_REST_JOINTS[sh])
            local[:, j] = q @ local[:, j] @ q.T
        local[:, sh] = local[:, sh] @ q.T
    a_pose = dataclasses.replace(clip, joint_rotations=matrix_to_axis_angle(local))
    # in its own rest pose the A-pose file moves exactly like the clip
    _, moved = forward_kinematics(rest_a, a_pose.joint_rotations, a_pose.root_translation)
    assert np.abs(moved - clip.joint_positions()).max() < 1e-9
    path = save_bvh(a_pose, tmp_path / "apose.bvh", rest_joints=rest_a)
    back = load_bvh(path)
    a, b = clip.joint_positions(), back.joint_positions()
    assert np.abs((a - a[:, :1]) - (b - b[:, :1])).max() < 1e-4


def _lines(path):
    return path.read_text().splitlines()


@pytest.fixture
def small_bvh(tmp_path):
    clip = load_clip("walk_slow")
    return save_bvh(clip, tmp_path / "walk.bvh", naming="mixamo")


def test_bad_bvh_files_name_the_file_and_line(tmp_path, small_bvh):
    lines = _lines(small_bvh)
    # unknown joint names
    renamed = tmp_path / "renamed.bvh"
    renamed.write_text("\n".join(line.replace("mixamorig:LeftUpLeg", "Thigh_L") for line in lines))
    with pytest.raises(InvalidInputError, match=r"renamed\.bvh.*joint names.*left_hip"):
        load_bvh(renamed)
    # truncated motion
    cut = tmp_path / "cut.bvh"
    cut.write_text("\n".join(lines[:-10]))
    with pytest.raises(InvalidInputError, match=r"cut\.bvh.*Frames.*truncated"):
        load_bvh(cut)
    # truncated hierarchy
    half = tmp_path / "half.bvh"
    half.write_text("\n".join(lines[:40]))
    with pytest.raises(InvalidInputError, match=r"half\.bvh.*MOTION"):
        load_bvh(half)
    # a frame with a missing value, reported by its line number
    short = tmp_path / "short.bvh"
    motion = lines.index("MOTION")
    bad = list(lines)
    bad[motion + 5] = " ".join(bad[motion + 5].split()[:-1])
    short.write_text("\n".join(bad))
    with pytest.raises(InvalidInputError, match=rf"short\.bvh: line {motion + 6}: frame 2: expected \d+ channel"):
        load_bvh(short)
    # a broken OFFSET
    off = tmp_path / "offset.bvh"
    bad = [line.replace("OFFSET", "OFFSET x", 1) if "OFFSET" in line else line for line in lines]
    off.write_text("\n".join(bad))
    with pytest.raises(InvalidInputError, match=r"offset\.bvh: line \d+: field 'OFFSET'"):
        load_bvh(off)
    # a joint line without its block: no offset, named
    orphan = tmp_path / "orphan.bvh"
    joint = next(k for k, line in enumerate(lines) if line.strip().startswith("JOINT"))
    orphan.write_text("\n".join(lines[:joint] + ["  JOINT Stray"] + lines[joint:]))
    with pytest.raises(InvalidInputError, match=r"orphan\.bvh: line \d+: field 'OFFSET': missing for joint 'Stray'"):
        parse_bvh(orphan)
    # not a BVH at all, and a missing file
    text = tmp_path / "notes.bvh"
    text.write_text("hello\n")
    with pytest.raises(InvalidInputError, match="HIERARCHY"):
        load_bvh(text)
    with pytest.raises(InvalidInputError, match="does not exist"):
        load_bvh(tmp_path / "nothing.bvh")
    with pytest.raises(InvalidInputError, match="skeleton"):
        load_bvh(small_bvh, skeleton="biovision")


def test_parse_bvh_reads_channels_in_any_order(tmp_path):
    text = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation
  JOINT Child
  {
    OFFSET 0 10 0
    CHANNELS 3 Xrotation Zrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.04
1 2 3 90 0 0 0 0 0
0 0 0 0 0 90 0 0 0
"""
    path = tmp_path / "tiny.bvh"
    path.write_text(text)
    bvh = parse_bvh(path)
    assert bvh.names == ["Hips", "Child"] and bvh.n_frames == 2 and bvh.frame_time == 0.04
    assert np.allclose(bvh.end_sites[1], [0, 5, 0])
    glob, pos = bvh.global_transforms()
    assert np.allclose(pos[0, 0], [1, 2, 3])
    assert np.allclose(pos[0, 1], [1, 12, 3])  # yaw about Y leaves the +Y bone in place
    # frame 1: 90 degrees about Z rolls the +Y bone to -X
    assert np.allclose(pos[1, 1], [-10, 0, 0], atol=1e-9)


# ----------------------------------------------------------------------------- AMASS
def _write_amass(path, poses, trans, rate=60.0, **extra):
    np.savez(path, poses=poses, trans=trans, mocap_framerate=np.array(rate), **extra)
    return path


def test_amass_frames_and_axes(tmp_path):
    n = 30
    poses = np.zeros((n, 72))
    poses[:, J["left_knee"] * 3] = np.radians(60)  # SMPL: +x flexes the knee
    trans = np.zeros((n, 3))
    trans[:, 2] = np.linspace(0, 1.2, n)  # walking along SMPL's +z (forward)
    clip = load_amass(_write_amass(tmp_path / "a.npz", poses, trans, rate=60.0))
    assert clip.fps == 60.0 and clip.n_frames == n and clip.kind == "mocap"
    assert np.allclose(clip.joint_rotations[:, J["left_knee"]], [-np.radians(60), 0, 0], atol=1e-9)
    assert np.allclose(clip.joint_rotations[:, 0], 0, atol=1e-9)  # facing +y
    assert np.allclose(np.diff(clip.root_translation[:, 1]), 1.2 / (n - 1))  # forward is +y
    pos = clip.joint_positions()
    assert (pos[:, J["left_ankle"], 1] < pos[:, J["left_knee"], 1]).all()  # shin bends backwards
    assert pos[:, [J["left_ankle"], J["right_ankle"]], 2].min() == pytest.approx(ANKLE_HEIGHT, abs=1e-6)
    # SMPL-H layout (156): the body part is read, the hands stay at rest
    poses_h = np.zeros((n, 156))
    poses_h[:, :66] = poses[:, :66]
    poses_h[:, 66:] = 0.3
    clip_h = load_amass(_write_amass(tmp_path / "h.npz", poses_h, trans))
    assert np.allclose(clip_h.joint_rotations[:, :22], clip.joint_rotations[:, :22])
    assert np.allclose(clip_h.joint_rotations[:, 22:], 0)
    # a Z-up archive: the root orientation carries SMPL's Y-up frame into the world
    poses_z = poses.copy()
    poses_z[:, :3] = [np.pi / 2, 0, 0]  # Y up -> Z up, facing -y
    clip_z = load_amass(_write_amass(tmp_path / "z.npz", poses_z, trans[:, [0, 2, 1]] * [1, -1, 1]), up="z")
    up_axis = axis_angle_to_matrix(clip_z.joint_rotations[:, 0])[:, :, 2]
    assert np.allclose(up_axis, [0, 0, 1], atol=1e-9)


def test_bad_amass_files_name_the_field(tmp_path):
    n = 5
    good = dict(poses=np.zeros((n, 72)), trans=np.zeros((n, 3)))
    cases = [
        (dict(poses=np.zeros((n, 70)), trans=good["trans"]), "'poses'"),
        (dict(poses=good["poses"], trans=np.zeros((n + 1, 3))), "'trans'"),
        (dict(poses=np.full((n, 72), np.nan), trans=good["trans"]), "'poses'.*non-finite"),
    ]
    for i, (fields, msg) in enumerate(cases):
        path = _write_amass(tmp_path / f"bad{i}.npz", fields["poses"], fields["trans"])
        with pytest.raises(InvalidInputError, match=rf"bad{i}\.npz.*{msg}"):
            load_amass(path)
    path = tmp_path / "notrans.npz"
    np.savez(path, poses=good["poses"], mocap_framerate=np.array(30.0))
    with pytest.raises(InvalidInputError, match=r"notrans\.npz.*'trans' is missing"):
        load_amass(path)
    path = _write_amass(tmp_path / "rate.npz", good["poses"], good["trans"], rate=-5.0)
    with pytest.raises(InvalidInputError, match="mocap_framerate"):
        load_amass(path)
    full = _write_amass(tmp_path / "full.npz", np.zeros((200, 72)), np.zeros((200, 3)))
    cut = tmp_path / "cut.npz"
    cut.write_bytes(full.read_bytes()[:-300])
    with pytest.raises(InvalidInputError, match=r"cut\.npz"):
        load_amass(cut)
    with pytest.raises(InvalidInputError, match="up"):
        load_amass(full, up="x")

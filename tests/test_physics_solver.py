"""Solver behaviour: tracking, collision resolution, solver agreement, damping (Fig. 4), correct()."""

import numpy as np
import pytest

from crowdstudy.physics import CrowdCorrector, PhysicsConfig, correct
from crowdstudy.physics.collision import KIND_INTER, CollisionPipeline, Contacts


@pytest.fixture(scope="module")
def records():
    from crowdstudy.body.shapes import sample_bodies

    return sample_bodies(4, 11)


@pytest.fixture(scope="module")
def bodies(records):
    from crowdstudy.physics.corrector import load_bodies

    return load_bodies(records)


def standing_root(bodies, xy):
    return np.array([[x, y, b.pelvis_height] for b, (x, y) in zip(bodies, xy, strict=True)])


def inter_depth(corr):
    pipe = CollisionPipeline(corr.model, corr.config.with_values(margin=0.0))
    contacts = Contacts.allocate(pipe.default_capacity(), "cpu")
    pipe.collide(corr.state, contacts)
    c = contacts.to_numpy()
    sel = (c["kind"] == KIND_INTER) & (c["depth"] > 0)
    return float(c["depth"][sel].sum())


def test_standing_character_tracks_its_animation_and_keeps_feet_on_ground(bodies):
    corr = CrowdCorrector(bodies[:1], device="cpu")
    root = standing_root(bodies[:1], [(0.0, 0.0)])
    rot = np.zeros((1, 24, 3))
    rot[0, 16] = [0, 0, -1.2]  # arms down
    rot[0, 17] = [0, 0, 1.2]
    corr.reset(rot, root)
    for _ in range(45):
        out_rot, out_root = corr.step(rot, root)
    assert np.abs(out_root - root).max() < 0.01
    from crowdstudy.body.skeleton import forward_kinematics

    _, joints = forward_kinematics(bodies[0].rest_joints, out_rot[0], out_root[0])
    _, target = forward_kinematics(bodies[0].rest_joints, rot[0], root[0])
    assert np.linalg.norm(joints - target, axis=1).mean() < 0.02
    assert abs(joints[[7, 8], 2] - target[[7, 8], 2]).max() < 0.01  # ankles stay where the animation puts them
    assert corr.solver.last_cg[1] < 1e-3


def test_overlapping_characters_separate(bodies):
    corr = CrowdCorrector(bodies[:2], device="cpu")
    root = standing_root(bodies[:2], [(0.0, 0.0), (0.2, 0.05)])
    rot = np.zeros((2, 24, 3))
    corr.reset(rot, root)
    before = inter_depth(corr)
    for _ in range(30):
        corr.step(rot, root)
    after = inter_depth(corr)
    assert before > 0.1
    assert after < 0.1 * before


def test_reset_with_settle_starts_resolved(bodies):
    corr = CrowdCorrector(bodies[:2], device="cpu", config=PhysicsConfig().with_values(settle_time=0.3))
    root = standing_root(bodies[:2], [(0.0, 0.0), (0.2, 0.05)])
    rot = np.zeros((2, 24, 3))
    corr.reset(rot, root)
    before = inter_depth(corr)
    corr.reset(rot, root, settle=True)
    assert inter_depth(corr) < 0.2 * before
    out_rot, out_root = corr.step(rot, root)
    assert out_rot.shape == (2, 24, 3) and out_root.shape == (2, 3)


def test_linear_solvers_agree(bodies):
    results = {}
    for name in ("fused", "scipy", "warp"):
        corr = CrowdCorrector(
            bodies[:2],
            device="cpu",
            linear_solver=name,
            config=PhysicsConfig().with_values(cg_tolerance=1e-6, cg_max_iterations=400),
        )
        root = standing_root(bodies[:2], [(0.0, 0.0), (0.25, 0.0)])
        corr.reset(np.zeros((2, 24, 3)), root)
        _, r = corr.step(np.zeros((2, 24, 3)), root + [0.0, 0.02, 0.0])
        results[name] = (corr.solver.dx.numpy().copy(), r)
    ref = results["fused"][0]
    for name in ("scipy", "warp"):
        assert np.abs(results[name][0] - ref).max() <= 1e-3 * np.abs(ref).max() + 1e-6, name


@pytest.fixture(scope="module")
def damping():
    from crowdstudy.physics.damping import damping_study

    return damping_study((0.0, 0.006, 0.06), device="cpu")


def test_damping_paper_value_recovers_smoothly(damping):
    m = damping["metrics"][0.006]
    assert m["return_time"] < 1.0
    assert m["overshoot"] < 0.05
    held = damping["position"][0.006][np.searchsorted(damping["time"], 3.4)]
    assert held < -0.1  # it really was held back before the release


def test_damping_zero_oscillates(damping):
    m0, m = damping["metrics"][0.0], damping["metrics"][0.006]
    assert m0["crossings"] >= 3
    assert m0["overshoot"] > 0.05 and m0["overshoot"] > 3 * m["overshoot"]


def test_damping_large_lags(damping):
    m = damping["metrics"][0.06]
    assert m["error_at_1s"] > 0.02
    assert m["return_time"] > 1.0


def _tiny_anim(records, bodies, n_frames=8):
    from crowdstudy.body.skeleton import JOINT_NAMES, PARENTS
    from crowdstudy.scene import CrowdAnimation

    n = 3
    root0 = standing_root(bodies[:n], [(0, 0), (0.3, 0.0), (0.15, 0.25)])
    t = np.arange(n_frames) / 30.0
    root = np.repeat(root0[None], n_frames, 0)
    root[:, :, 1] += 0.3 * t[:, None]
    rot = np.zeros((n_frames, n, 24, 3))
    rot[:, :, 16, 2] = -1.1
    rot[:, :, 17, 2] = 1.1
    return CrowdAnimation(
        joint_names=JOINT_NAMES,
        parents=PARENTS,
        root_translation=root,
        joint_rotations=rot,
        fps=30.0,
        bodies=tuple(records[:n]),
        clips=tuple({"name": "test"} for _ in range(n)),
        meta={"method": "Baseline", "seed": 1},
    )


def test_correct_removes_the_overlap_of_the_same_scene_and_keeps_the_layout(records, bodies):
    """Three characters 30 cm apart (their capsules interpenetrate in every frame): the
    correction removes the overlap, measured independently of the solver by
    ``crowdstudy.metrics.overlap_volume`` on the same scene, and stays near the animation.

    Measured (sample_bodies(4, 11), 8 frames, 2 cm grid): Baseline 2.83 L (capsules) and
    3.16 L (meshes) per character in every frame, Ours 0.0 L in every frame; the largest
    root drift 6.1 cm (1.1 cm vertically), the tracking error 5.6 cm, the closest pelvis
    pair 29.2 -> 34.3 cm apart. The bars leave margin: at least 20x less overlap in every
    frame, drift < 10 cm (< 3 cm vertically), tracking < 8 cm, the closest pair farther apart."""
    from crowdstudy.metrics import overlap_volume, tracking_error

    anim = _tiny_anim(records, bodies)
    out = correct(anim, progress=False, device="cpu")
    assert out.meta["method"] == "Ours" and out.meta["physics"]["steps"] == 2 * (anim.n_frames - 1)
    assert out.root_translation.shape == anim.root_translation.shape
    assert out.joint_rotations.shape == anim.joint_rotations.shape
    assert out.bodies == anim.bodies and out.clips == anim.clips
    for geometry in ("capsule", "mesh"):
        base = overlap_volume(anim, geometry=geometry).per_frame
        ours = overlap_volume(out, geometry=geometry).per_frame
        assert base.min() > 1e-3, (geometry, base)  # > 1 L per character: a real collision
        assert np.all(ours <= base / 20), (geometry, base, ours)  # every frame, not just on average
    # the correction pushes the characters apart, it does not teleport them
    drift = np.abs(out.root_translation - anim.root_translation)
    assert drift.max() < 0.10
    assert drift[..., 2].max() < 0.03  # horizontal separation, not lifting
    assert tracking_error(out, anim) < 8.0

    def pelvis(a):  # (T, N, N) horizontal distances between the pelvises
        return np.linalg.norm(a.root_translation[:, :, None, :2] - a.root_translation[:, None, :, :2], axis=-1)

    iu = np.triu_indices(anim.n_characters, 1)
    assert np.all(pelvis(out)[:, iu[0], iu[1]].min(axis=1) > pelvis(anim)[:, iu[0], iu[1]].min(axis=1))


def test_cli_correct_round_trip(tmp_path, records, bodies):
    from crowdstudy.cli import main
    from crowdstudy.scene import CrowdAnimation

    src = _tiny_anim(records, bodies, n_frames=4).save(tmp_path / "in.npz")
    rc = main(
        ["correct", str(src), str(tmp_path / "out.npz"), "--no-progress", "--device", "cpu", "--config", "damping=0.01"]
    )
    assert rc == 0
    out = CrowdAnimation.load(tmp_path / "out.npz")
    assert out.meta["method"] == "Ours" and out.meta["physics"]["config"]["control"]["damping"] == 0.01


def test_bad_inputs_name_the_argument(bodies):
    from crowdstudy.physics.model import ModelBuilder

    with pytest.raises(ValueError, match="solver.dt"):
        PhysicsConfig().with_values(dt=-1.0)
    with pytest.raises(ValueError, match="unknown PhysicsConfig field 'stifness'"):
        PhysicsConfig.from_overrides({"stifness": "3"}, strings=True)
    with pytest.raises(ValueError, match="damping"):
        PhysicsConfig.from_overrides({"damping": "abc"}, strings=True)
    with pytest.raises(ValueError, match="anim"):
        correct("not an animation")
    with pytest.raises(ValueError, match="linear_solver"):
        CrowdCorrector(bodies[:1], device="cpu", linear_solver="magic")
    with pytest.raises(ValueError, match="rest_joints"):
        ModelBuilder().add_character(np.zeros((5, 3)), bodies[0].capsules)
    with pytest.raises(ValueError, match="no characters"):
        ModelBuilder().finalize(device="cpu")
    corr = CrowdCorrector(bodies[:1], device="cpu")
    with pytest.raises(ValueError, match="reset"):
        corr.step(np.zeros((1, 24, 3)), np.zeros((1, 3)))
    corr.reset(np.zeros((1, 24, 3)), standing_root(bodies[:1], [(0.0, 0.0)]))
    with pytest.raises(ValueError, match="joint_rotations/root_translation"):
        corr.step(np.zeros((2, 24, 3)), np.zeros((2, 3)))


@pytest.mark.slow
def test_real_scene_d1_meets_the_overlap_and_tracking_bars():
    """Short clip (2 s) of the study's stationary D1 cell: mesh overlap <= 15 % of the
    Baseline's, tracking error within the D1 bar's 1.5 cm (the full 20 s clips are measured by
    ``crowdstudy bench physics --bars``). A clip this short is a smoke test, not the bar: two
    pairs make nearly all of a D1 cell's overlap, hence a bound looser than the full clip's
    5 % bar (how this clip's numbers moved is in the correction's history under docs/). On the
    generated mannequins, whose meshes the capsules fit closely (IoU about 0.81); the
    MakeHuman bodies (IoU about 0.76) keep 16 % of this clip's Baseline mesh overlap: the
    mesh beyond capsule + skin is not pushed (issue #11)."""
    from crowdstudy.design import load_design
    from crowdstudy.metrics import BarTolerances
    from crowdstudy.metrics.overlap import overlap_volume
    from crowdstudy.metrics.tracking import tracking_error
    from crowdstudy.motion.baseline import build_baseline

    base = build_baseline(load_design(), "stationary", "D1", duration=2.0, body_model="open")
    ours = correct(base, progress=False)
    frames = np.arange(0, base.n_frames, 6)
    ob = overlap_volume(base, geometry="mesh", frames=frames).mean
    oo = overlap_volume(ours, geometry="mesh", frames=frames).mean
    assert ob > 0
    assert oo <= 0.15 * ob
    assert tracking_error(ours, base) < BarTolerances().tracking_sparsest_cm  # the D1 bar
    from crowdstudy.body.skeleton import forward_kinematics
    from crowdstudy.physics.corrector import load_bodies

    rest = np.stack([np.asarray(b.rest_joints) for b in load_bodies(base.bodies)])
    _, p_ours = forward_kinematics(rest[None], ours.joint_rotations, ours.root_translation)
    _, p_base = forward_kinematics(rest[None], base.joint_rotations, base.root_translation)
    feet = [7, 8, 10, 11]
    assert np.abs(p_ours[:, :, feet, 2] - p_base[:, :, feet, 2]).mean() < 0.02  # feet stay on the ground


@pytest.mark.slow
def test_the_default_cg_tolerance_tracks_as_a_tight_solve_does():
    """One Newton step per frame needs no tight linear solve: on 0.5 s of the densest concert
    cell the default tolerance (3e-3) tracks the animation within 0.06 cm of a solve to 1e-5
    (measured 2026-12-05: 4.805 against 4.809 cm; 1e-3 4.794; a tolerance of 0.1 tracks at
    4.917, 0.11 cm off, which this test would catch). The joints themselves are not
    compared: in a crowd this dense a limb that meets its neighbour a step apart takes
    another way round it, whatever the tolerance (1e-4 against 1e-6: mean 1.6 cm, largest
    45 cm)."""
    from crowdstudy.design import load_design
    from crowdstudy.metrics.tracking import tracking_error
    from crowdstudy.motion.baseline import build_baseline

    base = build_baseline(load_design(), "stationary", "D5", duration=0.5, body_model="open")
    assert PhysicsConfig().solver.cg_tolerance == 3e-3
    default = tracking_error(correct(base, progress=False), base)
    tight_cfg = PhysicsConfig().with_values(cg_tolerance=1e-5, cg_max_iterations=400)
    tight = tracking_error(correct(base, tight_cfg, progress=False), base)
    assert tight > 2.0  # a dense cell: the contacts move the crowd
    assert abs(default - tight) <= 0.06, (default, tight)


@pytest.mark.slow
def test_a_dense_crowd_held_in_place_tracks_closer():
    """The root's translation spring stays stiff beyond its centimetre of reach (2e5 N/m), so
    a dense crowd makes room with the limbs that touch instead of spreading out: on 0.5 s of
    the densest concert cell the default tracks closer than with the earlier 1e4 N/m far
    spring, and the whole-clip shift of each character (the placement) is what shrinks.
    Measured with the 2 kN/m undamped pose springs of the day: 6.96 against 8.18 cm,
    placement 3.87 against 5.08 cm (on 1 s: 7.02 / 8.18, 3.68 / 4.97); on the 20 s cells
    (``crowdstudy bench physics --bars``) concert D5 8.71 -> 7.53 cm, corridor D5 5.41 ->
    4.91. With the damped 8 kN/m pose springs since, which hold the limbs too: 5.32 against
    5.91 cm, placement 2.75 against 3.50 cm; with the skins capped at 1.5 cm (2026-12-05),
    which need less room: 4.80 against 5.33 cm, placement 2.36 against 2.98 cm."""
    from crowdstudy.design import load_design
    from crowdstudy.metrics.tracking import tracking_parts
    from crowdstudy.motion.baseline import build_baseline

    base = build_baseline(load_design(), "stationary", "D5", duration=0.5, body_model="open")
    held = tracking_parts(correct(base, progress=False), base)
    soft = PhysicsConfig().with_values(root_translation_far_stiffness=1e4)
    spread = tracking_parts(correct(base, soft, progress=False), base)
    assert spread.placement_cm > 2.5  # the soft root lets the crowd spread
    assert held.total_cm <= spread.total_cm - 0.35, (held, spread)
    assert held.placement_cm <= spread.placement_cm - 0.45, (held, spread)


def _planted_foot_speed(anim, reference):
    """Mean horizontal speed (cm/s) of the foot joints of ``anim`` over the frames where the
    ``reference`` animation's foot is planted (within 10 cm of its lowest height, < 10 cm/s)."""
    from crowdstudy.body.skeleton import forward_kinematics
    from crowdstudy.physics.corrector import load_bodies

    rest = np.stack([np.asarray(b.rest_joints) for b in load_bodies(reference.bodies)])
    feet = [7, 8, 10, 11]
    pa = forward_kinematics(rest[None], anim.joint_rotations, anim.root_translation)[1][:, :, feet]
    pr = forward_kinematics(rest[None], reference.joint_rotations, reference.root_translation)[1][:, :, feet]
    va = np.linalg.norm(np.diff(pa[..., :2], axis=0), axis=-1) * reference.fps
    vr = np.linalg.norm(np.diff(pr[..., :2], axis=0), axis=-1) * reference.fps
    planted = (pr[1:, ..., 2] < pr[..., 2].min() + 0.1) & (vr < 0.1)
    return 100 * va[planted].mean(), 100 * vr[planted].mean()


@pytest.mark.slow
def test_real_walking_scene_keeps_planted_feet_planted():
    """Corridor D1, 2 s: the corrected feet slide < 3 cm/s while the Baseline's are planted
    (measured 1.7 cm/s; without the stance anchor they slide about 7 cm/s). The Baseline
    itself: 1.3 cm/s with the motion-captured walks (0.6 with the procedural ones), 2.1 cm/s
    on the MakeHuman bodies (their toe joint rolls more): the loose mask, within 10 cm of the
    floor and under 10 cm/s, includes the heel and toe roll."""
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline

    base = build_baseline(load_design(), "walking", "D1", duration=2.0)
    ours = correct(base, progress=False)
    skate, reference = _planted_foot_speed(ours, base)
    assert reference < 2.5
    assert skate < 3.0


def test_a_character_gliding_along_a_wall_is_not_held_back(bodies):
    """Arms down, the character's right hand 5 cm through a wall it glides past at 1 m/s for
    2 s: the wall (a frictionless plane) pushes the hand back to the body's side and does not
    slow the body; the same wall as point samples drags it about 10 cm behind its animation
    and lets the hand through (the corridor's walkers lagged so before the walls were planes)."""
    from crowdstudy.body.skeleton import forward_kinematics
    from crowdstudy.physics.collision import sample_static_walls

    body = bodies[0]
    rot = np.zeros((1, 24, 3))
    rot[0, 16] = [0, 0, -1.2]
    rot[0, 17] = [0, 0, 1.2]
    _, joints = forward_kinematics(body.rest_joints, rot[0], np.array([0.0, 0.0, body.pelvis_height]))
    wall_y = float(joints[:, 1].max()) - 0.05
    walls = np.array([[[-5.0, wall_y], [5.0, wall_y]]])
    result = {}
    for name, kw in (("plane", {"static_walls": walls}), ("points", {"static_points": sample_static_walls(walls)})):
        # the paper's soft root (1e4 N/m), which the point samples' drag shows on; the
        # defaults' stiff root holds the body within mm of its animation either way
        corr = CrowdCorrector([body], device="cpu", fps=30, config=PhysicsConfig.paper_controller(), **kw)
        root = standing_root([body], [(-1.0, 0.0)])
        corr.reset(rot, root)
        lag, reach = [], []
        for _ in range(60):
            root = root + np.array([[1.0 / 30.0, 0.0, 0.0]])
            out_rot, out_root = corr.step(rot, root)
            lag.append(root[0, 0] - out_root[0, 0])
            reach.append(forward_kinematics(body.rest_joints, out_rot[0], out_root[0])[1][:, 1].max())
        result[name] = (np.abs(lag[30:]).max(), max(reach[30:]))
    assert result["plane"][0] < 0.002  # m behind the animation
    assert result["plane"][1] < wall_y  # every joint on the body's side
    assert result["points"][0] > 0.03 and result["points"][1] > wall_y

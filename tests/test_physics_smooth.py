"""The causes of jitter removed in the physics, and the output stage (issue: Ours as smooth as
its animation): the C2 contact activation band, target-relative self and ground contacts,
the feed-forward prediction, damping independent of the step, loop closing, the deviation
low-pass and the planted-foot hold."""

import numpy as np
import pytest

from crowdstudy.body.posing import planted_runs
from crowdstudy.physics import CrowdCorrector, PhysicsConfig
from crowdstudy.physics.finish import close_loop, lock_planted_feet, smooth_deviation


@pytest.fixture(scope="module")
def bodies():
    from crowdstudy.body.shapes import sample_bodies
    from crowdstudy.physics.corrector import load_bodies

    return load_bodies(sample_bodies(2, 11))


def _joints(body, rot, root):
    from crowdstudy.body.skeleton import forward_kinematics

    return forward_kinematics(body.rest_joints, rot, root)[1]


def _single_contact_gradient(
    depth: float, activation: float, k: float = 3.0e4, *, kind: int = 1, stiffening: float = 0.0
):
    """Gradient (N) on body 0 and k_eff of one contact of the given depth and kind (default
    environment) against the world."""
    from crowdstudy.physics import ModelBuilder, Solver, State
    from crowdstudy.physics.collision import Contacts
    from crowdstudy.physics.state import Control
    from crowdstudy.warp_runtime import get_warp
    from tests.test_physics_energies import fixture_body

    wp = get_warp()
    builder = ModelBuilder()
    builder.add_character(*vars(fixture_body()).values())
    model = builder.finalize(device="cpu")
    cfg = PhysicsConfig().with_values(activation=activation, stiffening_depth=stiffening)
    control = Control(model)
    control.set_frames(np.zeros((1, 24, 3)), np.array([[0.0, 0.0, 1.0]]))
    control.advance(0, 0, 0.0)
    control.hold()
    state = State(model)
    state.x.assign(control.t_x)
    state.q.assign(control.t_glob)
    solver = Solver(model, cfg)
    empty = Contacts.allocate(0, "cpu")
    solver.assemble(state, control, empty, cfg.solver.dt)
    g0 = solver.grad_t.numpy()[0].astype(float)
    c = Contacts.allocate(1, "cpu")
    c.count.assign(wp.array([1], dtype=wp.int32))
    c.body_a.assign(wp.array([0], dtype=wp.int32))
    c.body_b.assign(wp.array([-1], dtype=wp.int32))
    c.normal.assign(wp.array([[0.0, 0.0, 1.0]], dtype=wp.vec3))
    c.depth.assign(wp.array([depth], dtype=wp.float32))
    c.stiffness.assign(wp.array([k], dtype=wp.float32))
    c.kind.assign(wp.array([kind], dtype=wp.int32))
    solver.assemble(state, control, c, cfg.solver.dt)
    g1 = solver.grad_t.numpy()[0].astype(float)
    return g1 - g0, float(solver.k_eff.numpy()[0])


def test_contact_activation_band_is_c2():
    k, e = 3.0e4, 0.005
    # gradient along u = -n: -phi'(d) on z; stiffness phi''(d)
    cases = {
        -0.006: (0.0, 0.0),
        -0.0025: (k * 0.0025**2 / (2 * e), k * 0.5),
        0.0: (k * e / 2, k),
        0.01: (k * (0.01 + e / 2), k),
    }
    for depth, (force, stiff) in cases.items():
        g, k_eff = _single_contact_gradient(depth, e, k)
        assert g[2] == pytest.approx(-force, rel=1e-4, abs=1e-3), depth
        assert k_eff == pytest.approx(stiff, rel=1e-4, abs=1e-3), depth
    # continuity of the force across the band's ends and at contact
    forces = [-_single_contact_gradient(d, e, k)[0][2] for d in (-e - 1e-4, -e + 1e-4, -1e-4, 1e-4)]
    assert forces[1] - forces[0] < 0.05 and forces[3] - forces[2] < k * 3e-4  # k (1e-4)^2 / (2 e) = 0.03 N
    # without the band a contact predicted apart does nothing and then pushes at full stiffness
    assert _single_contact_gradient(-0.0025, 0.0, k) == (pytest.approx(np.zeros(3)), 0.0)


def test_deep_inter_body_contacts_stiffen():
    from crowdstudy.physics.collision import KIND_ENVIRONMENT, KIND_INTER

    k, e, d0 = 3.0e4, 0.005, 0.01
    for depth in (0.004, 0.02):
        g, k_eff = _single_contact_gradient(depth, e, k, kind=KIND_INTER, stiffening=d0)
        assert -g[2] == pytest.approx(k * (depth + e / 2) + k * depth**2 / d0, rel=1e-4), depth
        assert k_eff == pytest.approx(k + 2 * k * depth / d0, rel=1e-4), depth
        # at 2 cm the stiffened contact pushes 3.4x harder than the plain one
        plain = -_single_contact_gradient(depth, e, k, kind=KIND_INTER)[0][2]
        assert -g[2] / plain == pytest.approx(1 + depth**2 / d0 / (depth + e / 2), rel=1e-4)
    # a light touch (in the activation band, or just in contact) is as soft as before: C2 at 0
    for depth in (-0.002, 1e-5):
        assert _single_contact_gradient(depth, e, k, kind=KIND_INTER, stiffening=d0)[1] == pytest.approx(
            _single_contact_gradient(depth, e, k, kind=KIND_INTER)[1], rel=3e-3
        )
    # only inter-body contacts stiffen: the walls and static objects keep their penalty
    g, k_eff = _single_contact_gradient(0.02, e, k, kind=KIND_ENVIRONMENT, stiffening=d0)
    assert -g[2] == pytest.approx(k * (0.02 + e / 2), rel=1e-4) and k_eff == pytest.approx(k, rel=1e-6)


def _folded_arm():
    rot = np.zeros((1, 24, 3))
    rot[0, 16] = [0.0, 0.0, -1.2]  # left arm down ...
    rot[0, 18] = [0.0, -2.4, 0.0]  # ... forearm folded through the trunk (7.9 cm deep)
    return rot


def test_self_overlap_of_the_animation_is_not_fought(bodies):
    body = bodies[:1]
    root = np.array([[0.0, 0.0, body[0].pelvis_height]])
    rot = _folded_arm()
    errors = {}
    for relative in (True, False):
        cfg = PhysicsConfig().with_values(target_relative_self=relative)
        corr = CrowdCorrector(body, device="cpu", config=cfg)
        corr.reset(rot, root)
        for _ in range(20):
            out_rot, out_root = corr.step(rot, root)
        errors[relative] = np.abs(_joints(body[0], out_rot[0], out_root[0]) - _joints(body[0], rot[0], root[0])).max()
    assert errors[True] < 0.002  # the folded arm stays where the animation puts it
    # the absolute self contact pushes it out of the trunk (5 mm against the world-space pose
    # springs, 9 mm with the joint springs alone)
    assert errors[False] > 0.004 and errors[False] > 3 * errors[True]


def _moving_pose(n_frames: int, fps: float, body):
    t = np.arange(n_frames) / fps
    rot = np.zeros((n_frames, 1, 24, 3))
    rot[:, 0, 16, 2] = -1.2 + 0.5 * np.sin(2 * np.pi * 1.3 * t)  # arm swings
    rot[:, 0, 17, 2] = 1.2 + 0.5 * np.sin(2 * np.pi * 1.1 * t)
    rot[:, 0, 0, 2] = 0.6 * np.sin(2 * np.pi * 0.4 * t)  # turning
    rot[:, 0, 12, 0] = 0.3 * np.sin(2 * np.pi * 0.9 * t)  # nodding
    root = np.zeros((n_frames, 1, 3))
    root[:, 0, 0] = 0.5 * np.sin(2 * np.pi * 0.5 * t)  # swaying 0.5 m
    root[:, 0, 2] = body.pelvis_height + 0.1 + 0.03 * np.sin(2 * np.pi * 2 * t)  # off the floor
    return rot, root


def test_feedforward_reproduces_an_animation_without_contacts(bodies):
    body = bodies[:1]
    fps = 30.0
    rot, root = _moving_pose(45, fps, body[0])
    worst = {}
    for ff in (True, False):
        corr = CrowdCorrector(body, device="cpu", fps=fps, config=PhysicsConfig().with_values(feedforward=ff))
        corr.reset(rot[0], root[0])
        err = 0.0
        for f in range(1, len(rot)):
            out_rot, out_root = corr.step(rot[f], root[f])
            err = max(
                err, np.abs(_joints(body[0], out_rot[0], out_root[0]) - _joints(body[0], rot[f, 0], root[f, 0])).max()
            )
        worst[ff] = err
    assert worst[True] < 0.002  # follows the moving animation exactly
    # the plain prediction lags and sags: 5.9 mm against the damped 8 kN/m pose springs of
    # 2026-12-04 (over 1 cm against the 2 kN/m undamped springs before them)
    assert worst[False] > 0.004 and worst[False] > 3 * worst[True]


def _release_curve(dt: float, signed: bool = False, **config):
    """Distance (m) of a body displaced 0.1 m from its (still) target, released, over 0.4 s
    (``signed``: its offset along the push, negative once it has overshot the target)."""
    from crowdstudy.body.shapes import sample_bodies
    from crowdstudy.physics.corrector import load_bodies

    body = load_bodies(sample_bodies(1, 3))
    # the paper's controller: the defaults' stiff root spring (3e5 N/m) is overdamped by the
    # implicit step itself at 1/60 s, which hides the damping term this measures
    corr = CrowdCorrector(
        body,
        device="cpu",
        fps=30.0,
        config=PhysicsConfig.paper_controller(
            dt=dt, feedforward=True, anchor_stiffness=0.0, ground_stiffness=0.0, **config
        ),
    )
    rot = np.zeros((1, 24, 3))
    root = np.array([[0.0, 0.0, body[0].pelvis_height + 0.2]])
    corr.reset(rot, root)
    wp = corr.solver.wp
    x = corr.state.x.numpy()
    corr.state.x.assign(wp.array(x + np.array([0.1, 0.0, 0.0], np.float32), dtype=wp.vec3))  # pushed 10 cm
    out = []
    for _ in range(12):
        _, r = corr.step(rot, root)
        out.append(r[0, 0] - root[0, 0] if signed else np.linalg.norm(r[0] - root[0]))
    return np.array(out)


def test_damping_does_not_change_with_the_step():
    a, b = _release_curve(1.0 / 60.0), _release_curve(1.0 / 120.0)
    assert a[0] < 0.1 and a[-1] < a[0]
    # the same recovery whatever the step (without the h / h0 scaling, d / h doubles at 1/120 s)
    np.testing.assert_allclose(a, b, atol=0.15 * a[0])


def test_pose_springs_pull_a_displaced_body_back_in_world_space():
    plain, posed = _release_curve(1.0 / 60.0), _release_curve(1.0 / 60.0, pose_translation_stiffness=3000.0)
    assert posed[3] < 0.8 * plain[3]  # the world-space springs add to the root's


def test_the_pose_damper_stops_a_pushed_body_overshooting():
    """The world-space pose springs' damper (``pose_translation_damping_scale``, 1000 by
    default: 360 N s/m against the body's velocity relative to the animation's) brings a body
    pushed 10 cm back without swinging through its target; undamped, the same 8 kN/m springs
    throw it past. On the 20 s concert D5 cell the damper took the overlap left from 4.8 % to
    3.7 % of the Baseline's at the same tracking (docs/lab-notes/correction-history.md, "Damped pose springs")."""
    defaults = PhysicsConfig().control
    springs = {"pose_translation_stiffness": defaults.pose_translation_stiffness}
    undamped = _release_curve(1.0 / 60.0, signed=True, pose_translation_damping_scale=0.0, **springs)
    damped = _release_curve(
        1.0 / 60.0, signed=True, pose_translation_damping_scale=defaults.pose_translation_damping_scale, **springs
    )
    assert undamped.min() < -0.005, undamped  # swings past the target (8 mm measured)
    assert damped.min() > -1e-4, damped  # settles from one side ...
    assert np.all(np.diff(damped) <= 1e-5), damped  # ... coming closer every frame
    assert damped[-1] < 0.002


def test_close_loop_continues_the_last_frame():
    rng = np.random.default_rng(0)
    n, warm, blend = 20, 5, 6
    rot = rng.normal(scale=0.1, size=(warm + n + blend, 2, 24, 3))
    root = np.cumsum(rng.normal(scale=0.01, size=(warm + n + blend, 2, 3)), axis=0)
    out_rot, out_root = close_loop(rot, root, n, warm, blend)
    assert out_rot.shape == (n, 2, 24, 3)
    # frame 0 is (almost) the continuation of the last frame, frame `blend` the clip's own
    np.testing.assert_allclose(out_root[blend:], root[warm + blend : warm + n])
    w0 = 1.0 - (10 * (1 / 7) ** 3 - 15 * (1 / 7) ** 4 + 6 * (1 / 7) ** 5)
    np.testing.assert_allclose(out_root[0], w0 * root[warm + n] + (1 - w0) * root[warm], rtol=1e-12)
    with pytest.raises(ValueError):
        close_loop(rot[:-1], root[:-1], n, warm, blend)


def test_smooth_deviation_keeps_the_input_and_removes_spikes():
    rng = np.random.default_rng(1)
    t = np.arange(90) / 30.0
    ref_rot = np.zeros((90, 1, 24, 3))
    ref_rot[:, 0, 18, 1] = 0.6 * np.sin(2 * np.pi * 9.0 * t)  # fast motion of the input itself
    ref_root = rng.normal(scale=0.01, size=(90, 1, 3))
    # a constant deviation passes unchanged, the input's own 9 Hz motion too
    rot = ref_rot.copy()
    rot[:, 0, 5, 0] += 0.2
    root = ref_root + [0.05, 0.0, 0.0]
    out_rot, out_root = smooth_deviation(rot, root, ref_rot, ref_root, 3.0)
    np.testing.assert_allclose(out_rot, rot, atol=1e-9)
    np.testing.assert_allclose(out_root, root, atol=1e-12)
    # a one-frame spike of the deviation is spread out
    root2 = root.copy()
    root2[40, 0, 1] += 0.06
    out_rot, out_root = smooth_deviation(rot, root2, ref_rot, ref_root, 3.0)
    assert abs(out_root[40, 0, 1] - root[40, 0, 1]) < 0.06 / 5
    # circular for loops: the seam frames get the spike's tail from the other end
    root3 = root.copy()
    root3[0, 0, 1] += 0.06
    _, wrapped = smooth_deviation(rot, root3, ref_rot, ref_root, 3.0, periodic=True)
    assert wrapped[-1, 0, 1] - root[-1, 0, 1] > 1e-3
    assert smooth_deviation(rot, root3, ref_rot, ref_root, 0.0)[1] is root3


def test_held_low_pass_keeps_the_separation_a_contact_needed():
    """A 10-frame push (a contact) survives the output stage at full size with the hold;
    a plain low-pass of the same width shaves it."""
    n = 60
    ref_rot = np.zeros((n, 1, 24, 3))
    ref_root = np.zeros((n, 1, 3))
    root = ref_root.copy()
    root[25:35, 0, 0] = 0.04
    _, plain = smooth_deviation(ref_rot, root, ref_rot, ref_root, 3.0)
    _, held = smooth_deviation(ref_rot, root, ref_rot, ref_root, 3.0, hold=1.0)
    assert plain[25:35, 0, 0].min() < 0.6 * 0.04  # shaved to 57 % at the contact's ends
    assert held[25:35, 0, 0].min() > 0.85 * 0.04  # kept (88 %) over the whole contact
    assert held[25:35, 0, 0].mean() > 0.95 * 0.04
    assert held[:15, 0, 0].max() < 5e-4 and held[45:, 0, 0].max() < 5e-4  # eased in and out
    assert np.abs(np.diff(held[:, 0, 0], 2)).max() < 0.002  # smoothly


def test_planted_runs_wrap_in_periodic_masks():
    mask = np.array([1, 1, 0, 0, 1, 1, 1, 0, 1], bool)
    assert planted_runs(mask) == [(0, 2), (4, 7), (8, 9)]
    assert planted_runs(mask, periodic=True) == [(4, 7), (8, 11)]
    assert planted_runs(np.ones(5, bool), periodic=True) == [(0, 5)]
    assert planted_runs(np.zeros(5, bool)) == []


def test_swing_carries_the_hold_offset_smoothly():
    from crowdstudy.physics.finish import _foot_hold

    n = 40
    ref = np.zeros((n, 3))
    ref[10:20, 0] = np.linspace(0.0, 0.5, 12)[1:-1]  # a 0.5 m step between two stances
    ref[20:, 0] = 0.5
    ref[10:20, 2] = 0.05
    out = ref.copy()
    out[:, 1] += np.linspace(0.0, 0.06, n)  # the correction drifts the foot sideways
    planted = np.ones(n, bool)
    planted[10:20] = False
    pull, weight = _foot_hold(out, ref, planted, False)
    held = out[:, :2] + pull
    assert np.ptp(held[:10], axis=0).max() < 1e-12 and np.ptp(held[20:], axis=0).max() < 1e-12
    # in the swing the foot keeps its own path, displaced smoothly (no drag back to the hold),
    # and is on it mid-swing
    assert np.abs(np.diff(held[:, 1], 2)).max() < 0.02  # 3 cm eased over ~3 frames
    assert np.abs(np.diff(held[8:22, 0], 2)).max() <= np.abs(np.diff(out[8:22, 0], 2)).max() + 1e-9
    assert np.abs(pull[14:16]).max() < 0.05 * np.abs(pull).max()
    assert np.all(weight == 1.0)


def test_pushed_character_keeps_its_planted_feet(bodies):
    body = bodies[0]
    n = 40
    ref_rot = np.zeros((n, 1, 24, 3))
    ref_root = np.tile([[0.0, 0.0, body.pelvis_height - 0.01]], (n, 1, 1))
    # the output: the same pose, the body pushed 5 cm sideways over the clip: the feet slide
    root = ref_root.copy()
    root[:, 0, 0] += np.linspace(0.0, 0.05, n)
    before = _joints(body, ref_rot[:, 0], root[:, 0])
    out = lock_planted_feet(ref_rot, root, ref_rot, ref_root, body.rest_joints[None], 30.0)
    after = _joints(body, out[:, 0], root[:, 0])
    for ankle in (7, 8):
        assert np.ptp(before[:, ankle, 0]) > 0.045
        assert np.ptp(after[:, ankle, 0]) < 1e-3  # held still ...
        # ... at the mean of the push over the stance (2.5 cm), which the leg reaches from
        # both ends of it
        assert after[:, ankle, 0].mean() == pytest.approx(before[:, ankle, 0].mean(), abs=1e-3)
        # near full extension the leg is soft-clamped (finish._soft_reach), which may lift
        # the ankle by mm
        assert np.abs(after[:, ankle, 2] - before[:, ankle, 2]).max() < 3e-3
    assert np.abs(after[:, 15] - before[:, 15]).max() < 1e-9  # the upper body is untouched


def test_a_held_foot_creeps_as_the_reference_does():
    from crowdstudy.physics.finish import _foot_hold

    n = 30
    ref = np.zeros((n, 3))
    ref[:, 0] = 0.01 * np.arange(n) / 60.0  # a planted mocap foot creeping at 1 cm/s
    out = ref.copy()
    out[:, 1] += np.linspace(0.0, 0.06, n)  # pushed 6 cm sideways over the stance
    pull, _ = _foot_hold(out, ref, np.ones(n, bool), False)
    held = out[:, :2] + pull
    # one offset for the whole stance (the push's mean, 3 cm): the foot moves exactly as the
    # reference's, so it slides no faster than the Baseline's own planted foot
    assert np.abs(held - ref[:, :2] - [0.0, 0.03]).max() < 1e-12


def test_a_heel_rise_turns_the_foot_about_the_ball():
    from crowdstudy.body.rotations import rotation_between
    from crowdstudy.physics.finish import _ankle_about_ball

    rng = np.random.default_rng(3)
    hip = rng.normal(size=(50, 3)) * 0.02 + [0.0, 0.0, 0.9]
    ball = rng.normal(size=(50, 3)) * 0.02 + [0.15, 0.0, 0.03]
    foot, reach = np.full(50, 0.15), np.full(50, 0.82)
    target = ball - [0.14, 0.0, -0.05]
    ankle = _ankle_about_ball(hip, reach, ball, foot, target)
    # on both spheres: at the leg's reach from the hip and a foot's length from the ball ...
    assert np.allclose(np.linalg.norm(ankle - hip, axis=1), reach, atol=1e-9)
    assert np.allclose(np.linalg.norm(ankle - ball, axis=1), foot, atol=1e-9)
    # ... and, of that circle, the point nearest the target
    e = (ball - hip) / np.linalg.norm(ball - hip, axis=1, keepdims=True)
    for i in range(0, 50, 10):
        u = np.cross(e[i], [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(e[i], u)
        centre = hip[i] + np.dot(ankle[i] - hip[i], e[i]) * e[i]
        rad = np.linalg.norm(ankle[i] - centre)
        circle = centre + rad * (
            np.cos(np.linspace(0, 2 * np.pi, 721))[:, None] * u + np.sin(np.linspace(0, 2 * np.pi, 721))[:, None] * v
        )
        assert np.linalg.norm(ankle[i] - target[i]) <= np.linalg.norm(circle - target[i], axis=1).min() + 1e-9
    # spheres that do not meet: straight from the hip towards the ball
    far = _ankle_about_ball(hip[:1], np.array([0.5]), ball[:1], foot[:1], target[:1])
    assert np.allclose(np.cross(far[0] - hip[0], ball[0] - hip[0]), 0.0, atol=1e-12)
    assert np.linalg.norm(far[0] - hip[0]) == pytest.approx(0.5)
    turn = rotation_between(np.tile([1.0, 0.0, 0.0], (50, 1)), ball - ankle)
    assert np.allclose(turn @ [1.0, 0.0, 0.0], (ball - ankle) / foot[:, None], atol=1e-9)
    assert np.allclose(turn @ np.swapaxes(turn, 1, 2), np.eye(3), atol=1e-9)
    # parallel and opposite directions: the identity (no axis to turn about)
    same = rotation_between(np.array([[0.0, 0.0, 2.0], [1.0, 0.0, 0.0]]), np.array([[0.0, 0.0, 1.0], [-3.0, 0.0, 0.0]]))
    assert np.array_equal(same, np.tile(np.eye(3), (2, 1, 1)))


def test_the_last_swing_of_a_clip_does_not_snap():
    from crowdstudy.physics.finish import _foot_hold

    n = 40
    ref = np.zeros((n, 3))
    ref[12:24, 0] = np.linspace(0.0, 0.3, 14)[1:-1]  # a 12-frame swing between two stances ...
    ref[24:, 0] = 0.3
    ref[37:, 0] = 0.3 + np.linspace(0.0, 0.05, 4)[1:]  # ... and a swing cut by the clip's end
    ref[12:24, 2] = ref[37:, 2] = 0.04
    out = ref.copy()
    out[:, 1] += np.linspace(0.08, 0.0, n)  # the correction's sideways drift shrinks
    planted = np.ones(n, bool)
    planted[12:24] = planted[37:] = False
    pull, weight = _foot_hold(out, ref, planted, False)
    off = np.linalg.norm(pull[36])
    assert off > 0.01  # the last stance holds the foot 1+ cm off its path
    # the 3 cut frames ease the offset out over a quarter of a whole swing: no single-frame jump
    jumps = np.linalg.norm(np.diff(pull[36:], axis=0), axis=1)
    assert jumps.max() <= 0.5 * off
    assert np.all(weight == 1.0)


def test_a_held_foot_does_not_stretch_a_straight_leg_further():
    from crowdstudy.physics.finish import STRAIGHT_HOLD, _soft_reach

    length = np.array([0.8, 0.8])
    hip = np.zeros((2, 3))
    own = np.array([[0.0, 0.0, -0.77], [0.0, 0.0, -0.6]])  # a nearly straight leg, a bent one
    target = own + np.array([[0.0, 0.15, 0.0], [0.0, 0.05, 0.0]])  # the hold pulls them forward
    goal = _soft_reach(hip, own, target, length)
    d = np.linalg.norm(goal - hip, axis=1)
    assert d[0] <= 0.77 + 0.01 * 0.8 + 1e-9  # at most 1 % of the leg beyond its own
    assert d[1] == pytest.approx(np.linalg.norm(target[1]))  # a bent leg reaches the target
    assert STRAIGHT_HOLD * 0.8 > np.linalg.norm(target[1])


def _two_fixture_characters(ahead_dy: float, config: PhysicsConfig):
    """Two test characters side by side, the second 0.18 m behind the first along y (their
    trunks and legs overlap, their arms do not), and the inter-body contacts the pipeline
    finds when the animation has moved the second by ``ahead_dy`` m along y one frame
    ahead: (stiffness (C,), depth (C,)) of those contacts."""
    from crowdstudy.physics import ModelBuilder, State
    from crowdstudy.physics.collision import KIND_INTER, CollisionPipeline, Contacts
    from crowdstudy.physics.state import Control
    from tests.test_physics_energies import fixture_body

    builder = ModelBuilder()
    for _ in range(2):
        builder.add_character(*vars(fixture_body()).values())
    model = builder.finalize(device="cpu")
    control = Control(model, n_frames=2)
    control.ahead_frames = 1.0
    rot = np.zeros((2, 2, 24, 3))
    root = np.array([[[0.0, 0.0, 1.0], [0.0, 0.18, 1.0]], [[0.0, 0.0, 1.0], [0.0, 0.18 + ahead_dy, 1.0]]])
    control.set_frames(rot, root)
    control.advance(0, 0, 0.0)
    state = State(model)
    state.x.assign(control.t_x)
    state.q.assign(control.t_glob)
    pipeline = CollisionPipeline(model, config)
    contacts = Contacts.allocate(pipeline.default_capacity(), "cpu")
    pipeline.collide(state, contacts, control)
    n = int(contacts.count.numpy()[0])
    inter = contacts.kind.numpy()[:n] == KIND_INTER
    return contacts.stiffness.numpy()[:n][inter], contacts.depth.numpy()[:n][inter]


def test_a_crossing_the_animation_completes_is_let_through():
    cfg = PhysicsConfig().with_values(pass_ahead=1.0 / 30.0, intra_body=False)
    k = cfg.contacts.stiffness
    # still overlapping one frame ahead (a lasting overlap): every contact pushes at full stiffness
    held, depth = _two_fixture_characters(0.0, cfg)
    assert len(held) > 3 and (depth > 0).any() and np.all(held == pytest.approx(k))
    # apart again on the same side (the animation separates them itself): full stiffness too
    apart, _ = _two_fixture_characters(0.5, cfg)
    assert len(apart) == len(held) and np.all(apart == pytest.approx(k))
    # the second character has passed through the first and stands 0.5 m on the other side:
    # the contacts let go
    through, _ = _two_fixture_characters(-0.68, cfg)
    assert len(through) == len(held) and np.all(through == 0.0)
    # only where the look-ahead is on
    off, _ = _two_fixture_characters(-0.68, cfg.with_values(pass_ahead=0.0))
    assert np.all(off == pytest.approx(k))
    # the pass fades in over contact_pass_width (2 cm): barely apart on the other side, a part of k
    partial, _ = _two_fixture_characters(-0.39, cfg)
    assert np.any((partial > 0.05 * k) & (partial < 0.95 * k))


def _translation_gradient(config: PhysicsConfig, shift: np.ndarray) -> np.ndarray:
    """(B, 3) N: the body terms' translational gradient with every body of a test character
    moved rigidly by ``shift`` m from its (still) target."""
    from crowdstudy.physics import ModelBuilder, Solver, State
    from crowdstudy.physics.collision import Contacts
    from crowdstudy.physics.state import Control
    from crowdstudy.warp_runtime import get_warp
    from tests.test_physics_energies import fixture_body

    wp = get_warp()
    builder = ModelBuilder()
    builder.add_character(*vars(fixture_body()).values())
    model = builder.finalize(device="cpu")
    control = Control(model)
    control.set_frames(np.zeros((1, 24, 3)), np.array([[0.0, 0.0, 1.0]]))
    control.advance(0, 0, 0.0)
    control.hold()
    state = State(model)
    state.x.assign(wp.array(control.t_x.numpy() + shift.astype(np.float32), dtype=wp.vec3))
    state.q.assign(control.t_glob)
    solver = Solver(model, config.with_values(anchor_stiffness=0.0))
    solver.assemble(state, control, Contacts.allocate(0, "cpu"), config.solver.dt)
    return solver.grad_t.numpy().astype(float)


def test_translation_springs_soften_beyond_their_reach():
    e = np.array([0.05, 0.0, 0.0])
    base = PhysicsConfig().with_values(
        root_translation_stiffness=3e5,
        root_translation_reach=0.0,
        feet_translation_stiffness=0.0,
        pose_translation_stiffness=0.0,
    )
    linear = _translation_gradient(base, e)
    np.testing.assert_allclose(linear[0], 3e5 * e, rtol=1e-4, atol=0.05)  # the root: k e (N)
    soft = _translation_gradient(base.with_values(root_translation_reach=0.01, root_translation_far_stiffness=1e4), e)
    k_eff = 1e4 + (3e5 - 1e4) / np.sqrt(1.0 + (0.05 / 0.01) ** 2)
    np.testing.assert_allclose(soft[0], k_eff * e, rtol=1e-4, atol=0.05)
    # near the animation the softened spring is as stiff as the linear one
    small = np.array([0.0005, 0.0, 0.0])
    np.testing.assert_allclose(
        _translation_gradient(base.with_values(root_translation_reach=0.01), small)[0],
        3e5 * small,
        rtol=2e-3,
        atol=0.05,
    )
    # the pose springs of the other bodies (here the right hand, joint 23) saturate at k r
    posed = base.with_values(pose_translation_stiffness=2000.0)
    hand = _translation_gradient(posed, e)[23] - linear[23]
    np.testing.assert_allclose(hand, 2000.0 * e, rtol=1e-3, atol=0.05)
    far = np.array([0.5, 0.0, 0.0])
    capped = (
        _translation_gradient(posed.with_values(pose_translation_reach=0.03), far)[23]
        - _translation_gradient(base, far)[23]
    )
    assert capped[0] == pytest.approx(2000.0 * 0.5 / np.sqrt(1.0 + (0.5 / 0.03) ** 2), rel=1e-3)
    assert capped[0] < 2000.0 * 0.03  # at most k r

"""Collision detection: ground, environment, inter-body (incl. periodic), intra-body."""

import types

import numpy as np
import pytest

from crowdstudy.body.capsules import closest_points_on_segments
from crowdstudy.body.skeleton import DEFAULT_PELVIS_HEIGHT, DEFAULT_REST_JOINTS, PARENTS, children
from crowdstudy.errors import InvalidInputError
from crowdstudy.physics.collision import (
    KIND_ENVIRONMENT,
    KIND_GROUND,
    KIND_INTER,
    KIND_INTRA,
    CollisionPipeline,
    Contacts,
    sample_static_walls,
    sweep_pairs,
)
from crowdstudy.physics.config import PhysicsConfig
from crowdstudy.physics.model import ModelBuilder
from crowdstudy.physics.state import Control, State
from crowdstudy.scene_meta import static_walls_from_meta


def fixture_body():
    """Test-only capsules along the default skeleton's bones."""
    rest = DEFAULT_REST_JOINTS
    kids = children(PARENTS)
    start, end, radius = rest.copy(), rest.copy(), np.full(24, 0.05)
    radius[[0, 3, 6, 9]] = 0.1
    for j in range(24):
        tip = rest[kids[j]].mean(0) if kids[j] else rest[j] + 0.5 * (rest[j] - rest[PARENTS[j]])
        d = tip - rest[j]
        start[j] = rest[j] + 0.25 * d
        end[j] = tip - 0.25 * d
    return types.SimpleNamespace(rest_joints=rest, capsules=types.SimpleNamespace(start=start, end=end, radius=radius))


def detect(roots, rot=None, cfg=None, points=None, period=None, walls=None):
    n = len(roots)
    builder = ModelBuilder()
    for _ in range(n):
        b = fixture_body()
        builder.add_character(b.rest_joints, b.capsules)
    model = builder.finalize(device="cpu")
    cfg = cfg or PhysicsConfig()
    control = Control(model)
    rot = np.zeros((n, 24, 3)) if rot is None else rot
    control.set_frames(rot, np.asarray(roots, float))
    control.advance(0, 0, 0.0)
    state = State(model)
    state.x.assign(control.t_x)
    state.q.assign(control.t_glob)
    pipe = CollisionPipeline(model, cfg, static_points=points, period=period, static_walls=walls)
    contacts = Contacts.allocate(pipe.default_capacity(), "cpu")
    pipe.collide(state, contacts)
    return model, contacts.to_numpy(), pipe


def test_ground_contacts_for_capsules_below_the_floor():
    _, c, _ = detect([[0, 0, DEFAULT_PELVIS_HEIGHT - 0.05]])
    ground = c["kind"] == KIND_GROUND
    assert ground.any()
    assert np.allclose(c["normal"][ground], [0, 0, 1])
    _, c_high, _ = detect([[0, 0, 2.0]])
    assert not (c_high["kind"] == KIND_GROUND).any()


def test_inter_body_contacts_match_exact_capsule_distance():
    model, c, _ = detect([[0, 0, 1.2], [0.15, 0.05, 1.2]], cfg=PhysicsConfig().with_values(margin=0.0))
    inter = (c["kind"] == KIND_INTER) & (c["depth"] > 0)
    assert inter.sum() > 5
    a, b = c["body_a"][inter], c["body_b"][inter]
    assert np.all(model.body_char[a] != model.body_char[b])
    # T-pose: world capsule = root + rest-frame end points; compare with the numpy distance
    caps = fixture_body().capsules
    roots = np.array([[0, 0, 1.2], [0.15, 0.05, 1.2]])
    ja, jb = model.body_joint[a], model.body_joint[b]
    ra, rb = roots[model.body_char[a]], roots[model.body_char[b]]
    _, _, dist = closest_points_on_segments(
        ra + caps.start[ja], ra + caps.end[ja], rb + caps.start[jb], rb + caps.end[jb]
    )
    np.testing.assert_allclose(c["depth"][inter], caps.radius[ja] + caps.radius[jb] - dist, atol=1e-4)
    # every overlapping capsule pair was found
    all_a, all_b = np.meshgrid(np.arange(24), np.arange(24), indexing="ij")
    _, _, d_all = closest_points_on_segments(
        roots[0] + caps.start[all_a],
        roots[0] + caps.end[all_a],
        roots[1] + caps.start[all_b],
        roots[1] + caps.end[all_b],
    )
    assert inter.sum() == np.count_nonzero(caps.radius[all_a] + caps.radius[all_b] - d_all > 0)
    _, far, _ = detect([[0, 0, 1.2], [3.0, 0, 1.2]])
    assert not (far["kind"] == KIND_INTER).any()


def test_the_sweep_finds_the_broadphase_kernels_pairs_in_its_order():
    """``sweep_pairs`` (the CPU's broad phase from 200 characters) returns exactly the
    pairs of ``broadphase_kernel`` in the same (i, j) order: random boxes on a crowd's
    floor, with shared lower x (ties) and boxes that touch exactly."""
    from crowdstudy.physics import collision_kernels as k
    from crowdstudy.warp_runtime import get_warp

    wp = get_warp()
    rng = np.random.default_rng(5)
    n = 700
    lo = np.column_stack([rng.uniform(0, 30, n), rng.uniform(0, 12, n), rng.uniform(0, 0.1, n)])
    lo[::7, 0] = lo[3, 0]  # ties along x
    hi = lo + np.column_stack([rng.uniform(0.3, 1.0, n), rng.uniform(0.3, 1.0, n), rng.uniform(1.5, 1.9, n)])
    lo[10] = (hi[11, 0], lo[11, 1], lo[11, 2])  # touching exactly along x
    hi[10] = lo[10] + (0.5, 0.5, 1.7)
    lo[12] = (lo[13, 0], hi[13, 1], lo[13, 2])  # ... and along y
    hi[12] = lo[12] + (0.5, 0.5, 1.7)
    lo, hi = lo.astype(np.float32), hi.astype(np.float32)
    cap = 20 * n
    count = wp.zeros(1, dtype=wp.int32)
    pi, pj = wp.zeros(cap, dtype=wp.int32), wp.zeros(cap, dtype=wp.int32)
    shift = wp.zeros(cap, dtype=wp.float32)
    wp.launch(
        k.broadphase_kernel,
        n,
        [wp.array(lo, dtype=wp.vec3), wp.array(hi, dtype=wp.vec3), 0.0, count, cap, pi, pj, shift],
    )
    m = int(count.numpy()[0])
    assert 1000 < m < cap
    i, j = sweep_pairs(lo, hi)
    assert len(i) == m
    np.testing.assert_array_equal(i, pi.numpy()[:m])
    np.testing.assert_array_equal(j, pj.numpy()[:m])
    assert {(10, 11), (12, 13)} <= set(zip(i.tolist(), j.tolist(), strict=True))


def test_periodic_minimum_image():
    _, c, _ = detect([[0.05, 0, 1.2], [4.4, 0, 1.2]], period=4.5)
    assert ((c["kind"] == KIND_INTER) & (c["depth"] > 0)).any()
    _, c2, _ = detect([[0.05, 0, 1.2], [4.4, 0, 1.2]])
    assert not (c2["kind"] == KIND_INTER).any()


def test_intra_pairs_skip_rest_touching_and_parent_child():
    model, c, _ = detect([[0, 0, 1.2]])
    pairs = model.intra_pairs
    assert len(pairs) > 50
    assert not np.any(PARENTS[pairs[:, 1]] == pairs[:, 0])
    caps = fixture_body().capsules
    _, _, d = closest_points_on_segments(
        caps.start[pairs[:, 0]], caps.end[pairs[:, 0]], caps.start[pairs[:, 1]], caps.end[pairs[:, 1]]
    )
    assert np.all(d > caps.radius[pairs[:, 0]] + caps.radius[pairs[:, 1]])
    assert not ((c["kind"] == KIND_INTRA) & (c["depth"] > 0)).any()  # the T-pose is free
    # bend the right elbow so the forearm folds through the chest -> an intra contact
    rot = np.zeros((1, 24, 3))
    rot[0, 17] = [0, 0, 1.4]
    rot[0, 19] = [0, 0, 2.6]
    _, cb, _ = detect([[0, 0, 1.2]], rot=rot)
    assert ((cb["kind"] == KIND_INTRA) & (cb["depth"] > 0)).any()


def test_environment_points_push_away_from_walls():
    walls = np.array([[[-2.0, 0.15], [2.0, 0.15]]])
    pts = sample_static_walls(walls, spacing=0.03)
    assert pts.shape[1] == 3 and pts[:, 2].max() >= 2.0
    _, c, _ = detect([[0, 0, 1.2]], points=pts, cfg=PhysicsConfig().with_values(margin=0.0))
    env = (c["kind"] == KIND_ENVIRONMENT) & (c["depth"] > 0)
    assert env.any()
    assert np.all(c["normal"][env][:, 1] < 0)  # pushed towards -y, away from the wall


def _wall_depths(pipe, wall_y, spec):
    """The end spheres of every capsule against the plane y = wall_y, free side y < wall_y,
    computed here in numpy from the pipeline's world capsules: sorted depths."""
    model = pipe.model
    r = model.wp["cap_radius"].numpy() + model.wp["cap_skin"].numpy() + pipe.config.contacts.margin
    ends = np.concatenate([pipe.p0w.numpy()[:, 1], pipe.p1w.numpy()[:, 1]])
    depth = np.concatenate([r, r]) - (wall_y - ends)
    return np.sort(depth[depth > -spec])


def test_walls_are_one_sided_planes_on_the_side_of_the_root():
    """A character turned so that its arms reach 0.6 m through a wall at y = 0.15: every end
    sphere is pushed along the wall's normal towards the root's side (-y), with the depth of
    its centre beyond the plane, also the ends that have crossed the wall; no contact has a
    component along the wall."""
    rot = np.zeros((1, 24, 3))
    rot[0, 0] = [0.0, 0.0, np.pi / 2]  # the T-pose's arms along y
    walls = np.array([[[-2.0, 0.15], [2.0, 0.15]]])
    cfg = PhysicsConfig().with_values(margin=0.0)
    _, c, pipe = detect([[0, 0, 1.2]], rot=rot, cfg=cfg, walls=walls)
    env = c["kind"] == KIND_ENVIRONMENT
    assert pipe.n_static_walls == 1 and env.sum() > 4
    assert np.allclose(c["normal"][env], [0.0, -1.0, 0.0], atol=0.0)
    assert c["depth"][env].max() > 0.5  # a hand 0.6 m through is pushed back, not out
    assert np.allclose(np.sort(c["depth"][env]), _wall_depths(pipe, 0.15, cfg.contacts.speculative_distance), atol=1e-6)
    # the same wall seen from the other side: a root at y = 0.3 is on the +y side
    _, c2, _ = detect([[0, 0.3, 1.2]], rot=rot, cfg=cfg, walls=walls)
    env2 = c2["kind"] == KIND_ENVIRONMENT
    assert env2.any() and np.allclose(c2["normal"][env2], [0.0, 1.0, 0.0], atol=0.0)
    # point samples of the same wall push an arm that crosses them sideways, along the wall
    # (x) or up and down (z): a drag on a walker's arm swing; why walls are planes
    pts = sample_static_walls(walls, spacing=0.03)
    _, cp, _ = detect([[0, 0, 1.2]], rot=rot, cfg=cfg, points=pts)
    envp = (cp["kind"] == KIND_ENVIRONMENT) & (cp["depth"] > 0)
    assert (np.abs(cp["normal"][envp][:, [0, 2]]).max(axis=1) > 0.9).any()


def test_walls_end_where_their_segment_ends_and_repeat_with_the_period():
    rot = np.zeros((1, 24, 3))
    rot[0, 0] = [0.0, 0.0, np.pi / 2]
    short = np.array([[[-1.0, 0.15], [1.0, 0.15]]])
    _, beside, _ = detect([[0.5, 0, 1.2]], rot=rot, walls=short)
    _, past, _ = detect([[2.5, 0, 1.2]], rot=rot, walls=short)
    assert (beside["kind"] == KIND_ENVIRONMENT).any()
    assert not (past["kind"] == KIND_ENVIRONMENT).any()
    # periodic along x (4.5 m): x = 4.9 is the image of x = 0.4, beside the wall
    _, here, _ = detect([[0.4, 0, 1.2]], rot=rot, walls=short, period=4.5)
    d_here = np.sort(here["depth"][here["kind"] == KIND_ENVIRONMENT])
    assert len(d_here) > 4
    for x in (4.9, 4.4 + 4.5 * 5, -4.1):  # images, also many periods on (a walker's unwrapped x)
        _, image, _ = detect([[x, 0, 1.2]], rot=rot, walls=short, period=4.5)
        d_image = np.sort(image["depth"][image["kind"] == KIND_ENVIRONMENT])
        assert np.allclose(d_here, d_image, atol=1e-4), x
    with pytest.raises(InvalidInputError, match="static_walls"):
        detect([[0.4, 0, 1.2]], walls=np.zeros((2, 3)))


def test_static_walls_from_meta():
    walls = [[[-1.0, -1.0], [5.5, -1.0]], [[-1.0, 1.0], [5.5, 1.0]]]
    corridor = static_walls_from_meta(
        {"scenario": "corridor", "periodic": {"axis": 0, "length": 4.5}, "obstacles": walls}
    )
    assert corridor.shape == (2, 2, 2) and np.array_equal(corridor, walls)
    assert static_walls_from_meta({}).shape == (0, 2, 2)
    assert static_walls_from_meta({"scenario": "concert", "obstacles": []}).shape == (0, 2, 2)
    # a concert/corridor file without its geometry (older version): never a default design's walls
    for scenario in ("concert", "corridor"):
        with pytest.raises(ValueError, match=r"meta\['obstacles'\].*regenerate"):
            static_walls_from_meta({"scenario": scenario, "periodic": {"axis": 0, "length": 4.5}})
    with pytest.raises(ValueError, match="obstacles"):
        static_walls_from_meta({"obstacles": [[1, 2, 3]]})


def test_a_dense_crowd_finds_every_touching_capsule_pair_of_different_characters():
    """The culling (character AABBs, the second character's capsules masked against the
    first's box, bounding spheres) drops no contact: on a 200-character D5 concert (the
    CPU's sweep broad phase), every pair of capsules of different characters closer than
    their radii + skins + margin + speculative distance (numpy, all pairs) is a contact."""
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline
    from crowdstudy.physics.corrector import CrowdCorrector, load_bodies

    anim = build_baseline(load_design(), "stationary", "D5", duration=0.2, body_model="open")
    reps = 4  # 240 characters: four floors side by side
    shift = np.array([8.0, 0.0, 0.0])
    root = np.concatenate([anim.root_translation + r * shift for r in range(reps)], 1)
    rot = np.concatenate([anim.joint_rotations] * reps, 1)
    bodies = load_bodies(anim.bodies * reps)
    corr = CrowdCorrector(bodies, fps=anim.fps, n_frames=anim.n_frames, device="cpu")
    corr.control.set_frames(rot, root)
    corr.reset_to_frame(0)
    corr.control.advance(0, 1, 1.0)
    pipe = corr.pipeline
    assert corr.model.n_characters >= 200 and pipe.period == 0.0
    pipe.collide(corr.states[0], corr.contacts, corr.control)
    c = corr.contacts.to_numpy()
    found = {(a, b) for a, b, kind in zip(c["body_a"], c["body_b"], c["kind"], strict=True) if kind == KIND_INTER}
    p0, p1 = pipe.p0w.numpy().astype(float), pipe.p1w.numpy().astype(float)
    reach = corr.model.wp["cap_radius"].numpy() + corr.model.wp["cap_skin"].numpy()
    limit = float(corr.config.contacts.margin) + pipe.speculative
    nj, n = corr.model.n_joints, corr.model.n_characters
    ci, cj = np.triu_indices(n, 1)  # character pairs less than 3 m apart
    pelvis = p0[::nj]
    close = np.linalg.norm(pelvis[ci] - pelvis[cj], axis=1) < 3.0
    ci, cj = ci[close], cj[close]
    ja, jb = np.meshgrid(np.arange(nj), np.arange(nj), indexing="ij")
    ia = (ci[:, None] * nj + ja.ravel()).ravel()
    ib = (cj[:, None] * nj + jb.ravel()).ravel()
    _, _, dist = closest_points_on_segments(p0[ia], p1[ia], p0[ib], p1[ib])
    touching = reach[ia] + reach[ib] + limit - dist > 1e-4  # clear of float32 rounding
    want = set(zip(ia[touching].tolist(), ib[touching].tolist(), strict=True))
    assert len(want) > 2000
    assert want <= found

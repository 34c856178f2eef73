"""How crowded a crowd is (crowdstudy.physics.crowding) and the profile the physics takes
from it (PhysicsConfig.for_density, applied by correct())."""

import numpy as np
import pytest

from crowdstudy.errors import InvalidInputError
from crowdstudy.physics.config import PhysicsConfig
from crowdstudy.physics.crowding import crowd_config, crowd_density, local_density


def _lattice(n: int, spacing: float) -> np.ndarray:
    g = np.arange(n) * spacing
    return np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)


def test_local_density_of_a_square_lattice():
    """Inside a lattice of spacing a the 4th neighbour is at a: 4 / (pi a^2); a corner's is
    at a sqrt(2) (its neighbours: 2 at a, 1 at a sqrt(2), 2 at 2a)."""
    a = 0.5
    xy = _lattice(7, a)
    dens = local_density(xy[None], k=4)
    inner = np.abs(xy - 1.5).max(1) < 1.0
    assert np.allclose(dens[inner], 4 / (np.pi * a**2))
    corner = np.flatnonzero((xy == 0).all(1))[0]
    assert dens[corner] == pytest.approx(4 / (np.pi * (2 * a) ** 2))
    # the median over frames: a frame where the crowd spreads out twice as far counts once in three
    frames = np.stack([xy, xy, 2 * xy])
    assert np.allclose(local_density(frames, k=4)[inner], 4 / (np.pi * a**2))


def test_a_periodic_row_has_no_ends():
    """Ten characters 0.4 m apart on a 4 m period: every one has neighbours on both sides."""
    x = np.arange(10) * 0.4 + 0.1
    xy = np.column_stack([x, np.zeros(10)])[None]
    open_row = local_density(xy, k=2)
    ring = local_density(xy, k=2, period=4.0)
    assert np.allclose(ring, 2 / (np.pi * 0.4**2))
    assert open_row[0] == pytest.approx(2 / (np.pi * 0.8**2)) and open_row[5] == pytest.approx(ring[5])
    # positions given outside the first period are the same crowd
    assert np.allclose(local_density(xy + [[8.0, 0.0]], k=2, period=4.0), ring)
    # a root a hair below 0 (its x mod the period rounds to the period itself) still counts
    seam = xy - [[0.1 + 1e-17, 0.0]]
    assert np.allclose(local_density(seam, k=2, period=4.0), ring)


def test_local_density_edge_cases_and_errors():
    assert np.array_equal(local_density(np.zeros((3, 1, 2))), np.zeros(1))  # alone: no neighbour
    two = local_density(np.array([[[0.0, 0.0], [1.0, 0.0]]]))  # k falls to 1
    assert np.allclose(two, 1 / np.pi)
    with pytest.raises(InvalidInputError, match="root_xy"):
        local_density(np.zeros((4, 2)))
    with pytest.raises(InvalidInputError, match="root_xy"):
        local_density(np.full((1, 3, 2), np.nan))
    with pytest.raises(InvalidInputError, match="period"):
        local_density(np.zeros((1, 3, 2)), period=0.0)
    with pytest.raises(InvalidInputError, match="k"):
        local_density(np.zeros((1, 3, 2)), k=0)


def test_profile_weight_and_for_density():
    cfg = PhysicsConfig()
    sp, dp = cfg.profile.sparse, cfg.profile.dense
    assert cfg.follows_profile and (cfg.skin.max, cfg.skin.hand_scale, cfg.output.hold) == (None, None, None)
    assert cfg.profile_weight(0.0) == 0.0 == cfg.profile_weight(sp.crowd_density)
    assert cfg.profile_weight(dp.crowd_density) == 1.0 == cfg.profile_weight(50.0)
    mid = 0.5 * (sp.crowd_density + dp.crowd_density)
    assert cfg.profile_weight(mid) == pytest.approx(0.5)

    sparse, dense, half = cfg.for_density(1.0), cfg.for_density(9.0), cfg.for_density(mid)
    assert (sparse.skin.max, sparse.skin.hand_scale, sparse.output.hold) == (
        sp.skin_max,
        sp.skin_hand_scale,
        sp.output_hold,
    )
    assert (dense.skin.max, dense.skin.hand_scale, dense.output.hold) == (
        dp.skin_max,
        dp.skin_hand_scale,
        dp.output_hold,
    )
    assert half.skin.max == pytest.approx(0.5 * (sp.skin_max + dp.skin_max))
    assert half.output.hold == pytest.approx(0.5 * (sp.output_hold + dp.output_hold))
    assert cfg.profile.at(mid).skin_max == half.skin.max and cfg.for_dense_crowd() == dense
    # the resolved copy is final (resolving twice changes nothing); fixed values are kept
    assert not sparse.follows_profile and sparse.for_density(9.0) is sparse
    fixed = cfg.with_values({"skin.max": 0.02})
    assert fixed.for_density(1.0).skin.max == 0.02 and fixed.for_density(1.0).output.hold == sp.output_hold
    assert fixed.for_density(9.0).skin.max == 0.02 and fixed.for_density(9.0).skin.hand_scale == dp.skin_hand_scale
    # nothing else moves
    assert sparse.with_values({"skin.max": None, "skin.hand_scale": None, "output.hold": None}) == cfg

    with pytest.raises(InvalidInputError, match="profile.dense.crowd_density"):
        cfg.with_values({"profile.sparse.crowd_density": 6.0})
    with pytest.raises(InvalidInputError, match="density"):
        cfg.profile_weight(-1.0)


def test_fixing_the_three_values_replaces_the_old_switch():
    """The skins and hold of the dense end for every crowd (what ``crowd_adaptive=false``
    did): fix the three fields; the former switch is an error that says so."""
    cfg = PhysicsConfig()
    dp = cfg.profile.dense
    fixed = cfg.with_values(
        {"skin.max": dp.skin_max, "skin.hand_scale": dp.skin_hand_scale, "output.hold": dp.output_hold}
    )
    assert not fixed.follows_profile and fixed.for_density(1.0) is fixed and fixed == cfg.for_dense_crowd()
    with pytest.raises(InvalidInputError, match="crowd_adaptive.*skin.max=0.015 skin.hand_scale=0.5 output.hold=0.6"):
        cfg.with_values(crowd_adaptive=False)


def test_correct_sizes_the_skins_by_the_crowd():
    """A D1 concert (sparse) is corrected with the sparse profile: the same bytes as the
    sparse values given by hand, not the dense ones; the meta says which and why."""
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline
    from crowdstudy.physics.corrector import correct

    clip = build_baseline(load_design(), "stationary", "D1", duration=1.0).frames(0, 4)
    cfg = PhysicsConfig().with_values(settle_time=0.1)
    sp = cfg.profile.sparse
    density = crowd_density(clip)
    assert density < sp.crowd_density

    ours = correct(clip, cfg, progress=False, device="cpu")
    phys = ours.meta["physics"]
    assert phys["crowd_density"] == pytest.approx(density) and phys["profile_weight"] == 0.0
    assert phys["config"]["skin"]["max"] == sp.skin_max and phys["config"]["output"]["hold"] == sp.output_hold
    assert PhysicsConfig.from_dict(phys["config"]) == cfg.for_density(density)

    by_hand = correct(
        clip,
        cfg.with_values(
            {"skin.max": sp.skin_max, "skin.hand_scale": sp.skin_hand_scale, "output.hold": sp.output_hold}
        ),
        progress=False,
        device="cpu",
    )
    dense = correct(clip, cfg.for_dense_crowd(), progress=False, device="cpu")
    assert np.array_equal(ours.joint_rotations, by_hand.joint_rotations)
    assert np.array_equal(ours.root_translation, by_hand.root_translation)
    assert not np.array_equal(ours.joint_rotations, dense.joint_rotations)
    assert by_hand.meta["physics"]["profile_weight"] is None
    # the one resolution correct() and the benchmarks' peers share
    used, measured, weight = crowd_config(clip, cfg)
    assert used.as_dict() == phys["config"] and measured == phys["crowd_density"] and weight == 0.0
    assert crowd_config(clip, cfg.for_dense_crowd())[2] is None
    with pytest.raises(InvalidInputError, match="config"):
        crowd_config(clip, {"skin.max": 0.04})

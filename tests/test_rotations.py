"""crowdstudy.body.rotations: the quaternion algebra and elementary rotations agree with
the matrix conversions (scalar-last quaternions, matrices acting on column vectors)."""

import numpy as np

from crowdstudy.body.rotations import (
    axis_angle_to_matrix,
    axis_angle_to_quaternion,
    quat_about_z,
    quat_align_signs,
    quat_blend,
    quat_conjugate,
    quat_multiply,
    quat_nearest_sign,
    quat_rotate,
    quaternion_to_matrix,
    rot_x,
    rot_y,
    rot_z,
    yaw_roll_pitch,
)


def _random_quats(rng, n):
    return axis_angle_to_quaternion(rng.normal(0.0, 1.5, (n, 3)))


def test_product_conjugate_and_rotation_match_the_matrices():
    rng = np.random.default_rng(0)
    a, b = _random_quats(rng, 50), _random_quats(rng, 50)
    v = rng.normal(size=(50, 3))
    ra, rb = quaternion_to_matrix(a), quaternion_to_matrix(b)
    np.testing.assert_allclose(quaternion_to_matrix(quat_multiply(a, b)), ra @ rb, atol=1e-12)
    np.testing.assert_allclose(quaternion_to_matrix(quat_conjugate(a)), np.swapaxes(ra, -1, -2), atol=1e-12)
    np.testing.assert_allclose(quat_rotate(a, v), np.einsum("nab,nb->na", ra, v), atol=1e-12)


def test_elementary_rotations_are_axis_angle_rotations():
    angle = np.linspace(-3.0, 3.0, 13)
    for axis, rot in enumerate((rot_x, rot_y, rot_z)):
        vec = np.zeros((len(angle), 3))
        vec[:, axis] = angle
        np.testing.assert_allclose(rot(angle), axis_angle_to_matrix(vec), atol=1e-12)
    np.testing.assert_allclose(quaternion_to_matrix(quat_about_z(angle)), rot_z(angle), atol=1e-12)
    yaw, roll, pitch = 0.3, -0.2, 0.7
    np.testing.assert_allclose(yaw_roll_pitch(yaw, roll, pitch), rot_z(yaw) @ rot_y(roll) @ rot_x(pitch), atol=0)


def test_signs_blends_and_alignment_take_the_short_arc():
    rng = np.random.default_rng(1)
    q, ref = _random_quats(rng, 200), _random_quats(rng, 200)
    near = quat_nearest_sign(q, ref)
    assert np.all(np.sum(near * ref, axis=-1) >= 0.0)
    flipped = np.sum(q * ref, axis=-1) < 0.0
    assert flipped.any() and (~flipped).any()
    np.testing.assert_array_equal(near[flipped], -q[flipped])
    np.testing.assert_array_equal(near[~flipped], q[~flipped])
    # blending q with -q's rotation half way stays on q's rotation (short arc), unit length
    mid = quat_blend(q, -q, 0.5)
    np.testing.assert_allclose(np.abs(np.sum(mid * q, axis=-1)), 1.0, atol=1e-12)
    track = quat_align_signs(q[:, None] * np.where(rng.uniform(size=(200, 1, 1)) < 0.5, -1.0, 1.0), axis=0)
    assert np.all(np.sum(track[1:] * track[:-1], axis=-1) >= 0.0)


def test_quat_align_signs_matches_the_frame_by_frame_rule():
    """Each quaternion takes the sign nearest its aligned predecessor; an exactly orthogonal
    neighbour (dot 0) keeps its own sign and the run starts again from it."""

    def one_by_one(q, axis):
        q = np.moveaxis(np.array(q, dtype=np.float64), axis, 0)
        for i in range(1, len(q)):
            q[i][np.sum(q[i] * q[i - 1], axis=-1) < 0.0] *= -1.0
        return np.moveaxis(q, 0, axis)

    rng = np.random.default_rng(5)
    q = rng.normal(size=(40, 3, 5, 4))
    q[10, 1, 2], q[11, 1, 2], q[12, 1, 2] = [1, 0, 0, 0], [0, 1, 0, 0], [0, -1, 0, 0]
    q[20, 0, 0], q[21, 0, 0] = [0, 0, -1, 0], [1, 0, 0, 0]
    for arr, axis in ((q, 0), (np.moveaxis(q, 0, 2), 2), (q[:1], 0), (q[:, 0, 0], 0)):
        np.testing.assert_array_equal(quat_align_signs(arr, axis=axis), one_by_one(arr, axis))

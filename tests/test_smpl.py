"""SMPL from a user-supplied file, tested on synthetic model files in SMPL's exact layout
(.npz and a Python-2-style .pkl with chumpy arrays and a sparse J_regressor)."""

import pickle
import sys
import types

import numpy as np
import pytest
import scipy.sparse as sp

import crowdstudy.body as cb
from crowdstudy.body.skeleton import DEFAULT_REST_JOINTS, PARENTS, joint_index
from crowdstudy.body.smpl import SMPL_TO_OURS, read_smpl_file
from crowdstudy.errors import InvalidInputError

C = SMPL_TO_OURS
PELVIS_SMPL = np.array([0.01, -0.2, 0.03])
N_V = 30


def _model_arrays(seed: int = 0) -> dict:
    """A tiny SMPL-layout model: vertices 0..23 sit on the joints (J_regressor picks them),
    24 is on the left forearm, 25 on the pelvis, 26..29 blend two bones."""
    rng = np.random.default_rng(seed)
    v = np.zeros((N_V, 3))
    v[:24] = DEFAULT_REST_JOINTS @ C + PELVIS_SMPL  # p_smpl = C^T p_ours
    el = joint_index("left_elbow")
    v[24] = v[el] + (0.1, 0.0, 0.0)  # SMPL's left arm points to +x
    v[25] = v[0] + (0.0, 0.0, 0.12)
    v[26:] = v[:4] + 0.05
    weights = np.zeros((N_V, 24))
    weights[np.arange(24), np.arange(24)] = 1.0
    weights[24, el] = 1.0
    weights[25, 0] = 1.0
    weights[26:, 3] = weights[26:, 6] = 0.5
    shapedirs = rng.normal(0, 0.01, (N_V, 3, 10))
    shapedirs[:, :, 0] = 0.05 * (v - v[0])  # like SMPL's first component: overall size
    posedirs = np.zeros((N_V, 3, 207))
    posedirs[25, 1, 0 * 9 + 4] = 0.2  # joint 1 (left_hip), element R[1, 1] - 1, SMPL's y
    j_reg = np.zeros((24, N_V))
    j_reg[np.arange(24), np.arange(24)] = 1.0
    kintree = np.stack([np.where(PARENTS < 0, 4294967295, PARENTS), np.arange(24)]).astype(np.uint32)
    faces = np.array([[i, i + 1, i + 2] for i in range(N_V - 2)], dtype=np.uint32)
    return {
        "v_template": v,
        "shapedirs": shapedirs,
        "posedirs": posedirs,
        "J_regressor": j_reg,
        "weights": weights,
        "kintree_table": kintree,
        "f": faces,
    }


@pytest.fixture
def smpl_npz(tmp_path):
    path = tmp_path / "SMPL_NEUTRAL.npz"
    np.savez(path, **_model_arrays())
    return path


class _FakeCh:
    """Pickles like a chumpy array (module chumpy.ch, value in state['x'])."""

    def __init__(self, x):
        self.x = x
        self._dirty_vars = set()


def _write_pkl(path, arrays):
    mod_root, mod_ch = types.ModuleType("chumpy"), types.ModuleType("chumpy.ch")
    _FakeCh.__module__, _FakeCh.__qualname__, _FakeCh.__name__ = "chumpy.ch", "Ch", "Ch"
    mod_ch.Ch = _FakeCh
    data = dict(arrays)
    data["v_template"] = _FakeCh(arrays["v_template"])
    data["shapedirs"] = _FakeCh(arrays["shapedirs"])
    data["J_regressor"] = sp.csc_matrix(arrays["J_regressor"])
    data["bs_style"] = "lbs"
    old = {k: sys.modules.get(k) for k in ("chumpy", "chumpy.ch")}
    sys.modules.update({"chumpy": mod_root, "chumpy.ch": mod_ch})
    try:
        with open(path, "wb") as fh:
            pickle.dump(data, fh, protocol=2)
    finally:
        for k, m in old.items():
            if m is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = m


def test_shape_blendshapes_and_joint_regression(smpl_npz):
    a = _model_arrays()
    betas = np.array([0.5, -1.0, 2.0])
    body = cb.load_body({"model": "smpl", "path": str(smpl_npz), "betas": betas.tolist()})
    shaped = a["v_template"] + a["shapedirs"][:, :, :3] @ betas
    joints = shaped[:24]  # the regressor picks vertices 0..23
    np.testing.assert_allclose(body.rest_vertices, (shaped - joints[0]) @ C.T, atol=1e-12)
    np.testing.assert_allclose(body.rest_joints, (joints - joints[0]) @ C.T, atol=1e-12)
    np.testing.assert_allclose(body.weights.sum(axis=1), 1.0, atol=1e-6)
    assert body.template_key.startswith("smpl-") and body.posedirs.shape == (N_V * 3, 207)
    # zero betas: the template, converted (SMPL's left arm at +x lands at -x here)
    rest = cb.load_body({"model": "smpl", "path": str(smpl_npz)})
    np.testing.assert_allclose(rest.rest_joints, DEFAULT_REST_JOINTS, atol=1e-12)
    assert rest.rest_joints[joint_index("left_hand"), 0] < 0


def test_linear_blend_skinning_hand_computed(smpl_npz):
    body = cb.load_body({"model": "smpl", "path": str(smpl_npz)})
    el = joint_index("left_elbow")
    rot = np.zeros((24, 3))
    rot[el] = (0.0, 0.0, np.pi / 2)  # our frame: 90 degrees about +z (up)
    root = np.array([0.3, -1.0, 0.95])
    verts, joints = body.pose(rot, root)
    # vertex 24 is 0.1 m out along the arm (-x here); a quarter turn about +z sends it to -y
    expected = root + DEFAULT_REST_JOINTS[el] + (0.0, -0.1, 0.0)
    np.testing.assert_allclose(verts[24], expected, atol=1e-12)
    np.testing.assert_allclose(joints[el], root + DEFAULT_REST_JOINTS[el], atol=1e-12)
    # half-half vertices: the mean of the two bones' transforms (both unrotated here)
    np.testing.assert_allclose(verts[26:], body.rest_vertices[26:] + root, atol=1e-12)


def test_pose_blendshapes_hand_computed(smpl_npz):
    body = cb.load_body({"model": "smpl", "path": str(smpl_npz)})
    theta = 0.7
    rot = np.zeros((24, 3))
    rot[joint_index("left_hip")] = (theta, 0.0, 0.0)  # about our x = SMPL's -x
    verts, _ = body.pose(rot, np.zeros(3))
    # SMPL feature R[1, 1] - 1 = cos(theta) - 1 moves vertex 25 along SMPL's y = our z
    offset = 0.2 * (np.cos(theta) - 1.0)
    np.testing.assert_allclose(verts[25], body.rest_vertices[25] + (0.0, 0.0, offset), atol=1e-12)
    rot[joint_index("left_hip")] = (0.0, 0.0, theta)  # about our z = SMPL's y: R[1, 1] = 1
    verts, _ = body.pose(rot, np.zeros(3))
    np.testing.assert_allclose(verts[25], body.rest_vertices[25], atol=1e-12)
    # batched poses broadcast
    verts, joints = body.pose(np.zeros((2, 3, 24, 3)), np.zeros((2, 3, 3)))
    assert verts.shape == (2, 3, N_V, 3) and joints.shape == (2, 3, 24, 3)


def test_pkl_with_chumpy_and_sparse_regressor_reads_like_npz(tmp_path, smpl_npz):
    pkl = tmp_path / "basicModel_f_lbs_10_207_0_v1.0.0.pkl"
    _write_pkl(pkl, _model_arrays())
    a, b = read_smpl_file(pkl), read_smpl_file(smpl_npz)
    for key in b:
        np.testing.assert_array_equal(a[key], b[key])
    body = cb.load_body({"model": "smpl", "path": str(pkl), "betas": [1.0]})
    ref = cb.load_body({"model": "smpl", "path": str(smpl_npz), "betas": [1.0]})
    np.testing.assert_allclose(body.rest_vertices, ref.rest_vertices)


def test_bad_smpl_files_name_the_file_and_field(tmp_path, smpl_npz):
    data = smpl_npz.read_bytes()
    trunc = tmp_path / "trunc.npz"
    trunc.write_bytes(data[: len(data) // 2])
    with pytest.raises(InvalidInputError, match="trunc.npz.*cannot be read"):
        read_smpl_file(trunc)
    for key, bad, field in [
        ("posedirs", np.zeros((N_V, 3, 10)), "posedirs"),
        ("J_regressor", np.zeros((23, N_V)), "J_regressor"),
        ("kintree_table", np.zeros((2, 24), np.uint32), "kintree_table"),
        ("f", np.array([[0, 1, 99]]), "'f'"),
    ]:
        arrays = _model_arrays()
        arrays[key] = bad
        path = tmp_path / f"bad_{key}.npz"
        np.savez(path, **arrays)
        with pytest.raises(InvalidInputError, match=f"bad_{key}.npz.*{field}"):
            read_smpl_file(path)
    arrays = _model_arrays()
    del arrays["weights"]
    path = tmp_path / "no_weights.npz"
    np.savez(path, **arrays)
    with pytest.raises(InvalidInputError, match="no_weights.npz.*missing field.*weights"):
        cb.load_body({"model": "smpl", "path": str(path)})
    evil = tmp_path / "evil.pkl"
    evil.write_bytes(b"cos\nsystem\n(S'echo hacked'\ntR.")
    with pytest.raises(InvalidInputError, match="evil.pkl.*refusing to load os.system"):
        read_smpl_file(evil)
    with pytest.raises(InvalidInputError, match="betas"):
        cb.load_body({"model": "smpl", "path": str(smpl_npz), "betas": [0.0] * 11})
    with pytest.raises(InvalidInputError, match="path"):
        cb.load_body({"model": "smpl"})


def test_sample_bodies_with_smpl_hits_the_sampled_heights(smpl_npz):
    recs = cb.sample_bodies(4, seed=1, smpl_path={"female": str(smpl_npz), "male": str(smpl_npz)}, model="smpl")
    assert [r["model"] for r in recs] == ["smpl"] * 4
    for rec in recs:
        body = cb.load_body(rec)
        assert body.height == pytest.approx(rec["height"], abs=1e-4)
    with pytest.raises(InvalidInputError, match="smpl_path"):
        cb.sample_bodies(2, seed=1, model="smpl")

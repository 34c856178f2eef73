"""SMPL bodies from a user-supplied model file (Loper et al., "SMPL: A Skinned Multi-Person
Linear Model", SIGGRAPH Asia 2015), in numpy, without chumpy or PyTorch.

The model file cannot be shipped; pass its path in the body record:
``{"model": "smpl", "path": ".../SMPL_FEMALE.pkl", "betas": [...]}``. Both distributed
layouts are read: the original ``.pkl`` (Python 2 pickle with chumpy arrays and a scipy
sparse ``J_regressor``, read by a restricted unpickler that turns chumpy arrays into numpy
and refuses every other class) and ``.npz`` conversions. Fields used: ``v_template``
(V, 3), ``shapedirs`` (V, 3, B), ``posedirs`` (V, 3, 207), ``J_regressor`` (24, V),
``weights`` (V, 24), ``kintree_table`` (2, 24), ``f`` (F, 3).

The model (shape, then pose):

    v_shaped = v_template + shapedirs @ betas;   J = J_regressor @ v_shaped
    v_posed  = v_shaped + posedirs @ concat_j(R_j - I), j = 1..23 (row-major 3x3)
    v_world  = sum_j w_j M_j [v_posed, 1]   (linear blend skinning, as in model.py)

Frames: SMPL is Y up and faces +z (its left side at +x); ours is Z up, facing +y, left at
-x. Points are mapped by the proper rotation ``C = [[-1, 0, 0], [0, 0, 1], [0, 1, 0]]``
(180 degrees about (0, 1, 1) / sqrt 2): ``p_ours = C p_smpl``, and joint rotations by
``R_ours = C R_smpl C^T``. The rest frame is then shifted so the pelvis joint is at the
origin. The pose blendshapes are re-expressed for rotations given in our frame.
"""

from __future__ import annotations

import copyreg
import functools
import hashlib
import io
import pickle
import zipfile
from pathlib import Path
from typing import ClassVar

import numpy as np

from crowdstudy.body.model import Body, check_fields
from crowdstudy.body.skeleton import NUM_JOINTS, PARENTS
from crowdstudy.errors import InvalidInputError

__all__ = ["SMPL_TO_OURS", "SmplModel", "read_smpl_file", "load_smpl_body", "smpl_model", "betas_for_height"]

#: Rotation taking SMPL's frame (Y up, facing +z) to ours (Z up, facing +y).
SMPL_TO_OURS = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
_REQUIRED = ("v_template", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table", "f")


class _ChumpyArray:
    """Stand-in for chumpy objects found in SMPL pickles; keeps their state."""

    def __setstate__(self, state):
        self.state = state

    def value(self):
        state = self.state if isinstance(self.state, dict) else {}
        for key in ("x", "a", "r"):
            if key in state:
                val = state[key]
                return val.value() if isinstance(val, _ChumpyArray) else np.asarray(val)
        raise ValueError("a chumpy object without an array value")


class _SparseStub:
    """Stand-in for pickled scipy.sparse matrices (old scipy module paths)."""

    kind: ClassVar[str] = ""  # the scipy class it stands for (set by _stub_for)

    def __init__(self, *args, **kwargs):
        self.__dict__["_args"] = args

    def __setstate__(self, state):
        self.__dict__.update(state)

    def toarray(self, kind: str):
        import scipy.sparse as sp

        d = self.__dict__
        shape = tuple(d.get("_shape", d.get("shape", ())))
        if kind == "csc_matrix":
            return sp.csc_matrix((d["data"], d["indices"], d["indptr"]), shape=shape).toarray()
        if kind == "csr_matrix":
            return sp.csr_matrix((d["data"], d["indices"], d["indptr"]), shape=shape).toarray()
        return sp.coo_matrix((d["data"], (d["row"], d["col"])), shape=shape).toarray()


def _stub_for(kind: str):
    return type(f"_Sparse_{kind}", (_SparseStub,), {"kind": kind})


_SPARSE_STUBS = {k: _stub_for(k) for k in ("csc_matrix", "csr_matrix", "coo_matrix")}


def _multiarray():
    try:
        from numpy._core import multiarray
    except ImportError:  # numpy < 2
        from numpy.core import multiarray
    return multiarray


class _RestrictedUnpickler(pickle.Unpickler):
    """Loads numpy arrays, scipy sparse matrices and chumpy arrays, nothing else."""

    def find_class(self, module: str, name: str):
        if module in ("copy_reg", "copyreg") and name == "_reconstructor":
            return copyreg._reconstructor  # pyright: ignore[reportAttributeAccessIssue]  (private, untyped)
        if module == "_codecs" and name == "encode":  # bytes in protocol-2 pickles
            import codecs

            return codecs.encode
        if module in ("__builtin__", "builtins") and name in ("object", "set", "frozenset", "slice"):
            return {"object": object, "set": set, "frozenset": frozenset, "slice": slice}[name]
        if module.split(".")[0] == "numpy" and name in ("_reconstruct", "ndarray", "dtype", "scalar"):
            if name in ("ndarray", "dtype"):
                return getattr(np, name)
            return getattr(_multiarray(), name)
        if module.startswith("scipy.sparse") and name in _SPARSE_STUBS:
            return _SPARSE_STUBS[name]
        if module.startswith("chumpy"):
            return _ChumpyArray
        raise pickle.UnpicklingError(f"refusing to load {module}.{name}")


def _to_array(value, path: Path, key: str) -> np.ndarray:
    try:
        if isinstance(value, _ChumpyArray):
            return np.asarray(value.value())
        if isinstance(value, _SparseStub):
            return np.asarray(value.toarray(type(value).kind))
        if hasattr(value, "toarray"):
            return np.asarray(value.toarray())
        arr = np.asarray(value)
        if arr.dtype == object and arr.shape == ():
            return _to_array(arr.item(), path, key)
        return arr
    except (ValueError, KeyError, TypeError) as exc:
        raise InvalidInputError(f"SMPL model file {path}: field {key!r} is not an array ({exc})") from None


def read_smpl_file(path) -> dict[str, np.ndarray]:
    """The SMPL fields of a ``.pkl`` or ``.npz`` model file as numpy arrays (SMPL frame).

    Raises InvalidInputError naming the file and the missing or malformed field.
    """
    path = Path(path)
    if not path.is_file():
        raise InvalidInputError(f"SMPL model file {path}: not found (field 'path' of the body record)")
    raw: dict
    try:
        if path.suffix == ".npz" or zipfile.is_zipfile(path):
            with np.load(path, allow_pickle=False) as data:
                raw = {k: data[k] for k in data.files}
        else:
            with open(path, "rb") as fh:
                raw = _RestrictedUnpickler(io.BytesIO(fh.read()), encoding="latin1").load()
    except (
        pickle.UnpicklingError,
        EOFError,
        zipfile.BadZipFile,
        OSError,
        ValueError,
        AttributeError,
        IndexError,
        TypeError,
    ) as exc:
        raise InvalidInputError(
            f"SMPL model file {path}: cannot be read ({type(exc).__name__}: {exc}); expected SMPL's .pkl or .npz"
        ) from None
    if not isinstance(raw, dict):
        raise InvalidInputError(f"SMPL model file {path}: expected a dict of arrays, got {type(raw).__name__}")
    missing = [k for k in _REQUIRED if k not in raw]
    if missing:
        raise InvalidInputError(f"SMPL model file {path}: missing field(s) {', '.join(missing)}")
    arrays = {k: _to_array(raw[k], path, k) for k in _REQUIRED}
    _check_layout(arrays, path)
    return arrays


def _check_layout(a: dict[str, np.ndarray], path: Path) -> None:
    def bad(key: str, expected: str):
        raise InvalidInputError(f"SMPL model file {path}: field {key!r} has shape {a[key].shape}, expected {expected}")

    v = a["v_template"]
    if v.ndim != 2 or v.shape[1] != 3 or len(v) < 4:
        bad("v_template", "(V, 3)")
    n_v = len(v)
    if a["shapedirs"].ndim != 3 or a["shapedirs"].shape[:2] != (n_v, 3):
        bad("shapedirs", f"({n_v}, 3, B)")
    if a["posedirs"].shape != (n_v, 3, (NUM_JOINTS - 1) * 9):
        bad("posedirs", f"({n_v}, 3, {(NUM_JOINTS - 1) * 9})")
    if a["J_regressor"].shape != (NUM_JOINTS, n_v):
        bad("J_regressor", f"({NUM_JOINTS}, {n_v})")
    if a["weights"].shape != (n_v, NUM_JOINTS):
        bad("weights", f"({n_v}, {NUM_JOINTS})")
    if a["kintree_table"].shape != (2, NUM_JOINTS):
        bad("kintree_table", f"(2, {NUM_JOINTS})")
    f = a["f"]
    if f.ndim != 2 or f.shape[1] != 3:
        bad("f", "(F, 3)")
    if f.size and (f.min() < 0 or f.max() >= n_v):
        raise InvalidInputError(f"SMPL model file {path}: field 'f' indexes vertices outside 0..{n_v - 1}")
    parents = a["kintree_table"][0].astype(np.int64)
    parents = np.where((parents < 0) | (parents >= NUM_JOINTS), -1, parents)
    if not np.array_equal(parents, PARENTS):
        raise InvalidInputError(
            f"SMPL model file {path}: field 'kintree_table' is not SMPL's 24-joint tree (parents {parents.tolist()})"
        )
    for key in ("v_template", "shapedirs", "posedirs", "J_regressor", "weights"):
        if not np.all(np.isfinite(a[key])):
            raise InvalidInputError(f"SMPL model file {path}: field {key!r} has non-finite values")


class SmplModel:
    """An SMPL model file's arrays, with the pose blendshapes re-expressed in our frame.

    Attributes:
        path: the model file; key: a short content-dependent id.
        v_template (V, 3), shapedirs (V, 3, B), J_regressor (24, V): SMPL frame, metres.
        weights: (V, 24) float32; faces: (F, 3) int32.
        posedirs_ours: (V * 3, 207) pose blendshapes taking our-frame ``R - I`` features to
            our-frame vertex offsets.
    """

    def __init__(self, path):
        self.path = Path(path)
        a = read_smpl_file(self.path)
        self.key = hashlib.sha1(self.path.read_bytes()).hexdigest()[:12]
        self.v_template = a["v_template"].astype(np.float64)
        self.shapedirs = a["shapedirs"].astype(np.float64)
        self.J_regressor = a["J_regressor"].astype(np.float64)
        w = a["weights"].astype(np.float64)
        sums = w.sum(axis=1, keepdims=True)
        if np.any(sums <= 0):
            raise InvalidInputError(f"SMPL model file {self.path}: field 'weights' has rows summing to 0")
        self.weights = (w / sums).astype(np.float32)
        self.faces = a["f"].astype(np.int32)
        c = SMPL_TO_OURS
        # feature map: vec(C^T A C) = (C^T kron C^T) vec(A) for row-major vec
        kron = np.kron(c.T, c.T)
        pd = a["posedirs"].astype(np.float64).reshape(len(self.v_template), 3, NUM_JOINTS - 1, 9)
        pd = np.einsum("ab,vbjk,kl->vajl", c, pd, kron)
        self.posedirs_ours = pd.reshape(len(self.v_template) * 3, (NUM_JOINTS - 1) * 9)
        self.posedirs_ours.flags.writeable = False

    @property
    def n_betas(self) -> int:
        return self.shapedirs.shape[2]

    def shaped(self, betas) -> tuple[np.ndarray, np.ndarray]:
        """Rest vertices (V, 3) and joints (24, 3) in our frame, relative to the pelvis."""
        b = np.asarray(betas, dtype=np.float64)
        v = self.v_template + self.shapedirs[:, :, : len(b)] @ b
        j = self.J_regressor @ v
        v = (v - j[0]) @ SMPL_TO_OURS.T
        j = (j - j[0]) @ SMPL_TO_OURS.T
        return v, j


@functools.lru_cache(maxsize=8)
def _smpl_model(path: str, mtime: float) -> SmplModel:
    return SmplModel(path)


def smpl_model(path) -> SmplModel:
    """The (cached) :class:`SmplModel` of a model file."""
    p = Path(path).expanduser()
    if not p.is_file():
        raise InvalidInputError(f"SMPL model file {p}: not found")
    return _smpl_model(str(p.resolve()), p.stat().st_mtime)


def betas_for_height(model: SmplModel, height: float, betas) -> np.ndarray:
    """``betas`` with its first component changed so the rest-pose stature is ``height`` m
    (stature is piecewise linear in each beta; a few secant steps converge)."""
    b = np.array(betas, dtype=np.float64).reshape(-1)
    if len(b) == 0:
        b = np.zeros(1)

    def stature(x: float) -> float:
        trial = b.copy()
        trial[0] = x
        v, _ = model.shaped(trial)
        return float(v[:, 2].max() - v[:, 2].min())

    x0, x1 = 0.0, 1.0
    f0, f1 = stature(x0) - height, stature(x1) - height
    for _ in range(8):
        if abs(f1) < 1e-6 or f1 == f0:
            break
        x0, x1 = x1, float(np.clip(x1 - f1 * (x1 - x0) / (f1 - f0), -5.0, 5.0))
        f0, f1 = f1, stature(x1) - height
    b[0] = x1
    return b


def load_smpl_body(record: dict):
    """A ``Body`` from an SMPL record ``{"model": "smpl", "path", "betas" (or "shape")}``."""
    check_fields(record, "smpl", ("model", "path", "betas", "shape", "sex", "height"))
    path = record.get("path")
    if not isinstance(path, str) or not path:
        raise InvalidInputError("body record field 'path': expected the SMPL model file path")
    p = Path(path).expanduser()
    if not p.is_file():
        raise InvalidInputError(f"body record field 'path': SMPL model file {p} not found")
    model = smpl_model(p)
    raw = record.get("betas", record.get("shape", []))
    field = "betas" if "betas" in record else "shape"
    try:
        betas = np.asarray(raw if raw is not None else [], dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise InvalidInputError(f"body record field {field!r}: expected a list of numbers, got {raw!r}") from None
    if len(betas) > model.n_betas:
        raise InvalidInputError(
            f"body record field {field!r}: {len(betas)} values but {p} has {model.n_betas} shape components"
        )
    if not np.all(np.isfinite(betas)):
        raise InvalidInputError(f"body record field {field!r}: values must be finite")
    sex = record.get("sex")
    if sex is not None and sex not in ("female", "male", "neutral"):
        raise InvalidInputError(f"body record field 'sex': expected 'female', 'male' or 'neutral', got {sex!r}")
    verts, joints = model.shaped(betas)
    return Body(
        record=dict(record),
        rest_joints=joints,
        rest_vertices=verts,
        faces=model.faces,
        weights=model.weights,
        pelvis_height=float(-verts[:, 2].min()),
        template_key=f"smpl-{model.key}",
        posedirs=model.posedirs_ours,
    )

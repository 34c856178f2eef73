"""One interface for every body model: ``Body``, a shaped, skinned character (the body
models build it from a record: :mod:`crowdstudy.body.loading`).

Posing (linear blend skinning): with ``G_j``, ``p_j`` the global rotation and position of
joint j from forward kinematics, ``M_j = [[G_j, p_j - G_j rest_j], [0, 1]]`` and
``v_world = sum_j w_j M_j [v_rest, 1]`` (plus SMPL's pose blendshapes on ``v_rest``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from crowdstudy.body.rotations import axis_angle_to_matrix
from crowdstudy.body.skeleton import NUM_JOINTS, forward_kinematics
from crowdstudy.errors import InvalidInputError

__all__ = ["Body", "Surface", "pose_bodies", "skinning_matrices", "check_fields", "META_FIELDS"]


def skinning_matrices(rest_joints: np.ndarray, joint_rotations: np.ndarray, root_translation: np.ndarray) -> np.ndarray:
    """LBS matrices (..., 24, 4, 4): ``M_j = [[G_j, p_j - G_j rest_j], [0, 0, 0, 1]]``.

    Args:
        rest_joints: (..., 24, 3) m; joint_rotations: (..., 24, 3) axis-angle rad (joint 0
        global); root_translation: (..., 3) m, world position of the pelvis.
    """
    glob, pos = forward_kinematics(rest_joints, joint_rotations, root_translation)
    rest = np.asarray(rest_joints, dtype=np.float64)
    out = np.zeros(glob.shape[:-2] + (4, 4))
    out[..., :3, :3] = glob
    out[..., :3, 3] = pos - np.einsum("...jab,...jb->...ja", glob, rest)
    out[..., 3, 3] = 1.0
    return out


@dataclass(frozen=True, eq=False)
class Surface:
    """A render surface split at texture seams (shared by every body of a template).

    Attributes:
        vertex: (R,) int32, the body vertex (row of ``rest_vertices``) of each render vertex.
        uv: (R, 2) float32 texture coordinates, origin bottom-left.
        faces: (F, 3) int32 triangles on render vertices (may include parts that are not in
            the closed ``Body.faces``, e.g. eyeballs).
        part: (R,) int8 material part: 0 skin/clothing texture, 1 eye.
    """

    vertex: np.ndarray
    uv: np.ndarray
    faces: np.ndarray
    part: np.ndarray

    def __post_init__(self):
        r = len(self.vertex)
        if self.uv.shape != (r, 2) or self.part.shape != (r,) or self.faces.ndim != 2 or self.faces.shape[1] != 3:
            raise InvalidInputError(
                f"Surface: inconsistent shapes vertex {self.vertex.shape}, uv {self.uv.shape}, "
                f"part {self.part.shape}, faces {self.faces.shape}"
            )
        for arr in (self.vertex, self.uv, self.faces, self.part):
            arr.flags.writeable = False


@dataclass(eq=False)
class Body:
    """A shaped, skinned character in its rest frame (T-pose facing +y, left side at -x,
    pelvis at the origin).

    Attributes:
        record: the body record it was built from (a copy).
        rest_joints: (24, 3) float64 m, relative to the pelvis.
        rest_vertices: (V, 3) float64 m, same frame.
        faces: (F, 3) int32, a closed (watertight) surface, outward normals.
        weights: (V, 24) float32 skinning weights, rows sum to 1.
        pelvis_height: float m, pelvis z standing in the rest pose with the soles on z = 0.
        template_key: bodies with the same key share ``faces``, vertex count and weights.
        posedirs: (V * 3, 207) float64 pose blendshapes (SMPL) in our frame, or None.
        surface: a UV-split :class:`Surface` for textured rendering, or None (the renderer
            then shades ``faces`` by body region).
    """

    record: dict
    rest_joints: np.ndarray
    rest_vertices: np.ndarray
    faces: np.ndarray
    weights: np.ndarray
    pelvis_height: float
    template_key: str
    posedirs: np.ndarray | None = None
    surface: Surface | None = None
    _cache: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        v = len(self.rest_vertices)
        checks = {
            "rest_joints": (self.rest_joints, (NUM_JOINTS, 3)),
            "rest_vertices": (self.rest_vertices, (v, 3)),
            "weights": (self.weights, (v, NUM_JOINTS)),
        }
        for name, (arr, shape) in checks.items():
            if np.shape(arr) != shape:
                raise InvalidInputError(f"Body.{name}: expected shape {shape}, got {np.shape(arr)}")
        if self.faces.ndim != 2 or self.faces.shape[1] != 3:
            raise InvalidInputError(f"Body.faces: expected shape (F, 3), got {self.faces.shape}")
        if self.posedirs is not None and self.posedirs.shape != (v * 3, (NUM_JOINTS - 1) * 9):
            raise InvalidInputError(
                f"Body.posedirs: expected shape ({v * 3}, {(NUM_JOINTS - 1) * 9}), got {self.posedirs.shape}"
            )
        if self.surface is not None and (
            len(self.surface.vertex) == 0 or int(self.surface.vertex.max()) >= v or int(self.surface.vertex.min()) < 0
        ):
            raise InvalidInputError(f"Body.surface: render vertices must index the {v} rest vertices")
        for arr in (self.rest_joints, self.rest_vertices, self.faces, self.weights):
            arr.flags.writeable = False

    # ------------------------------------------------------------------ derived data
    @property
    def n_vertices(self) -> int:
        return len(self.rest_vertices)

    @property
    def height(self) -> float:
        """Stature in the rest pose, m (top of the head to the soles)."""
        z = self.rest_vertices[:, 2]
        return float(z.max() - z.min())

    def top_weights(self, k: int = 4) -> tuple[np.ndarray, np.ndarray]:
        """The k largest weights per vertex: ``(indices (V, k) int32, values (V, k) float32)``,
        values renormalised to sum to 1 (for GPU skinning)."""
        key = ("top", k)
        if key not in self._cache:
            idx = np.argsort(-self.weights, axis=1, kind="stable")[:, :k].astype(np.int32)
            val = np.take_along_axis(self.weights, idx, axis=1).astype(np.float64)
            val /= val.sum(axis=1, keepdims=True)
            idx.flags.writeable = False
            val = val.astype(np.float32)
            val.flags.writeable = False
            self._cache[key] = (idx, val)
        return self._cache[key]

    @property
    def capsules(self):
        """Capsule proxies (``crowdstudy.body.capsules.Capsules``), fitted on first use (and
        kept in the cache folder: :func:`~crowdstudy.body.capsules.cached_fit_capsules`)."""
        if "capsules" not in self._cache:
            from crowdstudy.body.capsules import cached_fit_capsules

            self._cache["capsules"] = cached_fit_capsules(self)
        return self._cache["capsules"]

    def rest_touching_pairs(self) -> np.ndarray:
        """(P, 2) int32 capsule index pairs (i < j) that touch in the rest pose, every
        parent-child pair included; the physics skips them for intra-body collisions."""
        if "touching" not in self._cache:
            from crowdstudy.body.capsules import touching_pairs

            self._cache["touching"] = touching_pairs(self.capsules)
        return self._cache["touching"]

    def mesh(self):
        """The rest mesh as a ``trimesh.Trimesh`` (no processing)."""
        import trimesh

        return trimesh.Trimesh(np.array(self.rest_vertices), np.array(self.faces), process=False)

    # ------------------------------------------------------------------ posing
    def skinning_matrices(self, joint_rotations: np.ndarray, root_translation: np.ndarray) -> np.ndarray:
        """(..., 24, 4, 4) LBS matrices for ``joint_rotations`` (..., 24, 3) axis-angle rad and
        ``root_translation`` (..., 3) m: ``v_world = sum_j w_j M_j @ [v_rest, 1]``."""
        rot = _check_rotations(joint_rotations)
        root = _check_root(root_translation, rot.shape[:-2])
        return skinning_matrices(self.rest_joints, rot, root)

    def pose(self, joint_rotations: np.ndarray, root_translation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Skinned vertices (..., V, 3) and joint positions (..., 24, 3), metres, world frame.

        Args:
            joint_rotations: (..., 24, 3) axis-angle radians (joint 0 global).
            root_translation: (..., 3) metres, the pelvis.
        """
        rot = _check_rotations(joint_rotations)
        root = _check_root(root_translation, rot.shape[:-2])
        local = axis_angle_to_matrix(rot)
        glob, pos = forward_kinematics(self.rest_joints, local, root, rotations_are_matrices=True)
        mats = np.zeros(glob.shape[:-2] + (3, 4))
        mats[..., :3] = glob
        mats[..., 3] = pos - np.einsum("...jab,...jb->...ja", glob, self.rest_joints)
        rest = self.rest_vertices
        if self.posedirs is not None:
            feat = (local[..., 1:, :, :] - np.eye(3)).reshape(local.shape[:-3] + (-1,))
            rest = rest + (feat @ self.posedirs.T).reshape(feat.shape[:-1] + rest.shape)
        verts = _blend(mats, self.weights, rest)
        return verts, pos


def _blend(mats: np.ndarray, weights: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """sum_j w_vj (A_j v + t_j); mats (..., 24, 3, 4), weights (V, 24), rest (V, 3) or
    (..., V, 3). Works through the batch in chunks (about 64 MB of blended matrices)."""
    batch = mats.shape[:-3]
    n_v = len(weights)
    flat = mats.reshape((-1, NUM_JOINTS * 12))  # (B, 288)
    rest_b = np.broadcast_to(rest, batch + (n_v, 3)).reshape(-1, n_v, 3)
    w = weights.astype(np.float64)
    out = np.empty((len(flat), n_v, 3))
    step = max(1, int(64e6 // (n_v * 12 * 8)))
    for lo in range(0, len(flat), step):
        hi = min(lo + step, len(flat))
        blended = np.matmul(w, flat[lo:hi].reshape(hi - lo, NUM_JOINTS, 12)).reshape(hi - lo, n_v, 3, 4)
        r = rest_b[lo:hi]
        out[lo:hi] = (
            blended[..., 0] * r[..., 0:1]
            + blended[..., 1] * r[..., 1:2]
            + blended[..., 2] * r[..., 2:3]
            + blended[..., 3]
        )
    return out.reshape(batch + (n_v, 3))


def _check_rotations(joint_rotations) -> np.ndarray:
    rot = np.asarray(joint_rotations, dtype=np.float64)
    if rot.ndim < 2 or rot.shape[-2:] != (NUM_JOINTS, 3):
        raise InvalidInputError(f"joint_rotations: expected shape (..., {NUM_JOINTS}, 3) axis-angle, got {rot.shape}")
    return rot


def _check_root(root_translation, batch) -> np.ndarray:
    root = np.asarray(root_translation, dtype=np.float64)
    if root.shape[-1:] != (3,):
        raise InvalidInputError(f"root_translation: expected shape (..., 3), got {root.shape}")
    try:
        np.broadcast_shapes(root.shape[:-1], batch)
    except ValueError:
        raise InvalidInputError(
            f"root_translation: leading shape {root.shape[:-1]} does not match joint_rotations' {batch}"
        ) from None
    return root


def pose_bodies(
    bodies: list[Body], joint_rotations: np.ndarray, root_translation: np.ndarray, *, dtype=np.float32
) -> list[np.ndarray]:
    """Pose N bodies at one frame: a list of (V_i, 3) world vertex arrays.

    Vectorised across the bodies that share a template (``template_key``): forward
    kinematics for all N at once, then one matrix product per template for the blended
    per-vertex transforms. Pose blendshapes (SMPL) are applied per body.

    Args:
        bodies: N bodies.
        joint_rotations: (N, 24, 3) axis-angle radians; root_translation: (N, 3) m.
        dtype: float type of the skinning arithmetic (float32 is what a renderer needs).
    """
    rot = _check_rotations(joint_rotations)
    if rot.ndim != 3 or len(rot) != len(bodies):
        raise InvalidInputError(
            f"joint_rotations: expected shape ({len(bodies)}, 24, 3) for {len(bodies)} bodies, got {rot.shape}"
        )
    root = np.asarray(root_translation, dtype=np.float64)
    if root.shape != (len(bodies), 3):
        raise InvalidInputError(f"root_translation: expected shape ({len(bodies)}, 3), got {root.shape}")
    rest_j = np.stack([b.rest_joints for b in bodies])
    local = axis_angle_to_matrix(rot)
    glob, pos = forward_kinematics(rest_j, local, root, rotations_are_matrices=True)
    mats = np.empty(glob.shape[:-2] + (3, 4))
    mats[..., :3] = glob
    mats[..., 3] = pos - np.einsum("njab,njb->nja", glob, rest_j)
    out: list[np.ndarray | None] = [None] * len(bodies)
    groups: dict[str, list[int]] = {}
    for i, b in enumerate(bodies):
        groups.setdefault(b.template_key, []).append(i)
    for members in groups.values():
        first = bodies[members[0]]
        w = first._cache.get(("w", np.dtype(dtype).str))
        if w is None:
            w = np.ascontiguousarray(first.weights, dtype=dtype)
            first._cache[("w", np.dtype(dtype).str)] = w
        m = mats[members].astype(dtype).reshape(len(members), NUM_JOINTS, 12)
        blended = np.matmul(w, m).reshape(len(members), len(w), 3, 4)  # (n, V, 3, 4)
        for k, i in enumerate(members):
            b = bodies[i]
            rest = b.rest_vertices
            if b.posedirs is not None:
                feat = (local[i, 1:] - np.eye(3)).ravel()
                rest = rest + (b.posedirs @ feat).reshape(rest.shape)
            rest = rest.astype(dtype, copy=False)
            a = blended[k]
            out[i] = a[:, :, 0] * rest[:, 0:1] + a[:, :, 1] * rest[:, 1:2] + a[:, :, 2] * rest[:, 2:3] + a[:, :, 3]
    return out  # type: ignore[return-value]


#: Record fields any model accepts and ignores (labels for people and renderers).
META_FIELDS = ("name", "id", "seed", "label", "color", "colour")


def check_fields(record: dict, model: str, fields: tuple[str, ...]) -> None:
    """Raise InvalidInputError naming the fields of ``record`` that ``model`` does not know."""
    unknown = set(record) - set(fields) - set(META_FIELDS)
    if unknown:
        raise InvalidInputError(
            f"body record: unknown field(s) {', '.join(sorted(unknown))} for model {model!r} "
            f"(expected {', '.join(fields)})"
        )

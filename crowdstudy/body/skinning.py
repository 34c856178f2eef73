"""Posing and skinning a whole crowd per frame with Warp kernels (CPU or CUDA).

``CrowdSkinner(bodies)`` uploads the rest meshes and the 4 largest skinning weights of N
bodies once; ``pose(joint_rotations, root_translation)`` then runs forward kinematics (one
thread per body) and linear blend skinning (one thread per vertex) and returns all
vertices in one buffer, body i at ``vertices[offsets[i]:offsets[i + 1]]``. SMPL's pose
blendshapes are not applied here (use ``Body.pose`` for them); everything else matches
``Body.pose`` to float32 precision.
"""

from __future__ import annotations

import numpy as np

from crowdstudy.body.skeleton import NUM_JOINTS, PARENTS
from crowdstudy.errors import InvalidInputError

__all__ = ["CrowdSkinner"]

_KERNELS = None


def _kernels():
    global _KERNELS
    if _KERNELS is not None:
        return _KERNELS
    from crowdstudy.warp_runtime import get_warp

    wp = get_warp()

    @wp.kernel
    def forward_kinematics_kernel(rotvec: wp.array2d(dtype=wp.vec3), root: wp.array(dtype=wp.vec3),
                                  rest: wp.array2d(dtype=wp.vec3), parents: wp.array(dtype=wp.int32),
                                  glob: wp.array2d(dtype=wp.mat33), pos: wp.array2d(dtype=wp.vec3),
                                  skin_rot: wp.array2d(dtype=wp.mat33),
                                  skin_trans: wp.array2d(dtype=wp.vec3)):
        n = wp.tid()
        for j in range(parents.shape[0]):
            rv = rotvec[n, j]
            angle = wp.length(rv)
            local = wp.identity(n=3, dtype=wp.float32)
            if angle > 1.0e-8:
                local = wp.quat_to_matrix(wp.quat_from_axis_angle(rv / angle, angle))
            p = parents[j]
            g = local
            x = root[n]
            if p >= 0:
                g = glob[n, p] * local
                x = pos[n, p] + glob[n, p] * (rest[n, j] - rest[n, p])
            glob[n, j] = g
            pos[n, j] = x
            skin_rot[n, j] = g
            skin_trans[n, j] = x - g * rest[n, j]

    @wp.kernel
    def skin_kernel(rest: wp.array(dtype=wp.vec3), body: wp.array(dtype=wp.int32),
                    idx: wp.array2d(dtype=wp.int32), w: wp.array2d(dtype=wp.float32),
                    skin_rot: wp.array2d(dtype=wp.mat33), skin_trans: wp.array2d(dtype=wp.vec3),
                    out: wp.array(dtype=wp.vec3)):
        v = wp.tid()
        b = body[v]
        p = rest[v]
        acc = wp.vec3(0.0, 0.0, 0.0)
        for k in range(4):
            wk = w[v, k]
            if wk > 0.0:  # the open model has about 2 influences per vertex
                j = idx[v, k]
                acc += wk * (skin_rot[b, j] * p + skin_trans[b, j])
        out[v] = acc

    _KERNELS = (wp, forward_kinematics_kernel, skin_kernel)
    return _KERNELS


class CrowdSkinner:
    """Batched posing of N bodies on one Warp device.

    Args:
        bodies: N ``Body`` objects (any mix of templates).
        device: Warp device ("cpu", "cuda:0"; None picks CUDA when present).

    Attributes:
        offsets: (N + 1,) int64, body i's vertices are ``offsets[i]:offsets[i + 1]``.
        faces: (F_total, 3) int32 faces indexing the concatenated vertex buffer.
    """

    def __init__(self, bodies, device: str | None = None):
        from crowdstudy.warp_runtime import resolve_device

        if len(bodies) == 0:
            raise InvalidInputError("bodies: expected at least one Body")
        wp, self._fk, self._skin = _kernels()
        self._wp = wp
        self.device = resolve_device(device)
        self.n = len(bodies)
        counts = np.array([b.n_vertices for b in bodies], dtype=np.int64)
        self.offsets = np.r_[0, np.cumsum(counts)]
        rest = np.concatenate([b.rest_vertices for b in bodies]).astype(np.float32)
        body_of = np.repeat(np.arange(self.n, dtype=np.int32), counts)
        tops = [b.top_weights(4) for b in bodies]
        idx = np.concatenate([t[0] for t in tops]).astype(np.int32)
        w = np.concatenate([t[1] for t in tops]).astype(np.float32)
        self.faces = np.concatenate([np.asarray(b.faces, dtype=np.int64) + o
                                     for b, o in zip(bodies, self.offsets[:-1])]).astype(np.int32)
        rest_j = np.stack([b.rest_joints for b in bodies]).astype(np.float32)
        dev = self.device
        self._rest = wp.array(rest, dtype=wp.vec3, device=dev)
        self._body = wp.array(body_of, dtype=wp.int32, device=dev)
        self._idx = wp.array(idx, dtype=wp.int32, device=dev)
        self._w = wp.array(w, dtype=wp.float32, device=dev)
        self._rest_j = wp.array(rest_j, dtype=wp.vec3, device=dev)
        self._parents = wp.array(PARENTS.astype(np.int32), dtype=wp.int32, device=dev)
        shape = (self.n, NUM_JOINTS)
        self._glob = wp.zeros(shape, dtype=wp.mat33, device=dev)
        self._pos = wp.zeros(shape, dtype=wp.vec3, device=dev)
        self._skin_rot = wp.zeros(shape, dtype=wp.mat33, device=dev)
        self._skin_trans = wp.zeros(shape, dtype=wp.vec3, device=dev)
        self._out = wp.zeros(len(rest), dtype=wp.vec3, device=dev)
        self._rotvec = wp.zeros(shape, dtype=wp.vec3, device=dev)
        self._root = wp.zeros(self.n, dtype=wp.vec3, device=dev)

    @property
    def n_vertices(self) -> int:
        return int(self.offsets[-1])

    def pose_device(self, joint_rotations, root_translation):
        """Run the kernels; returns the device arrays ``(vertices (sum V,) vec3,
        joints (N, 24) vec3)`` without copying them back (for a renderer on the GPU)."""
        wp = self._wp
        rot = np.asarray(joint_rotations, dtype=np.float32)
        root = np.asarray(root_translation, dtype=np.float32)
        if rot.shape != (self.n, NUM_JOINTS, 3):
            raise InvalidInputError(
                f"joint_rotations: expected shape ({self.n}, {NUM_JOINTS}, 3) axis-angle, got {rot.shape}")
        if root.shape != (self.n, 3):
            raise InvalidInputError(f"root_translation: expected shape ({self.n}, 3), got {root.shape}")
        self._rotvec.assign(rot)
        self._root.assign(root)
        wp.launch(self._fk, dim=self.n, device=self.device,
                  inputs=[self._rotvec, self._root, self._rest_j, self._parents,
                          self._glob, self._pos, self._skin_rot, self._skin_trans])
        wp.launch(self._skin, dim=self.n_vertices, device=self.device,
                  inputs=[self._rest, self._body, self._idx, self._w, self._skin_rot,
                          self._skin_trans, self._out])
        return self._out, self._pos

    def pose(self, joint_rotations, root_translation) -> tuple[np.ndarray, np.ndarray]:
        """Posed vertices ``(sum V, 3)`` float32 m and joints ``(N, 24, 3)`` float32 m.

        Args:
            joint_rotations: (N, 24, 3) axis-angle radians (joint 0 global).
            root_translation: (N, 3) metres.
        """
        verts, joints = self.pose_device(joint_rotations, root_translation)
        return verts.numpy().reshape(-1, 3), joints.numpy().reshape(self.n, NUM_JOINTS, 3)

"""Posing and skinning a whole crowd per frame with Warp kernels (CPU or CUDA).

``CrowdSkinner(bodies)`` uploads the rest meshes and the 4 largest skinning weights of N
bodies once; ``pose(joint_rotations, root_translation)`` then runs forward kinematics (one
thread per body) and linear blend skinning, and returns all vertices in one buffer, body i
at ``vertices[offsets[i]:offsets[i + 1]]``. SMPL's pose blendshapes are not applied here
(use ``Body.pose`` for them); everything else matches ``Body.pose`` to float32 precision.

Layout (built once in the constructor). Bodies that share a template (``template_key``
and identical weights) share one copy of the weight data. Within a template the vertices
are sorted by their set of influencing joints (the open model has about 60 distinct sets
of 1 to 4 joints, about 2 influences per vertex on average); a *segment* is the run of one
body's vertices that share one joint set. Skinning then needs no per-vertex joint indices
and no data-dependent branches:

* CPU (``schedule="segments"``): one kernel thread per segment keeps its 1-4 joint
  transforms in registers and streams the segment's rest positions and weights, writing
  each result to its original place in the output. The segments are split into
  chunks of about equal vertex count; with ``threads > 1`` that many workers pull the chunks
  concurrently (Warp's CPU launches release the GIL; each launch is single-threaded).
* CUDA (``schedule="vertices"``): one thread per vertex looks up its segment.

Both schedules compute the same expression ``sum_k w_k (R_jk p + t_jk)`` in float32.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from crowdstudy.body.skeleton import NUM_JOINTS, PARENTS
from crowdstudy.errors import InvalidInputError

__all__ = ["CrowdSkinner"]

#: The segment table, int32 rows: body, first vertex in the sorted rest buffer,
#: first weight row, vertex count, number of joints nk, the body's output offset,
#: joints j0..j3 (unused slots 0). The kernels read these columns by position.
_SEG_COLUMNS = 10
_SEG_COUNT = 3
_MAX_INFLUENCES = 4
#: CPU launches per thread: the workers pull these from a shared queue.
_CHUNKS_PER_THREAD = 4


def _drain(launches) -> None:
    """Run recorded launches from a shared iterator until it is exhausted (the iterator's
    ``next`` runs under the GIL, so each launch runs once; the launch itself releases it)."""
    for cmd in launches:
        cmd.launch()


def _template_groups(bodies) -> tuple[list[int], list]:
    """Template index per body and one representative body per template (same
    ``template_key`` and identical weights)."""
    reps: list = []
    keys: list[str] = []
    of = []
    for b in bodies:
        for t, (key, rep) in enumerate(zip(keys, reps, strict=True)):
            if key == b.template_key and (rep.weights is b.weights or np.array_equal(rep.weights, b.weights)):
                of.append(t)
                break
        else:
            of.append(len(reps))
            reps.append(b)
            keys.append(b.template_key)
    return of, reps


def _sorted_template(body) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int, int, tuple]]]:
    """Vertex order grouping equal joint sets: ``(perm (V,) int32 original index per sorted
    slot, weights (V, 4) float32 in sorted order (joint slots ascending), runs [(start,
    count, nk, joints)])``."""
    idx, val = body.top_weights(_MAX_INFLUENCES)
    idx = np.asarray(idx, dtype=np.int64)
    val = np.asarray(val, dtype=np.float32)
    live = val > 0.0
    nk = live.sum(axis=1)
    if np.any(nk == 0):
        raise InvalidInputError("Body.weights: every vertex needs a positive weight")
    # joints ascending, unused slots last (keyed 24); weights follow their joint
    keyed = np.where(live, idx, NUM_JOINTS)
    order_k = np.argsort(keyed, axis=1, kind="stable")
    joints = np.take_along_axis(keyed, order_k, axis=1)
    weights = np.take_along_axis(np.where(live, val, 0.0).astype(np.float32), order_k, axis=1)
    perm = np.lexsort((np.arange(len(idx)), joints[:, 3], joints[:, 2], joints[:, 1], joints[:, 0], nk))
    joints, weights, nk = joints[perm], weights[perm], nk[perm]
    change = np.r_[True, np.any(joints[1:] != joints[:-1], axis=1)]
    starts = np.flatnonzero(change)
    ends = np.r_[starts[1:], len(perm)]
    runs = [
        (int(s), int(e - s), int(nk[s]), tuple(int(j) if j < NUM_JOINTS else 0 for j in joints[s]))
        for s, e in zip(starts, ends, strict=True)
    ]
    return perm.astype(np.int32), np.ascontiguousarray(weights), runs


class CrowdSkinner:
    """Batched posing of N bodies on one Warp device.

    Args:
        bodies: N ``Body`` objects (any mix of templates).
        device: Warp device ("cpu", "cuda:0"; None picks CUDA when present).
        threads: concurrent CPU launches (default 1). 2 about halves the time on an idle
            multi-core machine; on a loaded one the second thread waits for a core and the
            median gets worse, hence the default. Ignored on CUDA.
        schedule: "segments" (one thread per run of vertices; the CPU default) or
            "vertices" (one thread per vertex; the CUDA default). Both give the same result.

    Attributes:
        offsets: (N + 1,) int64, body i's vertices are ``offsets[i]:offsets[i + 1]``.
        faces: (F_total, 3) int32 faces indexing the concatenated vertex buffer.
    """

    def __init__(self, bodies, device: str | None = None, *, threads: int = 1, schedule: str | None = None):
        from crowdstudy.body import skinning_kernels as kernels
        from crowdstudy.warp_runtime import get_warp, resolve_device

        if len(bodies) == 0:
            raise InvalidInputError("bodies: expected at least one Body")
        wp = get_warp()
        self.device = resolve_device(device)
        is_cuda = wp.get_device(self.device).is_cuda
        if schedule is None:
            schedule = "vertices" if is_cuda else "segments"
        if schedule not in ("segments", "vertices"):
            raise InvalidInputError(f"schedule: expected 'segments' or 'vertices', got {schedule!r}")
        if not isinstance(threads, (int, np.integer)) or threads < 1:
            raise InvalidInputError(f"threads: expected a positive integer, got {threads!r}")
        self.schedule = schedule
        self.n = len(bodies)
        counts = np.array([b.n_vertices for b in bodies], dtype=np.int64)
        self.offsets = np.r_[0, np.cumsum(counts)]
        self.faces = np.concatenate(
            [np.asarray(b.faces, dtype=np.int64) + o for b, o in zip(bodies, self.offsets[:-1], strict=True)]
        ).astype(np.int32)

        # per template: sorted order, weights, runs; per body: segments over its rest copy
        template_of, reps = _template_groups(bodies)
        sorted_templates = [_sorted_template(rep) for rep in reps]
        weight_start = np.r_[0, np.cumsum([len(t[0]) for t in sorted_templates])]
        perm = np.concatenate([t[0] for t in sorted_templates])
        weights = np.concatenate([t[1] for t in sorted_templates])
        rest_sorted = np.empty((int(self.offsets[-1]), 3), dtype=np.float32)
        rows = []
        for i, b in enumerate(bodies):
            t = template_of[i]
            t_perm, _, runs = sorted_templates[t]
            base = int(self.offsets[i])
            rest_sorted[base : base + len(t_perm)] = b.rest_vertices[t_perm]
            for start, count, nk, joints in runs:
                rows.append((i, base + start, int(weight_start[t]) + start, count, nk, base, *joints))
        seg = np.array(rows, dtype=np.int32).reshape(-1, _SEG_COLUMNS)
        self.n_segments = len(seg)

        dev = self.device
        self._seg = wp.array(seg, dtype=wp.int32, device=dev)
        self._rest = wp.array(rest_sorted, dtype=wp.vec3, device=dev)
        self._weights = wp.array(weights, dtype=wp.float32, device=dev)
        self._perm = wp.array(perm, dtype=wp.int32, device=dev)
        self._rest_j = wp.array(np.stack([b.rest_joints for b in bodies]).astype(np.float32), dtype=wp.vec3, device=dev)
        self._parents = wp.array(PARENTS.astype(np.int32), dtype=wp.int32, device=dev)
        shape = (self.n, NUM_JOINTS)
        self._glob = wp.zeros(shape, dtype=wp.mat33, device=dev)
        self._pos = wp.zeros(shape, dtype=wp.vec3, device=dev)
        self._skin_trans = wp.zeros(shape, dtype=wp.vec3, device=dev)
        self._out = wp.zeros(self.n_vertices, dtype=wp.vec3, device=dev)
        self._rotvec = wp.zeros(shape, dtype=wp.vec3, device=dev)
        self._root = wp.zeros(self.n, dtype=wp.vec3, device=dev)

        # recorded launches (no per-frame argument packing)
        self._fk_cmd = wp.launch(
            kernels.forward_kinematics,
            dim=self.n,
            device=dev,
            record_cmd=True,
            inputs=[self._rotvec, self._root, self._rest_j, self._parents, self._glob, self._pos, self._skin_trans],
        )
        skin_args = [self._rest, self._weights, self._perm, self._glob, self._skin_trans, self._out]
        if schedule == "vertices":
            seg_of = np.repeat(np.arange(len(seg), dtype=np.int32), seg[:, _SEG_COUNT])
            self._seg_of = wp.array(seg_of, dtype=wp.int32, device=dev)
            self._skin_cmds = [
                wp.launch(
                    kernels.skin_vertices,
                    dim=self.n_vertices,
                    device=dev,
                    record_cmd=True,
                    inputs=[self._seg, self._seg_of, *skin_args],
                )
            ]
        else:
            n_parts = 1 if is_cuda or threads == 1 else _CHUNKS_PER_THREAD * int(threads)
            parts = self._split(seg[:, _SEG_COUNT], n_parts)
            self._seg_parts = [self._seg[lo:hi] for lo, hi in parts]
            self._skin_cmds = [
                wp.launch(kernels.skin_segments, dim=len(part), device=dev, record_cmd=True, inputs=[part, *skin_args])
                for part in self._seg_parts
            ]
        self.threads = 1 if len(self._skin_cmds) == 1 else int(threads)
        self._pool = ThreadPoolExecutor(self.threads - 1) if self.threads > 1 else None

    @staticmethod
    def _split(seg_counts: np.ndarray, parts: int) -> list[tuple[int, int]]:
        """Contiguous segment ranges of about equal vertex count."""
        cum = np.cumsum(seg_counts)
        cuts = [0] + [int(np.searchsorted(cum, cum[-1] * k / parts)) + 1 for k in range(1, parts)] + [len(cum)]
        cuts = sorted(set(min(max(c, 0), len(cum)) for c in cuts))
        return [(lo, hi) for lo, hi in zip(cuts[:-1], cuts[1:], strict=True) if hi > lo]

    @property
    def n_vertices(self) -> int:
        return int(self.offsets[-1])

    def pose_device(self, joint_rotations, root_translation):
        """Run the kernels; returns the device arrays ``(vertices (sum V,) vec3,
        joints (N, 24) vec3)`` without copying them back (for a renderer on the GPU). They
        are the skinner's own buffers, overwritten by the next call."""
        rot = np.asarray(joint_rotations, dtype=np.float32)
        root = np.asarray(root_translation, dtype=np.float32)
        if rot.shape != (self.n, NUM_JOINTS, 3):
            raise InvalidInputError(
                f"joint_rotations: expected shape ({self.n}, {NUM_JOINTS}, 3) axis-angle, got {rot.shape}"
            )
        if root.shape != (self.n, 3):
            raise InvalidInputError(f"root_translation: expected shape ({self.n}, 3), got {root.shape}")
        self._rotvec.assign(rot)
        self._root.assign(root)
        # a recorded launch (record_cmd=True) is never None; Warp's stub types the result
        # of wp.launch as optional either way
        self._fk_cmd.launch()  # pyright: ignore[reportOptionalMemberAccess]
        if self._pool is None:
            for cmd in self._skin_cmds:
                cmd.launch()  # pyright: ignore[reportOptionalMemberAccess]
        else:
            # the workers pull chunks until none is left, so a worker that the OS
            # schedules late does not hold the others up
            queue = iter(self._skin_cmds)
            futures = [self._pool.submit(_drain, queue) for _ in range(self.threads - 1)]
            _drain(queue)
            for f in futures:
                f.result()
        return self._out, self._pos

    def pose(self, joint_rotations, root_translation, *, copy: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Posed vertices ``(sum V, 3)`` float32 m and joints ``(N, 24, 3)`` float32 m.

        Args:
            joint_rotations: (N, 24, 3) axis-angle radians (joint 0 global).
            root_translation: (N, 3) metres.
            copy: return arrays of their own. Without it, on the CPU the arrays are views
                of the skinner's buffers (no copy), overwritten by the next call.
        """
        verts, joints = self.pose_device(joint_rotations, root_translation)
        verts = verts.numpy().reshape(-1, 3)
        joints = joints.numpy().reshape(self.n, NUM_JOINTS, 3)
        if copy:
            verts, joints = verts.copy(), joints.copy()
        return verts, joints

"""Simulation state (rigid bodies) and control (the animation's target pose for a step)."""

from __future__ import annotations

import numpy as np

from crowdstudy.body.rotations import axis_angle_to_quaternion
from crowdstudy.errors import InvalidInputError
from crowdstudy.warp_runtime import get_warp, host_threads, run_parallel

__all__ = ["State", "Control"]

#: from this many characters on, the CPU computes the current and the look-ahead targets on
#: two host threads at once (below, the hand-over costs more than the second launch)
_MIN_CHARACTERS_PARALLEL = 200


class State:
    """Rigid state of all B bodies on the model's device.

    Attributes (Warp arrays, length B): ``x`` vec3 centre of mass (m), ``q`` quat world
    orientation (rest frame = identity), ``v`` vec3 linear velocity (m/s), ``w`` vec3
    angular velocity (rad/s, world frame).
    """

    def __init__(self, model):
        wp = get_warp()
        nb, dev = model.n_bodies, model.device
        self.x = wp.zeros(nb, dtype=wp.vec3, device=dev)
        self.q = wp.array(np.tile(np.array([0, 0, 0, 1], np.float32), (nb, 1)), dtype=wp.quat, device=dev)
        self.v = wp.zeros(nb, dtype=wp.vec3, device=dev)
        self.w = wp.zeros(nb, dtype=wp.vec3, device=dev)

    def numpy(self) -> dict:
        """Host copies: x (B, 3), q (B, 4), v (B, 3), w (B, 3)."""
        return {name: getattr(self, name).numpy().copy() for name in ("x", "q", "v", "w")}


#: joint rotations converted and uploaded per block by :meth:`Control.set_frames`
_UPLOAD_ROTATIONS = 1 << 16


class Control:
    """The animation's target for the current step and the previous one (Eq. 4 needs both).

    ``frames`` holds F animation frames on the device: ``anim_q`` (F, B) joint rotations as
    quaternions (root global, others parent-relative) and ``anim_root`` (F, N) pelvis
    positions (m). :meth:`advance` moves the current target to "old" and computes the new one
    at ``(1 - alpha) * frame f0 + alpha * frame f1`` (nlerp of rotations, lerp of the root):
    ``t_rel`` (B,) quat, ``t_glob`` (B,) quat world rotations, ``t_x`` (B,) vec3 centres of
    mass; ``t_rel_old``, ``t_glob_old`` and ``t_x_old`` the previous step's, and
    ``t_glob_older``, ``t_x_older`` the one before (the solver's feed-forward prediction
    continues the animation's own motion: its velocity change over the last two steps).
    With ``ahead_frames`` > 0 :meth:`advance` also computes the target that many frames
    later (clamped to the last uploaded frame): ``t_glob_ahead``, ``t_x_ahead`` (the
    contacts' look-ahead, ``PhysicsConfig.contacts.pass_ahead``).
    """

    def __init__(self, model, n_frames: int = 2):
        self.model = model
        wp = get_warp()
        nb, n, dev = model.n_bodies, model.n_characters, model.device
        self.anim_q = wp.zeros((n_frames, nb), dtype=wp.quat, device=dev)
        self.anim_root = wp.zeros((n_frames, n), dtype=wp.vec3, device=dev)
        self.t_rel = wp.zeros(nb, dtype=wp.quat, device=dev)
        self.t_glob = wp.zeros(nb, dtype=wp.quat, device=dev)
        self.t_x = wp.zeros(nb, dtype=wp.vec3, device=dev)
        self.t_rel_old = wp.zeros(nb, dtype=wp.quat, device=dev)
        self.t_glob_old = wp.zeros(nb, dtype=wp.quat, device=dev)
        self.t_x_old = wp.zeros(nb, dtype=wp.vec3, device=dev)
        self.t_glob_older = wp.zeros(nb, dtype=wp.quat, device=dev)
        self.t_x_older = wp.zeros(nb, dtype=wp.vec3, device=dev)
        self.ahead_frames = 0.0
        self.t_rel_ahead = wp.zeros(nb, dtype=wp.quat, device=dev)
        self.t_glob_ahead = wp.zeros(nb, dtype=wp.quat, device=dev)
        self.t_x_ahead = wp.zeros(nb, dtype=wp.vec3, device=dev)

    def set_frames(
        self,
        joint_rotations: np.ndarray,
        root_translation: np.ndarray,
        start: int = 0,
        frames: np.ndarray | None = None,
    ) -> None:
        """Upload frames: joint_rotations (F, N, J, 3) axis-angle rad, root_translation (F, N, 3) m,
        into the slots from ``start``. ``frames``: which of the F frames to upload, in slot
        order (an integer index; None: all of them): a looped clip's schedule is gathered a
        few frames at a time, never copied whole."""
        m = self.model
        rot = np.asarray(joint_rotations, np.float64)
        root = np.asarray(root_translation, np.float64)
        if rot.ndim == 3:
            rot, root = rot[None], root[None]
        if rot.shape[1:] != (m.n_characters, m.n_joints, 3) or root.shape != (rot.shape[0], m.n_characters, 3):
            raise InvalidInputError(
                f"joint_rotations/root_translation: expected (F, {m.n_characters}, {m.n_joints}, 3)"
                f" and (F, {m.n_characters}, 3), got {rot.shape} and {root.shape}"
            )
        if frames is None:
            frames = np.arange(rot.shape[0])
        frames = np.asarray(frames)
        if (
            frames.ndim != 1
            or frames.dtype.kind not in "iu"
            or (len(frames) and (frames.min() < 0 or frames.max() >= rot.shape[0]))
        ):
            raise InvalidInputError(
                f"frames: expected a 1-D integer index into the {rot.shape[0]} frames given, got {frames!r}"
            )
        f = len(frames)
        if start < 0 or start + f > self.anim_q.shape[0]:
            raise InvalidInputError(f"start: frames [{start}, {start + f}) do not fit the {self.anim_q.shape[0]} slots")
        wp = get_warp()
        # a few frames at a time: no float64 quaternion copy of the whole clip
        step = max(1, _UPLOAD_ROTATIONS // max(1, m.n_bodies))
        for f0 in range(0, f, step):
            f1 = min(f, f0 + step)
            quats = axis_angle_to_quaternion(rot[frames[f0:f1]]).reshape(f1 - f0, -1, 4).astype(np.float32)
            self.anim_q[start + f0 : start + f1].assign(wp.array(quats, dtype=wp.quat, device=m.device))
        self.anim_root[start : start + f].assign(
            wp.array(root[frames].astype(np.float32), dtype=wp.vec3, device=m.device)
        )

    def advance(self, f0: int, f1: int, alpha: float) -> None:
        """Shift the targets (current -> old -> older) and compute the target between frames
        f0 and f1."""
        from crowdstudy.physics.kernels import targets_kernel

        self.t_rel, self.t_rel_old = self.t_rel_old, self.t_rel
        self.t_glob, self.t_glob_old, self.t_glob_older = self.t_glob_older, self.t_glob, self.t_glob_old
        self.t_x, self.t_x_old, self.t_x_older = self.t_x_older, self.t_x, self.t_x_old
        m = self.model
        wp = get_warp()
        args = [m.n_joints, m.wp["body_parent"], m.wp["anchor_parent"], m.wp["anchor_child"]]

        def current() -> None:
            wp.launch(
                targets_kernel,
                m.n_characters,
                [self.anim_q, self.anim_root, int(f0), int(f1), float(alpha), *args, self.t_rel, self.t_glob, self.t_x],
                device=m.device,
            )

        def ahead() -> None:
            last = self.anim_q.shape[0] - 1
            at = min(f0 + alpha * (f1 - f0) + self.ahead_frames, float(last))
            g0 = int(np.floor(at))
            g1 = min(g0 + 1, last)
            wp.launch(
                targets_kernel,
                m.n_characters,
                [
                    self.anim_q,
                    self.anim_root,
                    g0,
                    g1,
                    float(at - g0),
                    *args,
                    self.t_rel_ahead,
                    self.t_glob_ahead,
                    self.t_x_ahead,
                ],
                device=m.device,
            )

        if self.ahead_frames <= 0:
            current()
        elif m.device == "cpu" and m.n_characters >= _MIN_CHARACTERS_PARALLEL and host_threads() >= 2:
            run_parallel(current, ahead)  # disjoint outputs: the same bits either way
        else:
            current()
            ahead()

    def hold(self) -> None:
        """Make the previous targets equal to the current one (no animation velocity)."""
        self.t_rel_old.assign(self.t_rel)
        for old in (self.t_glob_old, self.t_glob_older):
            old.assign(self.t_glob)
        for old in (self.t_x_old, self.t_x_older):
            old.assign(self.t_x)

"""The MuJoCo peer of the correction: the same characters, contacts and targets as Ours, in
MuJoCo (an optional extra: ``pip install 'crowdstudy[peers]'``).

The model is built from the SAME crowdstudy Model as Ours (ModelBuilder +
PhysicsConfig.mesh_skin):

* per bone two capsules on the same segment: a "core" of the bare radius (density ->
  the same masses and inertias; ground contacts and self contacts, like ours) and a
  "hull" of radius + mesh skin with geom margin = contact_margin (inter-body and wall
  contacts, like ours). A MuJoCo contact of two geoms is active below
  max(margin1, margin2) = contact_margin, the distance the constraint holds: exactly our
  depth r_a + skin_a + r_b + skin_b + margin - distance (the margin counted once per pair;
  inflating both radii by the margin would count it twice, and walls once).
* contype/conaffinity: hull 1/1, core 2/0, ground plane 0/2 (cores only), walls 0/1
  (hulls only); every body pair of one character is <exclude>d from the dynamic pairs, and
  the self contacts are explicit <pair>s of core geoms, exactly Model.intra_pairs (not
  parent-child, not touching in the T-pose).
* targets: each bone is welded (soft equality) to a mocap body placed at every MuJoCo step
  at the same interpolated target as ours (nlerp of the joint rotations and lerp of the
  root between two frames, then forward kinematics: targets_kernel).
* settle: config.solver.settle_time simulated on frame 0, targets frozen, before frame 0 is read.
* walls: crowdstudy.scene_meta.static_walls_from_meta, as boxes WALL_DEPTH deep behind
  the wall's face (ours: one-sided planes facing the characters' roots); in periodic
  scenes (the corridor) the walls are stretched over the whole run and every character has
  two kinematic images at +-L (mocap bodies with its hulls, moved to the simulated pose
  every step): MuJoCo has no periodic boundary, the images stand in for our minimum image.
* output: the joint rotations R_parent^T R_child (root global) and the pelvis joint
  position, by :func:`rigid_to_animation`, the numpy twin of project_kernel.

How MuJoCo holds the welds and contacts is a tuning (:class:`MujocoSettings`); the ones
compared with Ours are :data:`MUJOCO_SETTINGS`.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from crowdstudy.errors import InvalidInputError, MissingDependencyError
from crowdstudy.physics.crowding import crowd_config

__all__ = [
    "MujocoSettings",
    "MUJOCO_SETTINGS",
    "WALL_DEPTH",
    "import_mujoco",
    "resolve_setting",
    "check_timeconsts",
    "interpolated_targets",
    "rigid_to_animation",
    "MujocoScene",
    "mujoco_peer",
]

#: m, how deep MuJoCo's wall boxes reach behind the wall's face (away from the crowd)
WALL_DEPTH = 0.5


@dataclass(frozen=True)
class MujocoSettings:
    """One MuJoCo tuning of the peer."""

    #: MuJoCo steps per frame of the animation (the step is 1 / (fps * substeps) s)
    substeps: int
    #: solref (time constant s, damping ratio) of the welds that pull each bone to its target
    weld_solref: tuple[float, float]
    #: solref (time constant s, damping ratio) of the contacts
    contact_solref: tuple[float, float]
    #: solimp (d0, dwidth, width m) of the welds and the contacts
    solimp: tuple[float, float, float]
    #: damping of the ball joints, N m s/rad
    joint_damping: float


#: the tunings compared with Ours, by name
MUJOCO_SETTINGS: dict[str, MujocoSettings] = {
    "weld0.05": MujocoSettings(
        substeps=2, weld_solref=(0.05, 1.0), contact_solref=(0.0334, 1.0), solimp=(0.9, 0.95, 0.001), joint_damping=1.0
    ),
    "weld0.1-stiffcontact": MujocoSettings(
        substeps=2, weld_solref=(0.1, 1.0), contact_solref=(0.0334, 1.0), solimp=(0.95, 0.99, 0.001), joint_damping=1.0
    ),
    "weld0.05-dt1/120": MujocoSettings(
        substeps=4, weld_solref=(0.05, 1.0), contact_solref=(0.0167, 1.0), solimp=(0.95, 0.99, 0.001), joint_damping=1.0
    ),
    # stiffer welds (MuJoCo clamps a timeconst below 2 steps, so this needs the 1/120 s step)
    "weld0.025-dt1/120": MujocoSettings(
        substeps=4,
        weld_solref=(0.025, 1.0),
        contact_solref=(0.0167, 1.0),
        solimp=(0.95, 0.99, 0.001),
        joint_damping=1.0,
    ),
}


def import_mujoco() -> Any:
    """The ``mujoco`` module, or a MissingDependencyError saying how to install it."""
    try:
        import mujoco
    except ImportError as exc:
        raise MissingDependencyError(
            "the MuJoCo peer needs the mujoco package: pip install 'crowdstudy[peers]'"
        ) from exc
    return mujoco


def resolve_setting(setting: str | MujocoSettings) -> MujocoSettings:
    """A tuning by name (a key of :data:`MUJOCO_SETTINGS`) or as given."""
    if isinstance(setting, MujocoSettings):
        return setting
    if setting not in MUJOCO_SETTINGS:
        raise InvalidInputError(
            f"setting: expected a MujocoSettings or one of {list(MUJOCO_SETTINGS)}, got {setting!r}"
        )
    return MUJOCO_SETTINGS[setting]


def check_timeconsts(setting: MujocoSettings, dt: float) -> None:
    """Raise InvalidInputError where a weld's or contact's solref time constant is under 2
    steps: MuJoCo silently clamps it to 2 * dt, so two such tunings would run the same model."""
    for key in ("weld_solref", "contact_solref"):
        timeconst = float(getattr(setting, key)[0])
        if timeconst < 2.0 * dt - 1e-9:
            raise InvalidInputError(
                f"MuJoCo setting {key}: time constant {timeconst:g} s is under 2 steps "
                f"({2.0 * dt:.4g} s at a {dt:.4g} s step), which MuJoCo clamps to 2 steps"
            )


def interpolated_targets(anim_q, anim_root, rests, f0: int, f1: int, alpha: float):
    """The target pose of ``targets_kernel`` in numpy (float64).

    anim_q (F, N, J, 4) joint rotations (scalar-last; root global), anim_root (F, N, 3) m,
    rests (N, J, 3) m. Local rotations nlerp (short arc) and the root lerps between frames
    f0 and f1 at ``alpha``; returns ``(global rotations (N, J, 4), joint positions (N, J, 3))``.
    """
    from crowdstudy.body.rotations import quat_blend, quat_multiply, quat_rotate
    from crowdstudy.body.skeleton import PARENTS

    local = quat_blend(anim_q[f0], anim_q[f1], alpha)
    glob = np.empty_like(local)
    pos = np.empty(local.shape[:-1] + (3,))
    glob[:, 0] = local[:, 0]
    pos[:, 0] = (1.0 - alpha) * anim_root[f0] + alpha * anim_root[f1]
    for j in range(1, len(PARENTS)):
        p = PARENTS[j]
        glob[:, j] = quat_multiply(glob[:, p], local[:, j])
        pos[:, j] = pos[:, p] + quat_rotate(glob[:, p], rests[:, j] - rests[:, p])
    return glob, pos


def rigid_to_animation(glob_q, root_pos):
    """Bone world rotations (..., J, 4) scalar-last and pelvis joint positions (..., 3) ->
    ``(joint_rotations (..., J, 3) axis-angle, root (..., 3))``: root global, the others
    R_parent^T R_child, as ``project_kernel`` writes Ours."""
    from crowdstudy.body.rotations import quat_conjugate, quat_multiply, quaternion_to_axis_angle
    from crowdstudy.body.skeleton import PARENTS

    q = np.asarray(glob_q, np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    local = q.copy()
    local[..., 1:, :] = quat_multiply(quat_conjugate(q[..., PARENTS[1:], :]), q[..., 1:, :])
    return quaternion_to_axis_angle(local), np.asarray(root_pos, np.float64).copy()


class MujocoScene:
    """The MuJoCo model of a crowd (see the module's notes) and the bookkeeping to drive it.

    Attributes: ``model``/``data`` (MjModel/MjData), ``xml`` (its MJCF), ``cs_model``
    (crowdstudy Model used for the geometry), ``config`` (the PhysicsConfig ``correct()``
    would use on this crowd), ``setting`` (:class:`MujocoSettings`), ``body_id`` (N, J)
    simulated bodies, ``mocap_id`` (N, J) target mocap slots, ``ghost_mocap`` (K, N, J)
    image mocap slots, ``ghost_shift`` (K,) m along x, ``hull_geom``/``core_geom`` (N, J)
    geom ids, ``dt`` s, ``substeps`` per frame.
    """

    def __init__(self, anim, config=None, setting: str | MujocoSettings = "weld0.05"):
        from crowdstudy.body.rotations import axis_angle_to_quaternion
        from crowdstudy.physics.corrector import load_bodies
        from crowdstudy.physics.model import ModelBuilder

        self.mujoco = mujoco = import_mujoco()
        self.anim = anim
        # the geometry and hold correct() would use on this crowd
        self.config = config = crowd_config(anim, config)[0]
        self.setting = st = resolve_setting(setting)
        builder = ModelBuilder()
        for b in load_bodies(anim.bodies):
            builder.add_character(b.rest_joints, b.capsules, config.mesh_skin(b))
        cm = self.cs_model = builder.finalize(density=config.body.density, device="cpu")
        self.n, self.nj = cm.n_characters, cm.n_joints
        self.rests = np.asarray(cm.rest_joints, np.float64)
        self.substeps = int(st.substeps)
        self.dt = 1.0 / (anim.fps * self.substeps)
        check_timeconsts(st, self.dt)
        self.anim_q = axis_angle_to_quaternion(anim.joint_rotations)
        self.anim_root = np.asarray(anim.root_translation, np.float64)
        period = anim.periodic_length
        self.ghost_shift = np.array([-period, period]) if period else np.zeros(0)
        # capsule ends in the rest frame, (N, J, 3) each
        self._cap_ends = (
            (cm.cap_p0 + cm.body_com_rest).reshape(self.n, self.nj, 3),
            (cm.cap_p1 + cm.body_com_rest).reshape(self.n, self.nj, 3),
        )
        self.xml = "".join(
            [*self._header_xml(), *self._walls_xml(period), *self._bodies_xml(), *self._constraints_xml()]
        )
        self.model = model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(model)
        self._index(model)
        self.place(0)

    # -- the MJCF --------------------------------------------------------------------------
    def _solref(self, value) -> str:
        return f"{value[0]:g} {value[1]:g}"

    def _solimp(self) -> str:
        return " ".join(f"{v:g}" for v in self.setting.solimp)

    def _header_xml(self) -> list[str]:
        """Options, the core/hull geom classes and the ground plane."""
        config, st = self.config, self.setting
        g = -float(config.body.gravity)
        return [
            f'<mujoco><option timestep="{self.dt:.10g}" gravity="0 0 {g:g}" integrator="implicitfast"/>',
            '<size memory="1G"/>',
            f'<default><geom condim="1" solref="{self._solref(st.contact_solref)}" solimp="{self._solimp()}"/>'
            f'<default class="core"><geom contype="2" conaffinity="0" density="{config.body.density:g}" group="1"/>'
            "</default>"
            f'<default class="hull"><geom contype="1" conaffinity="1" density="0" '
            f'margin="{float(config.contacts.margin):g}" group="2"/></default></default><worldbody>',
            '<geom name="ground" type="plane" size="0 0 0.1" contype="0" conaffinity="2"/>',
        ]

    def _walls_xml(self, period) -> list[str]:
        """The scene's walls as boxes WALL_DEPTH deep behind their faces."""
        from crowdstudy.scene_meta import static_walls_from_meta

        parts = []
        walls = np.asarray(static_walls_from_meta(self.anim.meta), np.float64).reshape(-1, 2, 2)
        x_lo = float(self.anim_root[..., 0].min()) - 3.0
        x_hi = float(self.anim_root[..., 0].max()) + 3.0
        for w, ((x0, y0), (x1, y1)) in enumerate(walls):
            if period and abs(y1 - y0) < 1e-9:  # periodic: cover the whole (unwrapped) run
                x0, x1 = min(x0, x1, x_lo), max(x0, x1, x_hi)
            c = 0.5 * np.array([x0 + x1, y0 + y1])
            half = 0.5 * float(np.hypot(x1 - x0, y1 - y0))
            ang = float(np.arctan2(y1 - y0, x1 - x0))
            # ours are one-sided planes facing the crowd (wall_kernel): a box WALL_DEPTH deep
            # behind the wall's face, away from the characters' roots, so that a limb through
            # the face is pushed back as ours is, not through a thin sheet
            normal = np.array([-np.sin(ang), np.cos(ang)])
            if np.mean((self.anim_root[0, :, :2] - c) @ normal) < 0:
                normal = -normal
            c = c - 0.5 * WALL_DEPTH * normal
            parts.append(
                f'<geom name="wall{w}" type="box" pos="{c[0]:.5f} {c[1]:.5f} 1.1" euler="0 0 {ang:.6f}" '
                f'size="{half:.5f} {0.5 * WALL_DEPTH:.5f} 1.1" contype="0" conaffinity="1"/>'
            )
        return parts

    def _segment(self, i: int, j: int) -> str:
        """The ``fromto`` of bone j of character i in its body's frame (the capsule's ends)."""
        s = self._cap_ends[0][i, j] - self.rests[i, j]
        e = self._cap_ends[1][i, j] - self.rests[i, j]
        if np.linalg.norm(e - s) < 1e-4:
            e = s + np.array([0.0, 0.0, 1e-4])
        return f'fromto="{s[0]:.6f} {s[1]:.6f} {s[2]:.6f} {e[0]:.6f} {e[1]:.6f} {e[2]:.6f}"'

    def _bodies_xml(self) -> list[str]:
        """Every character's body tree (core and hull capsules), the target mocap bodies and
        the periodic images."""
        from crowdstudy.body.skeleton import PARENTS

        cm, n, nj = self.cs_model, self.n, self.nj
        rad = cm.cap_radius.reshape(n, nj)
        hull = (cm.cap_radius + cm.cap_skin).reshape(n, nj)
        jd = float(self.setting.joint_damping)

        def body_xml(i: int, j: int) -> str:
            p = PARENTS[j]
            pos = self.anim_root[0, i] if p < 0 else self.rests[i, j] - self.rests[i, p]
            joint = "<freejoint/>" if p < 0 else f'<joint type="ball" damping="{jd:g}" armature="0.01"/>'
            kids = "".join(body_xml(i, c) for c in range(nj) if PARENTS[c] == j)
            seg = self._segment(i, j)
            return (
                f'<body name="c{i}b{j}" pos="{pos[0]:.6f} {pos[1]:.6f} {pos[2]:.6f}">{joint}'
                f'<geom name="core{i}_{j}" class="core" type="capsule" {seg} size="{rad[i, j]:.9g}"/>'
                f'<geom name="hull{i}_{j}" class="hull" type="capsule" {seg} size="{hull[i, j]:.9g}"/>'
                f"{kids}</body>"
            )

        parts = [body_xml(i, 0) for i in range(n)]
        parts += [f'<body name="m{i}b{j}" mocap="true"/>' for i in range(n) for j in range(nj)]
        for k in range(len(self.ghost_shift)):
            for i in range(n):
                for j in range(nj):
                    parts.append(
                        f'<body name="g{k}c{i}b{j}" mocap="true"><geom class="hull" contype="0" '
                        f'conaffinity="1" type="capsule" {self._segment(i, j)} size="{hull[i, j]:.9g}"/>'
                        "</body>"
                    )
        return parts

    def _constraints_xml(self) -> list[str]:
        """The self-contact pairs, the exclusions within each character, and the welds."""
        n, nj, st = self.n, self.nj, self.setting
        solref, solimp = self._solref(st.contact_solref), self._solimp()
        parts = ["</worldbody><contact>"]
        for a, b in self.cs_model.intra_pairs:
            ia, ja, ib, jb = a // nj, a % nj, b // nj, b % nj
            parts.append(
                f'<pair geom1="core{ia}_{ja}" geom2="core{ib}_{jb}" condim="1" solref="{solref}" solimp="{solimp}"/>'
            )
        for i in range(n):
            for a in range(nj):
                for b in range(a + 1, nj):
                    parts.append(f'<exclude body1="c{i}b{a}" body2="c{i}b{b}"/>')
        parts.append("</contact><equality>")
        for i in range(n):
            for j in range(nj):
                parts.append(
                    f'<weld body1="m{i}b{j}" body2="c{i}b{j}" relpose="0 0 0 1 0 0 0" '
                    f'solref="{self._solref(st.weld_solref)}" solimp="{solimp}"/>'
                )
        parts.append("</equality></mujoco>")
        return parts

    def _index(self, model) -> None:
        """The ids of the bodies, mocap slots and geoms, (N, J) each."""
        mujoco, n, nj = self.mujoco, self.n, self.nj
        name = lambda kind, s: mujoco.mj_name2id(model, kind, s)  # noqa: E731
        B, G = mujoco.mjtObj.mjOBJ_BODY, mujoco.mjtObj.mjOBJ_GEOM
        self.body_id = np.array([[name(B, f"c{i}b{j}") for j in range(nj)] for i in range(n)])
        self.mocap_id = np.array([[model.body_mocapid[name(B, f"m{i}b{j}")] for j in range(nj)] for i in range(n)])
        self.ghost_mocap = np.array(
            [
                [[model.body_mocapid[name(B, f"g{k}c{i}b{j}")] for j in range(nj)] for i in range(n)]
                for k in range(len(self.ghost_shift))
            ],
            dtype=np.int64,
        )
        self.hull_geom = np.array([[name(G, f"hull{i}_{j}") for j in range(nj)] for i in range(n)])
        self.core_geom = np.array([[name(G, f"core{i}_{j}") for j in range(nj)] for i in range(n)])

    # -- driving ---------------------------------------------------------------------------
    def set_targets(self, f0: int, f1: int, alpha: float) -> None:
        """The mocap targets at ``alpha`` between frames ``f0`` and ``f1``."""
        glob, pos = interpolated_targets(self.anim_q, self.anim_root, self.rests, f0, f1, alpha)
        self.target_glob, self.target_pos = glob, pos
        self.data.mocap_pos[self.mocap_id.ravel()] = pos.reshape(-1, 3)
        self.data.mocap_quat[self.mocap_id.ravel()] = glob.reshape(-1, 4)[:, [3, 0, 1, 2]]

    def place(self, frame: int) -> None:
        """Every body at the animation's frame ``frame``, at rest (like ``reset_to_frame``)."""
        m, d = self.model, self.data
        self.mujoco.mj_resetData(m, d)
        self.set_targets(frame, frame, 0.0)
        local = self.anim_q[frame]
        for i in range(self.n):
            for j in range(self.nj):
                jid = m.body_jntadr[self.body_id[i, j]]
                adr = m.jnt_qposadr[jid]
                if j == 0:
                    d.qpos[adr : adr + 3] = self.anim_root[frame, i]
                    d.qpos[adr + 3 : adr + 7] = local[i, 0][[3, 0, 1, 2]]
                else:
                    d.qpos[adr : adr + 4] = local[i, j][[3, 0, 1, 2]]
        self.mujoco.mj_forward(m, d)
        self._move_ghosts()

    def _move_ghosts(self) -> None:
        if not len(self.ghost_shift):
            return
        d = self.data
        xpos = d.xpos[self.body_id.ravel()]
        xquat = d.xquat[self.body_id.ravel()]
        for k, shift in enumerate(self.ghost_shift):
            d.mocap_pos[self.ghost_mocap[k].ravel()] = xpos + np.array([shift, 0.0, 0.0])
            d.mocap_quat[self.ghost_mocap[k].ravel()] = xquat

    def step(self) -> tuple[float, float]:
        """One mj_step (images moved first); returns its (wall ms, thread CPU ms)."""
        self._move_ghosts()
        t0, c0 = time.perf_counter(), time.thread_time()
        self.mujoco.mj_step(self.model, self.data)
        return 1000 * (time.perf_counter() - t0), 1000 * (time.thread_time() - c0)

    def read(self):
        """The current pose as ``(joint_rotations (N, J, 3), root (N, 3))``."""
        xq = self.data.xquat[self.body_id.ravel()][:, [1, 2, 3, 0]].reshape(self.n, self.nj, 4)
        return rigid_to_animation(xq, self.data.xpos[self.body_id[:, 0]])

    # -- what the tests compare with ours --------------------------------------------------
    def inter_body_radius(self) -> np.ndarray:
        """(N, J) m: hull radius + margin, the distance inter-body contacts hold per capsule
        side (ours: cap_radius + cap_skin, + contact_margin once per pair)."""
        return self.model.geom_size[self.hull_geom, 0] + self.model.geom_margin[self.hull_geom]

    def self_pairs(self) -> np.ndarray:
        """(P, 2) global body indices (i * J + j) of the same-character pairs that can touch."""
        m, nj = self.model, self.nj
        body_index = {int(b): k for k, b in enumerate(self.body_id.ravel())}
        pairs = set()
        for g1, g2 in zip(m.pair_geom1, m.pair_geom2, strict=True):
            a, b = body_index[int(m.geom_bodyid[g1])], body_index[int(m.geom_bodyid[g2])]
            if a // nj == b // nj:
                pairs.add((min(a, b), max(a, b)))
        excluded = {(int(s) >> 16, int(s) & 0xFFFF) for s in m.exclude_signature}
        for i in range(self.n):  # dynamic (contype/conaffinity) pairs not excluded
            ids = self.body_id[i]
            for a in range(nj):
                for b in range(a + 1, nj):
                    ba, bb = int(ids[a]), int(ids[b])
                    key = (min(ba, bb), max(ba, bb))
                    parent_child = m.body_parentid[ba] == bb or m.body_parentid[bb] == ba
                    if key in excluded or parent_child:
                        continue
                    if _geoms_filter(m, ba, bb):
                        pairs.add((i * nj + a, i * nj + b))
        return np.array(sorted(pairs), np.int64).reshape(-1, 2)


def _geoms_filter(m, ba: int, bb: int) -> bool:
    """Whether any geoms of bodies ba and bb pass MuJoCo's contype/conaffinity filter."""
    ga = range(m.body_geomadr[ba], m.body_geomadr[ba] + m.body_geomnum[ba])
    gb = range(m.body_geomadr[bb], m.body_geomadr[bb] + m.body_geomnum[bb])
    return any(
        (m.geom_contype[x] & m.geom_conaffinity[y]) or (m.geom_contype[y] & m.geom_conaffinity[x])
        for x in ga
        for y in gb
    )


def mujoco_peer(anim, config=None, setting: str | MujocoSettings = "weld0.05", *, settle: bool = True):
    """Simulate ``anim``'s targets in MuJoCo (:class:`MujocoScene`): settle on frame 0, then
    ``substeps`` steps per frame at the interpolated targets.

    Returns ``(anim, timing)``: the simulated CrowdAnimation (meta method "MuJoCo") and
    median cpu/wall ms per mj_step, the step (s) and steps per simulated 1/60 s, whether it
    went unstable (a non-finite root: the rest of the clip is the input), the model's size
    and the contacts of the last step.
    """
    scene = MujocoScene(anim, config, setting)
    t_frames = anim.n_frames
    out_rot = np.zeros(anim.joint_rotations.shape)
    out_root = np.zeros(anim.root_translation.shape)
    if settle:
        for _ in range(int(round(scene.config.solver.settle_time / scene.dt))):
            scene.set_targets(0, 0, 0.0)
            scene.step()
    out_rot[0], out_root[0] = scene.read()
    times = []
    unstable = False
    for f in range(1, t_frames):
        for s in range(1, scene.substeps + 1):
            scene.set_targets(f - 1, f, s / scene.substeps)
            times.append(scene.step())
        out_rot[f], out_root[f] = scene.read()
        if not np.all(np.isfinite(out_root[f])):
            unstable = True
            out_rot[f:], out_root[f:] = anim.joint_rotations[f:], anim.root_translation[f:]
            break
    res = anim.replace(root_translation=out_root, joint_rotations=out_rot, meta={"method": "MuJoCo"})
    timing = {
        "cpu_ms_per_step": statistics.median(t[1] for t in times),
        "wall_ms_per_step": statistics.median(t[0] for t in times),
        "dt": scene.dt,
        "steps_per_60th": scene.substeps * anim.fps / 60.0,
        "unstable": unstable,
        "nbody": int(scene.model.nbody),
        "ngeom": int(scene.model.ngeom),
        "contacts": float(scene.data.ncon),
    }
    return res, timing

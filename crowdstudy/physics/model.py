"""The immutable simulation model: one rigid body per bone of every character.

Body ``b = i * J + j`` is bone ``j`` of character ``i``. Its body frame has its origin at the
centre of mass of the bone's capsule and the *rest-pose* orientation (identity when the
character stands in the T-pose), so a body's world rotation equals the global joint
rotation ``G_j`` of forward kinematics and ``R_parent^T R_child`` is directly the joint's
parent-relative rotation (the rest frames factor out). A world point of bone ``j`` is
``x_b + R_b (p_rest - c_j)``, ``c_j`` the capsule centre in the rest frame of
``rest_joints`` (relative to the pelvis).

Mass and inertia come from the capsule (cylinder plus two hemispherical caps) at the
configured density. The second-moment matrix ``J = int rho r r^T dV`` (body frame, about the
centre of mass) gives the inertia tensor ``I = tr(J) Id - J``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from crowdstudy.body.capsules import closest_points_on_segments
from crowdstudy.body.skeleton import ARM_JOINTS, JOINT_INDEX, PARENTS
from crowdstudy.errors import InvalidInputError

__all__ = [
    "ModelBuilder",
    "Model",
    "capsule_mass_properties",
    "GROUP_BODY",
    "GROUP_PELVIS",
    "GROUP_FEET",
    "GROUP_ARM",
    "GROUP_TRUNK",
    "GROUP_HIPS",
    "MAX_CHILDREN",
]

GROUP_BODY, GROUP_PELVIS, GROUP_FEET, GROUP_ARM, GROUP_TRUNK, GROUP_HIPS = 0, 1, 2, 3, 4, 5
MAX_CHILDREN = 4
_PELVIS_GROUP_JOINTS = ("pelvis",)
_HIPS_GROUP_JOINTS = ("left_hip", "right_hip", "spine1")
_FEET_GROUP_JOINTS = ("left_ankle", "right_ankle", "left_foot", "right_foot")
_TRUNK_GROUP_JOINTS = ("spine2", "spine3", "neck", "head")


def capsule_mass_properties(start: np.ndarray, end: np.ndarray, radius: np.ndarray, density: float):
    """Mass (kg) and second-moment matrix J (kg m^2, about the centre) of capsules.

    Args:
        start, end: (K, 3) float, metres, segment end points.
        radius: (K,) float, metres.
        density: kg/m^3.

    Returns:
        ``(mass (K,), J (K, 3, 3))``; the inertia tensor is ``tr(J) Id - J``.
    """
    start = np.asarray(start, np.float64)
    end = np.asarray(end, np.float64)
    r = np.asarray(radius, np.float64)
    axis = end - start
    length = np.linalg.norm(axis, axis=-1)
    u = np.where(length[:, None] > 1e-9, axis / np.maximum(length, 1e-12)[:, None], np.array([0.0, 0.0, 1.0]))
    h = 0.5 * length
    m_cyl = density * np.pi * r**2 * length
    m_sph = density * 4.0 / 3.0 * np.pi * r**3
    # Along the axis: cylinder L^2/12; the two hemispherical caps at distance h + z', E[z'] = 3r/8,
    # E[z'^2] = r^2/5. Across: cylinder r^2/4, sphere r^2/5 (second moments per unit mass).
    j_axial = m_cyl * length**2 / 12.0 + m_sph * (h**2 + 0.75 * h * r + r**2 / 5.0)
    j_cross = m_cyl * r**2 / 4.0 + m_sph * r**2 / 5.0
    uu = u[:, :, None] * u[:, None, :]
    eye = np.eye(3)[None]
    J = j_cross[:, None, None] * (eye - uu) + j_axial[:, None, None] * uu
    return m_cyl + m_sph, J


@dataclasses.dataclass(frozen=True, eq=False)
class Model:
    """Immutable model of N characters x J bones (host arrays + device copies in ``wp``).

    Host arrays (numpy, read-only), B = N * J bodies:
        body_mass (B,) kg; body_J (B, 3, 3) kg m^2 second moment in the body frame;
        body_com_rest (B, 3) m, capsule centre in the character's rest frame;
        cap_p0, cap_p1 (B, 3) m, capsule end points in the body frame; cap_radius (B,) m;
        cap_skin (B,) m, added to the radius for inter-body/environment contacts;
        body_char (B,) character index; body_joint (B,) joint index j; body_parent (B,)
        global parent body (-1 for roots); body_children (B, MAX_CHILDREN) (-1 padded);
        anchor_parent (B, 3) m, the joint of body b in its parent's body frame;
        anchor_child (B, 3) m, the same joint in b's own frame (for roots: the pelvis joint);
        body_group (B,) GROUP_BODY/PELVIS/HIPS/FEET/ARM/TRUNK; intra_pairs (P, 2) global body pairs that
        may self-collide; rest_joints (N, J, 3) m; char_mass (N,) kg.
    """

    n_characters: int
    n_joints: int
    parents: np.ndarray
    rest_joints: np.ndarray
    body_mass: np.ndarray
    body_J: np.ndarray
    body_com_rest: np.ndarray
    cap_p0: np.ndarray
    cap_p1: np.ndarray
    cap_radius: np.ndarray
    cap_skin: np.ndarray
    body_char: np.ndarray
    body_joint: np.ndarray
    body_parent: np.ndarray
    body_children: np.ndarray
    anchor_parent: np.ndarray
    anchor_child: np.ndarray
    body_group: np.ndarray
    intra_pairs: np.ndarray
    char_mass: np.ndarray
    device: str
    wp: dict = dataclasses.field(repr=False)

    @property
    def n_bodies(self) -> int:
        return self.n_characters * self.n_joints


class ModelBuilder:
    """Collects characters (rest joints + capsules) and builds a :class:`Model`.

    Example::

        builder = ModelBuilder()
        for body in bodies:                       # crowdstudy.body.Body objects
            builder.add_character(body.rest_joints, body.capsules)
        model = builder.finalize(density=1000.0, device="cpu")
    """

    def __init__(self, parents: np.ndarray = PARENTS):
        self.parents = np.asarray(parents, dtype=np.int64)
        self._chars: list[tuple[np.ndarray, ...]] = []

    def add_character(self, rest_joints: np.ndarray, capsules, skin: np.ndarray | None = None) -> int:
        """Add one character; returns its index.

        Args:
            rest_joints: (J, 3) float, metres, T-pose joints relative to the pelvis.
            capsules: an object with ``start`` (J, 3), ``end`` (J, 3) (metres, rest frame of
                ``rest_joints``) and ``radius`` (J,) metres, capsule j riding on bone j.
            skin: (J,) metres added to the radii for inter-body and environment contacts
                (see :func:`crowdstudy.body.capsules.capsule_skin`); default zeros.
        """
        n_j = len(self.parents)
        rest = np.asarray(rest_joints, dtype=np.float64)
        if rest.shape != (n_j, 3) or not np.all(np.isfinite(rest)):
            raise InvalidInputError(f"rest_joints: expected a finite ({n_j}, 3) array, got shape {rest.shape}")
        try:
            start = np.asarray(capsules.start, np.float64)
            end = np.asarray(capsules.end, np.float64)
            radius = np.asarray(capsules.radius, np.float64)
        except AttributeError:
            raise InvalidInputError("capsules: expected an object with start, end and radius arrays") from None
        if start.shape != (n_j, 3) or end.shape != (n_j, 3) or radius.shape != (n_j,):
            raise InvalidInputError(
                f"capsules: expected start/end ({n_j}, 3) and radius ({n_j},), got "
                f"{start.shape}, {end.shape}, {radius.shape}"
            )
        if not (np.all(np.isfinite(start)) and np.all(np.isfinite(end)) and np.all(radius > 0)):
            raise InvalidInputError("capsules: end points must be finite and radii positive")
        skin = np.zeros(n_j) if skin is None else np.asarray(skin, np.float64)
        if skin.shape != (n_j,) or not np.all(np.isfinite(skin)) or np.any(skin < 0):
            raise InvalidInputError(f"skin: expected ({n_j},) finite values >= 0, got shape {skin.shape}")
        self._chars.append((rest, start, end, radius, skin))
        return len(self._chars) - 1

    def finalize(
        self, *, density: float = 1000.0, device: str | None = None, intra_touch_tolerance: float = 0.01
    ) -> Model:
        """Build the model and upload it to ``device`` (see ``resolve_device``).

        ``intra_touch_tolerance`` (m): capsule pairs closer than the sum of their radii plus
        this in the T-pose count as touching and never self-collide.
        """
        if not self._chars:
            raise InvalidInputError("ModelBuilder.finalize: no characters were added")
        from crowdstudy.warp_runtime import get_warp, resolve_device

        device = resolve_device(device)
        parents = self.parents
        n_j = len(parents)
        n = len(self._chars)
        rest = np.stack([c[0] for c in self._chars])
        start = np.stack([c[1] for c in self._chars]).reshape(-1, 3)
        end = np.stack([c[2] for c in self._chars]).reshape(-1, 3)
        radius = np.stack([c[3] for c in self._chars]).reshape(-1)
        skin = np.stack([c[4] for c in self._chars]).reshape(-1)
        mass, J = capsule_mass_properties(start, end, radius, density)
        com = 0.5 * (start + end)
        body_char = np.repeat(np.arange(n), n_j)
        body_joint = np.tile(np.arange(n_j), n)
        offset = body_char * n_j
        body_parent = np.where(parents[body_joint] >= 0, offset + parents[body_joint], -1)
        kids = [[c for c in range(n_j) if parents[c] == j] for j in range(n_j)]
        if max(len(k) for k in kids) > MAX_CHILDREN:
            raise InvalidInputError(f"parents: a joint has more than {MAX_CHILDREN} children")
        tmpl_children = np.full((n_j, MAX_CHILDREN), -1, np.int64)
        for j, k in enumerate(kids):
            tmpl_children[j, : len(k)] = k
        body_children = np.where(tmpl_children[body_joint] >= 0, offset[:, None] + tmpl_children[body_joint], -1)
        joint_rest = rest.reshape(-1, 3)  # joint j's rest position, per body
        par_com = com[np.maximum(body_parent, 0)]
        anchor_parent = np.where(body_parent[:, None] >= 0, joint_rest - par_com, 0.0)
        anchor_child = joint_rest - com
        group = np.full(n_j, GROUP_BODY, np.int64)
        for name in _PELVIS_GROUP_JOINTS:
            group[JOINT_INDEX[name]] = GROUP_PELVIS
        for names, g in (
            (_HIPS_GROUP_JOINTS, GROUP_HIPS),
            (_FEET_GROUP_JOINTS, GROUP_FEET),
            (ARM_JOINTS, GROUP_ARM),
            (_TRUNK_GROUP_JOINTS, GROUP_TRUNK),
        ):
            for name in names:
                group[JOINT_INDEX[name]] = g
        body_group = group[body_joint] if n_j == len(group) else np.zeros(n * n_j, np.int64)
        # Intra-body pairs: not parent-child, not touching in the T-pose.
        ii, jj = np.triu_indices(n_j, k=1)
        pairs = []
        for c in range(n):
            s, e, r = start[c * n_j : (c + 1) * n_j], end[c * n_j : (c + 1) * n_j], radius[c * n_j : (c + 1) * n_j]
            _, _, dist = closest_points_on_segments(s[ii], e[ii], s[jj], e[jj])
            keep = (parents[jj] != ii) & (parents[ii] != jj) & (dist > r[ii] + r[jj] + intra_touch_tolerance)
            pairs.append(np.stack([ii[keep], jj[keep]], 1) + c * n_j)
        intra = np.concatenate(pairs).astype(np.int64) if pairs else np.zeros((0, 2), np.int64)
        char_mass = mass.reshape(n, n_j).sum(1)

        host = dict(
            body_mass=mass,
            body_J=J,
            body_com_rest=com,
            cap_p0=start - com,
            cap_p1=end - com,
            cap_radius=radius,
            cap_skin=skin,
            body_char=body_char,
            body_joint=body_joint,
            body_parent=body_parent,
            body_children=body_children,
            anchor_parent=anchor_parent,
            anchor_child=anchor_child,
            body_group=body_group,
            intra_pairs=intra,
            char_mass=char_mass,
        )
        wp = get_warp()
        f32 = np.float32
        dev = dict(
            body_mass=wp.array(mass.astype(f32), dtype=wp.float32, device=device),
            body_J=wp.array(J.astype(f32), dtype=wp.mat33, device=device),
            cap_p0=wp.array((start - com).astype(f32), dtype=wp.vec3, device=device),
            cap_p1=wp.array((end - com).astype(f32), dtype=wp.vec3, device=device),
            cap_radius=wp.array(radius.astype(f32), dtype=wp.float32, device=device),
            cap_skin=wp.array(skin.astype(f32), dtype=wp.float32, device=device),
            body_char=wp.array(body_char.astype(np.int32), dtype=wp.int32, device=device),
            body_parent=wp.array(body_parent.astype(np.int32), dtype=wp.int32, device=device),
            body_children=wp.array(body_children.astype(np.int32), dtype=wp.int32, device=device),
            anchor_parent=wp.array(anchor_parent.astype(f32), dtype=wp.vec3, device=device),
            anchor_child=wp.array(anchor_child.astype(f32), dtype=wp.vec3, device=device),
            body_group=wp.array(body_group.astype(np.int32), dtype=wp.int32, device=device),
            intra_pairs=wp.array(
                intra.astype(np.int32).reshape(-1, 2) if len(intra) else np.zeros((0, 2), np.int32),
                dtype=wp.int32,
                device=device,
            ),
        )
        for arr in host.values():
            arr.flags.writeable = False
        rest.flags.writeable = False
        return Model(
            n_characters=n, n_joints=n_j, parents=parents.copy(), rest_joints=rest, device=device, wp=dev, **host
        )

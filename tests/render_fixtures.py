"""Test fixtures for the renderer: a light skinned mannequin (capsule limbs, rigid weights)
with the interface of ``crowdstudy.body.Body``, and small crowd animations built from it.

The mannequin keeps the render tests fast and independent of the body models; the
stimulus tests use the same loader through the ``body_loader`` hook.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from crowdstudy.body.skeleton import (
    DEFAULT_PELVIS_HEIGHT,
    DEFAULT_REST_JOINTS,
    JOINT_NAMES,
    PARENTS,
    forward_kinematics,
)
from crowdstudy.scene import CrowdAnimation

# (joint, start offset from the joint or None, end: child joint name or offset, radius)
_BONES = [
    ("pelvis", (-0.09, 0, -0.02), (0.09, 0, -0.02), 0.11),
    ("spine1", None, "spine2", 0.12),
    ("spine2", None, "spine3", 0.13),
    ("spine3", (-0.06, 0, 0.03), (0.06, 0, 0.03), 0.13),
    ("neck", None, "head", 0.05),
    ("head", (0, 0.01, 0.08), (0, 0.01, 0.12), 0.1),
    ("left_hip", None, "left_knee", 0.075),
    ("right_hip", None, "right_knee", 0.075),
    ("left_knee", None, "left_ankle", 0.055),
    ("right_knee", None, "right_ankle", 0.055),
    ("left_ankle", None, "left_foot", 0.045),
    ("right_ankle", None, "right_foot", 0.045),
    ("left_collar", None, "left_shoulder", 0.05),
    ("right_collar", None, "right_shoulder", 0.05),
    ("left_shoulder", None, "left_elbow", 0.05),
    ("right_shoulder", None, "right_elbow", 0.05),
    ("left_elbow", None, "left_wrist", 0.042),
    ("right_elbow", None, "right_wrist", 0.042),
    ("left_wrist", None, "left_hand", 0.038),
    ("right_wrist", None, "right_hand", 0.038),
]


@dataclasses.dataclass
class Capsules:
    start: np.ndarray
    end: np.ndarray
    radius: np.ndarray


def _capsule_mesh(a, b, r, rings=6, segs=10):
    a, b = np.asarray(a, float), np.asarray(b, float)
    axis = b - a
    length = np.linalg.norm(axis)
    z = axis / length if length > 1e-9 else np.array([0, 0, 1.0])
    x = np.cross(z, [0, 0, 1.0]) if abs(z[2]) < 0.9 else np.cross(z, [1.0, 0, 0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    verts = []
    # hemisphere rings from the bottom pole to the top pole
    lat = np.concatenate([np.linspace(-np.pi / 2, 0, rings + 1)[1:], np.linspace(0, np.pi / 2, rings + 1)[:-1]])
    for k, phi in enumerate(lat):
        centre = a if k < rings else b
        for s in range(segs):
            th = 2 * np.pi * s / segs
            d = np.cos(phi) * (np.cos(th) * x + np.sin(th) * y) + np.sin(phi) * z
            verts.append(centre + r * d)
    verts = [a - r * z] + verts + [b + r * z]
    faces = []
    n_rings = len(lat)
    for s in range(segs):
        faces.append((0, 1 + (s + 1) % segs, 1 + s))
    for k in range(n_rings - 1):
        for s in range(segs):
            i0, i1 = 1 + k * segs + s, 1 + k * segs + (s + 1) % segs
            j0, j1 = i0 + segs, i1 + segs
            faces += [(i0, i1, j1), (i0, j1, j0)]
    top = len(verts) - 1
    last = 1 + (n_rings - 1) * segs
    for s in range(segs):
        faces.append((top, last + s, last + (s + 1) % segs))
    return np.array(verts), np.array(faces)


class Mannequin:
    """Capsule-limbed character: rest_vertices, faces, weights, top_weights(), capsules,
    skinning_matrices(), template_key, rest_joints, pelvis_height (like crowdstudy.body.Body)."""

    def __init__(self, scale: float = 1.0):
        self.rest_joints = DEFAULT_REST_JOINTS * scale
        self.pelvis_height = DEFAULT_PELVIS_HEIGHT * scale
        self.template_key = "mannequin"
        names = list(JOINT_NAMES)
        verts, faces, owner = [], [], []
        start_c, end_c, rad_c = np.zeros((24, 3)), np.zeros((24, 3)), np.full(24, 0.02)
        for joint, start, end, r in _BONES:
            j = names.index(joint)
            p = self.rest_joints[j]
            a = p + (np.asarray(start) * scale if start is not None else 0.0)
            b = self.rest_joints[names.index(end)] if isinstance(end, str) else p + np.asarray(end) * scale
            if start is None and isinstance(end, str) and joint not in ("neck",):
                pass
            v, f = _capsule_mesh(a, b, r * scale)
            faces.append(f + sum(len(x) for x in verts))
            verts.append(v)
            owner.append(np.full(len(v), j))
            start_c[j], end_c[j], rad_c[j] = a, b, r * scale
        for j in range(24):  # joints without a drawn bone (feet, hands): tiny capsules at the joint
            if not any(names.index(b[0]) == j for b in _BONES):
                start_c[j] = end_c[j] = self.rest_joints[j]
        self.rest_vertices = np.concatenate(verts)
        self.faces = np.concatenate(faces).astype(np.int32)
        owner = np.concatenate(owner)
        self.weights = np.zeros((len(owner), 24), np.float32)
        self.weights[np.arange(len(owner)), owner] = 1.0
        self.capsules = Capsules(start_c, end_c, rad_c)

    def top_weights(self, k: int = 4):
        idx = np.argsort(-self.weights, axis=1)[:, :k].astype(np.int32)
        return idx, np.take_along_axis(self.weights, idx, axis=1).astype(np.float32)

    def skinning_matrices(self, joint_rotations, root_translation):
        glob, pos = forward_kinematics(self.rest_joints, joint_rotations, root_translation)
        out = np.zeros(glob.shape[:-2] + (4, 4))
        out[..., :3, :3] = glob
        out[..., :3, 3] = pos - np.einsum("...jab,...jb->...ja", glob, self.rest_joints)
        out[..., 3, 3] = 1.0
        return out


_CACHE: dict[float, Mannequin] = {}


def mannequin_loader(record: dict) -> Mannequin:
    """Body loader for the renderer: record["height"] scales the mannequin (1.70 m = 1)."""
    scale = round(float(record.get("height", 1.7)) / 1.7, 3)
    if scale not in _CACHE:
        _CACHE[scale] = Mannequin(scale)
    return _CACHE[scale]


#: the render tests' image size (tiny: fast on llvmpipe)
W, H = 192, 108


def mannequin_renderer(anim, design, **kw):
    """A :class:`~crowdstudy.render.renderer.CrowdRenderer` of ``anim`` drawing the
    mannequins, W x H unless ``width``/``height`` are given."""
    from crowdstudy.render.renderer import CrowdRenderer

    kw.setdefault("width", W)
    kw.setdefault("height", H)
    return CrowdRenderer(anim, design=design, body_loader=mannequin_loader, **kw)


def crowd_animation(
    positions,
    *,
    n_frames: int = 4,
    fps: float = 30.0,
    scenario: str = "concert",
    period: float | None = None,
    velocity=(0.0, 0.0),
    seed: int = 7,
    heights=None,
) -> CrowdAnimation:
    """Mannequins standing at ``positions`` (N, 2), facing +y, arms down, swaying a little."""
    pos = np.asarray(positions, float)
    n = len(pos)
    rng = np.random.default_rng(seed)
    heights = rng.uniform(1.55, 1.9, n) if heights is None else np.asarray(heights, float)
    t = np.arange(n_frames) / fps
    root = np.zeros((n_frames, n, 3))
    root[:, :, :2] = pos[None] + t[:, None, None] * np.asarray(velocity)[None, None]
    root[:, :, 2] = DEFAULT_PELVIS_HEIGHT * (heights / 1.7)[None]
    rot = np.zeros((n_frames, n, 24, 3))
    ls, rs = JOINT_NAMES.index("left_shoulder"), JOINT_NAMES.index("right_shoulder")
    phase = rng.uniform(0, 2 * np.pi, n)
    sway = 0.15 * np.sin(2 * np.pi * 1.0 * t[:, None] + phase[None])
    rot[:, :, ls, 1] = -1.25 + sway
    rot[:, :, rs, 1] = 1.25 - sway
    rot[:, :, 0, 2] = 0.1 * np.sin(2 * np.pi * 0.5 * t[:, None] + phase[None])
    meta = {"scenario": scenario, "seed": seed}
    if period:
        meta["periodic"] = {"axis": 0, "length": float(period)}
    bodies = tuple(
        {"model": "mannequin", "sex": "female" if i % 2 else "male", "height": float(h)} for i, h in enumerate(heights)
    )
    return CrowdAnimation(
        joint_names=JOINT_NAMES,
        parents=PARENTS,
        root_translation=root,
        joint_rotations=rot,
        fps=fps,
        bodies=bodies,
        clips=tuple({"name": "sway", "phase": float(p)} for p in phase),
        meta=meta,
    )


def grid_positions(n: int, extent=(3.0, 3.0), margin: float = 0.35, seed: int = 0) -> np.ndarray:
    """n positions on a jittered grid inside the area."""
    rng = np.random.default_rng(seed)
    cols = int(np.ceil(np.sqrt(n * extent[0] / extent[1])))
    rows = int(np.ceil(n / cols))
    xs = np.linspace(-extent[0] / 2 + margin, extent[0] / 2 - margin, cols)
    ys = np.linspace(-extent[1] / 2 + margin, extent[1] / 2 - margin, rows)
    pts = np.array([(x, y) for y in ys for x in xs])[:n]
    return pts + rng.uniform(-0.05, 0.05, pts.shape)

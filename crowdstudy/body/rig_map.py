"""Map any humanoid rig onto the 24-joint physics skeleton (:mod:`crowdstudy.body.skeleton`),
independently of the file format it came from (glTF today, USD's UsdSkel next).

Input (:func:`map_rig`): the rig's joints as three arrays, ``names`` (K labels, empty
strings for unnamed nodes), ``parents`` (K,) (-1 for roots) and ``rest`` (K, 3) rest
positions in metres, Z up; optionally ``sides`` (K,) hints (-1 left, +1 right, 0 unknown:
by default read from the names, :func:`side_of_name`), ``forward`` (3,) the direction the
rig faces when neither names nor toes tell (a format's convention), and ``overrides``
({physics joint: source joint name or index}, ``--map FILE.json``).

Output: a :class:`RigMap`, per physics joint the source joint and HOW it was found:

``name``
    the joint's name is in a naming table (:mod:`crowdstudy.body.joint_names`: Mixamo,
    Ready Player Me, VRM, VRoid, Rigify, CMU, crowdstudy's own exports);
``topology``
    the skeleton's shape (:func:`topology_map`): the root of the legs is the joint where two
    chains go down and one goes up (or where one chain goes down to a lower-pelvis joint
    that splits into the two legs, beside the spine); in each leg chain the hip is the first joint of the long
    descent, the ankle the first joint near the chain's bottom, the knee the chain joint
    half-way between them; the spine chain rises to the head, the arms are the two
    longest sideways branches of it (held out or hanging) (their branch point is ``spine3``), the wrist is where the
    fingers branch, the elbow the chain joint half-way between shoulder and wrist; left and
    right by the side hints, else by the toes' forward direction, else by ``forward``;
``map``
    the user's override.

Names win where they agree with the skeleton's shape (the hierarchy check of
:func:`check_hierarchy`); a rig whose names do not fit (Blender-style ``UpperArm.L``,
numbered ``leg_joint_L_1``, unnamed nodes) is mapped by topology, with any name matches
that fit kept. The optional joints (``spine3``, collars, hands, feet) may stay unmapped
(their rest position is then placed from their neighbours); a rig without knees or elbows
is too coarse for the physics skeleton and raises :class:`~crowdstudy.errors.InvalidInputError`
naming what is missing, as does a skeleton that is not a humanoid's.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping, Sequence
from typing import Literal

import numpy as np

from crowdstudy.body.joint_names import match_names
from crowdstudy.body.skeleton import JOINT_INDEX, JOINT_NAMES, PARENTS
from crowdstudy.errors import InvalidInputError

__all__ = [
    "MappingMethod",
    "MappedJoint",
    "RigMap",
    "OPTIONAL_JOINTS",
    "map_rig",
    "topology_map",
    "side_of_name",
    "check_hierarchy",
    "read_overrides",
]

#: How a physics joint found its source joint.
MappingMethod = Literal["name", "topology", "map"]
#: Physics joints a rig may lack (their rest positions are placed from their neighbours).
OPTIONAL_JOINTS = ("spine3", "left_collar", "right_collar", "left_hand", "right_hand", "left_foot", "right_foot")


@dataclasses.dataclass(frozen=True)
class MappedJoint:
    """One physics joint's source: ``source`` (index into the rig's joints), ``how`` it was
    found and a ``detail`` (the naming convention, or the topology rule)."""

    source: int
    how: MappingMethod
    detail: str


@dataclasses.dataclass(frozen=True)
class RigMap:
    """A rig's joints mapped onto the 24 physics joints.

    Attributes:
        joints: {physics joint: :class:`MappedJoint`} for the mapped joints, in skeleton order.
        missing: optional physics joints without a source (placed from their neighbours).
        names: (K,) the rig's joint labels (``#k`` for unnamed joints).
        parents: (K,) int64 parent of every rig joint (-1 for roots).
        rest: (K, 3) float64 rest positions, metres, Z up (as given to :func:`map_rig`).
    """

    joints: dict[str, MappedJoint]
    missing: tuple[str, ...]
    names: tuple[str, ...]
    parents: np.ndarray
    rest: np.ndarray

    @property
    def source_to_joint(self) -> dict[int, str]:
        """{rig joint: physics joint} of the mapped rig joints."""
        return {m.source: j for j, m in self.joints.items()}

    def weight_joint(self, k: int) -> str:
        """The physics joint that takes rig joint ``k``'s skin weights or rigid parts: its
        nearest mapped ancestor (itself when mapped); ``pelvis`` for the joints above the
        pelvis' source (an armature root); for a joint beside the mapped tree (an IK target
        next to the legs) the mapped joint nearest to it at rest."""
        mapped = self.source_to_joint
        a = k
        while a >= 0:
            if a in mapped:
                return mapped[a]
            a = int(self.parents[a])
        a = int(self.parents[self.joints["pelvis"].source])
        while a >= 0:
            if a == k:
                return "pelvis"
            a = int(self.parents[a])
        src = np.array(list(mapped))
        d = np.linalg.norm(self.rest[src] - self.rest[k], axis=1)
        return mapped[int(src[int(np.argmin(d))])]

    def table(self, weights: Mapping[int, float] | None = None) -> str:
        """A printable table: every physics joint, its source joint and how it was found,
        then the rig joints that map to none and the physics joint that takes their weights
        (``weights``: {rig joint: share of the skin weights}, shown when given)."""
        lines = [f"{'physics joint':16s} {'source joint':32s} how"]
        for j in JOINT_NAMES:
            m = self.joints.get(j)
            if m is None:
                lines.append(f"{j:16s} {'-':32s} placed from its neighbours")
            else:
                how = m.how if not m.detail else f"{m.how} ({m.detail})"
                lines.append(f"{j:16s} {self.names[m.source]:32s} {how}")
        mapped = self.source_to_joint
        rest = [k for k in range(len(self.names)) if k not in mapped]
        if rest:
            lines.append(f"not mapped ({len(rest)}): their weights and parts go to")
            for k in rest:
                share = f"  ({100.0 * weights[k]:.1f} % of the weights)" if weights and k in weights else ""
                lines.append(f"  {self.names[k]:30s} -> {self.weight_joint(k)}{share}")
        return "\n".join(lines)


_SIDE_WORDS = {"l": -1, "left": -1, "r": 1, "right": 1}


def side_of_name(name: str) -> int:
    """-1 for a left-side joint name, +1 for a right-side one, 0 when the name does not say:
    a whole word ``L``/``Left``/``R``/``Right`` between separators (``_ . - space``, digits)
    or case changes (``UpperArmL``, ``LeftUpLeg``, ``lThigh``, ``leg_joint_L_1``, ``thigh.L``)."""
    words = re.findall(r"[A-Z]?[a-z]+|[A-Z]+(?![a-z])|[a-z]+", re.sub(r"[\s_.\-\d:]+", " ", name))
    found = {_SIDE_WORDS[w.lower()] for w in words if w.lower() in _SIDE_WORDS}
    return found.pop() if len(found) == 1 else 0


def read_overrides(path) -> dict[str, str | int]:
    """A ``--map`` file: a JSON object {physics joint: source joint name or index}.
    Raises InvalidInputError naming the file and the bad key."""
    import json
    from pathlib import Path

    path = Path(path)
    if not path.is_file():
        raise InvalidInputError(f"--map: {path} is not a file")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InvalidInputError(f"--map {path}: not a JSON file ({exc})") from None
    if not isinstance(data, dict):
        raise InvalidInputError(f"--map {path}: expected a JSON object {{physics joint: source joint}}")
    for key, val in data.items():
        if key not in JOINT_INDEX:
            raise InvalidInputError(f"--map {path}: key {key!r} is not a physics joint ({', '.join(JOINT_NAMES)})")
        if isinstance(val, bool) or not isinstance(val, (str, int)):
            raise InvalidInputError(f"--map {path}: {key}: expected a joint name or index, got {val!r}")
    return dict(data)


def map_rig(
    names: Sequence[str],
    parents: Sequence[int] | np.ndarray,
    rest: np.ndarray,
    *,
    sides: Sequence[int] | None = None,
    forward: Sequence[float] | np.ndarray | None = None,
    overrides: Mapping[str, str | int] | None = None,
    label: str = "rig",
    table: tuple[str, Mapping[int, str]] | None = None,
) -> RigMap:
    """Map a rig onto the physics skeleton (see the module docstring); ``label`` names the
    rig in errors; ``table`` (convention, {rig joint: physics joint}) is a name table the
    file carries itself (a VRM humanoid), used instead of the name tables. Raises
    InvalidInputError when the rig is not a humanoid, is too coarse (no knees, elbows...),
    or an override names an unknown joint."""
    parents = np.asarray(parents, dtype=np.int64)
    rest = np.asarray(rest, dtype=np.float64)
    k = len(parents)
    if rest.shape != (k, 3) or len(names) != k:
        raise InvalidInputError(f"{label}: expected {k} names and ({k}, 3) rest positions, got {rest.shape}")
    labels = tuple(str(n) if n else f"#{i}" for i, n in enumerate(names))
    sides_arr = np.array([side_of_name(str(n)) for n in names] if sides is None else sides, dtype=np.int64)
    conv, by_name = table if table is not None else match_names({i: str(n) for i, n in enumerate(names) if n})
    by_name = dict(by_name)
    joints: dict[str, MappedJoint] = {}
    if _complete(by_name.values()) and not _hierarchy_errors(by_name, parents):
        joints = {j: MappedJoint(s, "name", conv) for s, j in by_name.items()}
    else:
        topo = topology_map(parents, rest, sides_arr, forward, label, labels)
        joints = {j: MappedJoint(s, "topology", rule) for j, (s, rule) in topo.items()}
        # name matches that fit the skeleton's shape replace the topology's guesses
        for s, j in by_name.items():
            if j in joints and joints[j].source != s:
                trial = {m.source: jj for jj, m in joints.items() if jj != j and m.source != s}
                trial[s] = j
                if not _hierarchy_errors(trial, parents):
                    joints[j] = MappedJoint(s, "name", conv)
            elif j in joints:
                joints[j] = MappedJoint(s, "name", conv)
    for j, src in (overrides or {}).items():
        joints = {jj: m for jj, m in joints.items() if jj != j and m.source != _source_index(src, labels, label)}
        joints[j] = MappedJoint(_source_index(src, labels, label), "map", "")
    return _finish(joints, labels, parents, rest, label)


def _source_index(src: str | int, labels: tuple[str, ...], label: str) -> int:
    if isinstance(src, int) and not isinstance(src, bool):
        if not 0 <= src < len(labels):
            raise InvalidInputError(f"--map: joint index {src} is not in {label}'s 0..{len(labels) - 1}")
        return src
    hits = [i for i, n in enumerate(labels) if n == src]
    if len(hits) != 1:
        what = "no joint" if not hits else f"{len(hits)} joints"
        raise InvalidInputError(f"--map: {label} has {what} named {src!r} (give its index instead)")
    return hits[0]


def _complete(found) -> bool:
    have = set(found)
    return all(j in have for j in JOINT_NAMES if j not in OPTIONAL_JOINTS)


def _finish(
    joints: dict[str, MappedJoint], labels: tuple[str, ...], parents: np.ndarray, rest: np.ndarray, label: str
) -> RigMap:
    required = [j for j in JOINT_NAMES if j not in joints and j not in OPTIONAL_JOINTS]
    if required:
        raise InvalidInputError(f"{label}: required joints missing: {', '.join(required)} (give them with --map)")
    bad = _hierarchy_errors({m.source: j for j, m in joints.items()}, parents)
    if bad:
        raise InvalidInputError(f"{label}: joint hierarchy does not match the 24-joint skeleton: " + "; ".join(bad))
    ordered = {j: joints[j] for j in JOINT_NAMES if j in joints}
    missing = tuple(j for j in JOINT_NAMES if j not in joints)
    return RigMap(joints=ordered, missing=missing, names=labels, parents=parents, rest=rest)


def check_hierarchy(node_map: Mapping[int, str], parents: np.ndarray, label: str) -> None:
    """Raise InvalidInputError when a mapped joint's nearest mapped ancestor in the rig is
    not its nearest present ancestor in the 24-joint tree (``node_map``: {rig joint:
    physics joint})."""
    bad = _hierarchy_errors(node_map, parents)
    if bad:
        raise InvalidInputError(f"{label}: joint hierarchy does not match the 24-joint skeleton: " + "; ".join(bad))


def _hierarchy_errors(node_map: Mapping[int, str], parents: np.ndarray) -> list[str]:
    found = set(node_map.values())
    bad = []
    for node, ours in node_map.items():
        expect = int(PARENTS[JOINT_INDEX[ours]])
        while expect >= 0 and JOINT_NAMES[expect] not in found:
            expect = int(PARENTS[expect])
        k = int(parents[node])
        while k >= 0 and k not in node_map:
            k = int(parents[k])
        got = node_map.get(k) if k >= 0 else None
        want = JOINT_NAMES[expect] if expect >= 0 else None
        if got != want:
            bad.append(f"{ours} (under {got}, expected under {want})")
    return bad


# ----------------------------------------------------------------------------- topology


@dataclasses.dataclass
class _Tree:
    parents: np.ndarray
    rest: np.ndarray
    kids: list[list[int]]
    sub: list[list[int]]  # every joint's subtree (itself first)
    height: float

    @classmethod
    def build(cls, parents: np.ndarray, rest: np.ndarray) -> _Tree:
        kids: list[list[int]] = [[] for _ in parents]
        for c, p in enumerate(parents):
            if p >= 0:
                kids[int(p)].append(c)
        sub: list[list[int]] = [[] for _ in parents]
        for k in _post_order(kids, parents):
            sub[k] = [k] + [d for c in kids[k] for d in sub[c]]
        return cls(parents, rest, kids, sub, float(np.ptp(rest[:, 2])) if len(rest) else 0.0)

    def zmin(self, k: int) -> float:
        return float(self.rest[self.sub[k], 2].min())

    def zmax(self, k: int) -> float:
        return float(self.rest[self.sub[k], 2].max())

    def chain(self, start: int, key) -> list[int]:
        """From ``start`` down the tree, each step to the child that maximises ``key(child)``."""
        out = [start]
        while self.kids[out[-1]]:
            out.append(max(self.kids[out[-1]], key=key))
        return out

    def dist(self, a: int, b: int) -> float:
        return float(np.linalg.norm(self.rest[a] - self.rest[b]))


def _post_order(kids: list[list[int]], parents: np.ndarray) -> list[int]:
    order: list[int] = []
    stack = [(int(r), False) for r in np.flatnonzero(parents < 0)]
    while stack:
        k, done = stack.pop()
        if done:
            order.append(k)
            continue
        stack.append((k, True))
        stack.extend((c, False) for c in kids[k])
    return order


def topology_map(
    parents: np.ndarray,
    rest: np.ndarray,
    sides: np.ndarray,
    forward: Sequence[float] | np.ndarray | None,
    label: str,
    labels: Sequence[str] | None = None,
) -> dict[str, tuple[int, str]]:
    """{physics joint: (rig joint, rule)} from the skeleton's shape alone (the rules of the
    module docstring). Raises InvalidInputError when the rig is not a humanoid or too coarse."""
    tree = _Tree.build(parents, rest)
    if tree.height <= 0:
        raise InvalidInputError(f"{label}: not a humanoid rig ({len(parents)} joints, no vertical extent)")
    if len(parents) < 10:  # a blocky figure: one joint per limb
        raise InvalidInputError(
            f"{label}: too coarse for the physics skeleton ({len(parents)} joints: {', '.join(labels or ())}): "
            "required joints missing: the knees, the elbows, the ankles, the wrists "
            "(each limb needs three joints; give them with --map)"
        )
    pelvis, legs, spine = _find_pelvis(tree, label)
    out: dict[str, tuple[int, str]] = {"pelvis": (pelvis, "legs and spine branch here")}
    leg_maps = [_leg(tree, c, label) for c in legs]
    chain = tree.chain(spine, lambda c: tree.zmax(c))
    arms, branch = _arms(tree, [pelvis] + chain, label)
    arm_maps = [_arm(tree, a, label) for a in arms]
    left = _left_direction(tree, leg_maps, forward, label)
    leg_side = _order_sides(tree, legs, sides, left, pelvis)
    arm_side = _order_sides(tree, arms, sides, left, pelvis)
    for side, i in zip(("left", "right"), leg_side, strict=True):
        out.update({f"{side}_{j}": v for j, v in leg_maps[i].items()})
    for side, i in zip(("left", "right"), arm_side, strict=True):
        out.update({f"{side}_{j}": v for j, v in arm_maps[i].items()})
    out.update(_spine(tree, [pelvis] + chain, branch, label))
    return out


def _find_pelvis(tree: _Tree, label: str) -> tuple[int, list[int], int]:
    """The joint where two chains go down (the legs) and one goes up (the spine)."""
    h = tree.height
    for k in _breadth_first(tree):
        z = tree.rest[k, 2]
        down = [c for c in tree.kids[k] if tree.zmin(c) < z - 0.2 * h]
        up = [c for c in tree.kids[k] if tree.zmax(c) > z + 0.15 * h]
        if len(down) == 1 and up:  # both legs under one lower-pelvis joint beside the spine
            d = down[0]
            while len(tree.kids[d]) == 1:
                d = tree.kids[d][0]
            down = [c for c in tree.kids[d] if tree.zmin(c) < z - 0.2 * h] or down
        if len(down) >= 2 and up:
            down = sorted(down, key=lambda c: tree.zmin(c))[:2]
            spine = max(up, key=lambda c: (tree.zmax(c), len(tree.sub[c])))
            rise = tree.rest[tree.sub[spine], 2].argmax()
            top = tree.rest[tree.sub[spine][rise]]
            if np.linalg.norm(top[:2] - tree.rest[k, :2]) > top[2] - z:
                raise InvalidInputError(
                    f"{label}: not a humanoid rig: the spine from joint {k} runs horizontally (a quadruped?)"
                )
            return k, down, spine
    raise InvalidInputError(
        f"{label}: not a humanoid rig: no joint where two legs go down and a spine goes up (give the joints with --map)"
    )


def _breadth_first(tree: _Tree) -> list[int]:
    order = [int(r) for r in np.flatnonzero(tree.parents < 0)]
    i = 0
    while i < len(order):
        order.extend(tree.kids[order[i]])
        i += 1
    return order


def _leg(tree: _Tree, root: int, label: str) -> dict[str, tuple[int, str]]:
    """hip, knee, ankle and (when present) foot of one leg's chain."""
    h = tree.height
    chain = tree.chain(root, lambda c: (-tree.zmin(c), len(tree.sub[c])))
    z = tree.rest[chain, 2]
    bottom = float(z.min())
    hip = next((i for i in range(len(chain) - 1) if z[i] - z[i + 1] >= 0.08 * h), None)
    if hip is None:
        raise InvalidInputError(f"{label}: the leg from joint {chain[0]} has no thigh (no joint above a long descent)")
    drop = z[hip] - bottom
    ankle = next((i for i in range(hip + 1, len(chain)) if z[i] - bottom <= 0.15 * drop), len(chain) - 1)
    inner = list(range(hip + 1, ankle))
    if not inner:
        raise InvalidInputError(
            f"{label}: too coarse for the physics skeleton: required joints missing: the knees (the leg from "
            f"joint {chain[hip]} has no joint between hip and ankle)"
        )
    knee = min(inner, key=lambda i: abs(tree.dist(chain[hip], chain[i]) - tree.dist(chain[i], chain[ankle])))
    out = {
        "hip": (chain[hip], "leg chain: top of the long descent"),
        "knee": (chain[knee], "leg chain: middle joint"),
        "ankle": (chain[ankle], "leg chain: near the bottom"),
    }
    if ankle + 1 < len(chain) and tree.dist(chain[ankle], chain[ankle + 1]) >= 0.02 * h:
        out["foot"] = (chain[ankle + 1], "leg chain: after the ankle")
    return out


def _arms(tree: _Tree, chain: list[int], label: str) -> tuple[list[int], int]:
    """The two sideways branches of the spine chain (the arms) and the chain joint they
    branch from."""
    h = tree.height
    on_chain = set(chain)
    axis = tree.rest[chain[0], :2]
    cands = []
    for k in chain[1:]:
        for c in tree.kids[k]:
            if c in on_chain:
                continue
            reach = np.linalg.norm(tree.rest[tree.sub[c], :2] - axis, axis=1).max()
            # arms held out (T-pose) reach far sideways; arms hanging at rest (a real
            # rig's A- or I-pose) less so, but they are the longest branches
            if reach >= 0.12 * h:
                length = np.linalg.norm(tree.rest[tree.sub[c]] - tree.rest[k], axis=1).max()
                cands.append((float(length), c, k))
    if len(cands) < 2:
        raise InvalidInputError(f"{label}: not a humanoid rig: no two arms branch sideways from the spine")
    cands.sort(reverse=True)
    (_, a, ka), (_, b, kb) = cands[:2]
    for c in (a, b):
        if tree.zmin(c) < tree.rest[chain[0], 2] - 0.3 * h:
            raise InvalidInputError(
                f"{label}: not a humanoid rig: the branch from joint {c} reaches the floor (front legs?)"
            )
    branch = ka if chain.index(ka) <= chain.index(kb) else kb
    return [a, b], branch


def _arm(tree: _Tree, root: int, label: str) -> dict[str, tuple[int, str]]:
    """collar (when present), shoulder, elbow, wrist and (when present) hand of one arm."""
    base = tree.rest[tree.parents[root]]
    chain = tree.chain(root, lambda c: float(np.linalg.norm(tree.rest[tree.sub[c]] - base, axis=1).max()))
    hub = next((i for i, k in enumerate(chain) if len(tree.kids[k]) >= 3), None)
    if hub is None:  # no fingers: the wrist sits where the chain's last long bone ends
        wrist = max(1, len(chain) - 2) if len(chain) > 3 else len(chain) - 1
    else:
        k = chain[hub]
        spread = np.mean([tree.dist(k, c) for c in tree.kids[k]])
        wrist = hub + 1 if spread > 0.04 * tree.height and hub + 1 < len(chain) else hub
    before = chain[:wrist]
    out: dict[str, tuple[int, str]] = {}
    if len(before) >= 3:
        out["collar"] = (before[0], "arm chain: first joint")
        shoulder, inner = 1, list(range(2, len(before)))
    else:
        shoulder, inner = 0, list(range(1, len(before)))
    w = chain[wrist]
    if not inner:
        raise InvalidInputError(
            f"{label}: too coarse for the physics skeleton: required joints missing: the elbows (the arm from "
            f"joint {root} has no joint between shoulder and wrist)"
        )
    s = before[shoulder]
    elbow = min(inner, key=lambda i: abs(tree.dist(s, before[i]) - tree.dist(before[i], w)))
    upper, fore = tree.dist(s, before[elbow]), tree.dist(before[elbow], w)
    if not 0.4 <= upper / max(fore, 1e-9) <= 2.5:
        raise InvalidInputError(
            f"{label}: too coarse for the physics skeleton: required joints missing: the elbows (the arm from "
            f"joint {root} has no joint half-way to the wrist: upper arm {upper:.3f} m, forearm {fore:.3f} m)"
        )
    out["shoulder"] = (s, "arm chain: start of the upper arm")
    out["elbow"] = (before[elbow], "arm chain: middle joint")
    out["wrist"] = (w, "arm chain: where the fingers branch")
    if wrist + 1 < len(chain):
        out["hand"] = (chain[wrist + 1], "arm chain: after the wrist")
    return out


def _spine(tree: _Tree, chain: list[int], branch: int, label: str) -> dict[str, tuple[int, str]]:
    """spine1..3, neck and head along the spine chain (``chain[0]`` is the pelvis)."""
    i_b = chain.index(branch)
    between = chain[1:i_b]
    after = chain[i_b + 1 :]
    out: dict[str, tuple[int, str]] = {}
    if not between:
        raise InvalidInputError(
            f"{label}: too coarse for the physics skeleton: required joints missing: spine1, spine2 (no joint "
            "between the pelvis and the arms)"
        )
    out["spine1"] = (between[0], "spine chain: above the pelvis")
    if len(between) == 1:
        out["spine2"] = (branch, "spine chain: where the arms branch")
    else:
        mid = 0.5 * (tree.rest[between[0], 2] + tree.rest[branch, 2])
        j = min(between[1:], key=lambda k: abs(tree.rest[k, 2] - mid))
        out["spine2"] = (j, "spine chain: half-way to the arms")
        out["spine3"] = (branch, "spine chain: where the arms branch")
    if len(after) < 2:
        raise InvalidInputError(
            f"{label}: too coarse for the physics skeleton: required joints missing: neck, head ({len(after)} "
            "joint above the arms)"
        )
    out["neck"] = (after[0], "spine chain: above the arms")
    out["head"] = (after[1], "spine chain: above the neck")
    return out


def _left_direction(
    tree: _Tree, legs: list[dict], forward: Sequence[float] | np.ndarray | None, label: str
) -> np.ndarray | None:
    """The horizontal direction of the rig's left: up x forward, forward from the toes when
    the legs have them, else ``forward``; None when neither is known."""
    dirs = [tree.rest[m["foot"][0]] - tree.rest[m["ankle"][0]] for m in legs if "foot" in m]
    fwd = np.mean(dirs, axis=0) if dirs else None
    if fwd is None or np.hypot(fwd[0], fwd[1]) < 1e-6:
        fwd = None if forward is None else np.asarray(forward, dtype=np.float64)
    if fwd is None:
        return None
    left = np.cross([0.0, 0.0, 1.0], fwd)
    n = np.linalg.norm(left[:2])
    return None if n < 1e-9 else left / n


def _order_sides(tree: _Tree, pair: list[int], sides: np.ndarray, left: np.ndarray | None, pelvis: int) -> list[int]:
    """Indices into ``pair`` as (left, right): by the names' side hints, else by geometry."""
    votes = [int(np.sign(sides[tree.sub[c]].sum())) for c in pair]
    if votes[0] != votes[1] and 0 not in votes:
        return [0, 1] if votes[0] < 0 else [1, 0]
    if left is None:
        raise InvalidInputError(
            "cannot tell the rig's left from its right (no side in the names, no toes, no forward direction): "
            "give the joints with --map"
        )
    off = [float((tree.rest[tree.sub[c]].mean(axis=0) - tree.rest[pelvis]) @ left) for c in pair]
    return [0, 1] if off[0] > off[1] else [1, 0]

"""BVH motion files: reading with retargeting to the 24-joint skeleton, and writing.

Reading (:func:`load_bvh`):

1. parse the hierarchy (joints, offsets, channels in any order, end sites) and the
   frames; every error names the file and the line;
2. forward kinematics of the file's own skeleton (rotation channels compose in the
   listed order, ``R = R_first R_second R_third``; position channels replace the offset);
3. map joint names to ours (``crowdstudy.body.skeleton.bvh_name_map``: CMU or Mixamo
   names, chosen automatically or forced with ``skeleton``);
4. change frames: the file's rest pose gives its up (hips -> head), left (right hip ->
   left hip) and forward axes, which are turned to ours (Z up, left at -x, facing +y), so
   Y-up files and other facings both work;
5. retarget: each of our joints takes the global rotation of its counterpart times a
   fixed rest alignment that turns our T-pose bone direction onto the file's rest bone
   direction (so A-pose or slightly bent rest poses are handled); local rotations follow;
6. units: the root path is scaled by our leg length over the file's (CMU files are in
   about 1/0.056 m units, Mixamo in cm) and lowered so the feet touch the floor.

Writing (:func:`save_bvh`) exports a clip on our skeleton (Y up, centimetres, Mixamo or
CMU names) for other tools; reading it back gives the same joint positions.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import NoReturn

import numpy as np

from crowdstudy.body.skeleton import DEFAULT_REST_JOINTS, JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, PARENTS
from crowdstudy.errors import InvalidInputError
from crowdstudy.motion.clip import MotionClip
from crowdstudy.motion.rig import ANKLE_HEIGHT, LEG_LENGTH

__all__ = ["BvhSkeleton", "parse_bvh", "load_bvh", "save_bvh"]

_AXES = {"X": 0, "Y": 1, "Z": 2}
_CHANNELS = {"Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"}
#: Our joint -> the joint whose direction from it defines its bone (for rest alignment).
_BONE_CHILD = {
    "left_hip": "left_knee",
    "right_hip": "right_knee",
    "spine1": "spine2",
    "left_knee": "left_ankle",
    "right_knee": "right_ankle",
    "spine2": "spine3",
    "left_ankle": "left_foot",
    "right_ankle": "right_foot",
    "spine3": "neck",
    "neck": "head",
    "left_collar": "left_shoulder",
    "right_collar": "right_shoulder",
    "left_shoulder": "left_elbow",
    "right_shoulder": "right_elbow",
    "left_elbow": "left_wrist",
    "right_elbow": "right_wrist",
    "left_wrist": "left_hand",
    "right_wrist": "right_hand",
}


class BvhSkeleton:
    """A parsed BVH file.

    Attributes:
        names: (B,) joint names in file order; parents: (B,) parent index (-1 root).
        offsets: (B, 3) rest offsets from the parent, file units.
        channels: per joint, the list of channel names in file order.
        end_sites: (B, 3) offset of the joint's end site (NaN when none).
        frame_time: seconds per frame; motion: (F, C) channel values (degrees / units).
    """

    def __init__(self, names, parents, offsets, channels, end_sites, frame_time, motion, source):
        self.names = list(names)
        self.parents = np.asarray(parents, dtype=np.int64)
        self.offsets = np.asarray(offsets, dtype=np.float64)
        self.channels = channels
        self.end_sites = np.asarray(end_sites, dtype=np.float64)
        self.frame_time = float(frame_time)
        self.motion = np.asarray(motion, dtype=np.float64)
        self.source = source

    @property
    def n_frames(self) -> int:
        return self.motion.shape[0]

    def rest_positions(self) -> np.ndarray:
        """(B, 3) joint positions in the rest pose (file units, root at the origin)."""
        pos = np.zeros_like(self.offsets)
        for j, p in enumerate(self.parents):
            if p >= 0:
                pos[j] = pos[p] + self.offsets[j]
        return pos

    def global_transforms(self) -> tuple[np.ndarray, np.ndarray]:
        """Global rotations (F, B, 3, 3) and positions (F, B, 3) of every joint, file frame."""
        from scipy.spatial.transform import Rotation

        n_f, n_b = self.n_frames, len(self.names)
        glob = np.empty((n_f, n_b, 3, 3))
        pos = np.empty((n_f, n_b, 3))
        col = 0
        for j in range(n_b):
            chans = self.channels[j]
            values = self.motion[:, col : col + len(chans)]
            col += len(chans)
            offset = np.broadcast_to(self.offsets[j], (n_f, 3)).copy()
            rot_axes = ""
            rot_cols = []
            for k, ch in enumerate(chans):
                if ch.endswith("position"):
                    offset[:, _AXES[ch[0]]] = values[:, k]
                else:
                    rot_axes += ch[0]
                    rot_cols.append(k)
            local = (
                Rotation.from_euler(rot_axes, values[:, rot_cols], degrees=True).as_matrix()
                if rot_axes
                else np.broadcast_to(np.eye(3), (n_f, 3, 3))
            )
            p = self.parents[j]
            if p < 0:
                glob[:, j] = local
                pos[:, j] = offset
            else:
                glob[:, j] = glob[:, p] @ local
                pos[:, j] = pos[:, p] + np.einsum("fab,fb->fa", glob[:, p], offset)
        return glob, pos


def _fail(path, line: int | None, msg: str) -> NoReturn:
    where = f"{path}: line {line}" if line is not None else f"{path}"
    raise InvalidInputError(f"BVH file {where}: {msg}")


def _number(tok: str, path, line: int, field: str) -> float:
    try:
        value = float(tok)
    except ValueError:
        _fail(path, line, f"{field}: expected a number, got {tok!r}")
    if not np.isfinite(value):
        _fail(path, line, f"{field}: expected a finite number, got {tok!r}")
    return value


def parse_bvh(path: str | Path) -> BvhSkeleton:
    """Read a BVH file (``.bvh``, or gzipped ``.bvh.gz``: hierarchy and motion) without interpreting it."""
    path = Path(path)
    lines = _read_lines(path)
    hierarchy, i = _parse_hierarchy(lines, path)
    n_channels = sum(len(c) for c in hierarchy.channels)
    frame_time, motion = _parse_motion(lines, i, n_channels, path)
    return BvhSkeleton(
        hierarchy.names,
        hierarchy.parents,
        hierarchy.offsets,
        hierarchy.channels,
        hierarchy.ends,
        frame_time,
        motion,
        str(path),
    )


def _read_lines(path: Path) -> list[str]:
    """The lines of a BVH file, plain or gzipped (``.gz``), decoded as strict UTF-8."""
    if not path.is_file():
        raise InvalidInputError(f"BVH file {str(path)!r} does not exist")
    try:
        if path.suffix == ".gz":
            import gzip

            with gzip.open(path, "rt", encoding="utf-8", errors="strict") as fh:
                return fh.read().splitlines()
        return path.read_text(encoding="utf-8", errors="strict").splitlines()
    except (UnicodeDecodeError, OSError, EOFError) as exc:
        raise InvalidInputError(f"BVH file {path}: not a text file ({exc})") from None


#: the ``stack`` / ``pending`` entry of an End Site block in :class:`_Hierarchy`
_END_SITE = -2


@dataclasses.dataclass
class _Hierarchy:
    """The HIERARCHY section read line by line: the joints in file order (names, parent
    indices, offsets and end-site offsets in file units, channel names) and the state of
    the braces (``stack`` of open blocks, joint indices or :data:`_END_SITE`)."""

    path: Path
    names: list[str] = dataclasses.field(default_factory=list)
    parents: list[int] = dataclasses.field(default_factory=list)
    offsets: list[list[float] | None] = dataclasses.field(default_factory=list)
    channels: list[list[str]] = dataclasses.field(default_factory=list)
    ends: list[list[float]] = dataclasses.field(default_factory=list)
    stack: list[int] = dataclasses.field(default_factory=list)
    pending: int | None = None  # the block whose '{' is expected
    in_end: bool = False

    def read(self, toks: list[str], n: int) -> None:
        """Take one non-blank line (its tokens, ``n`` its 1-based number) of the hierarchy."""
        key = toks[0]
        if key in ("ROOT", "JOINT"):
            self._joint(key, toks, n)
        elif key == "End":
            if not self.stack:
                _fail(self.path, n, "field 'End Site': outside of a joint block")
            self.in_end = True
            self.pending = _END_SITE
        elif key == "{":
            if self.pending is None:
                _fail(self.path, n, "unexpected '{'")
            self.stack.append(self.pending)
            self.pending = None
        elif key == "}":
            self._close(n)
        elif key == "OFFSET":
            self._offset(toks, n)
        elif key == "CHANNELS":
            self._channels(toks, n)
        else:
            _fail(self.path, n, f"unknown keyword {key!r} in the hierarchy")

    def _joint(self, key: str, toks: list[str], n: int) -> None:
        if len(toks) < 2:
            _fail(self.path, n, f"field '{key}': missing the joint name")
        if key == "ROOT" and (self.names or self.stack):
            _fail(self.path, n, "field 'ROOT': only one root is supported")
        if key == "JOINT" and not self.stack:
            _fail(self.path, n, "field 'JOINT': outside of a joint block")
        name = " ".join(toks[1:])
        if name in self.names:
            _fail(self.path, n, f"field '{key}': duplicate joint name {name!r}")
        self.names.append(name)
        self.parents.append(self.stack[-1] if self.stack else -1)
        self.offsets.append(None)
        self.channels.append([])
        self.ends.append([np.nan] * 3)
        self.pending = len(self.names) - 1

    def _close(self, n: int) -> None:
        if not self.stack:
            _fail(self.path, n, "unbalanced '}'")
        top = self.stack.pop()
        if top == _END_SITE:
            self.in_end = False
        elif self.offsets[top] is None:
            _fail(self.path, n, f"field 'OFFSET': missing for joint {self.names[top]!r}")

    def _offset(self, toks: list[str], n: int) -> None:
        if len(toks) != 4:
            _fail(self.path, n, f"field 'OFFSET': expected 3 numbers, got {len(toks) - 1}")
        vals = [_number(t, self.path, n, "OFFSET") for t in toks[1:]]
        if self.in_end:
            self.ends[self.stack[-2] if len(self.stack) >= 2 else self.stack[-1]] = vals
        else:
            self.offsets[self.stack[-1]] = vals

    def _channels(self, toks: list[str], n: int) -> None:
        if self.in_end or not self.stack:
            _fail(self.path, n, "field 'CHANNELS': not inside a joint")
        try:
            count = int(toks[1])
        except (IndexError, ValueError):
            _fail(self.path, n, "field 'CHANNELS': expected a channel count")
        chans = toks[2:]
        if len(chans) != count:
            _fail(self.path, n, f"field 'CHANNELS': count says {count}, lists {len(chans)}")
        bad = [c for c in chans if c not in _CHANNELS]
        if bad:
            _fail(self.path, n, f"field 'CHANNELS': unknown channel {bad[0]!r} (expected X/Y/Z position/rotation)")
        self.channels[self.stack[-1]] = chans


def _parse_hierarchy(lines: list[str], path: Path) -> tuple[_Hierarchy, int]:
    """The HIERARCHY section (after any blank lines at the top) up to its MOTION line;
    returns it and the index of the line after MOTION."""
    i = 0
    while i < len(lines) and not lines[i].strip():
        i += 1
    if i >= len(lines) or lines[i].strip() != "HIERARCHY":
        _fail(path, i + 1 if i < len(lines) else None, "field 'HIERARCHY': expected the file to start with it")
    hierarchy = _Hierarchy(path)
    motion_line = None
    start = i + 1
    for i in range(start, len(lines)):
        toks = lines[i].split()
        if not toks:
            continue
        if toks[0] == "MOTION":
            motion_line = i + 1
            break
        hierarchy.read(toks, i + 1)
    if motion_line is None:
        _fail(path, None, "field 'MOTION': missing (truncated file?)")
    if hierarchy.stack:
        _fail(
            path,
            motion_line,
            f"the hierarchy is not closed (joint {hierarchy.names[hierarchy.stack[-1]]!r} has no '}}')",
        )
    if not hierarchy.names:
        _fail(path, motion_line, "the hierarchy has no joints")
    for name, offset in zip(hierarchy.names, hierarchy.offsets, strict=True):
        if offset is None:  # a joint line without its block
            _fail(path, motion_line, f"field 'OFFSET': missing for joint {name!r}")
    return hierarchy, motion_line


def _motion_header(lines: list[str], i: int, key: str, path: Path) -> tuple[str, int, int]:
    """The value after ``key`` on the first non-blank line from index ``i``: returns
    ``(value, its 1-based line number, the index of the next line)``."""
    while i < len(lines) and not lines[i].strip():
        i += 1
    if i >= len(lines):
        _fail(path, None, f"field {key!r}: missing (truncated file?)")
    text, n = lines[i].strip(), i + 1
    if not text.startswith(key):
        _fail(path, n, f"field {key!r}: expected it here, got {text[:40]!r}")
    return text[len(key) :].strip(), n, i + 1


def _parse_motion(lines: list[str], i: int, n_channels: int, path: Path) -> tuple[float, np.ndarray]:
    """The MOTION section from line index ``i``: ``(frame_time seconds, motion (F, C) channel
    values)``, C = ``n_channels`` (degrees for rotations, file units for positions)."""
    value, n, i = _motion_header(lines, i, "Frames:", path)
    try:
        n_frames = int(value)
    except ValueError:
        _fail(path, n, f"field 'Frames': expected an integer, got {value!r}")
    if n_frames < 1:
        _fail(path, n, f"field 'Frames': expected at least 1 frame, got {n_frames}")
    value, n, i = _motion_header(lines, i, "Frame Time:", path)
    frame_time = _number(value, path, n, "Frame Time")
    if frame_time <= 0:
        _fail(path, n, f"field 'Frame Time': expected a positive number of seconds, got {value!r}")
    return frame_time, _read_frames(lines, i, n_frames, n_channels, path)


def _read_frames(lines: list[str], i: int, n_frames: int, n_channels: int, path: Path) -> np.ndarray:
    """``n_frames`` rows of ``n_channels`` finite numbers from line index ``i`` on (blank lines
    skipped, lines after the last frame ignored) -> (n_frames, n_channels) float64."""
    rows = []
    while i < len(lines) and len(rows) < n_frames:
        text = lines[i]
        n = i + 1
        i += 1
        if not text.strip():
            continue
        toks = text.split()
        if len(toks) != n_channels:
            _fail(path, n, f"frame {len(rows)}: expected {n_channels} channel values, got {len(toks)}")
        try:
            row = np.array(toks, dtype=np.float64)
        except ValueError:
            bad = next(t for t in toks if not _is_float(t))
            _fail(path, n, f"frame {len(rows)}: expected numbers, got {bad!r}")
        if not np.all(np.isfinite(row)):
            _fail(path, n, f"frame {len(rows)}: non-finite channel value")
        rows.append(row)
    if len(rows) < n_frames:
        _fail(path, len(lines), f"field 'Frames' says {n_frames} frames, the file has {len(rows)} (truncated?)")
    return np.stack(rows) if n_channels else np.zeros((n_frames, 0))


def _is_float(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _snap(v: np.ndarray) -> np.ndarray:
    """The signed coordinate axis closest to direction v."""
    k = int(np.argmax(np.abs(v)))
    out = np.zeros(3)
    out[k] = np.sign(v[k]) if v[k] != 0 else 1.0
    return out


def _swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation (3, 3) turning direction a onto direction b."""
    from crowdstudy.body.rotations import axis_angle_to_matrix

    a, b = _unit(a), _unit(b)
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(np.dot(a, b))
    if s < 1e-9:
        if c > 0:
            return np.eye(3)
        perp = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        return axis_angle_to_matrix(_unit(perp) * np.pi)
    return axis_angle_to_matrix(axis / s * np.arctan2(s, c))


def load_bvh(
    path: str | Path, skeleton: str = "auto", *, rest_joints: np.ndarray | None = None, name: str | None = None
) -> MotionClip:
    """Read a BVH file and retarget it to the 24-joint skeleton.

    Args:
        path: the ``.bvh`` file.
        skeleton: "auto" (pick the naming that matches), "cmu", "daz" (B. Hahne's
            Daz-friendly CMU release) or "mixamo".
        rest_joints: (24, 3) target skeleton for scaling and grounding (default the
            authoring skeleton).
        name: clip name (default the file stem).

    Returns:
        A non-looping ``MotionClip`` (kind "mocap") at the file's frame rate; meta holds
        the source, naming, unit scale (metres per file unit) and frame count.
    """
    from crowdstudy.body.rotations import matrix_to_axis_angle
    from crowdstudy.body.skeleton import BVH_DERIVED_JOINTS, bvh_convention, bvh_name_map, forward_kinematics

    if skeleton not in ("auto", "cmu", "daz", "mixamo"):
        raise InvalidInputError(f"skeleton: expected 'auto', 'cmu', 'daz' or 'mixamo', got {skeleton!r}")
    bvh = parse_bvh(path)
    convention = bvh_convention(bvh.names) if skeleton == "auto" else skeleton
    try:
        mapping = bvh_name_map(bvh.names, convention)
    except InvalidInputError as exc:
        raise InvalidInputError(f"BVH file {path}: joint names: {exc}") from None
    index = {ours: bvh.names.index(theirs) for theirs, ours in mapping.items()}
    rest = np.array(DEFAULT_REST_JOINTS if rest_joints is None else rest_joints, dtype=np.float64)
    if rest.shape != (NUM_JOINTS, 3):
        raise InvalidInputError(f"rest_joints: expected shape ({NUM_JOINTS}, 3), got {rest.shape}")

    rest_bvh = bvh.rest_positions()
    at = {j: rest_bvh[index[j]] for j in JOINT_NAMES if j in index}
    for j, (anchor, end, fraction) in BVH_DERIVED_JOINTS.get(convention, {}).items():
        if j in index:
            continue
        a = bvh.names.index(anchor)
        end_pos = rest_bvh[a] + bvh.end_sites[a] if end is None else rest_bvh[bvh.names.index(end)]
        if not np.all(np.isfinite(end_pos)):
            raise InvalidInputError(f"BVH file {path}: joint {anchor!r} has no end site to place {j!r}")
        index[j] = a  # rotates with its anchor
        at[j] = rest_bvh[a] + fraction * (end_pos - rest_bvh[a])
    # The file's axes, snapped to its coordinate axes (mocap frames are axis aligned; the
    # rest pose itself may lean a little).
    up = _snap(at["head"] - at["pelvis"])
    left = at["left_hip"] - at["right_hip"]
    left = _snap(left - np.dot(left, up) * up)
    forward = np.cross(left, up)
    frame_bvh = np.stack([left, forward, up], axis=1)
    frame_ours = np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]).T
    conv = frame_ours @ frame_bvh.T  # file frame -> ours

    def leg_length(points) -> float:
        return float(
            np.mean(
                [
                    np.linalg.norm(points[f"{s}_knee"] - points[f"{s}_hip"])
                    + np.linalg.norm(points[f"{s}_ankle"] - points[f"{s}_knee"])
                    for s in ("left", "right")
                ]
            )
        )

    ours_at = {j: rest[JOINT_INDEX[j]] for j in JOINT_NAMES}
    file_leg = leg_length(at)
    if file_leg <= 0:
        raise InvalidInputError(f"BVH file {path}: the legs have zero length in the rest pose")
    unit = leg_length(ours_at) / file_leg

    # Rest alignment per joint: our T-pose bone direction -> the file's rest bone direction.
    align = np.broadcast_to(np.eye(3), (NUM_JOINTS, 3, 3)).copy()
    for j, jn in enumerate(JOINT_NAMES):
        child = _BONE_CHILD.get(jn)
        if child is not None:
            d_file = conv @ (at[child] - at[jn])
            d_ours = ours_at[child] - ours_at[jn]
            if np.linalg.norm(d_file) > 1e-9 * file_leg and np.linalg.norm(d_ours) > 1e-9:
                align[j] = _swing(d_ours, d_file)
                continue
        if PARENTS[j] >= 0:
            align[j] = align[PARENTS[j]]
    glob_file, pos_file = bvh.global_transforms()
    sel = [index[j] for j in JOINT_NAMES]
    glob = np.einsum("ab,fjbc,dc->fjad", conv, glob_file[:, sel], conv) @ align  # (F, 24, 3, 3)
    local = glob.copy()
    local[:, 1:] = np.swapaxes(glob[:, PARENTS[1:]], -1, -2) @ glob[:, 1:]
    root = np.einsum("ab,fb->fa", conv, pos_file[:, index["pelvis"]]) * unit
    rotations = matrix_to_axis_angle(local)
    _, joints = forward_kinematics(rest, rotations, root)
    # Ground on a low percentile of the lower ankle (robust to a calibration frame).
    feet = float(np.percentile(joints[:, [JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]], 2].min(axis=1), 5))
    root[:, 2] += ANKLE_HEIGHT * _leg_ratio(rest) - feet
    meta = {
        "source": str(path),
        "skeleton": convention,
        "unit_scale": unit,
        "frames": bvh.n_frames,
        "frame_time": bvh.frame_time,
    }
    return MotionClip(
        name=name or Path(path).stem,
        kind="mocap",
        fps=1.0 / bvh.frame_time,
        joint_rotations=rotations,
        root_translation=root,
        loop=False,
        meta=meta,
    )


def _leg_ratio(rest: np.ndarray) -> float:
    """Leg length of ``rest`` over the authoring skeleton's."""
    legs = [
        np.linalg.norm(rest[JOINT_INDEX[f"{s}_knee"]] - rest[JOINT_INDEX[f"{s}_hip"]])
        + np.linalg.norm(rest[JOINT_INDEX[f"{s}_ankle"]] - rest[JOINT_INDEX[f"{s}_knee"]])
        for s in ("left", "right")
    ]
    return float(np.mean(legs)) / LEG_LENGTH


def save_bvh(
    clip: MotionClip,
    path: str | Path,
    *,
    naming: str = "mixamo",
    rest_joints: np.ndarray | None = None,
    units_per_metre: float = 100.0,
    order: str = "ZXY",
) -> Path:
    """Write a clip as a BVH file on our skeleton: Y up, facing +z, left at +x (the usual
    BVH frame), ``units_per_metre`` file units per metre, Euler channels in ``order``.

    Walking clips are written in place (their ``travel`` is not added).
    """
    from scipy.spatial.transform import Rotation

    from crowdstudy.body.rotations import axis_angle_to_matrix
    from crowdstudy.body.skeleton import BVH_NAME_MAPS

    if naming not in BVH_NAME_MAPS:
        raise InvalidInputError(f"naming: expected one of {sorted(BVH_NAME_MAPS)}, got {naming!r}")
    if sorted(order) != ["X", "Y", "Z"]:
        raise InvalidInputError(f"order: expected a permutation of 'XYZ', got {order!r}")
    names = {ours: theirs for theirs, ours in BVH_NAME_MAPS[naming].items()}
    rest = np.array(DEFAULT_REST_JOINTS if rest_joints is None else rest_joints, dtype=np.float64)
    # ours (Z up, facing +y, left -x) -> file (Y up, facing +z, left +x)
    conv = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]).T
    local = axis_angle_to_matrix(clip.joint_rotations)
    local_file = np.einsum("ab,fjbc,dc->fjad", conv, local, conv)
    euler = Rotation.from_matrix(local_file.reshape(-1, 3, 3)).as_euler(order, degrees=True)
    euler = euler.reshape(clip.n_frames, NUM_JOINTS, 3)
    root = clip.root_translation @ conv.T * units_per_metre
    kids = [[c for c in range(NUM_JOINTS) if PARENTS[c] == j] for j in range(NUM_JOINTS)]
    out = ["HIERARCHY"]
    rot_channels = " ".join(f"{a}rotation" for a in order)

    def emit(j: int, depth: int) -> None:
        pad = "  " * depth
        off = conv @ (rest[j] - rest[PARENTS[j]]) * units_per_metre if j else np.zeros(3)
        out.append(f"{pad}{'ROOT' if j == 0 else 'JOINT'} {names[JOINT_NAMES[j]]}")
        out.append(f"{pad}{{")
        out.append(f"{pad}  OFFSET {off[0]:.6f} {off[1]:.6f} {off[2]:.6f}")
        if j == 0:
            out.append(f"{pad}  CHANNELS 6 Xposition Yposition Zposition {rot_channels}")
        else:
            out.append(f"{pad}  CHANNELS 3 {rot_channels}")
        for c in kids[j]:
            emit(c, depth + 1)
        if not kids[j]:
            out.append(f"{pad}  End Site")
            out.append(f"{pad}  {{")
            out.append(f"{pad}    OFFSET 0.000000 {0.05 * units_per_metre:.6f} 0.000000")
            out.append(f"{pad}  }}")
        out.append(f"{pad}}}")

    emit(0, 0)
    out += ["MOTION", f"Frames: {clip.n_frames}", f"Frame Time: {1.0 / clip.fps:.8f}"]
    order_dfs: list[int] = []

    def walk(j: int) -> None:
        order_dfs.append(j)
        for c in kids[j]:
            walk(c)

    walk(0)
    for f in range(clip.n_frames):
        vals = list(root[f]) + [v for j in order_dfs for v in euler[f, j]]
        out.append(" ".join(f"{v:.6f}" for v in vals))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(out) + "\n", encoding="utf-8")
    return path

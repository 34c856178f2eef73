"""Scene containers passed between stages.

* :class:`Crowd`: 2D positions (a layout, T = 1) or trajectories of disc agents, the output
  of :mod:`crowdstudy.layout` and :mod:`crowdstudy.navigation`.
* :class:`CrowdAnimation`: full-body animation of N characters over T frames, the output of
  :mod:`crowdstudy.motion` (Baseline) and :mod:`crowdstudy.physics` (Ours).

Both save to a single ``.npz`` holding the arrays plus one JSON string (``__meta__``) with
the non-array fields and the schema version; loading validates every field and raises
:class:`~crowdstudy.errors.InvalidInputError` naming the file and the field.

A periodic scene (the walking corridor) records ``meta["periodic"] = {"axis": 0,
"length": L}``: positions are stored *unwrapped* (continuous in time) and every consumer
(physics contacts, overlap metrics, renderer) uses the minimum-image convention along that
axis.
"""

from __future__ import annotations

import dataclasses
import io
import json
import zipfile
from pathlib import Path

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.scene_meta import check_meta, periodic_length

__all__ = ["CrowdAnimation", "Crowd", "SCHEMA_VERSION"]

SCHEMA_VERSION = 1


def _as_array(value, name: str, dtype, ndim: int | None = None, cls: str = "") -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"{cls}.{name}: cannot convert to {np.dtype(dtype).name} array ({exc})") from None
    if ndim is not None and arr.ndim != ndim:
        raise InvalidInputError(f"{cls}.{name}: expected a {ndim}-D array, got shape {arr.shape}")
    return arr


def _check_finite(arr: np.ndarray, name: str, cls: str) -> None:
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise InvalidInputError(f"{cls}.{name}: non-finite value at index {tuple(int(i) for i in bad)}")


def _save_npz(path: Path, arrays: dict[str, np.ndarray], meta: dict) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = dict(arrays)
    payload["__meta__"] = np.array(json.dumps(meta, sort_keys=True, default=_json_default))
    # Write through a fixed-timestamp zip so identical content gives identical bytes.
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for key in sorted(payload):
            arr_buf = io.BytesIO()
            np.lib.format.write_array(arr_buf, np.asarray(payload[key]), allow_pickle=False)
            info = zipfile.ZipInfo(f"{key}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            zf.writestr(info, arr_buf.getvalue())
    tmp = path.with_suffix(path.suffix + ".tmp")
    try:
        tmp.write_bytes(buf.getvalue())
        tmp.replace(path)
    except BaseException:
        try:
            tmp.unlink(missing_ok=True)  # never leave a partial .tmp behind
        except OSError:
            pass
        raise
    return path


def _json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__}")


def _load_npz(path, cls: str) -> tuple[dict[str, np.ndarray], dict]:
    path = Path(path)
    if not path.is_file():
        raise InvalidInputError(f"{cls} file {str(path)!r} does not exist")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise InvalidInputError(f"{cls} file {str(path)!r} is not a readable .npz archive ({exc})") from None
    if "__meta__" not in arrays:
        raise InvalidInputError(f"{cls} file {str(path)!r}: field '__meta__' is missing (not a crowdstudy file?)")
    try:
        meta = json.loads(str(arrays.pop("__meta__")))
    except json.JSONDecodeError as exc:
        raise InvalidInputError(f"{cls} file {str(path)!r}: field '__meta__' is not valid JSON ({exc})") from None
    if meta.get("type") != cls:
        raise InvalidInputError(f"{cls} file {str(path)!r}: holds a {meta.get('type')!r}, expected {cls!r}")
    version = meta.get("schema_version")
    if version != SCHEMA_VERSION:
        raise InvalidInputError(
            f"{cls} file {str(path)!r}: field 'schema_version' is {version!r}, this crowdstudy reads {SCHEMA_VERSION}"
        )
    return arrays, meta


@dataclasses.dataclass(frozen=True, eq=False)
class CrowdAnimation:
    """Full-body animation of N characters over T frames.

    Attributes:
        joint_names: (J,) joint names (default: the 24-joint SMPL-compatible tree).
        parents: (J,) int parent indices, -1 for the root, ``parents[j] < j``.
        root_translation: (T, N, 3) float64, metres; world position of the pelvis.
        joint_rotations: (T, N, J, 3) float64 axis-angle radians; joint 0 is the global
            root orientation, the others are relative to their parent.
        fps: frames per second (> 0).
        bodies: N records (dicts): ``model`` (body model id), ``sex``, ``height`` (m),
            ``shape`` (list of shape parameters), plus any model-specific fields.
        clips: N records (dicts): which motion clip(s) drive the character, ``phase``.
        meta: scenario, density, seed, provenance, the scene's geometry, ``periodic``,
            ``loop``, ``physics`` ...: every key the package writes or reads is listed in
            :mod:`crowdstudy.scene_meta` and checked (:func:`~crowdstudy.scene_meta.check_meta`)
            when the animation is made, loaded or saved; other keys are the user's own.
    """

    joint_names: tuple[str, ...]
    parents: np.ndarray
    root_translation: np.ndarray
    joint_rotations: np.ndarray
    fps: float
    bodies: tuple[dict, ...]
    clips: tuple[dict, ...]
    meta: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        cls = "CrowdAnimation"
        names = tuple(self.joint_names)
        if not names or not all(isinstance(n, str) and n for n in names):
            raise InvalidInputError(f"{cls}.joint_names: expected a non-empty sequence of non-empty strings")
        if len(set(names)) != len(names):
            raise InvalidInputError(f"{cls}.joint_names: duplicate names")
        n_j = len(names)
        parents = _as_array(self.parents, "parents", np.int64, 1, cls)
        if parents.shape != (n_j,):
            raise InvalidInputError(f"{cls}.parents: expected shape ({n_j},) to match joint_names, got {parents.shape}")
        if parents[0] != -1 or np.any(parents[1:] < 0) or np.any(parents[1:] >= np.arange(1, n_j)):
            raise InvalidInputError(f"{cls}.parents: expected -1 for joint 0 and 0 <= parents[j] < j for the others")
        root = _as_array(self.root_translation, "root_translation", np.float64, 3, cls)
        if root.shape[2] != 3:
            raise InvalidInputError(f"{cls}.root_translation: expected shape (T, N, 3), got {root.shape}")
        t, n = root.shape[:2]
        if t < 1 or n < 1:
            raise InvalidInputError(
                f"{cls}.root_translation: needs at least one frame and one character, got {root.shape}"
            )
        rot = _as_array(self.joint_rotations, "joint_rotations", np.float64, 4, cls)
        if rot.shape != (t, n, n_j, 3):
            raise InvalidInputError(
                f"{cls}.joint_rotations: expected shape (T, N, J, 3) = ({t}, {n}, {n_j}, 3), got {rot.shape}"
            )
        _check_finite(root, "root_translation", cls)
        _check_finite(rot, "joint_rotations", cls)
        try:
            fps = float(self.fps)
        except (TypeError, ValueError):
            raise InvalidInputError(f"{cls}.fps: expected a number, got {self.fps!r}") from None
        if not np.isfinite(fps) or fps <= 0:
            raise InvalidInputError(f"{cls}.fps: expected a positive frame rate, got {self.fps!r}")
        for field in ("bodies", "clips"):
            records = tuple(getattr(self, field))
            if len(records) != n:
                raise InvalidInputError(f"{cls}.{field}: expected {n} records (one per character), got {len(records)}")
            for i, rec in enumerate(records):
                if not isinstance(rec, dict):
                    raise InvalidInputError(f"{cls}.{field}[{i}]: expected a dict, got {type(rec).__name__}")
            object.__setattr__(self, field, records)
        if not isinstance(self.meta, dict):
            raise InvalidInputError(f"{cls}.meta: expected a dict, got {type(self.meta).__name__}")
        check_meta(self.meta, cls)
        root.flags.writeable = False
        rot.flags.writeable = False
        parents.flags.writeable = False
        object.__setattr__(self, "joint_names", names)
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "root_translation", root)
        object.__setattr__(self, "joint_rotations", rot)
        object.__setattr__(self, "fps", fps)

    # -- sizes -------------------------------------------------------------------------
    @property
    def n_frames(self) -> int:
        return self.root_translation.shape[0]

    @property
    def n_characters(self) -> int:
        return self.root_translation.shape[1]

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def duration(self) -> float:
        """Seconds covered: n_frames / fps."""
        return self.n_frames / self.fps

    @property
    def periodic_length(self) -> float | None:
        """Period along x in metres for periodic scenes (corridor), else None."""
        return periodic_length(self.meta)

    # -- derived copies ----------------------------------------------------------------
    def replace(self, **changes) -> CrowdAnimation:
        """A validated copy with some fields replaced (``meta`` is merged, not replaced)."""
        if "meta" in changes:
            changes["meta"] = {**self.meta, **changes["meta"]}
        return dataclasses.replace(self, **changes)

    def frames(self, start: int = 0, stop: int | None = None) -> CrowdAnimation:
        """The frames [start, stop) as a new animation."""
        sl = slice(start, stop)
        if len(range(*sl.indices(self.n_frames))) == 0:
            raise InvalidInputError(f"frames: empty range [{start}, {stop}) of {self.n_frames} frames")
        return self.replace(root_translation=self.root_translation[sl], joint_rotations=self.joint_rotations[sl])

    # -- files -------------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Write one ``.npz`` (arrays + JSON metadata); identical content gives identical bytes.
        ``meta`` is checked again (:func:`~crowdstudy.scene_meta.check_meta`): it is a dict
        its owner may have changed since the animation was made."""
        check_meta(self.meta, f"CrowdAnimation.save({str(path)!r})")
        meta = {
            "type": "CrowdAnimation",
            "schema_version": SCHEMA_VERSION,
            "joint_names": list(self.joint_names),
            "fps": self.fps,
            "bodies": list(self.bodies),
            "clips": list(self.clips),
            "meta": self.meta,
        }
        return _save_npz(
            Path(path),
            {
                "parents": self.parents,
                "root_translation": self.root_translation,
                "joint_rotations": self.joint_rotations,
            },
            meta,
        )

    @classmethod
    def load(cls, path: str | Path) -> CrowdAnimation:
        """Read and validate a file written by :meth:`save`."""
        arrays, meta = _load_npz(path, "CrowdAnimation")
        for key in ("parents", "root_translation", "joint_rotations"):
            if key not in arrays:
                raise InvalidInputError(f"CrowdAnimation file {str(path)!r}: field {key!r} is missing")
        for key in ("joint_names", "fps", "bodies", "clips", "meta"):
            if key not in meta:
                raise InvalidInputError(f"CrowdAnimation file {str(path)!r}: field {key!r} is missing")
        try:
            return cls(
                joint_names=tuple(meta["joint_names"]),
                parents=arrays["parents"],
                root_translation=arrays["root_translation"],
                joint_rotations=arrays["joint_rotations"],
                fps=meta["fps"],
                bodies=tuple(meta["bodies"]),
                clips=tuple(meta["clips"]),
                meta=meta["meta"],
            )
        except InvalidInputError as exc:
            raise InvalidInputError(f"CrowdAnimation file {str(path)!r}: {exc}") from None


@dataclasses.dataclass(frozen=True, eq=False)
class Crowd:
    """2D disc agents: a layout (T = 1) or trajectories sampled at ``fps``.

    Attributes:
        positions: (T, N, 2) float64 metres in the (x, y) floor plane (unwrapped when
            periodic).
        radius: (N,) float64 metres, disc radius of each agent.
        fps: samples per second (> 0; any value for a layout).
        velocities: (T, N, 2) float64 m/s, or None for a layout.
        headings: (T, N) float64 radians, facing direction measured from +x towards +y,
            or None (then characters face the design's front, +y).
        obstacles: (M, 2, 2) float64 metres, static wall segments.
        region: (K, 2) float64 metres, the polygon the agents were placed in.
        meta: scenario, density, seed, provenance, ``periodic`` ...
    """

    positions: np.ndarray
    radius: np.ndarray
    fps: float = 30.0
    velocities: np.ndarray | None = None
    headings: np.ndarray | None = None
    obstacles: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 2, 2)))
    region: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 2)))
    meta: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        cls = "Crowd"
        pos = _as_array(self.positions, "positions", np.float64, None, cls)
        if pos.ndim == 2:
            pos = pos[None]
        if pos.ndim != 3 or pos.shape[2] != 2 or pos.shape[0] < 1 or pos.shape[1] < 1:
            raise InvalidInputError(
                f"{cls}.positions: expected shape (T, N, 2) or (N, 2), got {np.shape(self.positions)}"
            )
        _check_finite(pos, "positions", cls)
        t, n = pos.shape[:2]
        radius = _as_array(self.radius, "radius", np.float64, None, cls)
        radius = np.broadcast_to(radius, (n,)).copy() if radius.ndim == 0 else radius
        if radius.shape != (n,) or np.any(~np.isfinite(radius)) or np.any(radius <= 0):
            raise InvalidInputError(f"{cls}.radius: expected {n} positive radii, got shape {radius.shape}")
        vel = None
        if self.velocities is not None:
            vel = _as_array(self.velocities, "velocities", np.float64, 3, cls)
            if vel.shape != pos.shape:
                raise InvalidInputError(f"{cls}.velocities: expected shape {pos.shape}, got {vel.shape}")
            _check_finite(vel, "velocities", cls)
        head = None
        if self.headings is not None:
            head = _as_array(self.headings, "headings", np.float64, 2, cls)
            if head.shape != (t, n):
                raise InvalidInputError(f"{cls}.headings: expected shape ({t}, {n}), got {head.shape}")
            _check_finite(head, "headings", cls)
        obst = (
            _as_array(self.obstacles, "obstacles", np.float64, None, cls).reshape(-1, 2, 2)
            if np.size(self.obstacles)
            else np.zeros((0, 2, 2))
        )
        region = (
            _as_array(self.region, "region", np.float64, None, cls).reshape(-1, 2)
            if np.size(self.region)
            else np.zeros((0, 2))
        )
        fps = float(self.fps)
        if not np.isfinite(fps) or fps <= 0:
            raise InvalidInputError(f"{cls}.fps: expected a positive rate, got {self.fps!r}")
        if not isinstance(self.meta, dict):
            raise InvalidInputError(f"{cls}.meta: expected a dict")
        for name, arr in (
            ("positions", pos),
            ("radius", radius),
            ("velocities", vel),
            ("headings", head),
            ("obstacles", obst),
            ("region", region),
        ):
            if arr is not None:
                arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "fps", fps)

    @property
    def n_frames(self) -> int:
        return self.positions.shape[0]

    @property
    def n_agents(self) -> int:
        return self.positions.shape[1]

    @property
    def periodic_length(self) -> float | None:
        """Period along x in metres for periodic scenes (corridor), else None."""
        return periodic_length(self.meta)

    def replace(self, **changes) -> Crowd:
        if "meta" in changes:
            changes["meta"] = {**self.meta, **changes["meta"]}
        return dataclasses.replace(self, **changes)

    def save(self, path: str | Path) -> Path:
        arrays = {
            "positions": self.positions,
            "radius": self.radius,
            "obstacles": self.obstacles,
            "region": self.region,
        }
        if self.velocities is not None:
            arrays["velocities"] = self.velocities
        if self.headings is not None:
            arrays["headings"] = self.headings
        meta = {"type": "Crowd", "schema_version": SCHEMA_VERSION, "fps": self.fps, "meta": self.meta}
        return _save_npz(Path(path), arrays, meta)

    @classmethod
    def load(cls, path: str | Path) -> Crowd:
        arrays, meta = _load_npz(path, "Crowd")
        for key in ("positions", "radius"):
            if key not in arrays:
                raise InvalidInputError(f"Crowd file {str(path)!r}: field {key!r} is missing")
        try:
            return cls(
                positions=arrays["positions"],
                radius=arrays["radius"],
                fps=meta.get("fps", 30.0),
                velocities=arrays.get("velocities"),
                headings=arrays.get("headings"),
                obstacles=arrays.get("obstacles", np.zeros((0, 2, 2))),
                region=arrays.get("region", np.zeros((0, 2))),
                meta=meta.get("meta", {}),
            )
        except InvalidInputError as exc:
            raise InvalidInputError(f"Crowd file {str(path)!r}: {exc}") from None

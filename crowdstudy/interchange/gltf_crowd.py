"""A glTF file's skinned, animated characters as a :class:`~crowdstudy.scene.CrowdAnimation`
(``crowdstudy import-crowd FILE.glb --out anim.npz``).

Every character of the file (:func:`crowdstudy.body.gltf_rig.find_characters`: a skeleton
with its skinned meshes and rigid parts, or an animated tree of rigid parts; instanced
copies of a mesh each with their own skin are separate characters) becomes one character
of the animation:

* its body is its own mesh and weights (a ``{"model": "gltf", "path", "skin" | "node"}``
  record, :mod:`crowdstudy.body.gltf_model`), so the physics fits capsules to it, the
  overlap metric measures it and the renderer draws it;
* its skeleton is mapped onto the 24 joints (:func:`crowdstudy.body.rig_map.map_rig`:
  names, else the skeleton's shape, ``--map`` overrides);
* its animation (the chosen animations' channels, all by default; two animations that
  animate the same node are an error unless ``--animation`` picks) is sampled at ``fps``
  (default: the file's own rate, the spacing of its keys; characters keyed at different
  rates are an error unless ``fps`` is given) from the first key of the file to the last,
  and retargeted (:mod:`crowdstudy.interchange.retarget`): glTF's Y-up world becomes the
  toolkit's Z-up one (``Z_UP_TO_Y_UP``), units stay metres (an armature scaled by 0.01 or
  100 is part of the world matrices).

``meta["imported"]`` records the file, its SHA-256, the animations, the frame times and
each character's mapping, so that the corrected motion can be written back
(:mod:`crowdstudy.interchange.gltf_write`).
"""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from crowdstudy.body.gltf_container import Z_UP_TO_Y_UP, GltfFile, read_gltf
from crowdstudy.body.gltf_model import (
    GltfCharacter,
    body_from_character,
    character_from_gltf,
    node_parents,
    node_world_matrices,
)
from crowdstudy.body.gltf_rig import CharacterSpec, find_characters
from crowdstudy.body.skeleton import JOINT_NAMES, PARENTS
from crowdstudy.errors import InvalidInputError
from crowdstudy.interchange.gltf_sampling import (
    Channel,
    channels_of,
    keyframe_rate,
    select_animations,
    world_at_frames,
)
from crowdstudy.interchange.retarget import RetargetFrames, to_physics

if TYPE_CHECKING:
    from crowdstudy.scene import CrowdAnimation

__all__ = ["ImportedCharacter", "ImportedCrowd", "read_crowd", "RATE_TOLERANCE"]

#: Relative difference of two characters' key rates above which they count as different.
RATE_TOLERANCE = 0.005


@dataclasses.dataclass
class ImportedCharacter:
    """One character of an imported file: where it is (``spec``), what was read
    (``character``), its body (``body`` and its ``record``), its key rate (``rate``, 1/s,
    None when unkeyed) and its retargeting frames (``frames``)."""

    spec: CharacterSpec
    character: GltfCharacter
    body: object
    record: dict
    rate: float | None
    frames: RetargetFrames


@dataclasses.dataclass
class ImportedCrowd:
    """A glTF file read as a crowd: the loaded file, its node ``parent`` array, the chosen
    ``animations`` and their ``channels``, the frame ``times`` (T,) s, the ``characters``
    and the :class:`~crowdstudy.scene.CrowdAnimation` ``anim`` (with the bodies in
    ``bodies``, ready for :func:`~crowdstudy.physics.correct`)."""

    gltf: GltfFile
    parent: np.ndarray
    animations: list[int]
    channels: list[Channel]
    times: np.ndarray
    characters: list[ImportedCharacter]
    anim: CrowdAnimation
    bodies: list
    usd: object = None

    def report(self) -> str:
        """The import as text: per character its mapping table, rate and notes."""
        names = [str(self.gltf.doc["animations"][a].get("name", a)) for a in self.animations]
        lines = [
            f"{self.gltf.path}: {len(self.characters)} characters, animations {', '.join(names)}, "
            f"{len(self.times)} frames at {self.anim.fps:g} fps from t = {self.times[0]:g} s"
        ]
        for i, c in enumerate(self.characters):
            rig = c.character.rig
            where = f"skin {', '.join(map(str, c.spec.skins))}" if c.spec.skins else "rigid parts"
            rate = "unkeyed" if c.rate is None else f"keys at {c.rate:g}/s"
            if self.usd is not None:  # the character's SkelRoot and Skeleton, not the glTF stand-ins
                skin = self.usd.skins[c.spec.skins[0]]
                where = f"skeleton {skin.skeleton}, {len(skin.meshes)} meshes"
            lines.append(
                f"character {i} ({_where(self, c)}, {where}, "
                f"{len(rig.vertices)} vertices, {len(c.spec.rigid)} rigid parts, {rate}, "
                f"stature {c.character.height:.2f} m)"
            )
            if rig.renormalised:
                lo, hi = rig.weight_sum_range
                lines.append(
                    f"  skin weights of {rig.renormalised} vertices did not sum to one ({lo:.3f} .. {hi:.3f}): "
                    "normalised"
                )
            if i == 0 or c.character.rig_map.joints != self.characters[i - 1].character.rig_map.joints:
                lines.append(_indent(c.character.rig_map.table()))
            else:
                lines.append("  mapping: as the character above")
        return "\n".join(lines)


def _where(crowd: ImportedCrowd, c: ImportedCharacter) -> str:
    if crowd.usd is not None:
        return f"SkelRoot {crowd.usd.skins[c.spec.skins[0]].skel_root}"
    return f"node {c.spec.root} {crowd.gltf.doc['nodes'][c.spec.root].get('name', '')!r}"


def _indent(text: str) -> str:
    return "\n".join("  " + line for line in text.splitlines())


def read_crowd(
    path: str | Path,
    *,
    fps: float | None = None,
    animations: list[str] | None = None,
    overrides: dict | None = None,
) -> ImportedCrowd:
    """Read every character of a glTF file as one crowd (see the module docstring).

    Args:
        path: a .glb or .gltf file, or a USD file (.usd, .usda, .usdc: its UsdSkel
            characters, read as glTF by :func:`crowdstudy.body.usd_stage.read_usd`;
            ``usd`` then holds the :class:`~crowdstudy.body.usd_stage.UsdCrowdFile`).
        fps: frames per second to resample to (default: the file's own rate).
        animations: names (or indices) of the animations to import (default: all).
        overrides: {physics joint: joint name or index} applied to every character (``--map``).

    Raises InvalidInputError naming the file and the problem: no character (no skin and no
    animated tree of meshes), no animation, a rig that is not a humanoid's or too coarse,
    characters keyed at different rates without ``fps``.
    """
    path = Path(path)
    usd = _read_usd_if_usd(path)
    gltf = read_gltf(path) if usd is None else usd.gltf
    doc = gltf.doc
    parent = node_parents(doc)
    specs = find_characters(doc, parent)
    if not specs:
        what = "no skin" if not doc.get("skins") else "no mesh bound to a skin"
        raise InvalidInputError(
            f"glTF file {path}: no character to import ({what}, and no animated node tree carrying meshes)"
        )
    chosen = select_animations(doc, animations, path)
    channels = channels_of(gltf, chosen, path)
    if not channels:
        raise InvalidInputError(f"{_label(path)} {path}: the chosen animations move no node")
    world = node_world_matrices(doc, parent)
    sha = hashlib.sha256(path.read_bytes()).hexdigest()
    model = "gltf" if usd is None else "usd"
    chars = [_character(gltf, s, parent, world, overrides, channels, sha, model) for s in specs]
    _share_bodies(chars)
    fps = _frame_rate(chars, channels, fps, path)
    t0 = min(float(c.times[0]) for c in channels)
    t1 = max(float(c.times[-1]) for c in channels)
    n_frames = int(np.floor((t1 - t0) * fps + 1e-3)) + 1  # float32 key times
    times = t0 + np.arange(n_frames) / fps
    nodes = [int(n) for c in chars for n in c.character.rig.nodes]
    wmat, _ = world_at_frames(doc, parent, nodes, channels, times)
    rot = np.empty((n_frames, len(chars), len(JOINT_NAMES), 3))
    root = np.empty((n_frames, len(chars), 3))
    for i, c in enumerate(chars):
        w = np.stack([wmat[int(n)] for n in c.character.rig.nodes], axis=1)
        rot[:, i], root[:, i] = to_physics(w, c.frames)
    anim = _animation(path, sha, doc, chars, chosen, times, fps, rot, root, overrides, model)
    return ImportedCrowd(gltf, parent, chosen, channels, times, chars, anim, [c.body for c in chars], usd)


def _label(path: Path) -> str:
    from crowdstudy.body.usd_stage import USD_SUFFIXES

    return "USD file" if path.suffix.lower() in USD_SUFFIXES else "glTF file"


def _read_usd_if_usd(path: Path):
    """The :class:`~crowdstudy.body.usd_stage.UsdCrowdFile` of a USD path (checked: a
    SkelAnimation drives a character), None for a glTF path."""
    from crowdstudy.body.usd_stage import USD_SUFFIXES, read_usd

    if path.suffix.lower() not in USD_SUFFIXES:
        return None
    usd = read_usd(path)
    if not usd.animations:
        raise InvalidInputError(
            f"USD file {path}: no SkelAnimation drives a character (skel:animationSource): nothing to import"
        )
    return usd


def _character(gltf, spec, parent, world, overrides, channels, sha, model="gltf") -> ImportedCharacter:
    ch = character_from_gltf(gltf, spec, parent, world, overrides=overrides, sha256=sha)
    record = {"model": model, "path": str(Path(gltf.path).resolve()), **spec.key}
    if overrides:
        record["map"] = dict(overrides)
    own = set(spec.joints) | set(spec.rigid)
    rate = keyframe_rate([c for c in channels if c.node in own])
    frames = RetargetFrames(
        conv=Z_UP_TO_Y_UP.T,
        frame=ch.frame,
        rest_fix=ch.rest_fix,
        bind=ch.rig.bind,
        rig_map=ch.rig_map,
        rest_joints=None,
    )
    body = body_from_character(record, ch)
    frames = dataclasses.replace(frames, rest_joints=np.asarray(body.rest_joints))
    return ImportedCharacter(spec, ch, body, record, rate, frames)


def _share_bodies(chars: list[ImportedCharacter]) -> None:
    """Copies of one character (same template, same rest geometry) share one Body object,
    so its capsules are fitted once."""
    seen: list = []
    for c in chars:
        b = c.body
        twin = next(
            (
                s
                for s in seen
                if s.template_key == b.template_key
                and s.rest_vertices.shape == b.rest_vertices.shape
                and np.array_equal(s.rest_vertices, b.rest_vertices)
                and np.array_equal(s.rest_joints, b.rest_joints)
            ),
            None,
        )
        if twin is None:
            seen.append(b)
        else:
            c.body = twin


def _frame_rate(chars: list[ImportedCharacter], channels: list[Channel], fps: float | None, path: Path) -> float:
    """``fps`` when given, else the characters' common key rate."""
    if fps is not None:
        if not np.isfinite(fps) or fps <= 0:
            raise InvalidInputError(f"--fps: expected a positive frame rate, got {fps}")
        return float(fps)
    rates = sorted({c.rate for c in chars if c.rate is not None})
    if not rates:
        rate = keyframe_rate(channels)
        if rate is None:
            raise InvalidInputError(f"{_label(path)} {path}: its keys give no frame rate (one key each): give --fps")
        return rate
    if rates[-1] > rates[0] * (1.0 + RATE_TOLERANCE):
        per = ", ".join(f"{i}: {c.rate:g}/s" for i, c in enumerate(chars) if c.rate is not None)
        raise InvalidInputError(
            f"{_label(path)} {path}: characters are keyed at different rates ({per}): give --fps to resample them all"
        )
    return rates[0]


def _animation(path, sha, doc, chars, chosen, times, fps, rot, root, overrides, model="gltf"):
    from crowdstudy.provenance import provenance
    from crowdstudy.scene import CrowdAnimation

    names = [str(doc["animations"][a].get("name", a)) for a in chosen]
    characters = [
        {
            **c.spec.key,
            "root": c.spec.root,
            "mapping": {
                j: {"joint": m.source, "name": c.character.rig_map.names[m.source], "how": m.how}
                for j, m in c.character.rig_map.joints.items()
            },
        }
        for c in chars
    ]
    imported = {
        "format": model,
        "file": str(path.resolve()),
        "sha256": sha,
        "animations": names,
        "time_start": float(times[0]),
        "fps": float(fps),
        "overrides": dict(overrides or {}),
        "characters": characters,
    }
    return CrowdAnimation(
        joint_names=JOINT_NAMES,
        parents=PARENTS,
        root_translation=root,
        joint_rotations=rot,
        fps=fps,
        bodies=tuple(c.record for c in chars),
        clips=tuple({"source": model, "node": c.spec.root, "animations": names} for c in chars),
        meta={
            "scenario": "imported",
            "method": "Baseline",
            "source": str(path),
            "seed": 0,
            "obstacles": [],
            "loop": {"mode": "none"},
            "n_characters": len(chars),
            "imported": imported,
            "provenance": provenance(stage="import-crowd", source=str(path), sha256=sha),
        },
    )

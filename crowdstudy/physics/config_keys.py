"""Naming the fields of :class:`~crowdstudy.physics.config.PhysicsConfig` from outside: a
TOML file, the CLI's ``KEY=VALUE`` items, a study design's table, Python keywords.

A key is resolved, in this order, as

1. a dotted path (``control.damping``, ``profile.sparse.skin_max``);
2. a field name that occurs once in the whole configuration (``damping``,
   ``cg_tolerance``, ``wall_stiffness``); a name that occurs in several sections
   (``stiffness``: ``control.stiffness`` and ``contacts.stiffness``) is an error listing
   them;
3. a name of the former flat configuration (``contact_stiffness``,
   ``foot_anchor_stiffness``, ``sparse_output_hold``: :data:`FORMER_NAMES`), so older
   command lines keep working. The former ``crowd_adaptive``, ``mesh_skin_max``,
   ``mesh_skin_hand_scale`` and ``output_hold`` meant one thing with the density profile and
   another without it; they are errors that say which field to set now
   (:data:`RETIRED_NAMES`).

Nested mappings (a TOML table ``[contacts]``) name the fields of that section. An unknown
key is an error naming it, with the closest known name when there is one.
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Mapping

from crowdstudy.errors import InvalidInputError
from crowdstudy.physics.config_sections import DensityProfile, field_types

__all__ = [
    "FORMER_NAMES",
    "RETIRED_NAMES",
    "Leaf",
    "leaves",
    "sections",
    "resolve_key",
    "resolve_changes",
    "parse_text",
]

#: The flat names of the configuration before it had sections, for the fields whose new
#: name is not simply the same leaf name: former name -> dotted path.
FORMER_NAMES: dict[str, str] = {
    "contact_stiffness": "contacts.stiffness",
    "contact_margin": "contacts.margin",
    "contact_activation": "contacts.activation",
    "contact_release_distance": "contacts.release_distance",
    "contact_release_width": "contacts.release_width",
    "contact_pass_ahead": "contacts.pass_ahead",
    "contact_pass_width": "contacts.pass_width",
    "contact_stiffening_depth": "contacts.stiffening_depth",
    "target_relative_self_contacts": "contacts.target_relative_self",
    "max_contacts_per_character": "contacts.max_per_character",
    "foot_anchor_stiffness": "feet.anchor_stiffness",
    "foot_anchor_damping": "feet.anchor_damping",
    "foot_anchor_max_force": "feet.anchor_max_force",
    "foot_planted_speed": "feet.planted_speed",
    "foot_release_distance": "feet.release_distance",
    "foot_rejoin_distance": "feet.rejoin_distance",
    "mesh_skin_percentile": "skin.percentile",
    "output_smoothing": "output.smoothing",
    "output_smoothing_root": "output.smoothing_root",
    "sparse_density": "profile.sparse.crowd_density",
    "dense_density": "profile.dense.crowd_density",
    "sparse_mesh_skin_max": "profile.sparse.skin_max",
    "sparse_mesh_skin_hand_scale": "profile.sparse.skin_hand_scale",
    "sparse_output_hold": "profile.sparse.output_hold",
}

_DENSE = DensityProfile().dense
_FOLLOW = (
    "none (the default) follows the crowd's density between profile.sparse.{p} and profile.dense.{p}; "
    "a number fixes it for every crowd"
)
#: Former flat names whose meaning depended on another field: what to set instead.
RETIRED_NAMES: dict[str, str] = {
    "crowd_adaptive": "the skins and the hold follow the crowd's density while skin.max, skin.hand_scale and "
    "output.hold are none (the default); give those three numbers to fix them for every crowd "
    f"(the dense profile: skin.max={_DENSE.skin_max:g} skin.hand_scale={_DENSE.skin_hand_scale:g} "
    f"output.hold={_DENSE.output_hold:g})",
    "mesh_skin_max": "set skin.max: " + _FOLLOW.format(p="skin_max"),
    "mesh_skin_hand_scale": "set skin.hand_scale: " + _FOLLOW.format(p="skin_hand_scale"),
    "output_hold": "set output.hold: " + _FOLLOW.format(p="output_hold"),
}


@dataclasses.dataclass(frozen=True)
class Leaf:
    """One settable field: its dotted ``path``, its type ``kind`` (``float``, ``int``,
    ``bool``, ``float | None``) and whether it must be > 0."""

    path: str
    kind: object
    positive: bool


def leaves(cls: type, prefix: str = "") -> dict[str, Leaf]:
    """{dotted path: :class:`Leaf`} of every field of the dataclass ``cls`` and of its
    sections, depth first in declaration order."""
    out: dict[str, Leaf] = {}
    positive = getattr(cls, "POSITIVE", frozenset())
    for name, kind in field_types(cls).items():
        path = f"{prefix}{name}"
        if isinstance(kind, type) and dataclasses.is_dataclass(kind):
            out.update(leaves(kind, path + "."))
        else:
            out[path] = Leaf(path, kind, name in positive)
    return out


def sections(cls: type, prefix: str = "") -> list[str]:
    """The dotted paths of the sections (nested dataclasses) of ``cls``."""
    out = []
    for name, kind in field_types(cls).items():
        if isinstance(kind, type) and dataclasses.is_dataclass(kind):
            out.append(prefix + name)
            out.extend(sections(kind, f"{prefix}{name}."))
    return out


def _flatten(mapping: Mapping, where: str, prefix: str, known_sections: list[str]) -> list[tuple[str, object]]:
    out = []
    for key, value in mapping.items():
        if not isinstance(key, str) or not key.strip():
            raise InvalidInputError(f"{where}: expected field names, got the key {key!r}")
        key = f"{prefix}{key.strip()}"
        if isinstance(value, Mapping):
            if key not in known_sections:
                raise InvalidInputError(
                    f"{where}: [{key}] is not a section of PhysicsConfig; its sections are {', '.join(known_sections)}"
                )
            out.extend(_flatten(value, where, key + ".", known_sections))
        else:
            out.append((key, value))
    return out


def _unknown(key: str, names: list[str], where: str) -> InvalidInputError:
    close = difflib.get_close_matches(key, names, n=1, cutoff=0.6)
    hint = (
        f" (did you mean {close[0]}?)"
        if close
        else " (a dotted path such as control.damping, or a field name such as damping)"
    )
    return InvalidInputError(f"{where}: unknown PhysicsConfig field {key!r}{hint}")


def resolve_key(key: str, cls: type, where: str, *, paths_only: bool = False) -> str:
    """The dotted path ``key`` names in the configuration class ``cls`` (see the module's
    docstring); :class:`InvalidInputError` naming ``key`` and ``where`` otherwise."""
    fields = leaves(cls)
    if key in fields:
        return key
    known_sections = sections(cls)
    if key in known_sections:
        example = next(p for p in fields if p.startswith(key + "."))
        raise InvalidInputError(
            f"{where}: {key!r} is a section of PhysicsConfig, not a field; set its fields (e.g. {example})"
        )
    by_leaf: dict[str, list[str]] = {}
    for path in fields:
        by_leaf.setdefault(path.rsplit(".", 1)[-1], []).append(path)
    names = list(fields) + [leaf for leaf, paths in by_leaf.items() if len(paths) == 1]
    if paths_only or "." in key:
        raise _unknown(key, list(fields), where)
    if key in RETIRED_NAMES:
        raise InvalidInputError(f"{where}: {key!r} is no longer a PhysicsConfig field: {RETIRED_NAMES[key]}")
    found = by_leaf.get(key, [])
    if len(found) == 1:
        return found[0]
    if len(found) > 1:
        raise InvalidInputError(f"{where}: PhysicsConfig field {key!r} is ambiguous; name one of {', '.join(found)}")
    if key in FORMER_NAMES:
        return FORMER_NAMES[key]
    raise _unknown(key, names + list(FORMER_NAMES), where)


_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")


def parse_text(raw: str, leaf: Leaf, where: str) -> object:
    """The value a command-line string gives the field ``leaf``: true/false (yes/no, 1/0)
    for a switch, an integer, a number, or ``none`` where the field may be None."""
    text = raw.strip().lower()
    if leaf.kind is bool:
        if text in _TRUE or text in _FALSE:
            return text in _TRUE
        what = "true or false"
    elif leaf.kind is int:
        try:
            return int(text)
        except ValueError:
            what = "an integer"
    else:
        if text in ("none", "null") and leaf.kind == (float | None):
            return None
        try:
            return float(text)
        except ValueError:
            what = "a number" + (" or none" if leaf.kind == (float | None) else "")
    raise InvalidInputError(f"{where}: {leaf.path} expects {what}, got {raw!r}")


def resolve_changes(
    changes: Mapping, cls: type, *, where: str, strings: bool = False, paths_only: bool = False
) -> dict[str, object]:
    """{dotted path: value} of ``changes`` (keys as in the module's docstring, nested
    mappings for sections). With ``strings``, a ``str`` value is parsed
    (:func:`parse_text`); values are checked by the caller. A field named twice is an
    error."""
    if not isinstance(changes, Mapping):
        raise InvalidInputError(f"{where}: expected a table of PhysicsConfig fields, got {type(changes).__name__}")
    fields = leaves(cls)
    out: dict[str, object] = {}
    given: dict[str, str] = {}
    for key, value in _flatten(changes, where, "", sections(cls)):
        path = resolve_key(key, cls, where, paths_only=paths_only)
        if path in given:
            raise InvalidInputError(f"{where}: {path} is given twice (as {given[path]!r} and {key!r})")
        given[path] = key
        out[path] = parse_text(value, fields[path], where) if strings and isinstance(value, str) else value
    return out

"""Physics settings on the command line: ``--config [FILE.toml] [KEY=VALUE ...]``.

``crowdstudy correct``, ``crowdstudy stimuli`` and ``crowdstudy bench physics`` take the
same option. A TOML file has the sections of
:class:`~crowdstudy.physics.config.PhysicsConfig`::

    # physics.toml
    [control]
    damping = 0.01
    [contacts]
    stiffness = 3e4
    [profile.sparse]
    skin_max = 0.05

and ``KEY=VALUE`` items are applied on top of it, whatever their order on the command
line (``--config physics.toml damping=0.02``). A key is a dotted path
(``control.damping``), a field name that occurs once (``damping``) or a former flat name
(``contact_stiffness``; :mod:`crowdstudy.physics.config_keys`). A missing or unreadable
file, bad TOML, an unknown or ambiguous key or a value of the wrong type is one error naming
the file or option and the key, before anything runs.
"""

from __future__ import annotations

import argparse
import tomllib
from collections.abc import Sequence
from pathlib import Path

from crowdstudy.errors import InvalidInputError
from crowdstudy.physics.config import PhysicsConfig

__all__ = ["CONFIG_HELP", "add_config_option", "load_config_file", "config_from_cli"]

_DENSE = PhysicsConfig().profile.dense
CONFIG_HELP = (
    "physics settings: a TOML file with PhysicsConfig's sections ([control] damping = 0.01) and/or "
    "KEY=VALUE items applied on top of it; KEY is a dotted path (control.damping, contacts.stiffness, "
    "profile.sparse.skin_max) or a field name that occurs once (damping, cg_tolerance). skin.max, "
    "skin.hand_scale and output.hold follow the crowd's density (profile.sparse below "
    "profile.sparse.crowd_density, profile.dense above profile.dense.crowd_density) unless given a "
    f"number: skin.max={_DENSE.skin_max:g} skin.hand_scale={_DENSE.skin_hand_scale:g} "
    f"output.hold={_DENSE.output_hold:g} gives every crowd the dense profile"
)


def add_config_option(parser: argparse.ArgumentParser, what: str = "") -> None:
    """Add ``--config [FILE.toml] [KEY=VALUE ...]`` to ``parser`` (``what``: a note on
    what the settings are for, put before the common help)."""
    parser.add_argument(
        "--config",
        nargs="*",
        default=[],
        metavar="FILE.toml|KEY=VALUE",
        help=(what + "; " if what else "") + CONFIG_HELP,
    )


def load_config_file(path: str | Path, *, base: PhysicsConfig | None = None, option: str = "--config") -> PhysicsConfig:
    """``base`` (default: the defaults) with the settings of the TOML file ``path``;
    errors name ``option``, the file and the key."""
    where = f"{option} {str(path)!r}"
    path = Path(path)
    if not path.is_file():
        raise InvalidInputError(f"{where}: no such file (give a TOML file of physics settings or KEY=VALUE items)")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise InvalidInputError(f"{where}: cannot be read ({exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise InvalidInputError(f"{where}: not valid TOML ({exc})") from None
    return PhysicsConfig.from_overrides(data, where=where, base=base)


def config_from_cli(items: Sequence[str], *, option: str = "--config") -> PhysicsConfig:
    """The configuration ``--config`` items give: at most one TOML file (an item without
    ``=``), then the ``KEY=VALUE`` items on top of it (values parsed from text, see
    :meth:`PhysicsConfig.from_overrides`)."""
    files = [item for item in items if "=" not in item]
    if len(files) > 1:
        raise InvalidInputError(f"{option}: expected at most one TOML file, got {', '.join(map(repr, files))}")
    config = load_config_file(files[0], option=option) if files else PhysicsConfig()
    changes: dict[str, str] = {}
    for item in items:
        if "=" not in item:
            continue
        key, value = (s.strip() for s in item.split("=", 1))
        if not key:
            raise InvalidInputError(f"{option}: expected KEY=VALUE, got {item!r}")
        if key in changes:
            raise InvalidInputError(f"{option}: {key} is given twice")
        changes[key] = value
    return PhysicsConfig.from_overrides(changes, where=option, base=config, strings=True) if changes else config

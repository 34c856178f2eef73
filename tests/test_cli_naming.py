"""Every subcommand's module is named after its command: ``crowdstudy/<stage>/cli_<command>.py``
(or ``crowdstudy/cli_<command>.py``), dashes as underscores, with ``configure`` and ``run``;
and every ``cli_*.py`` module of the package is a command of ``COMMANDS``."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from crowdstudy.cli import COMMANDS

PACKAGE = Path(__file__).resolve().parent.parent / "crowdstudy"


def _path(module: str) -> Path:
    return PACKAGE.parent.joinpath(*module.split(".")).with_suffix(".py")


def _functions(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    return {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}


@pytest.mark.parametrize("name, module", [(name, module) for name, module, _ in COMMANDS])
def test_the_module_is_named_after_its_command(name, module):
    command = name.replace("-", "_")
    assert re.fullmatch(rf"crowdstudy(\.[a-z_]+)?\.cli_{command}", module), (name, module)
    if module.count(".") == 2:
        assert (PACKAGE / module.split(".")[1]).is_dir(), module  # a stage's subpackage
    path = _path(module)
    assert path.is_file(), path
    assert {"configure", "run"} <= _functions(path), path


def test_every_cli_module_is_a_command():
    listed = {_path(module) for _, module, _ in COMMANDS}
    found = {p for p in PACKAGE.rglob("cli_*.py")}
    assert found == listed, (sorted(map(str, found - listed)), sorted(map(str, listed - found)))


def test_the_check_sees_a_misnamed_module():
    assert not re.fullmatch(r"crowdstudy(\.[a-z_]+)?\.cli_sheet", "crowdstudy.render.sheet_cli")
    assert "run" not in _functions(PACKAGE / "bench.py")  # the command line lives in cli_bench.py

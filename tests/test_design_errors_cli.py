"""Bad study designs at every command that reads one: exit 2, one line naming the design
file and the dotted key, nothing written (issue #41, item 7)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from crowdstudy.cli import main

EXAMPLE = Path(__file__).resolve().parent.parent / "stimuli" / "examples" / "followup" / "study.toml"

#: (name, edit of the example design's text, the key the error must name, text it must say)
BROKEN = [
    (
        "unknown method in a pair",
        lambda t: t.replace('task = "2afc"   ', 'task = "2afc"\npairs = [["Baseline", "Nope"]]\n'),
        "stages.corridor.pairs[0]",
        "unknown method 'Nope'",
    ),
    (
        "PhysicsConfig typo",
        lambda t: t.replace('correction = "paper" ', 'config = { dampng = 0.06 }\ncorrection = "paper" '),
        "methods.Paper.config",
        "'dampng' (did you mean damping?)",
    ),
    (
        "files folder missing",
        lambda t: t.replace('correction = "paper" ', 'correction = "files"\npath = "no_such_folder" #'),
        "methods.Paper.path",
        "does not exist",
    ),
    (
        "unknown scenario kind",
        lambda t: t.replace("[scenarios.corridor]\n", '[scenarios.corridor]\nkind = "stadium"\n'),
        "scenarios.corridor.kind",
        "must be one of",
    ),
]


def _commands(design: Path, tmp: Path) -> dict[str, list[str]]:
    out = tmp / "out"
    responses = Path(__file__).resolve().parent.parent / "analysis" / "example_responses.csv"
    return {
        "stimuli": ["stimuli", "--design", str(design), "--out", str(out / "set"), "--preset", "quick"],
        "serve": ["serve", "--design", str(design), "--stimuli", str(tmp / "set"), "--db", f"sqlite:///{out}/s.db"],
        "export": ["export", "--design", str(design), "--db", f"sqlite:///{tmp}/s.db", "--out", str(out / "r.csv")],
        "analyze": ["analyze", str(responses), "--design", str(design), "--out", str(out / "a")],
        "power": ["power", "--design", str(design), "--out", str(out / "p.json")],
        "demo": ["demo", "--design", str(design), "--out", str(out / "demo")],
        "simulate-participants": ["simulate-participants", "--design", str(design), "--json", str(out / "b.json")],
        "layout": ["layout", "--design", str(design), "--density", "High", "--out", str(out / "l.npz")],
        "navigate": ["navigate", "--design", str(design), "--density", "High", "--out", str(out / "n.npz")],
        "animate": ["animate", "--design", str(design), "--stage", "all", "--out", str(out / "anim")],
    }


def _reads_a_design(command: str, capsys) -> bool:
    with pytest.raises(SystemExit):
        main([command, "--help"])
    return "--design" in capsys.readouterr().out


@pytest.mark.parametrize("case", BROKEN, ids=[c[0] for c in BROKEN])
@pytest.mark.parametrize("command", list(_commands(Path("d.toml"), Path("t"))))
def test_a_bad_design_is_one_named_line_and_nothing_written(command, case, tmp_path, capsys):
    if not _reads_a_design(command, capsys):
        pytest.skip(f"crowdstudy {command} has no --design option in this version")
    _, edit, key, says = case
    text = EXAMPLE.read_text()
    broken = edit(text)
    assert broken != text, "the edit must change the design"
    design = tmp_path / "design" / "study.toml"
    design.parent.mkdir()
    design.write_text(broken)
    (tmp_path / "set").mkdir()
    code = main(_commands(design, tmp_path)[command])
    captured = capsys.readouterr()
    assert code == 2, captured
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert str(design) in lines[0] and key in lines[0] and says in lines[0], lines[0]
    assert re.match(rf"crowdstudy {command}: error: ", lines[0])
    assert not (tmp_path / "out").exists(), sorted(p.name for p in (tmp_path / "out").rglob("*"))

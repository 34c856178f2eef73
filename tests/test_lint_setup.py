"""The lint set-up: `make lint`, the pre-commit hooks and the CI agree on what is checked,
and the commit-msg hook refuses a subject line over 72 characters."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "scripts" / "check_commit_subject.py"


def _lint_dirs() -> list[str]:
    match = re.search(r"^LINT_DIRS := (.+)$", (ROOT / "Makefile").read_text(), flags=re.M)
    assert match, "Makefile has no LINT_DIRS"
    return match.group(1).split()


def test_make_lint_covers_every_python_folder():
    dirs = _lint_dirs()
    for name in ("crowdstudy", "tests", "benchmarks", "paper_figs", "scripts", "analysis"):
        assert name in dirs
    # every top-level folder with Python files is linted
    python_dirs = {p.relative_to(ROOT).parts[0] for p in ROOT.glob("*/**/*.py")}
    python_dirs -= {".venv", "build", "ui", "demo_out", "stimuli"}
    assert python_dirs <= set(dirs), python_dirs - set(dirs)


def test_pre_commit_hooks_match_make_lint():
    config = (ROOT / ".pre-commit-config.yaml").read_text()
    ruff_files = re.findall(r"files: \^\((.+)\)/", config)
    assert len(ruff_files) == 2, "ruff check and ruff format hooks"
    for pattern in ruff_files:
        assert sorted(pattern.split("|")) == sorted(_lint_dirs())
    assert "entry: .venv/bin/pyright\n" in config  # the [tool.pyright] include, as in make lint
    assert "stages: [commit-msg]" in config and "check_commit_subject.py" in config
    assert "commit-msg" in config.split("repos:")[0]  # installed by `pre-commit install`


def test_pyright_checks_the_package_and_ignores_only_existing_modules():
    import tomllib

    settings = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pyright"]
    assert settings["include"] == ["crowdstudy"] and settings["typeCheckingMode"] == "basic"
    ignored = settings.get("ignore", [])
    # the modules still open, each an existing file of the package (not a folder or a pattern)
    assert ignored == sorted(set(ignored))
    assert all(name.startswith("crowdstudy/") and (ROOT / name).is_file() for name in ignored), ignored
    # the kernel modules are checked, with only Warp's type forms (and DSL rules) off
    for name in ("crowdstudy/physics/kernels.py", "crowdstudy/body/skinning_kernels.py"):
        assert name not in ignored
        assert "# pyright: reportInvalidTypeForm=false\n" in (ROOT / name).read_text()


def test_ci_runs_lint_then_test_then_docs():
    steps = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines() if line.startswith("make ")]
    assert steps == ["make lint", "make test", "make docs"]


@pytest.mark.parametrize(
    ("message", "code"),
    [
        ("x" * 72 + "\n\nA body line that may run as long as it likes, " + "y" * 80 + "\n", 0),
        ("x" * 73 + "\n", 1),
        ("# a comment git drops\n\n" + "x" * 73 + "\n", 1),
        ("# a comment git drops\n\nshort\n", 0),
    ],
)
def test_commit_subject_hook(tmp_path: Path, message: str, code: int):
    path = tmp_path / "COMMIT_EDITMSG"
    path.write_text(message)
    result = subprocess.run([sys.executable, str(SCRIPT), str(path)], capture_output=True, text=True)
    assert result.returncode == code, result.stderr
    if code:
        assert "73 characters" in result.stderr

"""The command line's error contract: the project's own errors are one line (exit 2), checked
before the long work starts; anything else (a bug) keeps its traceback (exit 1)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from crowdstudy.cli import main

ROOT = Path(__file__).resolve().parent.parent


def _one_line_error(capsys, argv, what, path, kind="folder"):
    rc = main(argv)
    err = capsys.readouterr().err.strip()
    assert rc == 2, err
    assert len(err.splitlines()) == 1, err
    assert what in err and str(path) in err and kind in err, err


def test_output_folder_instead_of_file_fails_at_once(tmp_path, capsys):
    """Every sub-command writing a file names the argument whose path is a folder; the
    inputs given do not exist, so a check made after reading them would name the input."""
    d = tmp_path / "dir.npz"
    d.mkdir()
    missing = str(tmp_path / "missing.npz")
    (tmp_path / "responses.csv").write_text("participant\n")
    cases = [
        (["layout", "--out", str(d)], "--out"),
        (["layout", "--out", str(tmp_path / "ok.npz"), "--plot", str(d)], "--plot"),
        (["navigate", "--out", str(d)], "--out"),
        (["render", missing, "--out", str(d)], "--out"),
        (["metrics", missing, "--json", str(d)], "--json"),
        (["export-gltf", missing, str(tmp_path / "dir.glb")], "output"),
        (["import-gltf", missing, "--out", str(tmp_path / "dir.json")], "--out"),
        (["power", "--out", str(d), "--sims", "1"], "--out"),
        (["export", "--db", "sqlite:///" + str(tmp_path / "no.db"), "--out", str(d)], "--out"),
        (
            [
                "export",
                "--db",
                "sqlite:///" + str(tmp_path / "no.db"),
                "--out",
                str(tmp_path / "r.csv"),
                "--demographics",
                str(d),
            ],
            "--demographics",
        ),
        (["simulate-participants", "--url", "http://127.0.0.1:9", "--json", str(d)], "--json"),
        (["animate", missing, "--out", str(d)], "--out"),
        (["motion", "report", "--json", str(d)], "--json"),
        (["sheet", missing, "--out", str(d)], "--out"),
    ]
    (tmp_path / "dir.glb").mkdir()
    (tmp_path / "dir.json").mkdir()
    for argv, what in cases:
        path = Path(argv[argv.index(what) + 1]) if what in argv else tmp_path / "dir.glb"
        _one_line_error(capsys, argv, what, path)


def test_output_file_instead_of_folder_fails_at_once(tmp_path, capsys):
    f = tmp_path / "a_file"
    f.write_text("x")
    (tmp_path / "responses.csv").write_text("participant\n")
    for argv in (
        ["stimuli", "--out", str(f)],
        ["demo", "--out", str(f)],
        ["animate", "--stage", "all", "--out", str(f)],
        ["motion", "build-library", "--source", str(tmp_path), "--out", str(f)],
        ["analyze", str(tmp_path / "responses.csv"), "--out", str(f)],
    ):
        _one_line_error(capsys, argv, "--out", f, kind="file")


def test_a_bug_keeps_its_traceback(monkeypatch):
    """A plain ValueError (numpy, pandas, a bug) is not turned into a user error."""
    import crowdstudy.layout.cli_layout as layout_cli

    def broken(args):
        raise ValueError("operands could not be broadcast together")

    monkeypatch.setattr(layout_cli, "run", broken)
    with pytest.raises(ValueError, match="broadcast"):
        main(["layout"])


def test_a_bug_prints_a_traceback_and_exits_1(tmp_path):
    code = (
        "import sys, crowdstudy.layout.cli_layout as m\n"
        "def broken(args):\n    raise ValueError('operands could not be broadcast together')\n"
        "m.run = broken\n"
        "from crowdstudy.cli import main\nsys.exit(main(['layout']))\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120
    )
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" in proc.stderr and "ValueError: operands could not be broadcast" in proc.stderr


def test_the_project_error_stays_one_line(tmp_path, capsys):
    rc = main(["metrics", str(tmp_path / "missing.npz")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "missing.npz" in err and "Traceback" not in err and len(err.splitlines()) == 1


def test_bench_checks_its_report_path_before_running(tmp_path, monkeypatch, capsys):
    import crowdstudy.bench as bench

    d = tmp_path / "study.json"
    d.mkdir()
    monkeypatch.setattr(bench, "report_path", lambda name: d)

    def refuse(name):
        class Module:
            @staticmethod
            def main(argv):
                raise AssertionError("the benchmark ran although its report cannot be written")

        return Module

    monkeypatch.setattr(bench, "load_benchmark", refuse)
    _one_line_error(capsys, ["bench", "study"], "benchmark study report", d)

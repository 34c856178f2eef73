"""Progress bars only on a terminal (crowdstudy.progress): a log or a pipe gets no carriage-return
lines unless ``crowdstudy --progress`` asks for them; ``--no-progress`` silences a terminal."""

from __future__ import annotations

import io
import os
import subprocess
import sys

import pytest

from crowdstudy.errors import InvalidInputError
from crowdstudy.progress import PROGRESS_ENV, progress_bar, progress_enabled, progress_mode, set_progress_mode


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.fixture
def auto(monkeypatch):
    monkeypatch.delenv(PROGRESS_ENV, raising=False)  # restored after the test


def _drawn(stream, **kw) -> str:
    bar = progress_bar(range(3), file=stream, mininterval=0, **kw)
    for _ in bar:
        pass
    bar.close()
    return stream.getvalue()


def test_a_bar_draws_on_a_terminal_only(auto):
    assert "\r" in _drawn(_Terminal())
    assert _drawn(io.StringIO()) == ""
    assert _drawn(_Terminal(), enabled=False) == ""  # the caller's own switch still holds
    assert list(progress_bar(range(3), file=io.StringIO())) == [0, 1, 2]  # a silent bar still iterates


def test_the_environment_forces_bars_on_or_off(auto):
    set_progress_mode("on")
    assert os.environ[PROGRESS_ENV] == "1" and progress_mode() == "on"
    assert "\r" in _drawn(io.StringIO())
    set_progress_mode("off")
    assert _drawn(_Terminal()) == ""
    set_progress_mode("auto")
    assert PROGRESS_ENV not in os.environ and progress_enabled(_Terminal())


def test_a_bad_setting_is_named(auto, monkeypatch):
    monkeypatch.setenv(PROGRESS_ENV, "yes please")
    with pytest.raises(InvalidInputError, match=PROGRESS_ENV):
        progress_enabled()
    with pytest.raises(InvalidInputError, match="mode"):
        set_progress_mode("sometimes")
    with pytest.raises(TypeError, match="enabled"):
        progress_bar(range(3), disable=True)


def test_the_setting_reaches_the_processes_a_command_starts(auto):
    set_progress_mode("on")
    child = subprocess.run(
        [
            sys.executable,
            "-c",
            "from crowdstudy.progress import progress_enabled; import io; print(progress_enabled(io.StringIO()))",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert child.stdout.strip() == "True", child.stderr


@pytest.mark.parametrize("flags, drawn", [([], False), (["--progress"], True), (["--no-progress"], False)])
def test_a_command_writes_bars_to_a_pipe_only_when_asked(flags, drawn):
    """``crowdstudy power`` has a bar over its simulated studies; its stderr here is a pipe."""
    env = {k: v for k, v in os.environ.items() if k != PROGRESS_ENV}
    proc = subprocess.run(
        [sys.executable, "-m", "crowdstudy", *flags, "power", "--sims", "3", "-n", "6", "--dz", "0.5"],
        capture_output=True,
        env=env,
        timeout=300,
    )  # bytes: \r kept
    err = proc.stderr.decode("utf-8", "replace")
    assert proc.returncode == 0, err[-2000:]
    assert b"Method" in proc.stdout
    assert ("\r" in err) == drawn, err[-2000:]
    assert ("power:" in err) == drawn, err[-2000:]

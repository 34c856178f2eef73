"""Run ``crowdstudy serve`` as a child process on a free loopback port (tests, figures, demos).

>>> with LocalServer(["--stimuli", "build/stim", "--db", "sqlite:///build/s.db"]) as srv:  # doctest: +SKIP
...     print(srv.url)
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path

from crowdstudy.errors import InvalidInputError

__all__ = ["LocalServer", "free_port", "write_small_design"]


def free_port() -> int:
    """A TCP port on 127.0.0.1 that is free right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def write_small_design(
    path: str | Path, levels: tuple[str, ...] = ("D1", "D2"), stage1_viewpoints=("V1",), stage2_viewpoints=("V3",)
) -> Path:
    """A copy of the paper's design with fewer densities and viewpoints (a short session:
    2 levels x 1 viewpoint x 2 methods = 4 videos per stage by default)."""
    import re

    from crowdstudy.design import default_design_path, load_design

    text = default_design_path().read_text(encoding="utf-8")
    for level in ("D1", "D2", "D3", "D4", "D5"):
        if level not in levels:
            text = re.sub(rf"^{level} = [0-9.]+\s*$\n", "", text, flags=re.M)
    text = text.replace(
        'viewpoints = ["V1", "V2", "V3", "V4"]', "viewpoints = [" + ", ".join(f'"{v}"' for v in stage1_viewpoints) + "]"
    )
    text = text.replace(
        'viewpoints = ["V3", "V4"]', "viewpoints = [" + ", ".join(f'"{v}"' for v in stage2_viewpoints) + "]"
    )
    path = Path(path)
    path.write_text(text, encoding="utf-8")
    load_design(path)  # validate
    return path


class LocalServer:
    """``crowdstudy serve ARGS --host 127.0.0.1 --port <free>`` in a child process.

    args: the serve arguments (``--stimuli``, ``--db``, ...); ``admin_token`` is passed on
    with ``--admin-token``; the child runs in ``cwd`` (default: this process's working
    directory, so relative paths in ``args`` mean the same to both). ``start()`` waits
    until ``/healthz`` answers; ``kill()`` sends SIGKILL (no clean shutdown); ``restart()``
    starts again on the same port.
    """

    def __init__(
        self,
        args: list[str],
        *,
        admin_token: str = "local-admin-token-0123456789",
        port: int | None = None,
        python: str | None = None,
        startup_timeout: float = 30.0,
        cwd: str | Path | None = None,
    ):
        if not isinstance(args, (list, tuple)) or not all(isinstance(a, str) for a in args):
            raise InvalidInputError("args must be a list of strings (crowdstudy serve arguments)")
        self.args = list(args)
        self.admin_token = admin_token
        self.port = port or free_port()
        self.python = python or sys.executable
        self.startup_timeout = startup_timeout
        self.cwd = cwd
        self.proc: subprocess.Popen | None = None
        self._log = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> LocalServer:
        cmd = [
            self.python,
            "-m",
            "crowdstudy",
            "serve",
            *self.args,
            "--host",
            "127.0.0.1",
            "--port",
            str(self.port),
            "--admin-token",
            self.admin_token,
        ]
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        if self._log is not None:
            self._log.close()
        self._log = tempfile.TemporaryFile(mode="w+", encoding="utf-8")
        self.proc = subprocess.Popen(cmd, cwd=self.cwd, env=env, stdout=self._log, stderr=subprocess.STDOUT, text=True)
        deadline = time.monotonic() + self.startup_timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"crowdstudy serve exited with {self.proc.returncode}:\n{self.output()}")
            try:
                with urllib.request.urlopen(self.url + "/healthz", timeout=1) as r:
                    if r.status == 200:
                        return self
            except (urllib.error.URLError, ConnectionError, OSError):
                time.sleep(0.1)
        self.stop()
        raise RuntimeError(f"crowdstudy serve did not answer on {self.url} within {self.startup_timeout} s")

    def kill(self) -> None:
        """SIGKILL the server (what a crash or a power cut looks like to the database)."""
        if self.proc and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(timeout=10)

    def stop(self) -> None:
        if self.proc and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=10)

    def output(self) -> str:
        """What the server printed so far (its start-up lines, warnings and errors)."""
        if self._log is None:
            return ""
        self._log.flush()
        self._log.seek(0)
        return self._log.read()

    def restart(self) -> LocalServer:
        self.kill()
        return self.start()

    def __enter__(self) -> LocalServer:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

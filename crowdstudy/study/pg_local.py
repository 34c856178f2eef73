"""A throwaway PostgreSQL cluster in a temporary folder (tests and ``crowdstudy bench study``).

Uses the server binaries of Debian's ``postgresql`` package (``/usr/lib/postgresql/<major>/bin``,
or ``$CROWDSTUDY_PG_BIN``): ``initdb`` a cluster with trust authentication on 127.0.0.1 and a
free port, start it with ``pg_ctl``, create one database, stop and delete everything on
exit. PostgreSQL refuses to run as root; as root the cluster runs as the user ``nobody``
(its folder is handed to that user).

>>> with LocalPostgres() as pg:            # doctest: +SKIP
...     print(pg.url)                      # postgresql+psycopg://crowdstudy@127.0.0.1:PORT/study
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from crowdstudy.errors import MissingDependencyError
from crowdstudy.study.local_server import free_port

__all__ = ["LocalPostgres", "find_pg_bin"]


def find_pg_bin() -> Path | None:
    """The folder holding initdb and pg_ctl (highest installed major version), or None."""
    env = os.environ.get("CROWDSTUDY_PG_BIN")
    candidates = (
        [Path(env)]
        if env
        else sorted(
            Path("/usr/lib/postgresql").glob("*/bin"),
            key=lambda p: int(p.parent.name) if p.parent.name.isdigit() else 0,
            reverse=True,
        )
    )
    for c in candidates:
        if (c / "initdb").is_file() and (c / "pg_ctl").is_file():
            return c
    return None


class LocalPostgres:
    """A PostgreSQL cluster for the duration of a ``with`` block.

    fsync: False for tests (faster; durability is PostgreSQL's concern there), True for
    benchmarks (what a real deployment does); max_connections: the server's limit.
    """

    def __init__(self, *, fsync: bool = False, max_connections: int = 200, database: str = "study"):
        found = find_pg_bin()
        if found is None:
            raise MissingDependencyError(
                "PostgreSQL server binaries (initdb, pg_ctl) not found: install Debian's "
                "`postgresql` package or set CROWDSTUDY_PG_BIN"
            )
        self.bin = found
        self.fsync, self.max_connections, self.database = fsync, int(max_connections), database
        self.port = free_port()
        self.dir: Path | None = None
        self.user = "crowdstudy"

    @property
    def url(self) -> str:
        """SQLAlchemy URL of the database (psycopg 3 driver)."""
        return f"postgresql+psycopg://{self.user}@127.0.0.1:{self.port}/{self.database}"

    def _run(self, *args: str) -> None:
        cmd = [str(self.bin / args[0]), *args[1:]]
        if os.geteuid() == 0:
            cmd = ["su", "nobody", "-s", "/bin/sh", "-c", " ".join(_quote(c) for c in cmd)]
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        if p.returncode != 0:
            raise RuntimeError(f"{args[0]} failed ({p.returncode}): {(p.stderr or p.stdout).strip()[-500:]}")

    def start(self) -> LocalPostgres:
        self.dir = Path(tempfile.mkdtemp(prefix="crowdstudy-pg-"))
        if os.geteuid() == 0:
            import pwd

            nobody = pwd.getpwnam("nobody")
            os.chown(self.dir, nobody.pw_uid, nobody.pw_gid)
        data = self.dir / "data"
        self._run("initdb", "-D", str(data), "-U", self.user, "--auth=trust", "-E", "UTF8", "--no-sync")
        opts = (
            f"-k {self.dir} -p {self.port} -c listen_addresses=127.0.0.1 -c max_connections={self.max_connections}"
            f" -c fsync={'on' if self.fsync else 'off'} -c synchronous_commit={'on' if self.fsync else 'off'}"
        )
        self._run("pg_ctl", "-D", str(data), "-o", opts, "-l", str(self.dir / "server.log"), "-w", "-t", "60", "start")
        self._run("createdb", "-h", "127.0.0.1", "-p", str(self.port), "-U", self.user, self.database)
        return self

    def stop(self) -> None:
        if self.dir is None:
            return
        try:
            self._run("pg_ctl", "-D", str(self.dir / "data"), "-m", "immediate", "-w", "stop")
        except RuntimeError:
            pass
        shutil.rmtree(self.dir, ignore_errors=True)
        self.dir = None

    def __enter__(self) -> LocalPostgres:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def _quote(s: str) -> str:
    import shlex

    return shlex.quote(s)

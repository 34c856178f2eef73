"""Provenance recorded in every output file: seed, git SHA and package versions.

No timestamps are recorded, so the same inputs and seed give byte-identical outputs.
"""

from __future__ import annotations

import functools
import importlib.metadata
import subprocess
from pathlib import Path

__all__ = ["provenance", "git_sha", "package_versions", "repository_root"]

_TRACKED_PACKAGES = ("crowdstudy", "numpy", "scipy", "pandas", "warp-lang", "moderngl", "mujoco", "pyrvo")


def repository_root() -> Path:
    """The folder holding the imported ``crowdstudy/``: the source tree of a checkout, or
    site-packages for an installed wheel. Only optional things use it (the git SHA, the
    benchmark scripts of a checkout); the package's own files are read with
    :mod:`importlib.resources` (:mod:`crowdstudy.package_data`)."""
    return Path(__file__).resolve().parent.parent


@functools.lru_cache(maxsize=1)
def git_sha() -> str:
    """The git commit of the source tree, with ``-dirty`` when it has local changes;
    ``"unknown"`` outside a git checkout of crowdstudy (an installed wheel: its
    site-packages may lie inside some other repository)."""
    root = repository_root()
    if not (root / "pyproject.toml").is_file():
        return "unknown"
    try:
        sha = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=5, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=5,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return f"{sha}-dirty" if dirty else sha


@functools.lru_cache(maxsize=1)
def package_versions() -> dict[str, str]:
    """Versions of the packages that shape the outputs (absent ones are left out)."""
    versions = {}
    for name in _TRACKED_PACKAGES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            continue
    return versions


def provenance(seed: int | None = None, **extra) -> dict:
    """A JSON-serialisable record: ``{"seed", "git_sha", "versions", **extra}``."""
    record = {"seed": None if seed is None else int(seed), "git_sha": git_sha(), "versions": dict(package_versions())}
    record.update(extra)
    return record

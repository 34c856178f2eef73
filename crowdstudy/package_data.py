"""Files shipped inside the package (the paper's design, the consent text, the
questionnaire's front end, shaders ...), found with :mod:`importlib.resources`.

They are read the same way from a source checkout and from an installed wheel; nothing is
ever written next to them (caches go to :func:`crowdstudy.paths.cache_root`).

>>> resource_path("crowdstudy.study", "study.toml").name
'study.toml'
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

__all__ = ["resource_path", "read_resource"]


def resource_path(package: str, *parts: str) -> Path:
    """The file-system path of the resource ``parts`` of ``package`` (file or folder).

    Folders (the questionnaire's ``ui/``) are served by path, so the package must be
    installed as files (every wheel install is); a zipped package raises ``RuntimeError``.
    """
    ref = resources.files(package).joinpath(*parts)
    if isinstance(ref, Path):
        return ref
    raise RuntimeError(
        f"crowdstudy resource {'/'.join(parts)!r} of {package} is not on the file system "
        f"({ref!r}); install crowdstudy unzipped (pip install crowdstudy)"
    )


def read_resource(package: str, *parts: str) -> str:
    """The text (UTF-8) of the resource ``parts`` of ``package``."""
    return resources.files(package).joinpath(*parts).read_text(encoding="utf-8")

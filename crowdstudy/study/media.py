"""Study videos as static files under opaque per-deployment names.

Every video gets the name ``<32 hex digits>.mp4``, an HMAC-SHA256 of (the study's secret,
stimulus id), so a name says nothing about the condition, is the same for every server
process on one database (the secret lives there) and differs between deployments. The
practice clip is named the same way. The browser fetches ``<media URL>/<name>``:

* without ``--media-dir`` the server itself answers ``/media/<name>`` (a dictionary lookup,
  never a path join) with :class:`BlindFileResponse`;
* with ``--media-dir DIR`` every server process publishes the files into ``DIR`` (atomic
  copies, idempotent, safe when several start together) and ``--media-url`` (default
  ``/media``) tells the browser where a CDN or nginx serves that folder: Python is then out of
  the video path.

Order and condition must not leak through headers. Videos are rendered in design order, so a
file's mtime (``Last-Modified``, and the ``ETag`` most servers derive from it) would sort a
participant's trials into design order: :class:`BlindFileResponse` sends neither, and the
published copies all carry the same mtime (:data:`PUBLISHED_MTIME`), so a static server's
validators are equal for every file (:func:`blind_file_response`). A file's size could
still hint at its condition (a denser crowd compresses worse), so the published copies are
also padded to one common size with a trailing MP4 ``free`` box (ignored by players): with
``--media-dir`` every video response has the same headers and length (the server's own
``/media`` route then serves the published copies too; without it, the originals).
"""

from __future__ import annotations

import hashlib
import hmac
import os
import re
import shutil
import tempfile
from collections.abc import Mapping
from pathlib import Path

from crowdstudy.errors import InvalidInputError

__all__ = [
    "media_name",
    "media_table",
    "publish_media",
    "padded_size",
    "MEDIA_NAME_PATTERN",
    "PUBLISHED_MTIME",
    "PRACTICE_KEY",
    "PAD_QUANTUM",
    "blind_file_response",
]

#: A published video's name: 32 lowercase hex digits and ``.mp4``.
MEDIA_NAME_PATTERN = re.compile(r"[0-9a-f]{32}\.mp4")
#: mtime (s since the epoch, 2000-01-01T00:00:00Z) of every published copy.
PUBLISHED_MTIME = 946684800
#: The key under which media_table() names the practice clip.
PRACTICE_KEY = "\x00practice"
#: Published copies are padded to a multiple of this many bytes (and >= 8 bytes of padding).
PAD_QUANTUM = 64 * 1024


def media_name(secret: str, stimulus_id: str) -> str:
    """The opaque file name of ``stimulus_id``'s video in this deployment (secret: the study's)."""
    if not isinstance(secret, str) or len(secret) < 16:
        raise InvalidInputError("secret must be the study's secret (>= 16 characters)")
    digest = hmac.new(secret.encode("utf-8"), f"crowdstudy-media\x00{stimulus_id}".encode(), hashlib.sha256)
    return digest.hexdigest()[:32] + ".mp4"


def media_table(secret: str, files: Mapping[str, Path], practice: Path) -> dict[str, tuple[str, Path]]:
    """{stimulus id (or PRACTICE_KEY): (opaque name, source file)}."""
    out = {sid: (media_name(secret, sid), Path(path)) for sid, path in files.items()}
    out[PRACTICE_KEY] = (media_name(secret, PRACTICE_KEY), Path(practice))
    if len({name for name, _ in out.values()}) != len(out):  # pragma: no cover - 2^-128
        raise InvalidInputError("two videos share a media name; use a new database (a new secret)")
    return out


def padded_size(sizes) -> int:
    """The common size (bytes) of the published copies of files of ``sizes`` bytes: the
    largest plus at least an 8-byte box header, rounded up to PAD_QUANTUM."""
    top = max(sizes) + 8
    return -(-top // PAD_QUANTUM) * PAD_QUANTUM


def publish_media(table: Mapping[str, tuple[str, Path]], out_dir: str | Path) -> Path:
    """Copy every video of ``table`` to ``out_dir/<name>``, padded to :func:`padded_size` with
    a trailing ``free`` box, with mtime PUBLISHED_MTIME.

    A copy already there with that size and mtime is kept; others are written to a
    temporary file and renamed into place (atomic, so server processes publishing together
    never expose a partial file). Returns the folder.
    """
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InvalidInputError(f"--media-dir: cannot create {str(out)!r} ({exc.strerror})") from None
    target = padded_size([src.stat().st_size for _, src in table.values()])
    if target - min(src.stat().st_size for _, src in table.values()) >= 2**32:
        raise InvalidInputError("--media-dir: the videos' sizes differ by 4 GiB or more; cannot pad them alike")
    for name, src in table.values():
        dest = out / name
        pad = target - src.stat().st_size
        try:
            st = dest.stat()
            if st.st_size == target and int(st.st_mtime) == PUBLISHED_MTIME:
                continue
        except FileNotFoundError:
            pass
        fd, tmp = tempfile.mkstemp(dir=out, prefix=".publish-", suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as fh, open(src, "rb") as fin:
                shutil.copyfileobj(fin, fh, 1 << 20)
                fh.write(pad.to_bytes(4, "big") + b"free")  # an ISO BMFF box players skip
                fh.write(bytes(pad - 8))
            os.chmod(tmp, 0o644)
            os.utime(tmp, (PUBLISHED_MTIME, PUBLISHED_MTIME))
            os.replace(tmp, dest)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    return out


_BLIND_CLASS: list = []


def blind_file_response(path: Path, headers: Mapping[str, str]):
    """A Starlette FileResponse for ``path`` (range requests work) WITHOUT Last-Modified and
    ETag: only Content-Length is taken from the file's stat; an ``If-Range`` request gets the
    whole file (there is no validator to match)."""
    if not _BLIND_CLASS:
        from starlette.responses import FileResponse

        class BlindFileResponse(FileResponse):
            def set_stat_headers(self, stat_result):
                self.headers.setdefault("content-length", str(stat_result.st_size))

            def _should_use_range(self, http_if_range: str) -> bool:
                return False

        _BLIND_CLASS.append(BlindFileResponse)
    return _BLIND_CLASS[0](path, media_type="video/mp4", headers=dict(headers))

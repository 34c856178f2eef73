"""Importing and initialising NVIDIA Warp the same way everywhere.

Warp compiles kernels on first use (seconds per module on CPU) and caches the binaries; the
cache lives in the per-user cache folder (``crowdstudy.paths``) unless ``WARP_CACHE_PATH``
says otherwise.
"""

from __future__ import annotations

import functools
import os

from crowdstudy.paths import cache_dir

__all__ = ["get_warp", "resolve_device"]


@functools.lru_cache(maxsize=1)
def get_warp():
    """The initialised ``warp`` module, quiet, with the project's kernel cache."""
    cache = os.environ.get("WARP_CACHE_PATH") or str(cache_dir("warp-cache"))
    os.makedirs(cache, exist_ok=True)
    import warp as wp

    # Warp >= 1.10 replaced ``config.quiet`` with ``config.log_level``: silence the banner and
    # the per-module load lines either way.
    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_WARNING
    else:  # pragma: no cover - older Warp
        wp.config.quiet = True
    wp.config.kernel_cache_dir = cache
    wp.init()
    return wp


def resolve_device(device: str | None = None) -> str:
    """``"cuda:0"`` when a CUDA device is present and ``device`` is None or ``"auto"``,
    else ``"cpu"``; an explicit name is checked and returned."""
    wp = get_warp()
    if device in (None, "auto"):
        return "cuda:0" if wp.is_cuda_available() else "cpu"
    try:
        wp.get_device(device)
    except Exception as exc:  # warp raises plain RuntimeError/ValueError for unknown devices
        from crowdstudy.errors import InvalidInputError

        raise InvalidInputError(f"device {device!r} is not available ({exc}); use 'cpu' or 'cuda:0'") from None
    return device

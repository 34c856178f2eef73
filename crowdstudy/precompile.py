"""``crowdstudy precompile``: compile every Warp kernel module of the toolkit once, ahead of use.

Warp compiles a module the first time one of its kernels is launched (seconds per module
on a CPU, the physics the longest) and keeps the binary in its
kernel cache (``WARP_CACHE_PATH``, else the per-user cache folder). A fresh installation pays
that inside its first ``crowdstudy correct`` or first test; ``make`` set-up runs this command
in the background while it installs the npm packages, compiling the modules on two threads,
so the tests and the first run start with a warm cache. Later runs only check the cache.

    crowdstudy precompile                  # the CPU modules
    crowdstudy precompile --device cuda:0  # and those of a GPU
"""

from __future__ import annotations

import importlib
import time

__all__ = ["KERNEL_MODULES", "precompile"]

#: (Python module, the function that defines its kernels or None when importing does) of
#: every Warp module of the toolkit. Importing a kernel module configures Warp
#: (:func:`~crowdstudy.warp_runtime.get_warp`: the kernel cache) before its kernels exist.
KERNEL_MODULES: tuple[tuple[str, str | None], ...] = (
    ("crowdstudy.physics.kernels", None),
    ("crowdstudy.physics.collision_kernels", None),
    ("crowdstudy.physics.linear", None),
    ("crowdstudy.metrics.kernels", None),
    ("crowdstudy.body.skinning_kernels", None),
    ("crowdstudy.navigation.orca_kernels", None),
)


def precompile(device: str = "cpu", *, workers: int = 2) -> dict[str, float]:
    """Compile (or load from the cache) every module of :data:`KERNEL_MODULES` on ``device``.

    Args:
        device: ``"cpu"``, ``"cuda:0"``, ... (checked by
            :func:`~crowdstudy.warp_runtime.resolve_device`).
        workers: modules compiled at once (threads; Warp releases the GIL while it compiles).
    Returns:
        ``{"modules": n, "seconds": wall time}``.
    """
    from crowdstudy.errors import InvalidInputError
    from crowdstudy.warp_runtime import get_warp, resolve_device

    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 0:
        raise InvalidInputError(f"workers: expected an integer >= 0, got {workers!r}")
    wp = get_warp()
    device = resolve_device(device)
    t0 = time.perf_counter()
    modules = []
    for name, factory in KERNEL_MODULES:
        module = importlib.import_module(name)
        if factory is not None:
            getattr(module, factory)()
        modules.append(wp.get_module(name))
    wp.force_load(device=device, modules=modules, max_workers=workers)
    return {"modules": len(modules), "seconds": time.perf_counter() - t0}

"""Headless OpenGL contexts through EGL (Mesa llvmpipe on CPUs, the NVIDIA driver on GPUs).

One context is created per thread and reused (moderngl standalone contexts are bound to
the thread that created them). A missing EGL/Mesa installation raises
:class:`~crowdstudy.errors.MissingDependencyError` naming the Debian packages to install.
"""

from __future__ import annotations

import threading

from crowdstudy.errors import MissingDependencyError

__all__ = ["get_context", "context_info", "EGL_PACKAGES", "REQUIRED_GL_VERSION"]

#: Debian/Ubuntu packages providing a software EGL/OpenGL 3.3+ implementation.
EGL_PACKAGES = ("libegl1", "libegl-mesa0", "libgl1-mesa-dri", "libgbm1")
REQUIRED_GL_VERSION = 330

_local = threading.local()


def _install_hint() -> str:
    return (
        "install EGL and Mesa: `sudo apt-get install " + " ".join(EGL_PACKAGES) + "` (Debian/Ubuntu; "
        "on an NVIDIA machine the driver's libEGL_nvidia provides it), and the Python packages with "
        "`pip install 'crowdstudy[render]'`"
    )


def get_context():
    """The calling thread's headless moderngl context (created on first use).

    Returns:
        ``moderngl.Context`` with OpenGL >= 3.3 core.

    Raises:
        MissingDependencyError: moderngl is not installed, or no EGL display/context can be
            created (the message says which packages to install).
    """
    ctx = getattr(_local, "ctx", None)
    if ctx is not None:
        return ctx
    try:
        import moderngl
    except ImportError as exc:
        raise MissingDependencyError(f"the renderer needs moderngl ({exc}); {_install_hint()}") from None
    try:
        # moderngl's stub types the keyword settings as one dict; backend is a string
        ctx = moderngl.create_standalone_context(backend="egl", require=REQUIRED_GL_VERSION)  # pyright: ignore[reportArgumentType]
    except Exception as exc:  # glcontext raises plain Exceptions for a missing libEGL or display
        raise MissingDependencyError(
            f"cannot create a headless OpenGL {REQUIRED_GL_VERSION // 100}.{REQUIRED_GL_VERSION % 100 // 10} "
            f"context through EGL ({exc}); {_install_hint()}"
        ) from None
    _local.ctx = ctx
    return ctx


def context_info() -> dict:
    """Renderer, version and vendor strings of the current thread's context."""
    ctx = get_context()
    return {
        "renderer": ctx.info.get("GL_RENDERER", "?"),
        "version": ctx.info.get("GL_VERSION", "?"),
        "vendor": ctx.info.get("GL_VENDOR", "?"),
        "max_samples": int(ctx.max_samples),
    }

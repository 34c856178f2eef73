"""Project exceptions.

Every error raised on bad input names the argument, file or field that is wrong and what
was expected. The classes subclass the builtin a caller would catch anyway
(``ValueError``, ``RuntimeError``) so ``except ValueError`` keeps working.
"""

__all__ = ["CrowdstudyError", "InvalidInputError", "MissingDependencyError"]


class CrowdstudyError(Exception):
    """Base class of the errors raised by crowdstudy on purpose."""


class InvalidInputError(CrowdstudyError, ValueError):
    """An argument, file or field does not have the expected value, type or shape."""


class MissingDependencyError(CrowdstudyError, RuntimeError):
    """A system component (EGL, ffmpeg, Chromium, a Python extra) is not available.

    The message says what to install.
    """

"""crowdstudy: perception research on dense 3D crowds.

Stages (one subpackage each): ``layout``, ``navigation``, ``body``, ``motion``,
``physics``, ``metrics``, ``render``, ``study``, ``stats``. The scene containers live in
:mod:`crowdstudy.scene` and the study design loader in :mod:`crowdstudy.design`.

Importing the package is cheap: heavy dependencies (warp, moderngl, mujoco, dask,
matplotlib) are imported by the functions that need them.
"""

from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version

try:
    __version__ = _version("crowdstudy")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.1.0"

__all__ = ["__version__"]

"""A study design's methods, made: each method's animation of a cell from the cell's Baseline.

A design names its methods as recipes (``[methods.NAME]``, :class:`crowdstudy.design.Method`);
:func:`make_method_animation` runs one recipe on one cell's Baseline animation:

* ``none``: the Baseline as generated, relabelled;
* ``physics`` / ``paper``: :func:`crowdstudy.physics.correct` with the method's
  :class:`~crowdstudy.physics.PhysicsConfig` (``PhysicsConfig()`` or
  ``PhysicsConfig.paper()`` with the method's ``config`` overrides);
* ``mujoco``: the MuJoCo peer (:func:`crowdstudy.physics.mujoco_peer.mujoco_peer`, tuning
  ``setting``);
* ``files``: the user's own animation of the cell, ``<path>/<cell>.npz`` (``cell`` =
  ``S{stage}-{level}``, ``path`` relative to the design file), which must be the same crowd
  as the cell's Baseline: the same characters (body records), frame count and frame rate.

The result's ``meta["method"]`` is the method's name and ``meta["recipe"]`` its
:meth:`~crowdstudy.design.Method.recipe` (:mod:`crowdstudy.scene_meta`).
:func:`check_method_inputs` checks, before any long work, what the recipes need from outside
the package (the ``files`` folders and every cell's file, the ``mujoco`` module).
"""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Iterable
from pathlib import Path

from crowdstudy.design import Method, StudyDesign
from crowdstudy.errors import InvalidInputError, MissingDependencyError
from crowdstudy.scene import CrowdAnimation

__all__ = [
    "make_method_animation",
    "method_physics_config",
    "method_files_folder",
    "method_file",
    "check_method_inputs",
    "files_digest",
]


def method_physics_config(method: Method, base=None):
    """The :class:`~crowdstudy.physics.PhysicsConfig` a ``physics`` or ``paper`` method runs
    (None for the other corrections).

    ``base`` replaces ``PhysicsConfig()`` as the starting point of a ``physics`` method (the
    ``--config`` of ``crowdstudy stimuli``); a ``paper`` method always starts from
    ``PhysicsConfig.paper()``. The method's ``config`` overrides apply on top."""
    if method.correction == "paper" or (method.correction == "physics" and base is None):
        return method.physics_config()
    if method.correction != "physics":
        return None
    from crowdstudy.physics.config import PhysicsConfig

    return PhysicsConfig.from_overrides(method.config, where=f"methods.{method.name}.config", base=base)


def method_files_folder(method: Method, design_dir: str | Path | None) -> Path:
    """The folder of a ``files`` method's animations: its ``path``, relative to the design
    file's folder ``design_dir`` (the working directory when None)."""
    path = Path(method.path or "")
    return path if path.is_absolute() or design_dir is None else Path(design_dir) / path


def method_file(method: Method, cell: str, design_dir: str | Path | None) -> Path:
    """The user's animation of ``cell`` (``S{stage}-{level}``) for a ``files`` method."""
    return method_files_folder(method, design_dir) / f"{cell}.npz"


@functools.lru_cache(maxsize=256)
def _file_sha256(path: str, size: int, mtime_ns: int) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def files_digest(method: Method, cell: str, design_dir: str | Path | None) -> str | None:
    """SHA-256 of a ``files`` method's animation of ``cell`` (None when the file is missing):
    part of the animation's digest, so a replaced file re-makes its videos."""
    path = method_file(method, cell, design_dir)
    try:
        st = path.stat()
    except OSError:
        return None
    return _file_sha256(str(path), st.st_size, st.st_mtime_ns)


def _design_dir(design: StudyDesign) -> Path | None:
    return None if design.source in ("", "<memory>") else Path(design.source).parent


def check_method_inputs(design: StudyDesign, methods: Iterable[str], cells: Iterable[str]) -> None:
    """Check what ``methods`` need for ``cells`` (``S{stage}-{level}``) before the long work:
    every ``files`` method's folder and each cell's file in it (a readable animation with
    the design's frame rate and the cell's character count), ``mujoco`` importable for a
    ``mujoco`` method. Raises :class:`~crowdstudy.errors.InvalidInputError` (or
    :class:`~crowdstudy.errors.MissingDependencyError`) naming the design, the method and
    the file."""
    cells = list(cells)
    where = design.source
    for name in methods:
        method = design.method(name)
        if method.correction == "mujoco":
            _import_mujoco(method)
        if method.correction != "files":
            continue
        folder = method_files_folder(method, _design_dir(design))
        if not folder.is_dir():
            raise InvalidInputError(
                f"{where}: key 'methods.{name}.path': the folder {str(folder)!r} of the method's animations "
                "does not exist"
            )
        for cell in cells:
            _check_cell_file(design, method, cell, method_file(method, cell, _design_dir(design)))


def _check_cell_file(design: StudyDesign, method: Method, cell: str, path: Path) -> None:
    if not path.is_file():
        raise InvalidInputError(
            f"{design.source}: key 'methods.{method.name}.path': no animation {path.name} for the cell {cell} "
            f"in {str(path.parent)!r} (one <cell>.npz per cell: S{{stage}}-{{level}}.npz)"
        )
    anim = CrowdAnimation.load(path)
    level = cell.split("-", 1)[1]
    expected = design.n_characters(level)
    if anim.n_characters != expected:
        raise InvalidInputError(
            f"{path}: method {method.name!r}: {anim.n_characters} characters, but the cell {cell} has {expected}"
        )
    if abs(anim.fps - design.fps) > 1e-9:
        raise InvalidInputError(f"{path}: method {method.name!r}: {anim.fps:g} fps, but the design's is {design.fps}")


def _import_mujoco(method: Method):
    from crowdstudy.physics.mujoco_peer import import_mujoco

    try:
        return import_mujoco()
    except MissingDependencyError:
        raise MissingDependencyError(
            f"method {method.name!r} (correction = 'mujoco') needs the mujoco package: pip install 'crowdstudy[peers]'"
        ) from None


def make_method_animation(
    method: Method,
    baseline: CrowdAnimation,
    *,
    cell: str,
    design_dir: str | Path | None = None,
    progress: bool = False,
    timings: dict | None = None,
    physics=None,
) -> CrowdAnimation:
    """``method``'s animation of one cell, made from the cell's Baseline.

    Args:
        method: the design's recipe (:class:`~crowdstudy.design.Method`).
        baseline: the cell's Baseline animation (T frames, N characters).
        cell: ``S{stage}-{level}``, the name of a ``files`` method's file (``S1-D3.npz``).
        design_dir: the design file's folder (``files`` paths are relative to it).
        progress: progress bars of the physics.
        timings: a dict the physics fills with its timings (``physics``, ``paper``; see
            :func:`crowdstudy.physics.correct`) or the MuJoCo peer with its own.
        physics: the starting ``PhysicsConfig`` of a ``physics`` method
            (:func:`method_physics_config`).
    Returns:
        A new CrowdAnimation with ``meta["method"]`` the method's name and
        ``meta["recipe"]`` its recipe.
    """
    label = {"method": method.name, "recipe": method.recipe()}
    if method.correction == "none":
        return baseline.replace(meta=label)
    if method.correction in ("physics", "paper"):
        from crowdstudy.physics import correct

        out = correct(baseline, method_physics_config(method, physics), progress=progress, timings=timings)
        return out.replace(meta=label)
    if method.correction == "mujoco":
        return _mujoco_animation(method, baseline, timings).replace(meta=label)
    if method.correction == "files":
        return _files_animation(method, baseline, cell, design_dir).replace(meta=label)
    raise InvalidInputError(f"methods.{method.name}.correction: unknown correction {method.correction!r}")


def _mujoco_animation(method: Method, baseline: CrowdAnimation, timings: dict | None) -> CrowdAnimation:
    _import_mujoco(method)
    from crowdstudy.physics.mujoco_peer import mujoco_peer

    if method.setting is None:
        out, timing = mujoco_peer(baseline, None)
    else:
        out, timing = mujoco_peer(baseline, None, setting=method.setting)
    if timings is not None:
        timings.update(timing)
    return out.replace(
        meta={"baseline_method": baseline.meta.get("method"), "baseline_provenance": baseline.meta.get("provenance")}
    )


def _files_animation(method: Method, baseline: CrowdAnimation, cell: str, design_dir) -> CrowdAnimation:
    """The user's animation of ``cell``, checked to be the Baseline's crowd."""
    path = method_file(method, cell, design_dir)
    if not path.is_file():
        raise InvalidInputError(f"method {method.name!r}: no animation for the cell {cell}: {str(path)!r} is missing")
    anim = CrowdAnimation.load(path)
    differs = []
    if tuple(anim.bodies) != tuple(baseline.bodies):
        differs.append(
            f"characters ({anim.n_characters} body records, the Baseline's {baseline.n_characters}"
            + (", not the same ones" if anim.n_characters == baseline.n_characters else "")
            + ")"
        )
    if anim.n_frames != baseline.n_frames:
        differs.append(f"frames ({anim.n_frames}, the Baseline's {baseline.n_frames})")
    if abs(anim.fps - baseline.fps) > 1e-9:
        differs.append(f"fps ({anim.fps:g}, the Baseline's {baseline.fps:g})")
    if tuple(anim.joint_names) != tuple(baseline.joint_names):
        differs.append("skeleton (joint names)")
    if differs:
        raise InvalidInputError(
            f"{path}: method {method.name!r} is not the cell {cell}'s crowd: it differs in " + ", ".join(differs)
        )
    scene = {k: v for k, v in baseline.meta.items() if k not in anim.meta}
    return anim.replace(meta={**scene, "baseline_method": baseline.meta.get("method")})

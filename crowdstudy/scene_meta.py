"""The ``meta`` dict of a :class:`~crowdstudy.scene.CrowdAnimation`: every key the package
writes or reads, its type and unit, who writes it and who reads it.

``meta`` travels with the animation (JSON inside its ``.npz``); each stage adds what the
later stages need, so that physics, metrics and rendering take a scene's geometry from the
file, never from a default design. Users may add keys of their own: keys not listed here
are kept and never checked. :func:`check_meta` checks the listed keys when an animation is
made, loaded or saved, and names a bad one by its path
(``meta.periodic.length: expected a positive number, got 0``).

The scene (written by :mod:`crowdstudy.layout` and :mod:`crowdstudy.navigation` into the
:class:`~crowdstudy.scene.Crowd`, copied into the animation by
:mod:`crowdstudy.motion.baseline`):

``scenario`` (str)
    ``"concert"`` (stationary dancers), ``"corridor"`` (walkers) or ``"crossing"`` (two
    flows crossing on a plaza); other values name a user's own scene. Read by the renderer
    (:func:`crowdstudy.render.assets.scenario_of`) and by :func:`static_walls_from_meta` (a
    concert, corridor or crossing must list its walls).
``floor`` (:class:`Floor`)
    ``{"width": m, "depth": m}``, the floor the crowd stands on (x by y), centred on the
    origin.
``stage_distance``, ``stage_front`` (float, m; concert)
    how far the stage lies in front of the floor's front edge, and the stage front's y.
``corridor_width``, ``corridor_length`` (float, m; corridor)
    the corridor's width (y) and the length of its periodic section (x).
``plaza`` (:class:`Plaza`; crossing)
    ``{"width": m, "depth": m, "angle": deg, "obstacles": [...]}``: the paved plaza around
    the crossing area, the second flow's direction and the obstacles as the design gave them
    (``{"shape": "circle", "center": [x, y], "radius": m}`` or ``{"shape": "polygon",
    "points": [[x, y], ...]}``, counter-clockwise, each with ``height`` m and ``label``).
    Read by the renderer (:mod:`crowdstudy.render.plaza`), which draws them as solids.
``obstacles`` (list of ``[[x0, y0], [x1, y1]]``, m)
    the scene's walls as floor segments (the concert's stage front, the corridor's walls as
    its navigation saw them, the edges of a crossing's obstacles, a circle as the 16-gon
    around it); ``[]`` for none. Read by the physics (one-sided wall
    contacts), :mod:`crowdstudy.metrics.walls` and :mod:`crowdstudy.metrics.floor`, through
    :func:`static_walls_from_meta`.
``periodic`` (:class:`Periodic` or absent)
    ``{"axis": 0, "length": L}`` with L in m: the scene repeats every L along x (the
    corridor); positions are stored unwrapped and every consumer uses the minimum image
    (:attr:`CrowdAnimation.periodic_length <crowdstudy.scene.CrowdAnimation.periodic_length>`:
    physics contacts, overlap and smoothness metrics, the renderer).

The cell (written by :func:`crowdstudy.motion.baseline.build_baseline` and
``crowdstudy animate``):

``stage`` (str)
    the design's stage key, ``"stationary"`` or ``"walking"``.
``stage_number`` (int)
    the design's stage number (1, 2).
``density_level`` (str), ``density`` (float, characters per m^2)
    the design's density level (``"D1"`` .. ``"D5"``) and its nominal density.
``n_characters`` (int)
    characters the design asked for.
``seed`` (int or None)
    the seed the crowd was drawn with; the physics records it in its provenance, the
    renderer draws the characters' colours from it.
``source`` (str)
    ``crowdstudy animate``: the crowd file the animation was made from.

The motion (:mod:`crowdstudy.motion.baseline`):

``method`` (str)
    the method that made the animation: ``"Baseline"`` (the animation as generated) or
    ``"Ours"`` (after the physics), or the name a study design gives the method
    (``[methods.NAME]``, :func:`crowdstudy.recipes.make_method_animation`); the
    benchmarks label other peers (``"MuJoCo"``). Read by the metrics' summaries.
``recipe`` (:class:`Recipe`)
    how a study design's method made the animation (:meth:`crowdstudy.design.Method.recipe`):
    ``{"correction": "none" | "physics" | "paper" | "mujoco" | "files"}`` and what that
    correction takes (``config``: the ``PhysicsConfig`` overrides, e.g. ``{"damping": 0.06}``;
    ``setting``: the MuJoCo tuning; ``path``: the folder of the user's animations). Written
    by :func:`crowdstudy.recipes.make_method_animation` (``crowdstudy stimuli``).
``bodies`` (:class:`BodiesMeta` or absent)
    ``{"shapes": "population"}``: the bodies' weight and muscle were drawn with that
    :data:`~crowdstudy.body.shapes.BodyShapes` (a design's ``[bodies] shapes``); absent: the
    default ``"study"`` draw (so the paper's animations keep their bytes). Written by
    :func:`crowdstudy.motion.baseline.build_baseline` and ``crowdstudy animate``.
``tempo`` (float bpm, or None; concert)
    the beat the dancers share (None: each motion-capture clip at its own tempo).
``loop`` (:class:`Loop`)
    how the video loops: ``{"mode": "periodic", "frames": T}`` the animation is exactly
    periodic over its T frames (the physics then corrects it as a loop);
    ``{"mode": "dissolve", "frames": D, "video_frames": T}`` the video shows the first T
    frames and cross-dissolves frames T .. T+D-1 into its first D (the renderer, the
    smoothness metric's seam); ``{"mode": "none"}`` no loop. See :func:`loop_mode`.
``provenance`` (dict)
    :func:`crowdstudy.provenance.provenance` of the stage that wrote the file: seed, git
    SHA, package versions, and (``stage``, ``design``) where known. No timestamps.

An imported crowd (:mod:`crowdstudy.interchange.gltf_crowd`, ``crowdstudy import-crowd``):

``imported`` (dict)
    where the animation came from, so the corrected motion can be written back: ``format``
    (``"gltf"``), ``file`` and its ``sha256``, the ``animations`` sampled, ``time_start``
    (s, the file time of frame 0), ``fps``, the ``overrides`` given with ``--map`` and per
    character its ``skin`` or ``node``, its ``root`` node and its ``mapping`` ({physics
    joint: {``joint``, ``name``, ``how``}}). Such a crowd's ``scenario`` is ``"imported"``.

The correction (:func:`crowdstudy.physics.corrector.correct`):

``physics`` (:class:`PhysicsMeta`)
    what the correction did: the configuration it used (resolved for the crowd), the
    crowd's measured density, the solver's counts (deterministic values only: no timings).
``baseline_method`` (str or None), ``baseline_provenance`` (dict or None)
    the input's ``method`` and ``provenance``.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Mapping
from typing import Any, Literal, TypedDict

import numpy as np

from crowdstudy.errors import InvalidInputError

__all__ = [
    "LoopMode",
    "LOOP_MODES",
    "Floor",
    "Periodic",
    "Plaza",
    "Loop",
    "PhysicsLoop",
    "PhysicsMeta",
    "Recipe",
    "BodiesMeta",
    "SceneMeta",
    "check_meta",
    "loop_mode",
    "periodic_length",
    "static_walls_from_meta",
    "wall_segments",
]

#: How an animation's video loops (``meta["loop"]["mode"]``).
LoopMode = Literal["periodic", "dissolve", "none"]
LOOP_MODES: tuple[LoopMode, ...] = ("periodic", "dissolve", "none")


class Floor(TypedDict):
    """``meta["floor"]``: the floor's extent, m (x by y)."""

    width: float
    depth: float


class Plaza(TypedDict):
    """``meta["plaza"]``: a crossing's plaza (m), flow angle (deg) and obstacle shapes."""

    width: float
    depth: float
    angle: float
    obstacles: list[dict[str, Any]]


class Periodic(TypedDict):
    """``meta["periodic"]``: the scene repeats every ``length`` m along ``axis`` (0: x)."""

    axis: int
    length: float


class Loop(TypedDict, total=False):
    """``meta["loop"]``: ``mode`` (:data:`LoopMode`); ``frames`` (periodic: the period T;
    dissolve: the cross-dissolve's D frames); ``video_frames`` (dissolve: the T frames the
    video shows)."""

    mode: LoopMode
    frames: int
    video_frames: int


class PhysicsLoop(TypedDict):
    """``meta["physics"]["loop"]``: whether the input was corrected as a loop, and the
    frames simulated before (``warmup_frames``) and after (``blend_frames``) it."""

    periodic: bool
    warmup_frames: int
    blend_frames: int


class PhysicsMeta(TypedDict, total=False):
    """``meta["physics"]`` of a corrected animation.

    Keys: ``config`` (the nested dict of the
    :class:`~crowdstudy.physics.config.PhysicsConfig` used, resolved for the crowd:
    ``PhysicsConfig.from_dict`` reads it back); ``crowd_density`` (characters per m^2, as
    :func:`~crowdstudy.physics.crowding.crowd_density` measured the input);
    ``profile_weight`` (0 sparse .. 1 dense end of the density profile, None when no field
    followed it); ``device`` (the Warp device, ``"cpu"``, ``"cuda:0"`` ...);
    ``linear_solver`` (``"fused"``, ``"warp"``, ``"scipy"``); ``steps`` (simulation steps,
    settle included); ``substeps_per_frame``; ``dt`` (s, the step used); ``cg_iterations_mean``
    and ``cg_iterations_max`` (per step); ``static_walls`` (walls the contacts saw);
    ``contacts_mean`` and ``contacts_max`` (per step); ``contacts_dropped_steps`` (steps whose
    contacts overflowed the capacity); ``pairs_dropped``; ``loop`` (:class:`PhysicsLoop`);
    ``speed_limit`` (the output stage's speed-limit report,
    :meth:`~crowdstudy.physics.speed_limit.SpeedLimitReport.as_dict`, or None when off).
    """

    config: dict[str, Any]
    crowd_density: float
    profile_weight: float | None
    device: str
    linear_solver: str
    steps: int
    substeps_per_frame: int
    dt: float
    cg_iterations_mean: float
    cg_iterations_max: int
    static_walls: int
    contacts_mean: float
    contacts_max: int
    contacts_dropped_steps: int
    pairs_dropped: int
    loop: PhysicsLoop
    speed_limit: dict[str, Any] | None


class Recipe(TypedDict, total=False):
    """``meta["recipe"]``: how a study design's method made the animation."""

    correction: str
    config: dict[str, Any]
    setting: str | None
    path: str


class BodiesMeta(TypedDict):
    """``meta["bodies"]``: the body-shape draw (``crowdstudy.body.shapes.BodyShapes``)."""

    shapes: str


class SceneMeta(TypedDict, total=False):
    """A :class:`~crowdstudy.scene.CrowdAnimation`'s ``meta``: every key optional (the
    module's docstring says what each means and who writes it); other keys allowed."""

    scenario: str
    floor: Floor
    stage_distance: float
    stage_front: float
    corridor_width: float
    corridor_length: float
    obstacles: list[list[list[float]]]
    plaza: Plaza
    periodic: Periodic
    stage: str
    stage_number: int
    density_level: str
    density: float
    n_characters: int
    seed: int | None
    source: str
    method: str
    recipe: Recipe
    bodies: BodiesMeta
    tempo: float | None
    loop: Loop
    provenance: dict[str, Any]
    imported: dict[str, Any]
    physics: PhysicsMeta
    baseline_method: str | None
    baseline_provenance: dict[str, Any] | None


# -- the checks ------------------------------------------------------------------------
def _fail(path: str, what: str, value: object) -> InvalidInputError:
    return InvalidInputError(f"{path}: expected {what}, got {value!r}")


def _finite(value: object) -> float | None:
    """``value`` as a float when it is a finite real number (not a bool), else None."""
    if not isinstance(value, numbers.Real) or isinstance(value, (bool, np.bool_)):
        return None
    x = float(value)
    return x if math.isfinite(x) else None


def _number(value: object, path: str, *, lo: float = -math.inf, positive: bool = False) -> None:
    x = _finite(value)
    if positive:
        if x is None or not x > 0:
            raise _fail(path, "a positive number", value)
    elif x is None or not x >= lo:
        raise _fail(path, "a number" if lo == -math.inf else f"a number >= {lo:g}", value)


def _integer(value: object, path: str, lo: int = 0) -> None:
    if not isinstance(value, numbers.Integral) or isinstance(value, (bool, np.bool_)) or value < lo:
        raise _fail(path, f"an integer >= {lo}", value)


def _text(value: object, path: str) -> None:
    if not isinstance(value, str):
        raise _fail(path, "a string", value)


def _mapping(value: object, path: str) -> Mapping[str, Any]:
    """``value`` when it is a mapping (the keys of a ``meta`` are strings)."""
    if not isinstance(value, Mapping):
        raise _fail(path, "a dict", value)
    return value


def _optional(check: Callable[[object, str], object]) -> Callable[[object, str], object]:
    return lambda value, path: None if value is None else check(value, path)


def _floor(value: object, path: str) -> None:
    value = _mapping(value, path)
    for key in ("width", "depth"):
        if key not in value:
            raise InvalidInputError(f"{path}.{key}: missing (the floor's extent in m)")
        _number(value[key], f"{path}.{key}", positive=True)


def _periodic(value: object, path: str) -> None:
    if not value:  # None or {}: not periodic
        return
    value = _mapping(value, path)
    if "length" not in value:
        raise InvalidInputError(f"{path}.length: missing (the period along x, m)")
    _number(value["length"], f"{path}.length", positive=True)
    _integer(value.get("axis", 0), f"{path}.axis")


def _obstacles(value: object, path: str) -> None:
    wall_segments(value, path)


def _plaza(raw: object, path: str) -> None:
    value = _mapping(raw, path)
    for key in ("width", "depth"):
        if key not in value:
            raise InvalidInputError(f"{path}.{key}: missing (the plaza's extent in m)")
        _number(value[key], f"{path}.{key}", positive=True)
    if not isinstance(value.get("obstacles", []), list):
        raise InvalidInputError(f"{path}.obstacles: expected a list of obstacle shapes")


def _loop(value: object, path: str) -> None:
    value = _mapping(value, path)
    mode = value.get("mode")
    if mode not in LOOP_MODES:
        raise _fail(f"{path}.mode", "one of " + ", ".join(map(repr, LOOP_MODES)), mode)
    if "frames" in value:
        _integer(value["frames"], f"{path}.frames")
    if mode == "dissolve":
        if "video_frames" not in value:
            raise InvalidInputError(f"{path}.video_frames: missing (the frames the video shows)")
        _integer(value["video_frames"], f"{path}.video_frames", lo=1)


#: The corrections a recipe names (``crowdstudy.design.Correction``; kept here as text so
#: that the meta schema imports nothing of the design).
_CORRECTIONS = ("none", "physics", "paper", "mujoco", "files")


def _recipe(raw: object, path: str) -> None:
    value = _mapping(raw, path)
    if value.get("correction") not in _CORRECTIONS:
        raise _fail(f"{path}.correction", f"one of {', '.join(_CORRECTIONS)}", value.get("correction"))
    if "config" in value:
        _mapping(value["config"], f"{path}.config")


#: The body-shape draws (``crowdstudy.body.shapes.BODY_SHAPES``, kept here as text too).
_BODY_SHAPES = ("study", "population")


def _bodies(raw: object, path: str) -> None:
    value = _mapping(raw, path)
    if value.get("shapes") not in _BODY_SHAPES:
        raise _fail(f"{path}.shapes", f"one of {', '.join(_BODY_SHAPES)}", value.get("shapes"))


def _physics(value: object, path: str) -> None:
    value = _mapping(value, path)
    if "config" in value:
        _mapping(value["config"], f"{path}.config")
    for key in ("crowd_density", "dt", "cg_iterations_mean", "contacts_mean"):
        if key in value:
            _number(value[key], f"{path}.{key}", lo=0.0)
    if value.get("profile_weight") is not None:
        _number(value["profile_weight"], f"{path}.profile_weight", lo=0.0)
    for key in (
        "steps",
        "substeps_per_frame",
        "cg_iterations_max",
        "static_walls",
        "contacts_max",
        "contacts_dropped_steps",
        "pairs_dropped",
    ):
        if key in value:
            _integer(value[key], f"{path}.{key}")
    for key in ("device", "linear_solver"):
        if key in value:
            _text(value[key], f"{path}.{key}")
    if "loop" in value:
        _mapping(value["loop"], f"{path}.loop")


_CHECKS: dict[str, Callable[[object, str], object]] = {
    "scenario": _text,
    "stage": _text,
    "density_level": _text,
    "method": _text,
    "source": _text,
    "baseline_method": _optional(_text),
    "stage_number": _integer,
    "n_characters": _integer,
    "seed": _optional(_integer),
    "density": lambda v, p: _number(v, p, lo=0.0),
    "tempo": _optional(lambda v, p: _number(v, p, positive=True)),
    "stage_distance": _number,
    "stage_front": _number,
    "corridor_width": lambda v, p: _number(v, p, positive=True),
    "corridor_length": lambda v, p: _number(v, p, positive=True),
    "floor": _floor,
    "obstacles": lambda v, p: _obstacles(v, p),
    "plaza": _plaza,
    "periodic": _periodic,
    "loop": _loop,
    "physics": _physics,
    "recipe": _recipe,
    "bodies": _bodies,
    "provenance": _optional(_mapping),
    "baseline_provenance": _optional(_mapping),
    "imported": _mapping,
}


def check_meta(meta: object, source: str = "") -> None:
    """Check the keys of ``meta`` this module lists (the others are the user's own and
    pass); :class:`~crowdstudy.errors.InvalidInputError` naming the key by its path
    (``meta.periodic.length``), after ``source`` (what the meta belongs to) when given."""
    prefix = f"{source}: " if source else ""
    if not isinstance(meta, Mapping):
        raise InvalidInputError(f"{prefix}meta: expected a dict, got {type(meta).__name__}")
    try:
        for key, check in _CHECKS.items():
            if key in meta:
                check(meta[key], f"meta.{key}")
    except InvalidInputError as exc:
        raise InvalidInputError(f"{prefix}{exc}") from None


# -- typed accessors -------------------------------------------------------------------
def loop_mode(meta: Mapping[str, Any]) -> LoopMode:
    """``meta["loop"]["mode"]``, ``"none"`` when the animation has no ``loop``."""
    loop = meta.get("loop")
    return loop.get("mode", "none") if isinstance(loop, Mapping) else "none"


def periodic_length(meta: Mapping[str, Any]) -> float | None:
    """``meta["periodic"]["length"]`` (m, the period along x), None when not periodic."""
    per = meta.get("periodic")
    return None if not per else float(per["length"])


def static_walls_from_meta(meta: Mapping[str, Any]) -> np.ndarray:
    """(M, 2, 2) wall segments (m) of a scene, from ``meta["obstacles"]``: the walls the
    stage that made the crowd wrote there (the concert's stage front, the corridor walls
    exactly as its navigation saw them); an empty list means no walls. Nothing is taken
    from a study design.

    A concert, corridor or crossing animation without ``meta["obstacles"]`` (a file written by an
    older version) is an error: its walls are unknown. A scene of any other scenario (or
    none) without the key has no walls.
    """
    if not isinstance(meta, Mapping):
        raise InvalidInputError(f"meta: expected a dict, got {type(meta).__name__}")
    if "obstacles" not in meta:
        scenario = meta.get("scenario")
        if scenario in ("concert", "corridor", "crossing"):
            raise InvalidInputError(
                f"meta['obstacles']: missing from this {scenario} animation, so its walls are unknown "
                "(written by an older crowdstudy?); regenerate it (crowdstudy layout/navigate, then "
                "crowdstudy animate, or crowdstudy.motion.build_baseline), or set meta['obstacles'] to "
                "its wall segments [[[x0, y0], [x1, y1]], ...] in metres ([] for none)"
            )
        return np.zeros((0, 2, 2))
    return wall_segments(meta["obstacles"], "meta['obstacles']")


def wall_segments(value: object, name: str) -> np.ndarray:
    """``value`` as (M, 2, 2) wall segments in the floor plane (m; empty: (0, 2, 2)), or an
    :class:`~crowdstudy.errors.InvalidInputError` naming ``name``."""
    try:
        walls = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        raise InvalidInputError(
            f"{name}: expected (M, 2, 2) wall segments [[[x0, y0], [x1, y1]], ...] in metres"
        ) from None
    if walls.size == 0:
        return np.zeros((0, 2, 2))
    if walls.ndim != 3 or walls.shape[1:] != (2, 2):
        raise InvalidInputError(f"{name}: expected (M, 2, 2) wall segments, got shape {walls.shape}")
    if not np.all(np.isfinite(walls)):
        raise InvalidInputError(f"{name}: wall end points must be finite numbers (m)")
    return walls

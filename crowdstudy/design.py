"""The study design (``crowdstudy/study/study.toml``, the paper's; ``stimuli/study.toml`` in a
checkout links to it): loading, validation and the stimulus list.

>>> design = load_design()                      # the paper's design shipped with the toolkit
>>> design.n_characters("D5")
60
>>> len(design.stimuli())                       # 40 stationary + 20 walking videos
60

Every error names the file and the key (``densities.D3``, ``viewpoints.V2.fov``...).
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, NamedTuple, NoReturn, TypeVar, cast, get_args

from crowdstudy.errors import InvalidInputError
from crowdstudy.package_data import resource_path

if TYPE_CHECKING:
    from crowdstudy.body.shapes import BodyShapes

__all__ = [
    "StudyDesign",
    "Stage",
    "Viewpoint",
    "Scenario",
    "Item",
    "Stimulus",
    "load_design",
    "default_design_path",
    "read_toml",
    "parse_design",
    "ScenarioKind",
    "MotionSource",
    "CorridorDirection",
    "Method",
    "Correction",
    "Task",
    "Comparison",
    "SliderScale",
    "DEFAULT_METHODS",
]

#: The kinds of scene a scenario builds: a stationary concert crowd, people walking a corridor,
#: two flows of walkers crossing on a plaza with obstacles. A design names its scenarios
#: freely (``[scenarios.NAME]``); ``kind`` says which builder makes them (a scenario named
#: like a kind is of that kind).
ScenarioKind = Literal["concert", "corridor", "crossing"]
#: Where a scenario's body motion comes from: motion-capture clips or procedural animation.
MotionSource = Literal["mocap", "procedural"]
#: Which way a corridor crowd walks: all one way, or both ways.
CorridorDirection = Literal["unidirectional", "bidirectional"]

#: How a method makes its animation from the cell's Baseline: ``none`` the Baseline as
#: generated; ``physics`` :func:`~crowdstudy.physics.correct` with ``PhysicsConfig()`` and the
#: method's ``config`` overrides; ``paper`` the same from ``PhysicsConfig.paper()`` (the
#: paper's method alone); ``mujoco`` the MuJoCo peer (:mod:`crowdstudy.physics.mujoco_peer`,
#: tuning ``setting``); ``files`` the user's own animations, one ``<cell>.npz`` per cell in
#: the folder ``path``.
Correction = Literal["none", "physics", "paper", "mujoco", "files"]
#: What a stage asks of the participant: six-point (the design's ``points``) Likert answers
#: to the statements, a 0-100 visual analogue scale per statement, or a two-alternative
#: forced choice between two videos of the same cell made by two methods.
Task = Literal["likert", "slider", "2afc"]

_KINDS: tuple[ScenarioKind, ...] = get_args(ScenarioKind)
_CORRECTIONS: tuple[Correction, ...] = get_args(Correction)
_TASKS: tuple[Task, ...] = get_args(Task)
_MOTION_SOURCES: tuple[MotionSource, ...] = get_args(MotionSource)
_CORRIDOR_DIRECTIONS: tuple[CorridorDirection, ...] = get_args(CorridorDirection)


@dataclasses.dataclass(frozen=True)
class Viewpoint:
    """A camera looking at the centre of the crowd area.

    ``azimuth`` (deg) is the direction from the area centre to the camera, from +x towards
    +y; ``elevation`` (deg) above the horizon; ``fov`` (deg) vertical field of view. The
    distance is chosen by the renderer so the whole area is framed.
    """

    id: str
    label: str
    azimuth: float
    elevation: float
    fov: float


@dataclasses.dataclass(frozen=True)
class Method:
    """One method of the design: how its animation of a cell is made (``[methods.NAME]``).

    Attributes:
        name: the method's name as the design writes it (``"Ours"``).
        correction: :data:`Correction`.
        config: ``PhysicsConfig`` overrides (``physics`` and ``paper``), as written: dotted
            paths, unique field names or section tables (``{"damping": 0.06}``).
        setting: the MuJoCo peer's tuning (``mujoco``; None: its default).
        path: the folder of the user's animations (``files``), as written; relative paths
            are relative to the design file.
    """

    name: str
    correction: Correction
    config: dict = dataclasses.field(default_factory=dict)
    setting: str | None = None
    path: str | None = None

    def recipe(self) -> dict[str, Any]:
        """What makes this method's animations, as plain JSON: recorded in each
        animation's ``meta["recipe"]`` and in the stimuli's digests."""
        out: dict[str, Any] = {"correction": self.correction}
        if self.correction in ("physics", "paper"):
            out["config"] = dict(self.config)
        if self.correction == "mujoco":
            out["setting"] = self.setting
        if self.correction == "files":
            out["path"] = self.path
        return out

    def physics_config(self):
        """The :class:`~crowdstudy.physics.PhysicsConfig` of a ``physics`` or ``paper``
        method (its overrides applied), None for the others."""
        if self.correction not in ("physics", "paper"):
            return None
        from crowdstudy.physics.config import PhysicsConfig

        base = PhysicsConfig.paper() if self.correction == "paper" else PhysicsConfig()
        return PhysicsConfig.from_overrides(self.config, where=f"methods.{self.name}.config", base=base)


#: The recipes of the two methods a design may name in ``order`` without a table.
DEFAULT_METHODS: dict[str, Method] = {
    "Baseline": Method("Baseline", "none"),
    "Ours": Method("Ours", "physics"),
}


@dataclasses.dataclass(frozen=True)
class Stage:
    """One stage of the study: a scenario seen from some viewpoints, with one task.

    ``methods`` are the methods whose videos the stage shows (every method of the design,
    or for a ``2afc`` stage those its ``pairs`` name, in the design's order); ``pairs`` the
    method pairs a ``2afc`` stage compares in every cell (empty for the other tasks)."""

    key: str  # "stationary" | "walking"
    number: int  # 1, 2 ...
    scenario: str  # a [scenarios.NAME] of the design
    description: str
    viewpoints: tuple[str, ...]
    task: Task = "likert"
    methods: tuple[str, ...] = ()
    pairs: tuple[tuple[str, str], ...] = ()


@dataclasses.dataclass(frozen=True)
class Scenario:
    """Scenario parameters as a read-only mapping (``scenario["width"]``): those of its
    scenario (a concert's ``stage_distance``, ``margin``, ``tempo``; a corridor's ``width``,
    ``length``, ``direction`` (:data:`CorridorDirection`), ``preferred_speed``,
    ``preferred_speed_sd``) and ``motion`` (:data:`MotionSource`). ``kind``
    (:data:`ScenarioKind`) says which builder makes its crowds."""

    name: str
    params: dict
    kind: ScenarioKind = "concert"

    def __getitem__(self, key: str) -> Any:
        try:
            return self.params[key]
        except KeyError:
            raise InvalidInputError(f"scenarios.{self.name}: no key {key!r}") from None


@dataclasses.dataclass(frozen=True)
class Item:
    id: str
    text: str
    reverse: bool


@dataclasses.dataclass(frozen=True)
class Comparison:
    """``[questionnaire.comparison]``: the one statement a ``2afc`` trial asks about its two
    videos (the answer is which video)."""

    text: str


@dataclasses.dataclass(frozen=True)
class SliderScale:
    """``[questionnaire.slider]``: the labels at the two ends of a ``slider`` stage's 0-100
    visual analogue scale (default: the Likert scale's first and last labels)."""

    left: str
    right: str
    minimum: int = 0
    maximum: int = 100


@dataclasses.dataclass(frozen=True)
class Stimulus:
    """One video of the study."""

    stimulus_id: str  # e.g. "S1-D3-V2-Ours"
    stage: int
    stage_key: str
    scenario: str
    density_level: str
    density: float
    n_characters: int
    viewpoint: str
    method: str
    seed: int  # seed of the (stage, density) cell: shared by all its viewpoints and methods

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class StudyDesign:
    name: str
    seed: int
    floor_width: float
    floor_depth: float
    densities: dict[str, float]
    viewpoints: dict[str, Viewpoint]
    methods: tuple[str, ...]  # the presentation and analysis order; the first is the reference
    video_width: int
    video_height: int
    duration: float
    fps: int
    stages: tuple[Stage, ...]
    scenarios: dict[str, Scenario]
    likert_points: int
    likert_labels: tuple[str, ...]
    items: tuple[Item, ...]
    composites: dict[str, tuple[str, ...]]
    source: str = "<memory>"
    #: every method's recipe, by name (``methods`` gives their order)
    method_recipes: dict[str, Method] = dataclasses.field(default_factory=dict)
    #: the ``2afc`` statement (required when a stage's task is ``2afc``)
    comparison: Comparison | None = None
    #: the ``slider`` scale's end labels
    slider: SliderScale | None = None
    #: the design's ``[online]`` table as written (the online study's controls, validated by
    #: ``crowdstudy.study.quality.online_config``), or None
    online: dict | None = None
    #: ``[bodies] shapes``: the MakeHuman bodies' weight and muscle draw
    #: (:data:`~crowdstudy.body.shapes.BodyShapes`); the paper's design keeps ``"study"``
    body_shapes: BodyShapes = "study"

    @property
    def reference_method(self) -> str:
        """The method the others are compared with: the first of ``methods``."""
        return self.methods[0]

    def method(self, name: str) -> Method:
        """The recipe of method ``name``."""
        try:
            return self.method_recipes[name]
        except KeyError:
            raise InvalidInputError(
                f"unknown method {name!r}; the design's methods are {', '.join(self.methods)}"
            ) from None

    def scenario_of(self, name_or_kind: str) -> Scenario:
        """The scenario named ``name_or_kind``, else the first of that kind (``"corridor"``:
        the design's corridor, whatever its name)."""
        if name_or_kind in self.scenarios:
            return self.scenarios[name_or_kind]
        for sc in self.scenarios.values():
            if sc.kind == name_or_kind:
                return sc
        raise InvalidInputError(
            f"the design has no scenario {name_or_kind!r}; its scenarios are "
            + ", ".join(f"{n} ({sc.kind})" for n, sc in self.scenarios.items())
        )

    def stage_of_kind(self, kind: ScenarioKind) -> Stage:
        """The first stage whose scenario is of ``kind`` (the paper's ``stationary`` for
        ``"concert"``, ``walking`` for ``"corridor"``): what ``crowdstudy layout`` and
        ``navigate`` take their cell seeds and scenario parameters from."""
        for st in self.stages:
            if self.scenarios[st.scenario].kind == kind:
                return st
        raise InvalidInputError(
            f"{self.source}: no stage of the design is a {kind} (its stages: "
            + ", ".join(f"{st.key} ({self.scenarios[st.scenario].kind})" for st in self.stages)
            + ")"
        )

    def tasks(self) -> tuple[Task, ...]:
        """The tasks of the design's stages, each once, in stage order."""
        return tuple(dict.fromkeys(st.task for st in self.stages))

    @property
    def floor_area(self) -> float:
        return self.floor_width * self.floor_depth

    def n_characters(self, level: str) -> int:
        """Number of characters for a density level: round(density * floor area)."""
        if level not in self.densities:
            raise InvalidInputError(f"unknown density level {level!r}; expected one of {', '.join(self.densities)}")
        return int(round(self.densities[level] * self.floor_area))

    def stage(self, key: str) -> Stage:
        for st in self.stages:
            if key in (st.key, str(st.number), st.scenario):
                return st
        raise InvalidInputError(f"unknown stage {key!r}; expected one of {', '.join(s.key for s in self.stages)}")

    def cell_seed(self, stage: Stage, level: str) -> int:
        """Seed of one (stage, density) cell, derived from the design's base seed."""
        return self.seed + 1000 * stage.number + list(self.densities).index(level)

    def stimuli(self) -> list[Stimulus]:
        """Every video of the study, stage by stage, density, viewpoint, method."""
        out = []
        for st in self.stages:
            for level, value in self.densities.items():
                for vp in st.viewpoints:
                    for method in st.methods:
                        out.append(
                            Stimulus(
                                stimulus_id=f"S{st.number}-{level}-{vp}-{method}",
                                stage=st.number,
                                stage_key=st.key,
                                scenario=st.scenario,
                                density_level=level,
                                density=value,
                                n_characters=self.n_characters(level),
                                viewpoint=vp,
                                method=method,
                                seed=self.cell_seed(st, level),
                            )
                        )
        return out


def default_design_path() -> Path:
    """The paper's design shipped in the package (``crowdstudy/study/study.toml``)."""
    return resource_path("crowdstudy.study", "study.toml")


_T = TypeVar("_T")


class _Reader:
    """Typed access to a TOML table that reports the full key path on error."""

    def __init__(self, table: dict, path: str, source: str):
        self.table, self.path, self.source = table, path, source
        self.used: set[str] = set()

    def _key(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else key

    def fail(self, key: str, msg: str) -> NoReturn:
        raise InvalidInputError(f"{self.source}: key '{self._key(key)}' {msg}")

    def get(self, key: str, kind: type[_T] | tuple[type[_T], ...], default: Any = dataclasses.MISSING) -> _T:
        """The value of ``key``, of type ``kind`` or one of the types ``kind`` lists (an
        integer counts as a float, a bool only as a bool), else ``default``; missing without
        a default is an error."""
        self.used.add(key)
        if key not in self.table:
            if default is dataclasses.MISSING:
                self.fail(key, "is missing")
            return default
        value = self.table[key]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if float in kinds and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if isinstance(value, bool) and bool not in kinds or not isinstance(value, kinds):
            names = " or ".join(k.__name__ for k in kinds)
            self.fail(key, f"must be {names}, got {type(value).__name__} {value!r}")
        return cast(_T, value)  # checked above: isinstance(value, kind)

    def number(
        self,
        key: str,
        *,
        lo: float | None = None,
        hi: float | None = None,
        lo_open: bool = False,
        default: Any = dataclasses.MISSING,
    ) -> float:
        value = self.get(key, float, default)
        if (
            not math.isfinite(value)
            or (lo is not None and (value <= lo if lo_open else value < lo))
            or (hi is not None and value > hi)
        ):
            lo_txt = "" if lo is None else (f"> {lo}" if lo_open else f">= {lo}")
            hi_txt = "" if hi is None else f"<= {hi}"
            self.fail(key, f"must be a finite number {' and '.join(t for t in (lo_txt, hi_txt) if t)}, got {value!r}")
        return value

    def integer(self, key: str, *, lo: int = 0, default: Any = dataclasses.MISSING) -> int:
        value = self.get(key, int, default)
        if value < lo:
            self.fail(key, f"must be an integer >= {lo}, got {value!r}")
        return value

    def table_(self, key: str) -> _Reader:
        return _Reader(self.get(key, dict), self._key(key), self.source)

    def strings(self, key: str) -> list[str]:
        value = self.get(key, list)
        if not value or not all(isinstance(v, str) and v for v in value):
            self.fail(key, "must be a non-empty list of non-empty strings")
        if len(set(value)) != len(value):
            self.fail(key, "has duplicate entries")
        return value

    def close(self, allowed_extra: tuple[str, ...] = ()) -> None:
        unknown = sorted(set(self.table) - self.used - set(allowed_extra))
        if unknown:
            where = f"table '{self.path}'" if self.path else "the top level"
            raise InvalidInputError(f"{self.source}: unknown key '{self._key(unknown[0])}' in {where}")


def load_design(path: str | Path | None = None) -> StudyDesign:
    """Load and validate a study design TOML file (default: the paper's design); a ``files``
    method's folder must exist (its ``path`` is relative to the design file)."""
    path = Path(path) if path is not None else default_design_path()
    design = parse_design(read_toml(path, f"study design file {str(path)!r} does not exist"), str(path))
    _check_method_folders(design, path.parent)
    return design


def _check_method_folders(design: StudyDesign, design_dir: Path) -> None:
    """Every ``files`` method's folder exists (the check of each cell's file in it waits for
    the commands that read them: ``crowdstudy stimuli``, ``demo``)."""
    for name in design.methods:
        method = design.method_recipes[name]
        if method.correction == "files":
            folder = Path(method.path or "")
            folder = folder if folder.is_absolute() else design_dir / folder
            if not folder.is_dir():
                raise InvalidInputError(
                    f"{design.source}: key 'methods.{name}.path': the folder {str(folder)!r} of the method's "
                    "animations does not exist (a relative path is relative to the design file)"
                )


def read_toml(path: str | Path, missing: str) -> dict:
    """The parsed TOML file ``path``; InvalidInputError ``missing`` when it is not a file, or
    naming the file when it is not valid TOML."""
    path = Path(path)
    if not path.is_file():
        raise InvalidInputError(missing)
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InvalidInputError(f"{path}: not valid TOML ({exc})") from None


def parse_design(raw: dict, source: str = "<memory>") -> StudyDesign:
    """Validate an already-parsed design table (see :func:`load_design`).

    One reader per table, in the file's order; each error names the file and the dotted key."""
    top = _Reader(raw, "", source)
    name = top.get("name", str)
    schema = top.integer("schema", lo=1)
    if schema != 1:
        top.fail("schema", f"is {schema}; this crowdstudy reads schema 1")
    seed = top.integer("seed", lo=0)
    width, depth = _read_floor(top)
    densities = _read_densities(top, width * depth)
    viewpoints = _read_viewpoints(top)
    recipes = _read_methods(top)
    methods = tuple(recipes)
    video = _read_video(top)
    stages = _read_stages(top, viewpoints, methods)
    scenarios = _read_scenarios(top, stages, width, depth)
    points, labels, items, comparison, slider = _read_questionnaire(top, stages)
    composites = _read_composites(top, items)
    body_shapes = _read_bodies(top)
    top.close(allowed_extra=("online",))  # the online study's controls: crowdstudy.study.quality

    return StudyDesign(
        name=name,
        seed=seed,
        floor_width=width,
        floor_depth=depth,
        densities=densities,
        viewpoints=viewpoints,
        methods=methods,
        video_width=video.width,
        video_height=video.height,
        duration=video.duration,
        fps=video.fps,
        stages=stages,
        scenarios=scenarios,
        likert_points=points,
        likert_labels=labels,
        items=items,
        composites=composites,
        source=source,
        method_recipes=recipes,
        comparison=comparison,
        slider=slider,
        online=raw.get("online"),
        body_shapes=body_shapes,
    )


def _read_bodies(top: _Reader) -> BodyShapes:
    """``[bodies]`` (optional): ``shapes``, the characters' body-shape draw
    (:data:`~crowdstudy.body.shapes.BodyShapes`, default ``"study"``, the paper's)."""
    from crowdstudy.body.shapes import BODY_SHAPES

    if "bodies" not in top.table:
        return "study"
    bodies = top.table_("bodies")
    shapes = bodies.get("shapes", str, "study")
    if shapes not in BODY_SHAPES:
        bodies.fail("shapes", f"must be one of {', '.join(map(repr, BODY_SHAPES))}, got {shapes!r}")
    bodies.close()
    return cast("BodyShapes", shapes)


def _read_floor(top: _Reader) -> tuple[float, float]:
    """``[floor]``: width and depth (m) of the crowd area."""
    floor = top.table_("floor")
    width = floor.number("width", lo=0, lo_open=True)
    depth = floor.number("depth", lo=0, lo_open=True)
    floor.close()
    return width, depth


def _read_densities(top: _Reader, floor_area: float) -> dict[str, float]:
    """``[densities]``: level -> characters/m^2, each giving at least one character on the floor."""
    dens = top.table_("densities")
    densities = {}
    for level in dens.table:
        densities[level] = dens.number(level, lo=0, lo_open=True)
        if round(densities[level] * floor_area) < 1:
            dens.fail(level, f"gives {densities[level] * floor_area:.2f} characters on the floor; need at least 1")
    if not densities:
        top.fail("densities", "must list at least one density level")
    dens.close()
    return densities


def _read_viewpoints(top: _Reader) -> dict[str, Viewpoint]:
    """``[viewpoints.ID]``: label, azimuth, elevation and field of view (degrees)."""
    vps = top.table_("viewpoints")
    viewpoints = {}
    for vid in vps.table:
        vt = vps.table_(vid)
        viewpoints[vid] = Viewpoint(
            id=vid,
            label=vt.get("label", str, vid),
            azimuth=vt.number("azimuth"),
            elevation=vt.number("elevation", lo=-89.0, hi=90.0),
            fov=vt.number("fov", lo=1.0, hi=170.0),
        )
        vt.close()
    if not viewpoints:
        top.fail("viewpoints", "must define at least one viewpoint")
    vps.close()
    return viewpoints


def _read_methods(top: _Reader) -> dict[str, Method]:
    """``[methods]``: ``order`` (the presentation and analysis order; the first is the
    reference) and a ``[methods.NAME]`` recipe per method; ``Baseline`` and ``Ours`` may go
    without one (:data:`DEFAULT_METHODS`)."""
    meth = top.table_("methods")
    order = meth.strings("order")
    recipes: dict[str, Method] = {}
    for name in order:
        if name in meth.table:
            if not isinstance(meth.table[name], dict):
                meth.fail(name, "must be a table ([methods.NAME] with its correction)")
            recipes[name] = _read_method(meth.table_(name), name)
            if name == "Baseline" and recipes[name].correction != "none":
                meth.table_(name).fail(
                    "correction",
                    "must be 'none': Baseline names the uncorrected animation every method starts "
                    "from; give this method another name",
                )
        elif name in DEFAULT_METHODS:
            recipes[name] = DEFAULT_METHODS[name]
        else:
            meth.fail("order", f"names {name!r}, which has no [methods.{name}] table saying how it is made")
    extra = sorted(set(meth.table) - {"order", *order})
    if extra:
        meth.fail(extra[0], "is a method that 'order' does not list")
    meth.used.update(order)
    meth.close()
    return recipes


def _read_method(r: _Reader, name: str) -> Method:
    """``[methods.NAME]``: ``correction`` (:data:`Correction`) and what that correction takes:
    ``config`` (physics, paper), ``setting`` (mujoco), ``path`` (files)."""
    correction = r.get("correction", str)
    if correction not in _CORRECTIONS:
        r.fail("correction", f"must be one of {', '.join(_CORRECTIONS)}, got {correction!r}")
    allowed = {"physics": "config", "paper": "config", "mujoco": "setting", "files": "path"}.get(correction)
    for key in ("config", "setting", "path"):
        if key in r.table and key != allowed:
            r.fail(key, f"does not apply to correction = {correction!r}")
    method = Method(name, correction)
    if allowed == "config":
        config = dict(r.get("config", dict, {}))
        try:
            Method(name, correction, config).physics_config()
        except InvalidInputError as exc:
            raise InvalidInputError(f"{r.source}: {exc}") from None
        method = Method(name, correction, config)
    elif allowed == "setting":
        method = Method(name, correction, setting=_mujoco_setting(r))
    elif allowed == "path":
        path = r.get("path", str)
        if not path.strip():
            r.fail("path", "must name the folder of the method's animations")
        method = Method(name, correction, path=path)
    r.close()
    return method


def _mujoco_setting(r: _Reader) -> str | None:
    """``setting`` of a ``mujoco`` method: one of the MuJoCo peer's tunings, or None."""
    setting = r.get("setting", str, None)
    if setting is not None:
        from crowdstudy.physics.mujoco_peer import MUJOCO_SETTINGS

        if setting not in MUJOCO_SETTINGS:
            r.fail("setting", f"must be one of {', '.join(MUJOCO_SETTINGS)}, got {setting!r}")
    return setting


class _Video(NamedTuple):
    width: int
    height: int
    duration: float
    fps: int


def _read_video(top: _Reader) -> _Video:
    """``[video]``: frame size (even, for H.264 yuv420p), duration (s) and frame rate."""
    vid_t = top.table_("video")
    video_w = vid_t.integer("width", lo=16)
    video_h = vid_t.integer("height", lo=16)
    if video_w % 2 or video_h % 2:
        vid_t.fail("width", f"and height must be even for H.264 yuv420p, got {video_w}x{video_h}")
    duration = vid_t.number("duration", lo=0, lo_open=True)
    fps = vid_t.integer("fps", lo=1)
    vid_t.close()
    return _Video(video_w, video_h, duration, fps)


def _read_stages(top: _Reader, viewpoints: dict[str, Viewpoint], methods: tuple[str, ...]) -> tuple[Stage, ...]:
    """``[stages.KEY]``: number, scenario, description, the viewpoints shown and the task
    (:data:`Task`; a ``2afc`` stage's ``pairs``); sorted by number."""
    st_t = top.table_("stages")
    stages = []
    for key in st_t.table:
        s = st_t.table_(key)
        vlist = s.strings("viewpoints")
        for v in vlist:
            if v not in viewpoints:
                s.fail("viewpoints", f"names unknown viewpoint {v!r}; defined: {', '.join(viewpoints)}")
        task = s.get("task", str, "likert")
        if task not in _TASKS:
            s.fail("task", f"must be one of {', '.join(_TASKS)}, got {task!r}")
        pairs = _read_pairs(s, methods) if task == "2afc" else ()
        if task != "2afc" and "pairs" in s.table:
            s.fail("pairs", f"applies to a 2afc stage only (this stage's task is {task!r})")
        shown = tuple(m for m in methods if any(m in p for p in pairs)) if pairs else methods
        stages.append(
            Stage(
                key=key,
                number=s.integer("number", lo=1),
                scenario=s.get("scenario", str),
                description=s.get("description", str, ""),
                viewpoints=tuple(vlist),
                task=task,
                methods=shown,
                pairs=pairs,
            )
        )
        s.close()
    if not stages:
        top.fail("stages", "must define at least one stage")
    if len({s.number for s in stages}) != len(stages):
        top.fail("stages", "have duplicate 'number' values")
    st_t.close()
    return tuple(sorted(stages, key=lambda s: s.number))


def _read_pairs(s: _Reader, methods: tuple[str, ...]) -> tuple[tuple[str, str], ...]:
    """A ``2afc`` stage's ``pairs``: lists of two different methods of the design, each pair
    once; by default every pair of the design's methods, in the design's order."""
    if "pairs" not in s.table:
        if len(methods) < 2:
            s.fail("task", "is '2afc', which needs at least two methods in [methods] order")
        return tuple((a, b) for i, a in enumerate(methods) for b in methods[i + 1 :])
    raw = s.get("pairs", list)
    pairs: list[tuple[str, str]] = []
    for i, pair in enumerate(raw):
        if not (isinstance(pair, list) and len(pair) == 2 and all(isinstance(m, str) for m in pair)):
            s.fail(f"pairs[{i}]", f"must be a list of two method names, got {pair!r}")
        for m in pair:
            if m not in methods:
                s.fail(f"pairs[{i}]", f"names unknown method {m!r}; the design's methods are {', '.join(methods)}")
        if pair[0] == pair[1]:
            s.fail(f"pairs[{i}]", f"compares {pair[0]!r} with itself")
        if any({pair[0], pair[1]} == set(p) for p in pairs):
            s.fail(f"pairs[{i}]", f"repeats the pair {pair!r}")
        pairs.append((pair[0], pair[1]))
    if not pairs:
        s.fail("pairs", "must list at least one pair of methods")
    return tuple(pairs)


def _read_scenarios(top: _Reader, stages: tuple[Stage, ...], width: float, depth: float) -> dict[str, Scenario]:
    """``[scenarios.NAME]``: each scenario's ``kind`` (:data:`ScenarioKind`; by default its
    name), the parameters of that kind (one reader per kind) and its motion source; every
    stage's scenario must have a table."""
    sc_t = top.table_("scenarios")
    scenarios = {}
    for sname in sc_t.table:
        r = sc_t.table_(sname)
        kind = r.get("kind", str, sname if sname in _KINDS else None)
        if kind is None:
            r.fail("kind", f"is missing: a scenario not named after a kind says which it is ({', '.join(_KINDS)})")
        if kind not in _KINDS:
            r.fail("kind", f"must be one of {', '.join(_KINDS)}, got {kind!r}")
        params = _SCENARIO_PARAMS[kind](r, width, depth)
        params["motion"] = r.get("motion", str, "mocap")
        if params["motion"] not in _MOTION_SOURCES:
            r.fail("motion", f"must be 'mocap' (motion capture) or 'procedural', got {params['motion']!r}")
        r.close()
        scenarios[sname] = Scenario(sname, params, kind)
    for st in stages:
        if st.scenario not in scenarios:
            top.fail(
                f"stages.{st.key}.scenario",
                f"names the scenario {st.scenario!r}, which has no [scenarios.{st.scenario}] table; "
                f"the design's scenarios are {', '.join(scenarios) or 'none'}",
            )
    sc_t.close()
    return scenarios


def _concert_params(r: _Reader, width: float, depth: float) -> dict[str, Any]:
    """``[scenarios.concert]``: distance to the stage, margin inside the floor, music tempo (bpm)."""
    params = {
        "stage_distance": r.number("stage_distance", lo=0),
        "margin": r.number("margin", lo=0),
        "tempo": r.number("tempo", lo=40.0, hi=240.0, default=120.0),
    }
    if 2 * params["margin"] >= min(width, depth):
        r.fail("margin", "leaves no room inside the floor area")
    return params


def _corridor_params(r: _Reader, width: float, depth: float) -> dict[str, Any]:
    """``[scenarios.corridor]``: size (m), walking direction(s) and preferred speed (m/s, mean and SD)."""
    params = {
        "width": r.number("width", lo=0, lo_open=True),
        "length": r.number("length", lo=0, lo_open=True),
        "direction": r.get("direction", str),
    }
    if params["direction"] not in _CORRIDOR_DIRECTIONS:
        r.fail("direction", f"must be {' or '.join(map(repr, _CORRIDOR_DIRECTIONS))}, got {params['direction']!r}")
    params["preferred_speed"] = r.number("preferred_speed", lo=0, lo_open=True, hi=5.0)
    params["preferred_speed_sd"] = r.number("preferred_speed_sd", lo=0)
    return params


def _crossing_params(r: _Reader, width: float, depth: float) -> dict[str, Any]:
    """``kind = "crossing"``: two flows of walkers crossing the floor (the crossing area) on a
    plaza (``plaza_width`` x ``plaza_depth`` m, default three times the floor's), the second
    flow at ``angle`` degrees from the first (+x); ``share`` of the walkers in the first flow;
    preferred speeds (m/s, mean and SD; a number or one per flow); ``obstacles``."""
    params: dict[str, Any] = {
        "plaza_width": r.number("plaza_width", lo=width, default=3.0 * width),
        "plaza_depth": r.number("plaza_depth", lo=depth, default=3.0 * depth),
        "angle": r.number("angle", lo=20.0, hi=160.0, default=90.0),
        "share": r.number("share", lo=0.05, hi=0.95, default=0.5),
        "preferred_speed": _per_flow(r, "preferred_speed", 1.2, lo=0.2, hi=3.0),
        "preferred_speed_sd": _per_flow(r, "preferred_speed_sd", 0.1, lo=0.0, hi=1.0),
    }
    params["obstacles"] = [
        _read_obstacle(r, i, raw, params["plaza_width"], params["plaza_depth"])
        for i, raw in enumerate(r.get("obstacles", list, []))
    ]
    return params


def _per_flow(r: _Reader, key: str, default: float, *, lo: float, hi: float) -> list[float]:
    """A per-flow number: one for both flows or a list of two, each in [lo, hi]."""
    value = r.get(key, (float, list), default)
    values = [value, value] if isinstance(value, (int, float)) else value  # get made an int a float
    if len(values) != 2 or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
        r.fail(key, f"must be a number or a list of two numbers (one per flow), got {value!r}")
    if not all(math.isfinite(v) and lo <= v <= hi for v in values):
        r.fail(key, f"must lie in [{lo}, {hi}], got {value!r}")
    return [float(v) for v in values]


def _read_obstacle(r: _Reader, i: int, raw: Any, plaza_w: float, plaza_d: float) -> dict[str, Any]:
    """``obstacles[i]`` of a crossing: ``{center = [x, y], radius = r}`` (a bollard, a round
    planter) or ``{polygon = [[x, y], ...]}`` (convex, at least 3 corners: a planter, a
    kiosk), with ``height`` (m, default 0.8) and an optional ``label``; inside the plaza.
    Returned as ``{"shape": "circle", "center", "radius"}`` or ``{"shape": "polygon",
    "points"}`` (counter-clockwise), with ``height`` and ``label``."""
    if not isinstance(raw, dict):
        r.fail(
            f"obstacles[{i}]", f"must be a table ({{center = [x, y], radius = r}} or {{polygon = ...}}), got {raw!r}"
        )
    o = _Reader(raw, r._key(f"obstacles[{i}]"), r.source)
    label = o.get("label", str, "")
    height = o.number("height", lo=0.0, lo_open=True, hi=10.0, default=0.8)
    if ("polygon" in raw) == ("center" in raw):
        o.fail("polygon", "or 'center' (with 'radius'): give exactly one shape")
    if "center" in raw:
        center = _point(o, "center", o.get("center", list))
        radius = o.number("radius", lo=0.0, lo_open=True, hi=20.0)
        out = {"shape": "circle", "center": center, "radius": radius}
        lo_pt, hi_pt = [c - radius for c in center], [c + radius for c in center]
    else:
        out = {"shape": "polygon", "points": _convex_polygon(o, o.get("polygon", list))}
        lo_pt = [min(p[k] for p in out["points"]) for k in (0, 1)]
        hi_pt = [max(p[k] for p in out["points"]) for k in (0, 1)]
    if lo_pt[0] < -plaza_w / 2 or hi_pt[0] > plaza_w / 2 or lo_pt[1] < -plaza_d / 2 or hi_pt[1] > plaza_d / 2:
        o.fail("center" if "center" in raw else "polygon", f"reaches outside the plaza ({plaza_w:g} x {plaza_d:g} m)")
    o.close()
    return {**out, "height": height, "label": label}


def _point(o: _Reader, key: str, value: Any) -> list[float]:
    if not (
        isinstance(value, list)
        and len(value) == 2
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    ):
        o.fail(key, f"must be a point [x, y] in metres, got {value!r}")
    return [float(value[0]), float(value[1])]


def _convex_polygon(o: _Reader, value: list) -> list[list[float]]:
    """A convex polygon's corners [[x, y], ...] (m), counter-clockwise."""
    if len(value) < 3:
        o.fail("polygon", f"must list at least 3 corners [[x, y], ...], got {len(value)}")
    pts = [_point(o, f"polygon[{k}]", v) for k, v in enumerate(value)]
    n = len(pts)
    cross = [
        (pts[(k + 1) % n][0] - pts[k][0]) * (pts[(k + 2) % n][1] - pts[(k + 1) % n][1])
        - (pts[(k + 1) % n][1] - pts[k][1]) * (pts[(k + 2) % n][0] - pts[(k + 1) % n][0])
        for k in range(n)
    ]
    area = 0.5 * sum(pts[k][0] * pts[(k + 1) % n][1] - pts[(k + 1) % n][0] * pts[k][1] for k in range(n))
    if abs(area) < 1e-4:
        o.fail("polygon", "has no area")
    if not (all(c > 1e-9 for c in cross) or all(c < -1e-9 for c in cross)):
        o.fail("polygon", "must be convex, its corners in order (split a concave obstacle into convex ones)")
    return pts if area > 0 else pts[::-1]


#: Each scenario kind's parameter reader: (its table, floor width, floor depth) -> parameters.
_SCENARIO_PARAMS: dict[str, Callable[[_Reader, float, float], dict[str, Any]]] = {
    "concert": _concert_params,
    "corridor": _corridor_params,
    "crossing": _crossing_params,
}


def _read_questionnaire(
    top: _Reader, stages: tuple[Stage, ...]
) -> tuple[int, tuple[str, ...], tuple[Item, ...], Comparison | None, SliderScale | None]:
    """``[questionnaire]``: scale points, one label per point, the items (id, text,
    reverse), the ``2afc`` statement (``[questionnaire.comparison]``, required when a stage
    is ``2afc``) and the slider's end labels (``[questionnaire.slider]``)."""
    q = top.table_("questionnaire")
    points = q.integer("points", lo=2)
    labels = q.strings("labels")
    if len(labels) != points:
        q.fail("labels", f"must have {points} entries (one per scale point), got {len(labels)}")
    raw_items = q.get("items", list)
    items = []
    for i, it in enumerate(raw_items):
        if not isinstance(it, dict):
            q.fail(f"items[{i}]", "must be a table")
        ir = _Reader(it, f"questionnaire.items[{i}]", top.source)
        items.append(Item(id=ir.get("id", str), text=ir.get("text", str), reverse=ir.get("reverse", bool)))
        ir.close()
    if not items or len({it.id for it in items}) != len(items):
        q.fail("items", "must be a non-empty list with unique ids")
    comparison = None
    if "comparison" in q.table:
        c = q.table_("comparison")
        comparison = Comparison(text=c.get("text", str))
        c.close()
    elif any(st.task == "2afc" for st in stages):
        first = next(st for st in stages if st.task == "2afc")
        q.fail(
            "comparison", f"is missing: stage '{first.key}' is a 2afc stage, which asks [questionnaire.comparison] text"
        )
    slider = SliderScale(labels[0], labels[-1])
    if "slider" in q.table:
        sl = q.table_("slider")
        slider = SliderScale(sl.get("left", str, labels[0]), sl.get("right", str, labels[-1]))
        sl.close()
    q.close()
    return points, tuple(labels), tuple(items), comparison, slider


def _read_composites(top: _Reader, items: tuple[Item, ...]) -> dict[str, tuple[str, ...]]:
    """``[composites]``: name -> the items averaged into it."""
    comp_t = top.table_("composites")
    composites = {}
    item_ids = {it.id for it in items}
    for cname in comp_t.table:
        members = comp_t.strings(cname)
        for m in members:
            if m not in item_ids:
                comp_t.fail(cname, f"names unknown item {m!r}")
        composites[cname] = tuple(members)
    comp_t.close()
    return composites

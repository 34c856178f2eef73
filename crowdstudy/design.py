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
from typing import Any, Literal, NamedTuple, NoReturn, TypeVar, cast, get_args

from crowdstudy.errors import InvalidInputError
from crowdstudy.package_data import resource_path

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
    "ScenarioName",
    "MotionSource",
    "CorridorDirection",
]

#: The scenarios a stage can show: a stationary concert crowd, people walking a corridor.
ScenarioName = Literal["concert", "corridor"]
#: Where a scenario's body motion comes from: motion-capture clips or procedural animation.
MotionSource = Literal["mocap", "procedural"]
#: Which way a corridor crowd walks: all one way, or both ways.
CorridorDirection = Literal["unidirectional", "bidirectional"]

_SCENARIOS: tuple[ScenarioName, ...] = get_args(ScenarioName)
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
class Stage:
    key: str  # "stationary" | "walking"
    number: int  # 1, 2 ...
    scenario: ScenarioName
    description: str
    viewpoints: tuple[str, ...]


@dataclasses.dataclass(frozen=True)
class Scenario:
    """Scenario parameters as a read-only mapping (``scenario["width"]``): those of its
    scenario (a concert's ``stage_distance``, ``margin``, ``tempo``; a corridor's ``width``,
    ``length``, ``direction`` (:data:`CorridorDirection`), ``preferred_speed``,
    ``preferred_speed_sd``) and ``motion`` (:data:`MotionSource`)."""

    name: ScenarioName
    params: dict

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
    methods: tuple[str, ...]
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
    #: the design's ``[online]`` table as written (the online study's controls, validated by
    #: ``crowdstudy.study.quality.online_config``), or None
    online: dict | None = None

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
                    for method in self.methods:
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

    def get(self, key: str, kind: type[_T], default: Any = dataclasses.MISSING) -> _T:
        """The value of ``key``, of type ``kind`` (an integer counts as a float, a bool
        only as a bool), else ``default``; missing without a default is an error."""
        self.used.add(key)
        if key not in self.table:
            if default is dataclasses.MISSING:
                self.fail(key, "is missing")
            return default
        value = self.table[key]
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if isinstance(value, bool) and kind is not bool or not isinstance(value, kind):
            self.fail(key, f"must be {kind.__name__}, got {type(value).__name__} {value!r}")
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
    """Load and validate a study design TOML file (default: the paper's design)."""
    path = Path(path) if path is not None else default_design_path()
    return parse_design(read_toml(path, f"study design file {str(path)!r} does not exist"), str(path))


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
    methods = _read_methods(top)
    video = _read_video(top)
    stages = _read_stages(top, viewpoints)
    scenarios = _read_scenarios(top, stages, width, depth)
    points, labels, items = _read_questionnaire(top)
    composites = _read_composites(top, items)
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
        online=raw.get("online"),
    )


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


def _read_methods(top: _Reader) -> tuple[str, ...]:
    """``[methods]``: ``order``, the methods compared, in the order the analysis reports them."""
    meth = top.table_("methods")
    methods = tuple(meth.strings("order"))
    meth.close()
    return methods


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


def _read_stages(top: _Reader, viewpoints: dict[str, Viewpoint]) -> tuple[Stage, ...]:
    """``[stages.KEY]``: number, scenario, description and the viewpoints shown; sorted by number."""
    st_t = top.table_("stages")
    stages = []
    for key in st_t.table:
        s = st_t.table_(key)
        scenario = s.get("scenario", str)
        if scenario not in _SCENARIOS:
            s.fail("scenario", f"must be one of {', '.join(_SCENARIOS)}, got {scenario!r}")
        vlist = s.strings("viewpoints")
        for v in vlist:
            if v not in viewpoints:
                s.fail("viewpoints", f"names unknown viewpoint {v!r}; defined: {', '.join(viewpoints)}")
        stages.append(
            Stage(
                key=key,
                number=s.integer("number", lo=1),
                scenario=scenario,
                description=s.get("description", str, ""),
                viewpoints=tuple(vlist),
            )
        )
        s.close()
    if not stages:
        top.fail("stages", "must define at least one stage")
    if len({s.number for s in stages}) != len(stages):
        top.fail("stages", "have duplicate 'number' values")
    st_t.close()
    return tuple(sorted(stages, key=lambda s: s.number))


def _read_scenarios(top: _Reader, stages: tuple[Stage, ...], width: float, depth: float) -> dict[str, Scenario]:
    """``[scenarios.NAME]``: the parameters of each scenario (one reader per scenario) and
    its motion source; every stage's scenario must have a table."""
    sc_t = top.table_("scenarios")
    scenarios = {}
    for sname in sc_t.table:
        if sname not in _SCENARIOS:
            sc_t.fail(sname, f"is not a known scenario ({', '.join(_SCENARIOS)})")
        r = sc_t.table_(sname)
        params = _SCENARIO_PARAMS[sname](r, width, depth)
        params["motion"] = r.get("motion", str, "mocap")
        if params["motion"] not in _MOTION_SOURCES:
            r.fail("motion", f"must be 'mocap' (motion capture) or 'procedural', got {params['motion']!r}")
        r.close()
        scenarios[sname] = Scenario(sname, params)
    for st in stages:
        if st.scenario not in scenarios:
            top.fail("scenarios", f"has no [scenarios.{st.scenario}] table, needed by stage '{st.key}'")
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


#: Each scenario's parameter reader: (its table, floor width, floor depth) -> parameters.
_SCENARIO_PARAMS: dict[str, Callable[[_Reader, float, float], dict[str, Any]]] = {
    "concert": _concert_params,
    "corridor": _corridor_params,
}


def _read_questionnaire(top: _Reader) -> tuple[int, tuple[str, ...], tuple[Item, ...]]:
    """``[questionnaire]``: scale points, one label per point, and the items (id, text, reverse)."""
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
    q.close()
    return points, tuple(labels), tuple(items)


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

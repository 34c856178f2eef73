"""Scoring of questionnaire answers: validation of responses.csv, reversal of the negative
items, item-pair reliability, composite scores and per participant x cell means.

The paper's rule: ``Q' = 7 - Q`` for the negative items Q2, Q4, Q6 (in general
``likert_points + 1 - Q`` for every item with ``reverse = true`` in the design),
reliability of each pair checked first, then QCR = (Q1 + Q2')/2, QCA = (Q3 + Q4')/2,
QOR = (Q5 + Q6')/2 (the design's ``[composites]``).

Rows of a ``slider`` stage (``task`` column ``slider``) hold integers on the design's
slider scale (0..100 by default) and are reversed as ``maximum + minimum - Q`` (``100 -
Q``); their composites are means on that scale. A responses table without a ``task``
column is read as all ``likert`` (exports written before tasks existed).

The names of the within factors (``Density``, ``Viewpoint``, ``Method``) are defined once,
by :class:`FactorNames`; every table and figure takes them from the value passed to
:func:`cell_means` and the analysis.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np
import pandas as pd

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import plain, row_label

__all__ = [
    "validate_responses",
    "check_complete",
    "reverse_items",
    "item_reliability",
    "composite_scores",
    "cell_means",
    "FACTOR_COLUMNS",
    "FACTORS",
    "FACTOR_NAMES",
    "FactorNames",
    "REQUIRED_COLUMNS",
    "RatingTask",
    "row_tasks",
    "scale_range",
]

#: The tasks whose answers are ratings in responses.csv (2AFC trials go to comparisons.csv).
RatingTask = Literal["likert", "slider"]


@dataclasses.dataclass(frozen=True)
class FactorNames:
    """The names the analysis gives the design's three within factors (the columns
    ``density_level``, ``viewpoint`` and ``method`` of responses.csv): every table, figure
    and summary line uses them."""

    density: str = "Density"
    viewpoint: str = "Viewpoint"
    method: str = "Method"

    def columns(self) -> dict[str, str]:
        """responses.csv column -> factor name."""
        return {"density_level": self.density, "viewpoint": self.viewpoint, "method": self.method}

    @property
    def order(self) -> tuple[str, str, str]:
        """The factors in the ANOVA's order: density, viewpoint, method."""
        return (self.density, self.viewpoint, self.method)


#: The factor names of the paper's analysis.
FACTOR_NAMES = FactorNames()
#: responses.csv column -> factor name used in the analysis tables (the default names).
FACTOR_COLUMNS = FACTOR_NAMES.columns()
#: The within factors of the study's ANOVA, in order (the columns :func:`cell_means` names).
FACTORS = FACTOR_NAMES.order
#: Columns an analysis needs (the item columns come from the design).
REQUIRED_COLUMNS = ("participant_id", "stage", "scenario", "density_level", "viewpoint", "method")


def _design(design):
    if design is None:
        from crowdstudy.design import load_design

        return load_design()
    return design


def row_tasks(responses: pd.DataFrame) -> pd.Series:
    """Each row's task: the ``task`` column, or ``"likert"`` for every row of a table
    without one."""
    if "task" in responses.columns:
        return responses["task"].astype(str)
    return pd.Series("likert", index=responses.index)


def scale_range(design, task: str) -> tuple[int, int]:
    """The lowest and highest answer of a rating ``task``: 1..points for ``likert``, the
    slider's minimum..maximum (0..100) for ``slider``."""
    if task == "slider":
        sl = design.slider
        return (sl.minimum, sl.maximum) if sl is not None else (0, 100)
    return 1, int(design.likert_points)


def _where(out: pd.DataFrame, i: int) -> str:
    """``row N (participant 'x')`` with N 1-based (row 1 = the first data row; in a CSV with
    a header it is on line N + 1)."""
    who = out["participant_id"].iloc[i] if "participant_id" in out.columns else None
    return row_label(i) + (f" (participant {plain(who)})" if who is not None and not pd.isna(who) else "")


def validate_responses(responses: pd.DataFrame, design=None, *, source: str = "responses") -> pd.DataFrame:
    """Check a responses table and return a clean copy (items as int, stage as int).

    Raises InvalidInputError, prefixed with ``source`` (the file name when read from one),
    naming the missing column; or the column, 1-based row and participant of a
    non-numeric / non-integer / out-of-range answer, an empty id, a stage number the
    design does not define, a scenario that is not its stage's, or a density level,
    viewpoint or method that is not one of that stage's levels in the design.
    """
    design = _design(design)
    if not isinstance(responses, pd.DataFrame):
        raise InvalidInputError(f"responses must be a pandas DataFrame, got {type(responses).__name__}")
    items = [it.id for it in design.items]
    missing = [c for c in (*REQUIRED_COLUMNS, *items) if c not in responses.columns]
    if missing:
        shown = ", ".join(map(str, responses.columns[:12])) + (" ..." if len(responses.columns) > 12 else "")
        raise InvalidInputError(f"{source}: missing column(s) {', '.join(map(repr, missing))}; have {shown}")
    if len(responses) == 0:
        raise InvalidInputError(f"{source}: no rows")
    out = responses.copy()
    for col in ("participant_id", "scenario"):
        if out[col].isna().any():
            i = int(out[col].isna().to_numpy().nonzero()[0][0])
            raise InvalidInputError(f"{source}: column {col!r} {row_label(i)} is empty")
    tasks = _check_tasks(out, source)
    low = np.where(tasks == "slider", scale_range(design, "slider")[0], 1)
    high = np.where(tasks == "slider", scale_range(design, "slider")[1], design.likert_points)
    for col in items:
        raw = out[col]
        num = pd.to_numeric(raw, errors="coerce")
        bad = num.isna() | (num != np.round(num)) | (num < low) | (num > high)
        if bad.any():
            i = int(bad.to_numpy().nonzero()[0][0])
            raise InvalidInputError(
                f"{source}: column {col!r} {_where(out, i)} holds {plain(raw.iloc[i])}; expected an integer "
                f"{int(low[i])}..{int(high[i])} ({tasks[i]} answer)"
            )
        out[col] = num.astype(int)
    stage = pd.to_numeric(out["stage"], errors="coerce")
    bad = stage.isna() | (stage != np.round(stage))
    if bad.any():
        i = int(bad.to_numpy().nonzero()[0][0])
        raise InvalidInputError(
            f"{source}: column 'stage' {_where(out, i)} holds {plain(out['stage'].iloc[i])}; "
            f"expected a stage number ({', '.join(str(st.number) for st in design.stages)})"
        )
    out["stage"] = stage.astype(int)
    stages = {st.number: st for st in design.stages}
    unknown = ~out["stage"].isin(list(stages))
    if unknown.any():
        i = int(unknown.to_numpy().nonzero()[0][0])
        raise InvalidInputError(
            f"{source}: column 'stage' {_where(out, i)} holds stage {int(out['stage'].iloc[i])}, "
            f"which the design ({design.source}) does not define; it defines "
            f"{', '.join(f'{st.number} ({st.scenario})' for st in design.stages)}"
        )
    for number, st in stages.items():
        rows = (out["stage"] == number).to_numpy()
        if not rows.any():
            continue
        sub = out[rows]
        if st.task == "2afc" or (tasks[rows] != st.task).any():
            j = int((tasks[rows] != st.task).nonzero()[0][0]) if st.task != "2afc" else 0
            i = int(rows.nonzero()[0][j])
            raise InvalidInputError(
                f"{source}: column 'task' {_where(out, i)} says {tasks[i]!r}, but stage {number} ({st.scenario}) "
                f"of the design ({design.source}) is a {st.task} stage"
                + ("; its trials belong in comparisons.csv" if st.task == "2afc" else "")
            )
        for col, known, what in (
            ("scenario", [st.scenario], "scenario"),
            ("density_level", list(design.densities), "density level"),
            ("viewpoint", list(st.viewpoints), "viewpoint"),
            ("method", list(st.methods or design.methods), "method"),
        ):
            off = ~sub[col].astype(str).isin(known)
            if off.any():
                j = int(off.to_numpy().nonzero()[0][0])
                i = int(rows.nonzero()[0][j])
                raise InvalidInputError(
                    f"{source}: column {col!r} {_where(out, i)} has unknown level "
                    f"{plain(sub[col].iloc[j])}: stage {number} ({st.scenario}) of the design "
                    f"({design.source}) has the {what}(s) {', '.join(known)}"
                )
    return out


def _check_tasks(out: pd.DataFrame, source: str) -> np.ndarray:
    """The rows' tasks as an array; an unknown or 2afc task is an error naming the row."""
    tasks = row_tasks(out).to_numpy()
    bad = ~np.isin(tasks, ["likert", "slider"])
    if bad.any():
        i = int(bad.nonzero()[0][0])
        hint = " (2AFC trials belong in comparisons.csv)" if tasks[i] == "2afc" else ""
        raise InvalidInputError(
            f"{source}: column 'task' {_where(out, i)} holds {tasks[i]!r}; expected 'likert' or 'slider'{hint}"
        )
    return tasks


def check_complete(data: pd.DataFrame, design=None, *, source: str = "responses") -> None:
    """What ``analyze`` needs beyond :func:`validate_responses` (whose output ``data`` is):

    - every stage present has rows for every density level, viewpoint and method the
      design gives it (a missing level would silently shrink the ANOVA's design);
    - each participant answered each stimulus (stage x density x viewpoint x method) at
      most once (the study shows each video once per participant; two answers would be
      averaged silently).

    Raises InvalidInputError naming the stage and missing level, or the participant, the
    cell and the 1-based rows of a repeated answer (counted by the frame's integer index
    when it has one, so rows of a filtered file keep their numbers).
    """
    design = _design(design)
    for st in design.stages:
        sub = data[data["stage"] == st.number]
        if not len(sub):
            continue
        for col, known, what in (
            ("density_level", list(design.densities), "density level"),
            ("viewpoint", list(st.viewpoints), "viewpoint"),
            ("method", list(st.methods or design.methods), "method"),
        ):
            absent = [lv for lv in known if lv not in set(sub[col].astype(str))]
            if absent:
                raise InvalidInputError(
                    f"{source}: stage {st.number} ({st.scenario}) has no rows for the {what} "
                    f"{absent[0]!r} (the design {design.source} lists {', '.join(known)}); "
                    f"analyse a design without it or export the missing answers"
                )
    keys = ["participant_id", "stage", "density_level", "viewpoint", "method"]
    dup = data.duplicated(keys, keep=False).to_numpy()
    if dup.any():
        first = int(dup.nonzero()[0][0])
        row = data.iloc[first]
        same = (data[keys] == row[keys]).all(axis=1).to_numpy().nonzero()[0]
        if pd.api.types.is_integer_dtype(data.index):  # a filtered frame keeps the file's row numbers
            same = data.index.to_numpy()[same]
        n_cells = data[dup].groupby(keys).ngroups
        raise InvalidInputError(
            f"{source}: participant {plain(row['participant_id'])} answered stage {int(row['stage'])}, "
            f"density_level {plain(row['density_level'])}, viewpoint {plain(row['viewpoint'])}, "
            f"method {plain(row['method'])} {len(same)} times (rows {', '.join(str(i + 1) for i in same)}); each "
            f"stimulus is shown once per participant ({n_cells} participant x stimulus combination(s) repeated)"
        )


def reverse_items(responses: pd.DataFrame, design=None) -> pd.DataFrame:
    """Copy with every reversed item ``Q`` replaced by ``likert_points + 1 - Q`` (a slider
    row's by ``maximum + minimum - Q``, 100 - Q)."""
    design = _design(design)
    out = validate_responses(responses, design)
    slider = (row_tasks(out) == "slider").to_numpy()
    lo, hi = scale_range(design, "slider")
    for it in design.items:
        if it.reverse:
            out[it.id] = np.where(slider, lo + hi - out[it.id], design.likert_points + 1 - out[it.id])
    out.attrs["reversed"] = [it.id for it in design.items if it.reverse]
    return out


def _alpha(x: np.ndarray) -> float:
    k = x.shape[1]
    total = x.sum(axis=1).var(ddof=1)
    if total == 0:
        return float("nan")
    return float(k / (k - 1) * (1.0 - x.var(axis=0, ddof=1).sum() / total))


def item_reliability(responses: pd.DataFrame, design=None, *, by: str | None = "scenario") -> pd.DataFrame:
    """Internal reliability of each composite's items (after reversal), before combining.

    One row per (``by`` group, composite) over all answered trials: ``items``, ``n``
    (trials), ``pearson_r`` (mean inter-item correlation; the pair's r for two items),
    ``spearman_brown`` (``k r / (1 + (k - 1) r)``), ``cronbach_alpha``, and
    ``alpha_participant_means`` (alpha on per-participant item means).
    """
    design = _design(design)
    scored = reverse_items(responses, design)
    if by is not None and by not in scored.columns:
        raise InvalidInputError(f"by column {by!r} is not in the responses")
    groups = [("all", scored)] if by is None else list(scored.groupby(by, sort=True))
    rows = []
    for key, g in groups:
        for cname, items in design.composites.items():
            x = g[list(items)].to_numpy(float)
            k = len(items)
            if k >= 2 and len(x) > 2:
                with np.errstate(invalid="ignore", divide="ignore"):
                    corr = np.corrcoef(x, rowvar=False)
                r = float(corr[np.triu_indices(k, 1)].mean())
                sb = k * r / (1 + (k - 1) * r)
                alpha = _alpha(x)
                pm = g.groupby("participant_id")[list(items)].mean().to_numpy(float)
                alpha_p = _alpha(pm) if len(pm) > 2 else float("nan")
            else:
                r = sb = alpha = alpha_p = float("nan")
            rows.append(
                {
                    "group": key,
                    "composite": cname,
                    "items": "+".join(items),
                    "n": len(x),
                    "pearson_r": r,
                    "spearman_brown": sb,
                    "cronbach_alpha": alpha,
                    "alpha_participant_means": alpha_p,
                }
            )
    out = pd.DataFrame(rows)
    if by is not None:
        out = out.rename(columns={"group": by})
    return out


def composite_scores(responses: pd.DataFrame, design=None) -> pd.DataFrame:
    """Responses with the reversed items and one column per composite (mean of its items)."""
    design = _design(design)
    scored = reverse_items(responses, design)
    for cname, items in design.composites.items():
        scored[cname] = scored[list(items)].mean(axis=1)
    return scored


def cell_means(
    scored: pd.DataFrame,
    composite: str,
    design=None,
    *,
    stage: int | None = None,
    names: FactorNames = FACTOR_NAMES,
) -> pd.DataFrame:
    """Per participant x (Density, Viewpoint, Method) mean of ``composite`` for one stage.

    ``scored``: output of :func:`composite_scores`. Returns a long DataFrame with columns
    ``participant_id``, the three factors as ``names`` names them (categoricals ordered as
    in the design, the reference method first; only the levels present) and
    ``composite``'s name.
    """
    design = _design(design)
    if composite not in scored.columns:
        raise InvalidInputError(f"composite {composite!r} is not a column; known: {', '.join(design.composites)}")
    data = scored if stage is None else scored[scored["stage"] == int(stage)]
    if len(data) == 0:
        raise InvalidInputError(f"no responses for stage {stage!r}")
    order = {
        "density_level": list(design.densities),
        "viewpoint": list(design.viewpoints),
        "method": list(design.methods),
    }
    columns = names.columns()
    g = (
        data.groupby(["participant_id", *columns], observed=True)[composite]
        .mean()
        .reset_index()
        .rename(columns=columns)
    )
    for col, name in columns.items():
        present = [lv for lv in order[col] if lv in set(g[name])]
        g[name] = pd.Categorical(g[name], categories=present, ordered=True)
    return g.sort_values(["participant_id", *columns.values()]).reset_index(drop=True)

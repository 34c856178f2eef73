"""Input handling shared by the ANOVA and the post hoc tests: long/wide data -> a complete
subject x cell matrix, with errors that name the column, level or subject at fault."""

from __future__ import annotations

import dataclasses
import itertools
import warnings
from typing import Any

import numpy as np
import pandas as pd

from crowdstudy.errors import InvalidInputError

__all__ = ["CellMatrix", "cell_matrix", "factor_levels", "plain", "row_label"]


def plain(value):
    """A value as a user reads it: numpy scalars as Python numbers (``7``, not ``np.int64(7)``),
    strings quoted, everything else via ``repr``."""
    if isinstance(value, np.generic):
        value = value.item()
    return repr(value)


def row_label(position: int) -> str:
    """``"row N"`` with N 1-based (the first data row is row 1; in a CSV file with a header
    it is on line N + 1)."""
    return f"row {int(position) + 1}"


@dataclasses.dataclass(frozen=True)
class CellMatrix:
    """Per-subject cell means of a fully within-subject design.

    ``values``: (n_subjects, n_cells) float64, cells in row-major order of ``levels``
    (the last factor varies fastest); ``subjects``: the kept subject ids; ``factors``:
    factor names; ``levels``: one tuple of levels per factor; ``dropped``: subjects removed
    by listwise deletion; ``aggregated``: True when some subject x cell had several rows
    (averaged, as afex does, with a warning unless asked not to).
    """

    values: np.ndarray
    subjects: tuple
    factors: tuple[str, ...]
    levels: tuple[tuple, ...]
    dropped: tuple = ()
    aggregated: bool = False

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(lv) for lv in self.levels)

    def cells(self) -> list[tuple]:
        return list(itertools.product(*self.levels))


def factor_levels(series: pd.Series) -> tuple[Any, ...]:
    """Level order of a factor: categorical order if categorical, else sorted unique values."""
    if isinstance(series.dtype, pd.CategoricalDtype):
        present = set(series.dropna().unique())
        return tuple(c for c in series.cat.categories if c in present)
    values = series.dropna().unique().tolist()
    try:
        return tuple(sorted(values))
    except TypeError:
        return tuple(sorted(values, key=str))


def _as_list(within) -> list[str]:
    if within is None:
        return []
    if isinstance(within, str):
        return [within]
    try:
        out = list(within)
    except TypeError:
        raise InvalidInputError(f"within must be a column name or a list of column names, got {within!r}") from None
    if not all(isinstance(w, str) for w in out):
        raise InvalidInputError(f"within must list column names (strings), got {within!r}")
    return out


def _wide_to_long(data: pd.DataFrame, within: list[str], subject: str | None) -> tuple[pd.DataFrame, str, list, str]:
    cols = data.columns
    names = [n for n in cols.names] if isinstance(cols, pd.MultiIndex) else [cols.name]
    if within:
        if len(within) != len(names):
            raise InvalidInputError(f"wide data has {len(names)} column level(s) {names}; within names {len(within)}")
        names = within
    if any(n is None for n in names):
        raise InvalidInputError("wide data: name the column levels (data.columns.names) or pass within=[...]")
    names = [str(n) for n in names]
    subj = subject or str(data.index.name or "subject")
    long = data.copy()
    long.columns = pd.MultiIndex.from_tuples([c if isinstance(c, tuple) else (c,) for c in cols], names=names)
    long.index = long.index.rename(subj)
    stacked = long.stack(list(range(len(names))), future_stack=True)  # every level: a Series
    long = stacked.rename("value").reset_index()  # pyright: ignore[reportArgumentType]  # stubs: stack may be a frame
    return long, "value", names, subj


def cell_matrix(
    data: pd.DataFrame, dv: str | None, within, subject: str | None, *, missing: str = "raise", duplicates: str = "warn"
) -> CellMatrix:
    """Validate ``data`` and arrange it as a subject x cell matrix (see :class:`CellMatrix`).

    Long input: one row per observation with columns ``subject``, the ``within`` factors and
    ``dv``. Wide input (``dv=None``): one row per subject (index = subject), columns = the
    cells (a MultiIndex whose level names are the factors, or ``within`` names them).
    ``missing="raise"`` rejects a subject without every cell (naming subject and cell);
    ``"drop"`` removes such subjects (listwise deletion; listed in ``.dropped``).
    ``duplicates``: several rows for one subject x cell are averaged; ``"warn"`` (default)
    says so with a ``UserWarning`` naming the first such subject and cell (as afex does),
    ``"mean"`` averages silently, ``"raise"`` refuses with an error naming them.
    """
    if not isinstance(data, pd.DataFrame):
        raise InvalidInputError(f"data must be a pandas DataFrame, got {type(data).__name__}")
    if missing not in ("raise", "drop"):
        raise InvalidInputError(f"missing must be 'raise' or 'drop', got {missing!r}")
    if duplicates not in ("warn", "mean", "raise"):
        raise InvalidInputError(f"duplicates must be 'warn', 'mean' or 'raise', got {duplicates!r}")
    within = _as_list(within)
    if dv is None:
        data, dv, within, subject = _wide_to_long(data, within, subject)
    if not within:
        raise InvalidInputError("within must name at least one within-subject factor")
    if len(set(within)) != len(within):
        raise InvalidInputError(f"within lists a factor twice: {within}")
    for role, col in [("dv", dv), ("subject", subject), *[("within", w) for w in within]]:
        if not isinstance(col, str) or col not in data.columns:
            raise InvalidInputError(
                f"{role} column {col!r} is not in the data; columns: {', '.join(map(str, data.columns))}"
            )
    if subject in within or dv in within or dv == subject:
        raise InvalidInputError(f"dv {dv!r}, subject {subject!r} and within {within} must be distinct columns")
    y = data[dv]
    if not (pd.api.types.is_numeric_dtype(y) and not pd.api.types.is_bool_dtype(y)):
        converted = pd.to_numeric(y, errors="coerce")
        bad = y[converted.isna() & y.notna()]
        if len(bad):
            pos = int(np.flatnonzero((converted.isna() & y.notna()).to_numpy())[0])
            raise InvalidInputError(f"dv column {dv!r} must be numeric; {row_label(pos)} holds {plain(bad.iloc[0])}")
        y = converted
    y = y.astype(float)
    if np.isinf(y).any():
        pos = int(np.flatnonzero(np.isinf(y.to_numpy()))[0])
        raise InvalidInputError(f"dv column {dv!r} holds an infinite value ({row_label(pos)})")
    for col in [subject, *within]:
        if data[col].isna().any():
            pos = int(np.flatnonzero(data[col].isna().to_numpy())[0])
            raise InvalidInputError(f"column {col!r} has a missing value ({row_label(pos)})")
    levels = [factor_levels(data[w]) for w in within]
    for w, lv in zip(within, levels, strict=True):
        if len(lv) < 2:
            found = f"a single level {plain(lv[0])}" if lv else "no level (no rows)"
            raise InvalidInputError(f"within factor {w!r} has {found}; a factor needs >= 2 levels")
    frame = pd.DataFrame({"_s": data[subject].to_numpy(), "_y": y.to_numpy()})
    for i, w in enumerate(within):
        frame[f"_f{i}"] = data[w].to_numpy()
    keys = ["_s", *[f"_f{i}" for i in range(len(within))]]
    grouped = frame.dropna(subset=["_y"]).groupby(keys, sort=False, observed=True)["_y"]
    counts = grouped.size()
    aggregated = bool((counts > 1).any())
    if aggregated and duplicates != "mean":
        many = counts[counts > 1]
        key = many.index[0]
        where = ", ".join(f"{w}={plain(c)}" for w, c in zip(within, key[1:], strict=True))
        text = (
            f"subject {plain(key[0])} has {int(many.iloc[0])} {dv!r} values for the cell {where} "
            f"({len(many)} subject x cell combination(s) with more than one row)"
        )
        if duplicates == "raise":
            raise InvalidInputError(text + "; one value per subject and cell expected")
        warnings.warn(text + "; averaged (as afex's fun_aggregate = mean)", UserWarning, stacklevel=3)
    means = grouped.mean()
    subjects = factor_levels(data[subject])
    cells = list(itertools.product(*levels))
    full_index = pd.MultiIndex.from_tuples([(s, *c) for s in subjects for c in cells], names=keys)
    values = means.reindex(full_index).to_numpy().reshape(len(subjects), len(cells))
    holes = np.isnan(values)
    dropped: tuple = ()
    if holes.any():
        bad_rows = np.flatnonzero(holes.any(axis=1))
        if missing == "raise":
            s = bad_rows[0]
            cell = cells[int(np.flatnonzero(holes[s])[0])]
            where = ", ".join(f"{w}={plain(c)}" for w, c in zip(within, cell, strict=True))
            raise InvalidInputError(
                f"subject {plain(subjects[s])} has no {dv!r} value for the cell {where} "
                f"({len(bad_rows)} subject(s) lack some cell); "
                "pass missing='drop' (CLI: --missing drop) for listwise deletion"
            )
        dropped = tuple(subjects[i] for i in bad_rows)
        keep = ~holes.any(axis=1)
        values = values[keep]
        subjects = tuple(s for s, k in zip(subjects, keep, strict=True) if k)
    if len(subjects) < 2:
        raise InvalidInputError(
            f"need at least 2 subjects with every cell, got {len(subjects)}"
            + (f" after dropping {len(dropped)}" if dropped else "")
        )
    return CellMatrix(
        values=values,
        subjects=tuple(subjects),
        factors=tuple(within),
        levels=tuple(levels),
        dropped=dropped,
        aggregated=aggregated,
    )

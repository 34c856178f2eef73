"""Scoring of questionnaire answers: validation of responses.csv, reversal of the negative
items, item-pair reliability, composite scores and per participant x cell means.

The paper's rule (DESIGN.md, "The study"): ``Q' = 7 - Q`` for the negative items Q2, Q4,
Q6 (in general ``likert_points + 1 - Q`` for every item with ``reverse = true`` in the
design), reliability of each pair checked first, then QCR = (Q1 + Q2')/2,
QCA = (Q3 + Q4')/2, QOR = (Q5 + Q6')/2 (the design's ``[composites]``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from crowdstudy.errors import InvalidInputError

__all__ = ["validate_responses", "reverse_items", "item_reliability", "composite_scores", "cell_means",
           "FACTOR_COLUMNS", "REQUIRED_COLUMNS"]

#: responses.csv column -> factor name used in the analysis tables.
FACTOR_COLUMNS = {"density_level": "Density", "viewpoint": "Viewpoint", "method": "Method"}
#: Columns an analysis needs (the item columns come from the design).
REQUIRED_COLUMNS = ("participant_id", "stage", "scenario", "density_level", "viewpoint", "method")


def _design(design):
    if design is None:
        from crowdstudy.design import load_design
        return load_design()
    return design


def validate_responses(responses: pd.DataFrame, design=None) -> pd.DataFrame:
    """Check a responses table and return a clean copy (items as int, stage as int).

    Raises InvalidInputError naming the missing column, or the column, row and participant
    of a non-numeric / non-integer / out-of-range answer, or an unknown level.
    """
    design = _design(design)
    if not isinstance(responses, pd.DataFrame):
        raise InvalidInputError(f"responses must be a pandas DataFrame, got {type(responses).__name__}")
    items = [it.id for it in design.items]
    missing = [c for c in (*REQUIRED_COLUMNS, *items) if c not in responses.columns]
    if missing:
        raise InvalidInputError(f"responses: missing column(s) {', '.join(map(repr, missing))}; "
                                f"have {', '.join(map(str, responses.columns))}")
    if len(responses) == 0:
        raise InvalidInputError("responses: no rows")
    out = responses.copy()
    top = design.likert_points
    for col in items:
        raw = out[col]
        num = pd.to_numeric(raw, errors="coerce")
        bad = num.isna() | (num != np.round(num)) | (num < 1) | (num > top)
        if bad.any():
            i = bad.to_numpy().nonzero()[0][0]
            who = out["participant_id"].iloc[i]
            raise InvalidInputError(f"responses: column {col!r} row {i} (participant {who!r}) holds "
                                    f"{raw.iloc[i]!r}; expected an integer 1..{top}")
        out[col] = num.astype(int)
    stage = pd.to_numeric(out["stage"], errors="coerce")
    if stage.isna().any():
        i = stage.isna().to_numpy().nonzero()[0][0]
        raise InvalidInputError(f"responses: column 'stage' row {i} holds {out['stage'].iloc[i]!r}; expected 1, 2 ...")
    out["stage"] = stage.astype(int)
    for col, known in (("density_level", list(design.densities)), ("viewpoint", list(design.viewpoints)),
                       ("method", list(design.methods))):
        unknown = sorted(set(out[col].astype(str)) - set(known))
        if unknown:
            raise InvalidInputError(f"responses: column {col!r} has unknown level {unknown[0]!r}; "
                                    f"the design ({design.source}) defines {', '.join(known)}")
    for col in ("participant_id", "scenario"):
        if out[col].isna().any():
            i = out[col].isna().to_numpy().nonzero()[0][0]
            raise InvalidInputError(f"responses: column {col!r} row {i} is empty")
    return out


def reverse_items(responses: pd.DataFrame, design=None) -> pd.DataFrame:
    """Copy with every reversed item ``Q`` replaced by ``likert_points + 1 - Q``."""
    design = _design(design)
    out = validate_responses(responses, design)
    for it in design.items:
        if it.reverse:
            out[it.id] = design.likert_points + 1 - out[it.id]
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
            rows.append({"group": key, "composite": cname, "items": "+".join(items), "n": len(x),
                         "pearson_r": r, "spearman_brown": sb, "cronbach_alpha": alpha,
                         "alpha_participant_means": alpha_p})
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


def cell_means(scored: pd.DataFrame, composite: str, design=None, *, stage: int | None = None) -> pd.DataFrame:
    """Per participant x (Density, Viewpoint, Method) mean of ``composite`` for one stage.

    ``scored``: output of :func:`composite_scores`. Returns a long DataFrame with columns
    ``participant_id``, ``Density``, ``Viewpoint``, ``Method`` (categoricals ordered as in
    the design; only the levels present) and ``composite``'s name.
    """
    design = _design(design)
    if composite not in scored.columns:
        raise InvalidInputError(f"composite {composite!r} is not a column; known: {', '.join(design.composites)}")
    data = scored if stage is None else scored[scored["stage"] == int(stage)]
    if len(data) == 0:
        raise InvalidInputError(f"no responses for stage {stage!r}")
    order = {"density_level": list(design.densities), "viewpoint": list(design.viewpoints),
             "method": list(design.methods)}
    g = (data.groupby(["participant_id", *FACTOR_COLUMNS], observed=True)[composite].mean().reset_index()
         .rename(columns=FACTOR_COLUMNS))
    for col, name in FACTOR_COLUMNS.items():
        present = [lv for lv in order[col] if lv in set(g[name])]
        g[name] = pd.Categorical(g[name], categories=present, ordered=True)
    return g.sort_values(["participant_id", *FACTOR_COLUMNS.values()]).reset_index(drop=True)

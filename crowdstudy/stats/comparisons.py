"""The analysis of a 2AFC stage: two videos of one cell made by two methods, the answer is
which one (comparisons.csv, columns :data:`~crowdstudy.schema.COMPARISON_COLUMNS`).

Per stage:

- **choice shares**: for each method of the stage, the share of the trials showing it in
  which it was chosen, per cell (density x viewpoint) and over all cells, with the exact
  Clopper-Pearson interval and the two-sided binomial test against 1/2 (R's
  ``binom.test``);
- **position bias**: the share of "left" answers with the same interval and test (the
  sides are counterbalanced, so a share far from 1/2 is a bias of the participants, not
  of a method);
- **per pair** ``(a, b)`` of the stage (the design's ``pairs``): a logistic mixed model of
  choosing ``b``, ``logit P(b) = intercept + Density (sum-coded) + u_participant``,
  ``u ~ N(0, s^2)`` (lme4's ``glmer(chose_b ~ Density + (1 | participant), family =
  binomial)``, Laplace; :func:`~crowdstudy.stats.choice_models.logistic_mixed_model`).
  The intercept is the logit of choosing ``b`` at the average density: ``P(b)`` with its
  Wald interval is reported, and its z test is the test of the pair. When the pair's
  choices cannot support the Density terms (one density level, or a density where every
  choice is the same) the model keeps the intercept alone, and says so;
- **Bradley-Terry** (more than two methods): one ability per method on the logit scale,
  the stage's first method fixed at 0, with SEs (``BradleyTerry2::BTm``, no random
  effect; :func:`~crowdstudy.stats.choice_models.bradley_terry`).
"""

from __future__ import annotations

import dataclasses
import itertools
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats as _st

from crowdstudy.design import Stage, StudyDesign
from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import plain, row_label
from crowdstudy.stats.choice_models import BradleyTerryResult, LogisticMixedResult, bradley_terry, logistic_mixed_model
from crowdstudy.stats.scoring import FACTOR_NAMES, FactorNames

__all__ = [
    "ChoiceResult",
    "PairModel",
    "validate_comparisons",
    "load_comparisons",
    "choice_shares",
    "position_bias",
    "pair_model",
    "compute_choices",
    "SHARE_COLUMNS",
    "REQUIRED_COMPARISON_COLUMNS",
]

#: Columns a 2AFC analysis needs (the others of comparisons.csv are kept and ignored).
REQUIRED_COMPARISON_COLUMNS = (
    "participant_id",
    "stage",
    "density_level",
    "viewpoint",
    "method_left",
    "method_right",
    "choice",
)
#: Columns of :func:`choice_shares` (``cell`` "all" for the row over every cell).
SHARE_COLUMNS = (
    "method",
    "density_level",
    "viewpoint",
    "cell",
    "chosen",
    "shown",
    "share",
    "lower_CL",
    "upper_CL",
    "p",
)


def _where(data: pd.DataFrame, i: int) -> str:
    return f"{row_label(i)} (participant {plain(data['participant_id'].iloc[i])})"


def validate_comparisons(table: pd.DataFrame, design: StudyDesign, *, source: str = "comparisons") -> pd.DataFrame:
    """Check a comparisons table against the design and return a clean copy (``stage`` as
    int, ``chosen_method`` filled from ``choice``). Errors (InvalidInputError, prefixed
    with ``source``) name the missing column, or the column and 1-based row of a stage that
    is not a 2afc stage of the design, a level or method pair the stage does not have, a
    ``choice`` other than left/right, a ``chosen_method`` that is not the chosen side's,
    or a pair answered twice by one participant in one cell."""
    missing = [c for c in REQUIRED_COMPARISON_COLUMNS if c not in table.columns]
    if missing:
        raise InvalidInputError(
            f"{source}: missing column(s) {', '.join(map(repr, missing))}; have {', '.join(map(str, table.columns))}"
        )
    if len(table) == 0:
        raise InvalidInputError(f"{source}: no rows")
    out = table.reset_index(drop=True).copy()
    for col in REQUIRED_COMPARISON_COLUMNS:
        if out[col].isna().any():
            i = int(out[col].isna().to_numpy().nonzero()[0][0])
            raise InvalidInputError(f"{source}: column {col!r} {row_label(i)} is empty")
    stage = pd.to_numeric(out["stage"], errors="coerce")
    stages = {st.number: st for st in design.stages if st.task == "2afc"}
    bad = ~stage.isin(list(stages))
    if bad.any():
        i = int(bad.to_numpy().nonzero()[0][0])
        raise InvalidInputError(
            f"{source}: column 'stage' {_where(out, i)} holds {plain(out['stage'].iloc[i])}, which is not a 2afc "
            f"stage of the design ({design.source}); its 2afc stages: {', '.join(map(str, stages)) or 'none'}"
        )
    out["stage"] = stage.astype(int)
    choice = out["choice"].astype(str)
    bad = ~choice.isin(["left", "right"])
    if bad.any():
        i = int(bad.to_numpy().nonzero()[0][0])
        raise InvalidInputError(
            f"{source}: column 'choice' {_where(out, i)} holds {plain(out['choice'].iloc[i])}; "
            "expected 'left' or 'right'"
        )
    for st in stages.values():
        _check_stage_rows(out, st, design, source)
    chosen = np.where(choice == "left", out["method_left"].astype(str), out["method_right"].astype(str))
    if "chosen_method" in out.columns:
        given = out["chosen_method"].astype(str).to_numpy()
        bad = given != chosen
        if bad.any():
            i = int(bad.nonzero()[0][0])
            raise InvalidInputError(
                f"{source}: column 'chosen_method' {_where(out, i)} holds {given[i]!r}, but choice "
                f"{choice.iloc[i]!r} chose {chosen[i]!r}"
            )
    out["chosen_method"] = chosen
    _check_repeats(out, source)
    return out


def _check_stage_rows(out: pd.DataFrame, st: Stage, design: StudyDesign, source: str) -> None:
    rows = (out["stage"] == st.number).to_numpy()
    sub = out[rows]
    for col, known, what in (
        ("density_level", list(design.densities), "density level"),
        ("viewpoint", list(st.viewpoints), "viewpoint"),
        ("method_left", list(st.methods), "method"),
        ("method_right", list(st.methods), "method"),
    ):
        off = ~sub[col].astype(str).isin(known)
        if off.any():
            i = int(rows.nonzero()[0][int(off.to_numpy().nonzero()[0][0])])
            raise InvalidInputError(
                f"{source}: column {col!r} {_where(out, i)} has unknown level {plain(out[col].iloc[i])}: stage "
                f"{st.number} ({st.scenario}) of the design ({design.source}) has the {what}(s) {', '.join(known)}"
            )
    pairs = {frozenset(p) for p in st.pairs}
    shown = [
        frozenset((a, b)) for a, b in zip(sub["method_left"].astype(str), sub["method_right"].astype(str), strict=True)
    ]
    for j, p in enumerate(shown):
        if p not in pairs:
            i = int(rows.nonzero()[0][j])
            raise InvalidInputError(
                f"{source}: columns 'method_left', 'method_right' {_where(out, i)} show "
                f"{out['method_left'].iloc[i]!r} and {out['method_right'].iloc[i]!r}, which stage {st.number} "
                f"does not compare; its pairs: {'; '.join(' vs '.join(p) for p in st.pairs)}"
            )


def _check_repeats(out: pd.DataFrame, source: str) -> None:
    pair = [
        " vs ".join(sorted(p))
        for p in zip(out["method_left"].astype(str), out["method_right"].astype(str), strict=True)
    ]
    keys = out[["participant_id", "stage", "density_level", "viewpoint"]].astype(str).assign(_pair=pair)
    dup = keys.duplicated(keep=False).to_numpy()
    if dup.any():
        first = int(dup.nonzero()[0][0])
        same = (keys == keys.iloc[first]).all(axis=1).to_numpy().nonzero()[0]
        row = keys.iloc[first]
        raise InvalidInputError(
            f"{source}: participant {row['participant_id']!r} compared {row['_pair']} in stage {row['stage']}, "
            f"density_level {row['density_level']!r}, viewpoint {row['viewpoint']!r} {len(same)} times (rows "
            f"{', '.join(str(i + 1) for i in same)}); each pair is shown once per cell"
        )


def load_comparisons(
    comparisons: pd.DataFrame | str | Path,
    design: StudyDesign,
    *,
    participants: str | Path | pd.DataFrame | None = None,
) -> tuple[pd.DataFrame, str]:
    """Read (a path) and check comparisons.csv: ``(data, source)``. ``participants``:
    participants.csv (path or table) whose excluded participants are dropped."""
    from crowdstudy.stats.inputs import apply_exclusions, read_csv_file, read_participants

    source = "comparisons"
    if isinstance(comparisons, (str, Path)):
        source = str(comparisons)
        comparisons = read_csv_file(comparisons, "comparisons")
    data = validate_comparisons(comparisons, design, source=source)
    if participants is not None:
        psrc = "participants" if isinstance(participants, pd.DataFrame) else str(participants)
        data, _ = apply_exclusions(data, read_participants(participants), psrc)
        data = data.reset_index(drop=True)
    return data, source


def _binomial_row(x: int, n: int, level: float) -> dict:
    """share, Clopper-Pearson interval and two-sided p against 1/2 (R's binom.test)."""
    if n == 0:
        return {"chosen": 0, "shown": 0, "share": np.nan, "lower_CL": np.nan, "upper_CL": np.nan, "p": np.nan}
    test = _st.binomtest(int(x), int(n), 0.5)
    ci = test.proportion_ci(confidence_level=level, method="exact")
    return {
        "chosen": int(x),
        "shown": int(n),
        "share": x / n,
        "lower_CL": float(ci.low),
        "upper_CL": float(ci.high),
        "p": float(test.pvalue),
    }


def choice_shares(data: pd.DataFrame, stage: Stage, design: StudyDesign, *, level: float = 0.95) -> pd.DataFrame:
    """Each method's choice share in one stage's trials (``data``: validated rows of that
    stage), per cell in the design's order and over all cells (``cell`` "all"); columns
    :data:`SHARE_COLUMNS`."""
    left, right = data["method_left"].astype(str), data["method_right"].astype(str)
    chosen = data["chosen_method"].astype(str)
    cells = list(itertools.product(design.densities, stage.viewpoints))
    rows = []
    for m in stage.methods:
        shown = ((left == m) | (right == m)).to_numpy()
        won = (chosen == m).to_numpy() & shown
        for level_, view in [*cells, ("", "")]:
            where = shown.copy()
            if level_:
                where &= (data["density_level"].astype(str) == level_).to_numpy()
                where &= (data["viewpoint"].astype(str) == view).to_numpy()
            rows.append(
                {
                    "method": m,
                    "density_level": level_,
                    "viewpoint": view,
                    "cell": f"{level_} {view}" if level_ else "all",
                    **_binomial_row(int((won & where).sum()), int(where.sum()), level),
                }
            )
    return pd.DataFrame(rows, columns=SHARE_COLUMNS)


def position_bias(data: pd.DataFrame, *, level: float = 0.95) -> dict:
    """The share of "left" answers: ``{"left", "trials", "share", "lower_CL", "upper_CL", "p"}``."""
    row = _binomial_row(int((data["choice"].astype(str) == "left").sum()), len(data), level)
    return {
        "left": row["chosen"],
        "trials": row["shown"],
        **{k: row[k] for k in ("share", "lower_CL", "upper_CL", "p")},
    }


@dataclasses.dataclass(frozen=True)
class PairModel:
    """The logistic mixed model of one pair (see the module docstring): ``method_a``,
    ``method_b`` (the model's outcome is choosing ``b``); ``terms``: "Density" or
    "intercept" (what the fixed effects hold); ``fit`` (None when even the intercept model
    is undefined); ``note``: why the model was reduced or is missing ("" otherwise);
    ``n_trials``, ``chose_b``: the pair's trials and how many chose ``b``."""

    method_a: str
    method_b: str
    terms: str
    fit: LogisticMixedResult | None
    note: str
    n_trials: int
    chose_b: int

    @property
    def pair(self) -> str:
        return f"{self.method_a} vs {self.method_b}"

    def probability(self, level: float = 0.95) -> dict:
        """P(choose b) at the average density (the intercept) with its Wald interval, and
        the intercept's z test: ``{"P_b", "lower_CL", "upper_CL", "logit", "SE", "z", "p"}``."""
        if self.fit is None:
            return dict.fromkeys(("P_b", "lower_CL", "upper_CL", "logit", "SE", "z", "p"), float("nan"))
        row = self.fit.fixed.iloc[0]
        crit = float(_st.norm.ppf(0.5 + level / 2.0))

        def expit(v: float) -> float:
            return float(1.0 / (1.0 + np.exp(-v)))

        return {
            "P_b": expit(row["estimate"]),
            "lower_CL": expit(row["estimate"] - crit * row["SE"]),
            "upper_CL": expit(row["estimate"] + crit * row["SE"]),
            "logit": float(row["estimate"]),
            "SE": float(row["SE"]),
            "z": float(row["z"]),
            "p": float(row["p"]),
        }


def pair_model(data: pd.DataFrame, a: str, b: str, levels: list[str], names: FactorNames = FACTOR_NAMES) -> PairModel:
    """Fit the pair ``(a, b)``'s model on one stage's validated trials ``data`` (``levels``:
    the design's density levels, in order)."""
    from crowdstudy.stats.robust import _sum_coding

    left, right = data["method_left"].astype(str), data["method_right"].astype(str)
    sub = data[((left == a) & (right == b)) | ((left == b) & (right == a))]
    y = (sub["chosen_method"].astype(str) == b).to_numpy(float)
    groups = sub["participant_id"].astype(str).to_numpy()
    present = [lv for lv in levels if lv in set(sub["density_level"].astype(str))]
    base: dict[str, Any] = dict(method_a=a, method_b=b, n_trials=len(sub), chose_b=int(y.sum()))
    if len(sub) == 0:
        return PairModel(terms="intercept", fit=None, note="no trials", **base)
    note = ""
    if len(present) > 1:
        x = np.column_stack([np.ones(len(sub)), _sum_coding(sub["density_level"].astype(str), present)])
        term_names = ["(Intercept)", *[f"{names.density}{j + 1}" for j in range(len(present) - 1)]]
        by_level = sub.groupby(sub["density_level"].astype(str))["chosen_method"].agg(lambda c: (c == b).mean())
        if ((by_level == 0) | (by_level == 1)).any():
            note = f"every choice at some {names.density} level is the same; intercept only"
        else:
            try:
                return PairModel(
                    terms=names.density, fit=logistic_mixed_model(y, x, groups, term_names), note="", **base
                )
            except InvalidInputError as exc:
                note = f"{exc}; intercept only"
    else:
        note = f"one {names.density} level; intercept only"
    try:
        fit = logistic_mixed_model(y, np.ones((len(sub), 1)), groups, ["(Intercept)"])
    except InvalidInputError as exc:
        return PairModel(terms="intercept", fit=None, note=str(exc), **base)
    return PairModel(terms="intercept", fit=fit, note=note, **base)


@dataclasses.dataclass(frozen=True)
class ChoiceResult:
    """The analysis of one 2AFC stage (see the module docstring): ``stage``, ``scenario``,
    ``methods`` (the stage's, the first is its reference), ``n_participants``,
    ``n_trials``; ``shares`` (:func:`choice_shares`); ``position`` (:func:`position_bias`);
    ``pairs``: one :class:`PairModel` per pair of the stage; ``bradley_terry`` (None with
    two methods); ``names``: the factor names; ``statement``: the question asked."""

    stage: int
    scenario: str
    methods: tuple[str, ...]
    n_participants: int
    n_trials: int
    shares: pd.DataFrame
    position: dict
    pairs: tuple[PairModel, ...]
    bradley_terry: BradleyTerryResult | None
    names: FactorNames = FACTOR_NAMES
    statement: str = ""
    level: float = 0.95

    @property
    def label(self) -> str:
        return f"Stage {self.stage} ({self.scenario}), 2AFC"

    def pair_table(self) -> pd.DataFrame:
        """One row per pair: trials, how many chose b, P(b) at the average density with its
        interval and test, the participant variance, log-likelihood and the model's note."""
        rows = []
        for pm in self.pairs:
            fit = pm.fit
            rows.append(
                {
                    "pair": pm.pair,
                    "method_a": pm.method_a,
                    "method_b": pm.method_b,
                    "trials": pm.n_trials,
                    "chose_b": pm.chose_b,
                    "share_b": pm.chose_b / pm.n_trials if pm.n_trials else float("nan"),
                    **pm.probability(self.level),
                    "terms": pm.terms,
                    "variance": fit.variance if fit else float("nan"),
                    "loglik": fit.loglik if fit else float("nan"),
                    "singular": bool(fit.singular) if fit else False,
                    "note": pm.note,
                }
            )
        return pd.DataFrame(rows)

    def fixed_effects(self) -> pd.DataFrame:
        """Every pair model's fixed effects (logits), a ``pair`` column first."""
        parts = [pm.fit.fixed.assign(pair=pm.pair) for pm in self.pairs if pm.fit is not None]
        if not parts:
            return pd.DataFrame(columns=["pair", "term", "estimate", "SE", "z", "p"])
        out = pd.concat(parts, ignore_index=True)
        return out[["pair", "term", "estimate", "SE", "z", "p"]]


def compute_choices(
    data: pd.DataFrame,
    design: StudyDesign,
    stage: Stage,
    *,
    level: float = 0.95,
    names: FactorNames = FACTOR_NAMES,
) -> ChoiceResult:
    """The whole 2AFC analysis of one stage (``data``: validated comparisons, any stages)."""
    sub = data[data["stage"] == stage.number].reset_index(drop=True)
    if len(sub) == 0:
        raise InvalidInputError(f"comparisons: no trials for stage {stage.number} ({stage.scenario})")
    levels = list(design.densities)
    pairs = tuple(pair_model(sub, a, b, levels, names) for a, b in stage.pairs)
    bt = None
    if len(stage.methods) > 2:
        won = (sub["choice"].astype(str) == "left").to_numpy(int)
        try:
            bt = bradley_terry(sub["method_left"], sub["method_right"], won, list(stage.methods), level=level)
        except (InvalidInputError, np.linalg.LinAlgError):
            bt = None
    return ChoiceResult(
        stage=stage.number,
        scenario=stage.scenario,
        methods=tuple(stage.methods),
        n_participants=int(sub["participant_id"].nunique()),
        n_trials=len(sub),
        shares=choice_shares(sub, stage, design, level=level),
        position=position_bias(sub, level=level),
        pairs=pairs,
        bradley_terry=bt,
        names=names,
        statement=design.comparison.text if design.comparison is not None else "",
        level=level,
    )

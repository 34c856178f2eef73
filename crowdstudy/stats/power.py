"""Monte-Carlo power analysis: simulate whole studies with the synthetic ResponseModel and
run each through the same scoring and ANOVA pipeline as real data.

Power of an effect = fraction of simulated studies whose ANOVA p (under the chosen
sphericity rule) is below alpha; its Monte-Carlo standard error is sqrt(P (1 - P) / sims)
and its interval the exact (Clopper-Pearson) binomial interval, as R's ``binom.test``.

Standardised terms: each row also reports the median partial eta squared of the effect over
the simulated studies and, for Method, the median d_z of the Ours - Baseline difference of
the participants' means; :func:`method_points` converts a planned d_z (or eta_p^2 of the
Method effect) into the Likert-point ``method_effect`` of the model.

The analysed stage's task decides what is simulated and tested:

- a ``likert`` or ``slider`` stage: the ANOVA's effects (``effects``); with more than two
  methods also one row per method against the reference (effect ``"Baseline - Stiff"``):
  the Tukey-adjusted pairwise comparison of the Method main effect, and the median d_z of
  that method's difference from the reference;
- a ``2afc`` stage (choices from :func:`~crowdstudy.stats.synthetic.simulate_study`): one
  row per pair of the stage (effect ``"a vs b"``), the power of the pair's logistic mixed
  model (random intercept per participant, the intercept's Wald z test of P(b) = 1/2:
  :func:`~crowdstudy.stats.choice_models.logistic_mixed_model`, fitted without the Density
  terms the analysis adds, which leave the intercept's test nearly the same and cost
  several times the time), and the median share of trials choosing ``b``.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pandas as pd

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import cell_matrix
from crowdstudy.stats.anova import anova_from_cells
from crowdstudy.stats.scoring import FACTOR_NAMES, cell_means, composite_scores
from crowdstudy.stats.synthetic import ResponseModel, simulate_responses

__all__ = ["power_analysis", "PowerResult", "DEFAULT_EFFECTS", "method_points", "clopper_pearson"]

#: Effects whose power is reported by default.
DEFAULT_EFFECTS = (FACTOR_NAMES.method, f"{FACTOR_NAMES.density}:{FACTOR_NAMES.method}")


def clopper_pearson(hits: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact binomial interval of a proportion ``hits / n`` (R's ``binom.test(hits, n)$conf.int``)."""
    from scipy import stats

    a = 1.0 - level
    lo = 0.0 if hits == 0 else float(stats.beta.ppf(a / 2.0, hits, n - hits + 1))
    hi = 1.0 if hits == n else float(stats.beta.ppf(1.0 - a / 2.0, hits + 1, n - hits))
    return lo, hi


def method_points(
    model: ResponseModel, design, stage: int, *, dz: float | None = None, eta_p2: float | None = None
) -> float:
    """Likert points of ``method_effect`` that give the Method main effect a population d_z
    of ``dz`` (or a partial eta squared ``eta_p2``, via ``d_z = sqrt(eta_p2 / (1 - eta_p2))``,
    the large-sample relation of a 1-df within effect), for the first composite.

    The SD of a participant's Ours - Baseline difference of means over the stage's ``C``
    cells per method is ``sqrt(participant_method_sd^2 + 2 (noise_sd^2 + 1/12) / (k C))``
    (``k`` items per composite; 1/12: rounding to whole points); the effect averaged over
    the densities is ``method_effect`` times the mean density multiplier. Clipping at the
    scale's ends is ignored, so check the realised ``dz_median`` of the power table.
    """
    if dz is not None and eta_p2 is None:
        d_z = float(dz)
    elif eta_p2 is not None and dz is None:
        if not 0 <= eta_p2 < 1:
            raise InvalidInputError(f"eta_p2 must be in [0, 1), got {eta_p2!r}")
        d_z = float(np.sqrt(eta_p2 / (1.0 - eta_p2)))
    else:
        raise InvalidInputError("give exactly one of dz or eta_p2")
    st = next((s for s in design.stages if s.number == stage), None)
    if st is None:
        raise InvalidInputError(f"stage {stage!r} is not in the design")
    comp = next(iter(model.composites))
    k = len(model.composites[comp])
    cells = len(design.densities) * len(st.viewpoints)
    sd = float(np.sqrt(model.participant_method_sd**2 + 2.0 * (model.noise_sd**2 + 1.0 / 12.0) / (k * cells)))
    unit = float(model.composite_effects.get(comp, 1.0)) * float(
        np.mean(
            [max(0.0, 1.0 + model.density_slope * (model.reference_density - d)) for d in design.densities.values()]
        )
    )
    if unit <= 0:
        raise InvalidInputError("the model's density_slope leaves no Method effect at any density")
    return d_z * sd / unit


@dataclasses.dataclass
class PowerResult:
    """``table``: one row per (composite, effect): power, mc_se (Monte-Carlo standard
    error), ci_low/ci_high (exact Clopper-Pearson 95 % interval), n_significant, sims,
    np2_median (median partial eta squared over the studies), dz_median (Method rows: the
    median d_z of the participants' treated - untreated difference; NaN otherwise).
    ``p_values``: (sims, composites x effects) p of every simulated study, columns
    ``"COMP/effect"``. ``settings``: the inputs."""

    table: pd.DataFrame
    p_values: pd.DataFrame
    settings: dict


def power_analysis(
    design,
    n_participants: int,
    *,
    model: ResponseModel | None = None,
    sims: int = 200,
    seed: int = 1,
    stage: int = 1,
    composites=None,
    effects=DEFAULT_EFFECTS,
    alpha: float = 0.05,
    correction="auto",
    progress: bool = False,
) -> PowerResult:
    """Estimate power by simulating ``sims`` studies of ``n_participants`` participants.

    ``model``: the generative model (default ``ResponseModel.for_design(design)``); study
    ``i`` uses seed ``(seed, i)`` so results are reproducible. ``stage``: stage number
    analysed; ``composites``: default all of the design; ``effects``: ANOVA sources.
    """
    if isinstance(sims, bool) or not isinstance(sims, (int, np.integer)) or sims < 1:
        raise InvalidInputError(f"sims must be an integer >= 1, got {sims!r}")
    if isinstance(n_participants, bool) or not isinstance(n_participants, (int, np.integer)) or n_participants < 2:
        raise InvalidInputError(f"n_participants must be an integer >= 2, got {n_participants!r}")
    if not 0 < alpha < 1:
        raise InvalidInputError(f"alpha must be in (0, 1), got {alpha!r}")
    if stage not in [s.number for s in design.stages]:
        raise InvalidInputError(f"stage {stage!r} is not in the design; stages: {[s.number for s in design.stages]}")
    model = model or ResponseModel.for_design(design)
    st = next(s_ for s_ in design.stages if s_.number == stage)
    seeds = np.random.SeedSequence(int(seed)).generate_state(int(sims), dtype=np.uint32)
    iterator = range(int(sims))
    if progress:
        from crowdstudy.progress import progress_bar

        iterator = progress_bar(iterator, desc="power", unit="study", leave=False)
    if st.task == "2afc":
        rows = _choice_power(design, st, int(n_participants), model, seeds, iterator, alpha)
        pvals = pd.DataFrame(rows.pop("p_values"))
        table = pd.DataFrame(rows["rows"])
    else:
        comps = list(design.composites) if composites is None else list(composites)
        for c in comps:
            if c not in design.composites:
                raise InvalidInputError(f"unknown composite {c!r}; the design defines {', '.join(design.composites)}")
        table, pvals = _rating_power(
            design, st, int(n_participants), model, seeds, iterator, comps, effects, alpha, correction
        )
    settings = {
        "n_participants": int(n_participants),
        "sims": int(sims),
        "seed": int(seed),
        "stage": int(stage),
        "task": st.task,
        "alpha": float(alpha),
        "correction": correction,
        "model": dataclasses.asdict(model),
    }
    return PowerResult(table, pvals, settings)


def _power_row(composite: str, effect: str, p: np.ndarray, alpha: float) -> dict:
    """power, its Monte-Carlo SE and exact interval from the studies' p-values."""
    sims = len(p)
    hits = int((p < alpha).sum())
    pw = hits / sims
    lo, hi = clopper_pearson(hits, sims)
    return {
        "composite": composite,
        "effect": effect,
        "power": pw,
        "mc_se": float(np.sqrt(pw * (1 - pw) / sims)),
        "ci_low": lo,
        "ci_high": hi,
        "n_significant": hits,
        "sims": sims,
    }


def _median(x: np.ndarray) -> float:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return float(np.nanmedian(x))


def _rating_power(design, st, n, model, seeds, iterator, comps, effects, alpha, correction):
    """The ANOVA effects' power (and each method against the reference, k > 2)."""
    from crowdstudy.stats.posthoc import pairwise_from_cells

    methods = list(st.methods)
    ref = methods[0]
    contrasts = [f"{ref} - {m}" for m in methods[1:]] if len(methods) > 2 else []
    labels = [*effects, *contrasts]
    sims = len(seeds)
    pvals = np.full((sims, len(comps) * len(labels)), np.nan)
    np2 = np.full_like(pvals, np.nan)
    dzs = np.full((sims, len(comps), len(methods) - 1), np.nan)
    for i in iterator:
        raw = simulate_responses(design, n, model, seed=int(seeds[i]), stages=[st.number])
        scored = composite_scores(raw, design)
        for ci, comp in enumerate(comps):
            long = cell_means(scored, comp, design, stage=st.number)
            cm = cell_matrix(long, comp, list(FACTOR_NAMES.order), "participant_id")
            table = anova_from_cells(cm, correction=correction, alpha=alpha).set_index("Source")
            grid = cm.values.reshape(len(cm.subjects), -1, cm.shape[-1]).mean(axis=1)  # (n, k) method means
            for j in range(1, len(methods)):
                diff = grid[:, j] - grid[:, 0]
                sd = diff.std(ddof=1)
                dzs[i, ci, j - 1] = diff.mean() / sd if sd > 0 else np.nan
            for ei, eff in enumerate(effects):
                if eff not in table.index:
                    raise InvalidInputError(f"effect {eff!r} is not an ANOVA source; sources: {', '.join(table.index)}")
                pvals[i, ci * len(labels) + ei] = table.at[eff, "p"]
                np2[i, ci * len(labels) + ei] = table.at[eff, "np2"]
            if contrasts:
                pairs = pairwise_from_cells(cm, FACTOR_NAMES.method, []).set_index("contrast")["p_adj"]
                for j, con in enumerate(contrasts):
                    pvals[i, ci * len(labels) + len(effects) + j] = pairs[con]
    columns = [f"{c}/{e}" for c in comps for e in labels]
    rows = []
    for j, col in enumerate(columns):
        comp, eff = col.split("/", 1)
        ci = comps.index(comp)
        if eff == FACTOR_NAMES.method:
            dz = _median(dzs[:, ci, -1])
        elif eff in contrasts:
            dz = _median(dzs[:, ci, contrasts.index(eff)])
        else:
            dz = float("nan")
        rows.append({**_power_row(comp, eff, pvals[:, j], alpha), "np2_median": _median(np2[:, j]), "dz_median": dz})
    return pd.DataFrame(rows), pd.DataFrame(pvals, columns=columns)


def _choice_power(design, st, n, model, seeds, iterator, alpha) -> dict:
    """Each pair's power in a 2afc stage (see the module docstring)."""
    from crowdstudy.stats.choice_models import logistic_mixed_model
    from crowdstudy.stats.synthetic import simulate_study

    sims = len(seeds)
    pvals = np.full((sims, len(st.pairs)), np.nan)
    shares = np.full_like(pvals, np.nan)
    for i in iterator:
        data = simulate_study(design, n, model, seed=int(seeds[i]), stages=[st.number]).comparisons
        left, right = data["method_left"].astype(str), data["method_right"].astype(str)
        for j, (a, b) in enumerate(st.pairs):
            sub = data[((left == a) & (right == b)) | ((left == b) & (right == a))]
            y = (sub["chosen_method"].astype(str) == b).to_numpy(float)
            shares[i, j] = y.mean()
            try:
                fit = logistic_mixed_model(
                    y, np.ones((len(y), 1)), sub["participant_id"].to_numpy(), ["(Intercept)"], polish=False
                )
                pvals[i, j] = float(fit.fixed["p"].iloc[0])
            except InvalidInputError:  # every choice the same: the share is 0 or 1
                pvals[i, j] = 0.0
    rows = []
    for j, (a, b) in enumerate(st.pairs):
        rows.append({**_power_row("2afc", f"{a} vs {b}", pvals[:, j], alpha), "share_b_median": _median(shares[:, j])})
    return {"rows": rows, "p_values": {f"2afc/{a} vs {b}": pvals[:, j] for j, (a, b) in enumerate(st.pairs)}}

"""Monte-Carlo power analysis: simulate whole studies with the synthetic ResponseModel and
run each through the same scoring and ANOVA pipeline as real data.

Power of an effect = fraction of simulated studies whose ANOVA p (under the chosen
sphericity rule) is below alpha; its Monte-Carlo standard error is sqrt(P (1 - P) / sims)
and its interval the exact (Clopper-Pearson) binomial interval, as R's ``binom.test``.

Standardised terms: each row also reports the median partial eta squared of the effect over
the simulated studies and, for Method, the median d_z of the Ours - Baseline difference of
the participants' means; :func:`method_points` converts a planned d_z (or eta_p^2 of the
Method effect) into the Likert-point ``method_effect`` of the model.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pandas as pd

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import cell_matrix
from crowdstudy.stats.anova import anova_from_cells
from crowdstudy.stats.scoring import FACTORS, cell_means, composite_scores
from crowdstudy.stats.synthetic import ResponseModel, simulate_responses

__all__ = ["power_analysis", "PowerResult", "DEFAULT_EFFECTS", "method_points", "clopper_pearson"]

#: Effects whose power is reported by default.
DEFAULT_EFFECTS = ("Method", "Density:Method")


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
    if (dz is None) == (eta_p2 is None):
        raise InvalidInputError("give exactly one of dz or eta_p2")
    if eta_p2 is not None:
        if not 0 <= eta_p2 < 1:
            raise InvalidInputError(f"eta_p2 must be in [0, 1), got {eta_p2!r}")
        dz = float(np.sqrt(eta_p2 / (1.0 - eta_p2)))
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
    return float(dz) * sd / unit


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
    comps = list(design.composites) if composites is None else list(composites)
    for c in comps:
        if c not in design.composites:
            raise InvalidInputError(f"unknown composite {c!r}; the design defines {', '.join(design.composites)}")
    effects = list(effects)
    seeds = np.random.SeedSequence(int(seed)).generate_state(int(sims), dtype=np.uint32)
    iterator = range(int(sims))
    if progress:
        from crowdstudy.progress import progress_bar

        iterator = progress_bar(iterator, desc="power", unit="study", leave=False)
    pvals = np.full((int(sims), len(comps) * len(effects)), np.nan)
    np2 = np.full_like(pvals, np.nan)
    dzs = np.full((int(sims), len(comps)), np.nan)
    for i in iterator:
        raw = simulate_responses(design, int(n_participants), model, seed=int(seeds[i]), stages=[stage])
        scored = composite_scores(raw, design)
        for ci, comp in enumerate(comps):
            long = cell_means(scored, comp, design, stage=stage)
            cm = cell_matrix(long, comp, list(FACTORS), "participant_id")
            table = anova_from_cells(cm, correction=correction, alpha=alpha).set_index("Source")
            grid = cm.values.reshape(len(cm.subjects), -1, cm.shape[-1])
            diff = grid[:, :, -1].mean(axis=1) - grid[:, :, 0].mean(axis=1)
            sd = diff.std(ddof=1)
            dzs[i, ci] = diff.mean() / sd if sd > 0 else np.nan
            for ei, eff in enumerate(effects):
                if eff not in table.index:
                    raise InvalidInputError(f"effect {eff!r} is not an ANOVA source; sources: {', '.join(table.index)}")
                pvals[i, ci * len(effects) + ei] = table.at[eff, "p"]
                np2[i, ci * len(effects) + ei] = table.at[eff, "np2"]
    columns = [f"{c}/{e}" for c in comps for e in effects]
    rows = []
    for j, col in enumerate(columns):
        hits = int((pvals[:, j] < alpha).sum())
        pw = hits / sims
        se = float(np.sqrt(pw * (1 - pw) / sims))
        comp, eff = col.split("/", 1)
        lo, hi = clopper_pearson(hits, int(sims))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            dz_med = float(np.nanmedian(dzs[:, comps.index(comp)])) if eff == "Method" else float("nan")
            np2_med = float(np.nanmedian(np2[:, j]))
        rows.append(
            {
                "composite": comp,
                "effect": eff,
                "power": pw,
                "mc_se": se,
                "ci_low": lo,
                "ci_high": hi,
                "n_significant": hits,
                "sims": int(sims),
                "np2_median": np2_med,
                "dz_median": dz_med,
            }
        )
    settings = {
        "n_participants": int(n_participants),
        "sims": int(sims),
        "seed": int(seed),
        "stage": int(stage),
        "alpha": float(alpha),
        "correction": correction,
        "model": dataclasses.asdict(model),
    }
    return PowerResult(pd.DataFrame(rows), pd.DataFrame(pvals, columns=columns), settings)

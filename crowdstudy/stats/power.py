"""Monte-Carlo power analysis: simulate whole studies with the synthetic ResponseModel and
run each through the same scoring and ANOVA pipeline as real data.

Power of an effect = fraction of simulated studies whose ANOVA p (under the chosen
sphericity rule) is below alpha; its Monte-Carlo standard error is sqrt(P (1 - P) / sims).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import cell_matrix
from crowdstudy.stats.anova import anova_from_cells
from crowdstudy.stats.scoring import cell_means, composite_scores
from crowdstudy.stats.synthetic import ResponseModel, simulate_responses

__all__ = ["power_analysis", "PowerResult", "DEFAULT_EFFECTS"]

#: Effects whose power is reported by default.
DEFAULT_EFFECTS = ("Method", "Density:Method")
_FACTORS = ["Density", "Viewpoint", "Method"]


@dataclasses.dataclass
class PowerResult:
    """``table``: one row per (composite, effect): power, mc_se (Monte-Carlo standard
    error), ci_low/ci_high (power +- 1.96 mc_se, clipped to [0, 1]), n_significant, sims.
    ``p_values``: (sims, composites x effects) p of every simulated study, columns
    ``"COMP/effect"``. ``settings``: the inputs."""
    table: pd.DataFrame
    p_values: pd.DataFrame
    settings: dict


def power_analysis(design, n_participants: int, *, model: ResponseModel | None = None, sims: int = 200,
                   seed: int = 1, stage: int = 1, composites=None, effects=DEFAULT_EFFECTS, alpha: float = 0.05,
                   correction="auto", progress: bool = False) -> PowerResult:
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
        from tqdm import tqdm
        iterator = tqdm(iterator, desc="power", unit="study", leave=False)
    pvals = np.full((int(sims), len(comps) * len(effects)), np.nan)
    for i in iterator:
        raw = simulate_responses(design, int(n_participants), model, seed=int(seeds[i]), stages=[stage])
        scored = composite_scores(raw, design)
        for ci, comp in enumerate(comps):
            long = cell_means(scored, comp, design, stage=stage)
            table = anova_from_cells(cell_matrix(long, comp, _FACTORS, "participant_id"), correction=correction,
                                     alpha=alpha).set_index("Source")
            for ei, eff in enumerate(effects):
                if eff not in table.index:
                    raise InvalidInputError(f"effect {eff!r} is not an ANOVA source; sources: {', '.join(table.index)}")
                pvals[i, ci * len(effects) + ei] = table.at[eff, "p"]
    columns = [f"{c}/{e}" for c in comps for e in effects]
    rows = []
    for j, col in enumerate(columns):
        hits = int((pvals[:, j] < alpha).sum())
        pw = hits / sims
        se = float(np.sqrt(pw * (1 - pw) / sims))
        comp, eff = col.split("/", 1)
        rows.append({"composite": comp, "effect": eff, "power": pw, "mc_se": se,
                     "ci_low": max(0.0, pw - 1.96 * se), "ci_high": min(1.0, pw + 1.96 * se),
                     "n_significant": hits, "sims": int(sims)})
    settings = {"n_participants": int(n_participants), "sims": int(sims), "seed": int(seed), "stage": int(stage),
                "alpha": float(alpha), "correction": correction, "model": dataclasses.asdict(model)}
    return PowerResult(pd.DataFrame(rows), pd.DataFrame(pvals, columns=columns), settings)

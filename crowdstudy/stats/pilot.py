"""The simulation model of :mod:`crowdstudy.stats.synthetic` fitted to pilot responses, so a
power analysis can start from what a pilot study measured (``crowdstudy power --pilot
responses.csv``).

Moment estimates on the scored scale (negative items reversed), in Likert points:

- fixed part, one least-squares fit over every trial and composite: a common intercept
  (``base_score``), scenario and viewpoint offsets (the design's first scenario / viewpoint
  at 0), the density penalty, and per composite the Method effect at the reference density
  ``a_c`` and its change per character/m^2 ``b_c``; then ``method_effect = a`` of the first
  composite, ``composite_effects[c] = a_c / method_effect`` and ``density_slope =
  sum(a_c b_c) / sum(a_c^2)``;
- ``noise_sd`` from the two items of a composite in one trial: ``var(Q_a - Q_b) / 2 - 1/12``
  (the 1/12 removes the rounding to whole points);
- participant SDs from the residuals: the spread of each participant's mean (Baseline
  trials), of their Ours - Baseline difference, of their own density slope and of their
  viewpoint means, each minus the part the trial noise explains.

Clipping at the ends of the scale biases the SDs down a little; :func:`fit_pilot` returns
the table of estimates so a planner sees what went into the simulation.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats.scoring import composite_scores, validate_responses
from crowdstudy.stats.synthetic import ResponseModel

__all__ = ["fit_pilot"]


def _var(x) -> float:
    x = np.asarray(x, dtype=float)
    return float(x.var(ddof=1)) if x.size > 1 else 0.0


def fit_pilot(responses: pd.DataFrame, design, *, source: str = "pilot") -> tuple[ResponseModel, pd.DataFrame]:
    """Estimate a :class:`~crowdstudy.stats.synthetic.ResponseModel` from pilot responses.

    Returns ``(model, table)``; ``table`` lists each estimated parameter with its value
    (points, or points per character/m^2 for slopes) and how it was estimated.
    """
    data = validate_responses(responses, design, source=source)
    if data["participant_id"].nunique() < 3:
        raise InvalidInputError(
            f"{source}: a pilot needs at least 3 participants to estimate their spread, "
            f"got {data['participant_id'].nunique()}"
        )
    treated = list(design.methods)[-1]
    if set(data["method"].astype(str)) != set(design.methods):
        raise InvalidInputError(f"{source}: the pilot must include every method ({', '.join(design.methods)})")
    scored = composite_scores(data, design)
    comps = list(design.composites)
    ref = float(np.median(list(design.densities.values())))
    dens = scored["density_level"].astype(str).map(design.densities).to_numpy(float)
    scen_levels = sorted(set(scored["scenario"].astype(str)), key=[st.scenario for st in design.stages].index)
    view_levels = [v for v in design.viewpoints if v in set(scored["viewpoint"].astype(str))]
    rows, ys, keys = [], [], []
    for ci, c in enumerate(comps):
        t = (scored["method"].astype(str) == treated).to_numpy(float)
        cols = {"base": np.ones(len(scored)), "density": -(dens - ref)}
        for s in scen_levels[1:]:
            cols[f"scenario:{s}"] = (scored["scenario"].astype(str) == s).to_numpy(float)
        for v in view_levels[1:]:
            cols[f"viewpoint:{v}"] = (scored["viewpoint"].astype(str) == v).to_numpy(float)
        for cj, c2 in enumerate(comps):
            cols[f"a:{c2}"] = t * (ci == cj)
            cols[f"b:{c2}"] = t * (ci == cj) * (ref - dens)
        rows.append(pd.DataFrame(cols))
        ys.append(scored[c].to_numpy(float))
        keys.append(scored[["participant_id", "method", "viewpoint"]].assign(composite=c, density=dens))
    x = pd.concat(rows, ignore_index=True)
    y = np.concatenate(ys)
    coef, *_ = np.linalg.lstsq(x.to_numpy(), y, rcond=None)
    est = dict(zip(x.columns, coef, strict=True))
    resid = y - x.to_numpy() @ coef
    frame = pd.concat(keys, ignore_index=True).assign(r=resid)
    a = np.array([est[f"a:{c}"] for c in comps])
    b = np.array([est[f"b:{c}"] for c in comps])
    method_effect = float(a[0])
    comp_eff = {c: (float(a[i] / a[0]) if abs(a[0]) > 1e-9 else 1.0) for i, c in enumerate(comps)}
    slope = float((a * b).sum() / (a * a).sum()) if (a * a).sum() > 1e-12 else 0.0
    # item noise from the two items of each composite within a trial
    pairs = []
    for items in design.composites.values():
        if len(items) >= 2:
            rev = {it.id for it in design.items if it.reverse}
            q = [design.likert_points + 1 - data[i] if i in rev else data[i] for i in items[:2]]
            pairs.append(_var((q[0] - q[1]).to_numpy(float)) / 2.0)
    noise_var = max(0.0, float(np.mean(pairs)) - 1.0 / 12.0) if pairs else 0.0
    # within participant x composite x method residual variance (trial noise of a composite)
    cell = frame.groupby(["participant_id", "composite", "method"])["r"]
    dof = cell.size() - 1
    within = float(np.average(cell.var(ddof=1).fillna(0.0), weights=dof)) if dof.sum() > 0 else 0.0
    k = len(comps)
    base = frame[frame["method"].astype(str) != treated]
    per_pc = base.groupby(["participant_id", "composite"])["r"].agg(["mean", "size"])
    p_var = float(per_pc.groupby("composite")["mean"].var(ddof=1).mean()) - within / float(per_pc["size"].mean())
    pm = frame.groupby(["participant_id", "method"])["r"].agg(["mean", "size"]).unstack("method")
    diff = pm[("mean", treated)] - pm[("mean", [m for m in design.methods if m != treated][0])]
    n_t = float(pm[("size", treated)].mean()) / k
    pm_var = _var(diff) - within / k * 2.0 / n_t
    slopes, ssx = [], []
    for _, g in frame.groupby("participant_id"):
        dx = g["density"].to_numpy() - g["density"].mean()
        if (dx * dx).sum() > 0:
            slopes.append(float((dx * g["r"].to_numpy()).sum() / (dx * dx).sum()))
            ssx.append(float((dx * dx).sum()))
    d_var = _var(slopes) - within / float(np.mean(ssx)) if slopes else 0.0
    vm = frame.groupby(["participant_id", "viewpoint"])["r"].agg(["mean", "size"])
    centred = vm["mean"] - vm["mean"].groupby("participant_id").transform("mean")
    n_views = vm.groupby("participant_id").size().mean()
    v_var = (
        (
            float((centred**2).sum() / max(1, len(vm) - vm.index.get_level_values(0).nunique()))
            - within / float(vm["size"].mean())
        )
        if n_views > 1
        else 0.0
    )
    scen_off = {s: float(est.get(f"scenario:{s}", 0.0)) for s in scen_levels}
    view_off = {v: float(est.get(f"viewpoint:{v}", 0.0)) for v in view_levels}
    model = ResponseModel.for_design(
        design,
        method_effect=method_effect,
        composite_effects=comp_eff,
        density_slope=slope,
        reference_density=ref,
        density_penalty=float(est["density"]),
        base_score=float(est["base"]),
        noise_sd=float(np.sqrt(noise_var)),
        participant_sd=float(np.sqrt(max(0.0, p_var))),
        participant_method_sd=float(np.sqrt(max(0.0, pm_var))),
        participant_density_sd=float(np.sqrt(max(0.0, d_var))),
        participant_viewpoint_sd=float(np.sqrt(max(0.0, v_var))),
        scenario_offsets=scen_off,
        viewpoint_offsets=view_off,
        treated_method=treated,
    )
    how = {
        "method_effect": f"{treated} - baseline on {comps[0]} at {ref:g}/m^2 (least squares)",
        "density_slope": "relative change of the Method effect per character/m^2",
        "density_penalty": "drop per character/m^2",
        "base_score": "untreated score at the reference density",
        "noise_sd": "item noise: var(item a - item b) / 2 - 1/12",
        "participant_sd": "participant offset",
        "participant_method_sd": "participant deviation of the Method effect",
        "participant_density_sd": "participant density slope",
        "participant_viewpoint_sd": "participant viewpoint offset",
    }
    table = pd.DataFrame(
        [{"parameter": k_, "value": float(getattr(model, k_)), "estimated_from": v} for k_, v in how.items()]
    )
    table.attrs.update(participants=int(data["participant_id"].nunique()), trials=int(len(data)))
    return model, table

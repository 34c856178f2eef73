"""What ``crowdstudy analyze`` writes for a 2AFC stage (a
:class:`~crowdstudy.stats.comparisons.ChoiceResult`): the APA lines of summary.md, the
tables, the figures and the stage's entry of analysis.json.

Files in the stage's folder (``stageN_<scenario>/``)::

    2afc_shares.{csv,md}        each method's choice share per cell and overall (Clopper-Pearson)
    2afc_position.csv           the share of "left" answers (position bias)
    2afc_pairs.{csv,md}         per pair: P(choose b) at the average density from the glmer
    2afc_glmer.csv              every pair model's fixed effects (logits)
    2afc_bradley_terry.{csv,md} the Bradley-Terry scale (more than two methods)
    2afc_shares.png             shares with intervals per cell, one panel per viewpoint
    2afc_bradley_terry.png      the scale with 95 % intervals (more than two methods)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from crowdstudy.stats.choice_models import BradleyTerryResult
from crowdstudy.stats.comparisons import ChoiceResult
from crowdstudy.stats.report import format_p, write_table

__all__ = ["choice_summary_lines", "write_choice_tables", "choice_figures", "choice_record"]


def _pct(x: float) -> str:
    return f"{100 * x:.1f}%"


def choice_summary_lines(res: ChoiceResult, alpha: float) -> list[str]:
    """summary.md's section of one 2AFC stage."""
    pct = f"{100 * res.level:g}%"
    lines = ["", f"## {res.label}", ""]
    if res.statement:
        lines.append(f'Statement: "{res.statement}" ({res.n_participants} participants, {res.n_trials} trials).')
    else:
        lines.append(f"{res.n_participants} participants, {res.n_trials} trials.")
    overall = res.shares[res.shares["cell"] == "all"]
    lines.append(
        "Choice shares (chosen when shown, exact Clopper-Pearson interval, binomial test against 50%): "
        + "; ".join(
            f"{r['method']} {_pct(r['share'])} ({r['chosen']}/{r['shown']}), {pct} CI "
            f"[{_pct(r['lower_CL'])}, {_pct(r['upper_CL'])}], {format_p(r['p'])}"
            for r in overall.to_dict("records")
        )
        + "."
    )
    for pm in res.pairs:
        pr = pm.probability(res.level)
        if pm.fit is None:
            lines.append(f"{pm.pair}: no model ({pm.note}).")
            continue
        reduced = f"; {pm.note}" if pm.note else ""
        lines.append(
            f"{pm.pair}: {pm.method_b} chosen in {pm.chose_b} of {pm.n_trials} trials; logistic mixed model "
            f"(random intercept per participant, {pm.terms if pm.terms == 'intercept' else pm.terms + ' sum-coded'}"
            f"{reduced}): P({pm.method_b}) = {pr['P_b']:.2f}, {pct} CI [{pr['lower_CL']:.2f}, {pr['upper_CL']:.2f}], "
            f"z = {pr['z']:.2f}, {format_p(pr['p'])}; participant variance {pm.fit.variance:.3f}"
            + (" (singular fit)" if pm.fit.singular else "")
            + "."
        )
    if res.bradley_terry is not None:
        ab = res.bradley_terry.abilities
        lines.append(
            f"Bradley-Terry scale (logits, {ab['method'].iloc[0]} = 0, {pct} Wald CI): "
            + "; ".join(
                f"{r['method']} {r['ability']:.2f} [{r['lower_CL']:.2f}, {r['upper_CL']:.2f}]"
                for r in ab.iloc[1:].to_dict("records")
            )
            + "."
        )
    pos = res.position
    lines.append(
        f"Position bias: left chosen in {_pct(pos['share'])} of trials, {pct} CI [{_pct(pos['lower_CL'])}, "
        f"{_pct(pos['upper_CL'])}], {format_p(pos['p'])}" + (" (a bias to one side)." if pos["p"] < alpha else ".")
    )
    return lines


def write_choice_tables(res: ChoiceResult, d: Path) -> list[Path]:
    """The tables of one 2AFC stage in folder ``d`` (see the module docstring)."""
    label = res.label
    files = write_table(
        res.shares,
        d / "2afc_shares",
        formats=("csv", "md"),
        caption=f"{label}: choice share per method (chosen / shown, Clopper-Pearson {100 * res.level:g}% CI)",
    )
    import pandas as pd

    files += write_table(pd.DataFrame([res.position]), d / "2afc_position", formats=("csv",))
    files += write_table(
        res.pair_table(),
        d / "2afc_pairs",
        formats=("csv", "md"),
        caption=f"{label}: P(choose b) per pair, logistic mixed model (random intercept per participant)",
    )
    files += write_table(res.fixed_effects(), d / "2afc_glmer", formats=("csv",))
    if res.bradley_terry is not None:
        files += write_table(
            res.bradley_terry.abilities,
            d / "2afc_bradley_terry",
            formats=("csv", "md"),
            caption=f"{label}: Bradley-Terry scale (logits, the reference at 0)",
        )
    return files


def choice_figures(
    res: ChoiceResult, d: Path, density_values: dict[str, float], *, note: str = "", dpi: int = 150
) -> list[Path]:
    """2afc_shares.png (and 2afc_bradley_terry.png with more than two methods)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from crowdstudy.stats.figures import method_styles

    styles = method_styles(res.methods)
    cells = res.shares[res.shares["cell"] != "all"]
    views = list(dict.fromkeys(cells["viewpoint"]))
    levels = list(dict.fromkeys(cells["density_level"]))
    x = np.arange(len(levels))
    fig, axes = plt.subplots(
        1, len(views), figsize=(max(4.2, 2.8 * len(views) + 0.8), 3.4), sharey=True, squeeze=False, layout="constrained"
    )
    k = len(res.methods)
    for c, vp in enumerate(views):
        ax = axes[0, c]
        for m, meth in enumerate(res.methods):
            part = cells[(cells["viewpoint"] == vp) & (cells["method"] == meth)]
            off = (m - (k - 1) / 2) * 0.1
            y = part["share"].to_numpy(float)
            err = np.vstack([y - part["lower_CL"].to_numpy(float), part["upper_CL"].to_numpy(float) - y])
            color, marker = styles[meth]
            ax.errorbar(x + off, y, yerr=err, color=color, marker=marker, ms=4, lw=1.2, capsize=2.5, label=meth)
        ax.axhline(0.5, color="0.5", lw=0.8, ls="--")
        ax.set_ylim(-0.02, 1.02)
        ax.set_xticks(x)
        ax.set_xticklabels([f"{density_values.get(lv, 0):.2f}" for lv in levels], fontsize=7)
        ax.set_title(f"{res.names.viewpoint} {vp}", fontsize=9)
        ax.set_xlabel("density (characters/m$^2$)", fontsize=8)
        ax.grid(axis="y", lw=0.4, alpha=0.5)
    axes[0, 0].set_ylabel("share chosen when shown", fontsize=9)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=k, fontsize=8, frameon=False)
    head = (f"{note}\n" if note else "") + f"{res.label}: choice share per method\n"
    fig.suptitle(
        head + f"{100 * res.level:g}% Clopper-Pearson intervals; dashed: 50%",
        fontsize=9,
        color="#b03a2e" if note else "black",
    )
    files = [_save(fig, d / "2afc_shares.png", dpi)]
    if res.bradley_terry is not None:
        files.append(_bt_figure(res, res.bradley_terry, d / "2afc_bradley_terry.png", styles, note, dpi))
    return files


def _bt_figure(res: ChoiceResult, bt: BradleyTerryResult, out: Path, styles: dict, note: str, dpi: int) -> Path:
    import matplotlib.pyplot as plt

    ab = bt.abilities
    fig, ax = plt.subplots(figsize=(4.6, 1.2 + 0.45 * len(ab)), layout="constrained")
    y = np.arange(len(ab))[::-1]
    for yy, r in zip(y, ab.to_dict("records"), strict=True):
        color, marker = styles[r["method"]]
        ax.errorbar(
            r["ability"],
            yy,
            xerr=[[r["ability"] - r["lower_CL"]], [r["upper_CL"] - r["ability"]]],
            color=color,
            marker=marker,
            ms=5,
            capsize=3,
        )
    ax.axvline(0.0, color="0.5", lw=0.8, ls="--")
    ax.set_ylim(-0.6, len(ab) - 0.4)
    ax.set_yticks(y)
    ax.set_yticklabels(ab["method"])
    ax.set_xlabel("Bradley-Terry ability (logit; reference = 0)", fontsize=8)
    ax.grid(axis="x", lw=0.4, alpha=0.5)
    fig.suptitle(
        (f"{note}\n" if note else "") + f"{res.label}: Bradley-Terry scale, {100 * res.level:g}% CI",
        fontsize=9,
        color="#b03a2e" if note else "black",
    )
    return _save(fig, out, dpi)


def _save(fig, out: Path, dpi: int) -> Path:
    import matplotlib.pyplot as plt

    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi, metadata={"Software": None})
    plt.close(fig)
    return out


def choice_record(res: ChoiceResult) -> dict:
    """The stage's results for analysis.json."""

    def rows(df):
        return [{k: (v if isinstance(v, str) else _num(v)) for k, v in r.items()} for r in df.to_dict("records")]

    bt = res.bradley_terry
    return {
        "n_participants": res.n_participants,
        "n_trials": res.n_trials,
        "statement": res.statement,
        "shares": rows(res.shares),
        "position_bias": {k: _num(v) for k, v in res.position.items()},
        "pairs": rows(res.pair_table()),
        "glmer_fixed_effects": rows(res.fixed_effects()),
        "bradley_terry": None if bt is None else {"abilities": rows(bt.abilities), "loglik": bt.loglik},
    }


def _num(v):
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    v = float(v)
    return None if np.isnan(v) else v

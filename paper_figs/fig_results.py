"""The study's result figures (paper Figs. 8-9 style): composite scores (QCR, QCA, QOR) by
density for Baseline vs Ours, one panel per viewpoint, error bars (SD) and * / ** / *** for
the Method effect at each density, one figure per stage.

By default the responses come from SIMULATED participants (crowdstudy.stats.synthetic),
and every title says so; pass ``--responses responses.csv`` (``crowdstudy export``) to plot
a real study.

    .venv/bin/python paper_figs/fig_results.py [--quick] [--responses FILE] [--participants 30]
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

from figstyle import apply_style, cache_path, figure_args, out_path


def main(argv=None) -> int:
    args = figure_args(
        __doc__.splitlines()[0],
        argv,  # writes one figure per stage; --out is not used
        responses=dict(type=Path, default=None, help="responses.csv from crowdstudy export"),
        participants=dict(type=int, default=30, help="simulated participants (default 30)"),
        seed=dict(type=int, default=2024, help="seed of the simulated participants"),
    )
    apply_style()
    from crowdstudy.design import load_design
    from crowdstudy.provenance import provenance
    from crowdstudy.stats.options import AnalysisOptions
    from crowdstudy.stats.pipeline import analyze
    from crowdstudy.stats.synthetic import simulate_responses

    design = load_design()
    if args.responses is None:
        n = 8 if args.quick else args.participants
        responses = simulate_responses(design, n, seed=args.seed)
        note = f" - SIMULATED participants (n = {n})"
    else:
        n = None
        responses = args.responses
        note = ""
    work = cache_path("results_quick" if args.quick else "results")
    result = analyze(responses, design, work, AnalysisOptions(figures=True, figure_note=note))
    written = []
    for stage in design.stages:
        produced = [f for f in result.files if f.name == "scores_by_density.png" and f"stage{stage.number}" in str(f)]
        if not produced:
            continue
        suffix = "_quick" if args.quick else ""
        target = out_path(f"fig_results_stage{stage.number}_{stage.scenario}{suffix}")
        shutil.copyfile(produced[0], target)
        # sidecar: the plotted numbers (method_figure's .json), the ANOVA behind the stars, provenance
        plotted = json.loads(produced[0].with_suffix(".json").read_text())
        anova = {
            comp: {
                row.Source: {
                    "F": row.F,
                    "ddof1": row.ddof1,
                    "ddof2": row.ddof2,
                    "p_unc": row.p_unc,
                    "p": row.p,
                    "np2": row.np2,
                }
                for row in result.results[(stage.number, comp)].anova.itertuples()
            }
            for comp in design.composites
            if (stage.number, comp) in result.results
        }
        target.with_suffix(".json").write_text(
            json.dumps(
                {
                    **plotted,
                    "figure": target.name,
                    "stage": stage.number,
                    "scenario": stage.scenario,
                    "responses": "simulated" if args.responses is None else str(args.responses),
                    "participants": n,
                    "seed": args.seed if args.responses is None else None,
                    "provenance": provenance(args.seed),
                    "anova": anova,
                },
                indent=1,
                default=float,
            )
        )
        written.append(target)
        print(f"wrote {target}")
    summary = work / "summary.md"
    if summary.is_file():
        print(f"statistics summary: {summary}")
    return 0 if written else 1


if __name__ == "__main__":
    sys.exit(main())

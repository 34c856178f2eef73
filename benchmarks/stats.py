"""Statistics benchmark: the full analysis of a 30-participant x 60-trial study.

    crowdstudy bench stats [--participants 30] [--repeat 5] [--figures]

Rows:
- ``analyze``: the whole pipeline without figures (validation, reliability, composites,
  6 three-way RM ANOVAs with Mauchly/GG, Tukey post hoc tests, descriptives, Shapiro-Wilk,
  APA text) on 30 participants x 60 trials; target < 5 s. ``--figures`` adds a row with
  every table and figure written to a temporary folder.
- ``rm_anova 3-way`` (ours) vs ``statsmodels AnovaRM`` (F tests only, no sphericity) on the
  stage-1 QCR cell means (Density x Viewpoint x Method).
- ``rm_anova 2-way`` (ours) vs ``pingouin.rm_anova`` on Density x Method (viewpoints
  averaged), the largest design pingouin supports; F values are checked to agree.
"""

from __future__ import annotations

import argparse
import tempfile
import warnings

import numpy as np


def main(argv: list[str]) -> int:
    from crowdstudy.bench import measure, write_report
    from crowdstudy.design import load_design
    from crowdstudy.stats.anova import rm_anova
    from crowdstudy.stats.pipeline import analyze
    from crowdstudy.stats.scoring import cell_means, composite_scores
    from crowdstudy.stats.synthetic import simulate_responses
    from crowdstudy.tables import format_table

    parser = argparse.ArgumentParser(prog="crowdstudy bench stats")
    parser.add_argument("--participants", type=int, default=30)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--figures", action="store_true", help="also time the run that writes every figure")
    args = parser.parse_args(argv)

    design = load_design()
    responses = simulate_responses(design, args.participants, seed=args.seed)
    rows = []
    full = measure(lambda: analyze(responses, design, None), repeat=args.repeat, warmup=1)
    rows.append(
        {
            "case": f"analyze ({args.participants} x {len(responses) // args.participants} trials, no figures)",
            "median_s": full["median"],
            "peer": "-",
            "peer_median_s": float("nan"),
            "ratio": float("nan"),
            "target_s": 5.0,
            "ok": full["median"] < 5.0,
        }
    )
    if args.figures:
        with tempfile.TemporaryDirectory() as tmp:
            figs = measure(lambda: analyze(responses, design, tmp), repeat=1, warmup=0)
        rows.append(
            {
                "case": "analyze with tables + figures written",
                "median_s": figs["median"],
                "peer": "-",
                "peer_median_s": float("nan"),
                "ratio": float("nan"),
                "target_s": float("nan"),
                "ok": True,
            }
        )

    long = cell_means(composite_scores(responses, design), "QCR", design, stage=1)
    long3 = long.assign(**{c: long[c].astype(str) for c in ("Density", "Viewpoint", "Method")})
    ours3 = measure(
        lambda: rm_anova(long3, "QCR", ["Density", "Viewpoint", "Method"], "participant_id"), repeat=args.repeat * 4
    )
    import time

    from statsmodels.stats.anova import AnovaRM

    t0 = time.perf_counter()  # several seconds per fit: measured once
    fitted = AnovaRM(long3, "QCR", "participant_id", within=["Density", "Viewpoint", "Method"]).fit()
    peer3 = {"median": time.perf_counter() - t0}
    f_ours = rm_anova(long3, "QCR", ["Density", "Viewpoint", "Method"], "participant_id").set_index("Source")["F"]
    f_peer = fitted.anova_table["F Value"]
    agree3 = bool(np.allclose(f_ours.loc[f_peer.index].to_numpy(), f_peer.to_numpy(), rtol=1e-9))
    rows.append(
        {
            "case": "rm_anova 3-way (+Mauchly, GG, HF, ges)",
            "median_s": ours3["median"],
            "peer": "statsmodels AnovaRM (F only)",
            "peer_median_s": peer3["median"],
            "ratio": peer3["median"] / ours3["median"],
            "target_s": float("nan"),
            "ok": agree3,
        }
    )

    two = long3.groupby(["participant_id", "Density", "Method"], as_index=False)["QCR"].mean()
    ours2 = measure(lambda: rm_anova(two, "QCR", ["Density", "Method"], "participant_id"), repeat=args.repeat * 4)
    import pingouin

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        peer2 = measure(
            lambda: pingouin.rm_anova(two, dv="QCR", within=["Density", "Method"], subject="participant_id"),
            repeat=args.repeat * 4,
        )
        pg = pingouin.rm_anova(two, dv="QCR", within=["Density", "Method"], subject="participant_id")
    f2 = rm_anova(two, "QCR", ["Density", "Method"], "participant_id")["F"].to_numpy()
    agree2 = bool(np.allclose(np.sort(f2), np.sort(pg["F"].to_numpy()), rtol=1e-9))
    rows.append(
        {
            "case": "rm_anova 2-way",
            "median_s": ours2["median"],
            "peer": "pingouin.rm_anova",
            "peer_median_s": peer2["median"],
            "ratio": peer2["median"] / ours2["median"],
            "target_s": float("nan"),
            "ok": agree2,
        }
    )
    print(format_table(rows))
    print("ratio = peer time / ours (> 1: ours faster); ok = under target or F values agree with the peer")
    path = write_report("stats", rows, seed=args.seed, participants=args.participants)
    print(f"wrote {path}")
    return 0 if all(r["ok"] for r in rows) else 1

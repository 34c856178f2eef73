"""``crowdstudy analyze responses.csv --out DIR``: the analysis of exported responses, each
stage by its task (Likert and slider ratings from responses.csv, 2AFC choices from
comparisons.csv beside it or ``--comparisons FILE``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from crowdstudy.errors import InvalidInputError

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("responses", help="responses.csv exported by `crowdstudy export` (or simulated)")
    parser.add_argument("--out", required=True, help="output folder for tables, figures and summary.md")
    parser.add_argument("--design", default=None, help="study design TOML (default: stimuli/study.toml)")
    parser.add_argument(
        "--correction",
        choices=("auto", "always", "never"),
        default="auto",
        help="Greenhouse-Geisser: where Mauchly's p < alpha (auto, the paper's rule), always (afex's default) or never",
    )
    parser.add_argument("--alpha", type=float, default=0.05, help="significance level (default 0.05)")
    parser.add_argument(
        "--adjust",
        choices=("tukey", "bonferroni", "holm"),
        default="tukey",
        help="post hoc p-value adjustment (default tukey)",
    )
    parser.add_argument(
        "--effsize",
        choices=("np2", "ng2"),
        default="np2",
        help="effect size quoted in the APA summary (both are in the tables)",
    )
    parser.add_argument(
        "--missing",
        choices=("raise", "drop"),
        default="raise",
        help="a participant without every condition: error (raise) or listwise deletion (drop)",
    )
    parser.add_argument("--error-bars", choices=("sd", "se", "ci95"), default="sd", help="figure error bars")
    parser.add_argument(
        "--stage", type=int, action="append", default=None, help="analyse only this stage number (repeatable)"
    )
    parser.add_argument("--no-figures", action="store_true", help="skip the figures (tables only)")
    parser.add_argument(
        "--participants",
        default=None,
        help="participants.csv of the study export (participant, excluded 0/1, exclusion_reason); "
        "excluded participants are dropped and counted per reason (default: participants.csv "
        "beside the responses file, when there is one)",
    )
    parser.add_argument(
        "--comparisons",
        default=None,
        help="comparisons.csv of the study export (the 2AFC trials; default: comparisons.csv beside the "
        "responses file, when there is one)",
    )
    parser.add_argument(
        "--stars",
        choices=("always", "omnibus"),
        default="always",
        help="figure stars for Method in every cell (always), or only where the ANOVA's Method "
        "effect or an interaction with Method is significant (omnibus)",
    )


def run(args: argparse.Namespace) -> int:
    from crowdstudy.design import load_design
    from crowdstudy.paths import check_output_dir
    from crowdstudy.stats.options import AnalysisOptions
    from crowdstudy.stats.pipeline import analyze

    path = Path(args.responses)
    if not path.is_file():
        raise InvalidInputError(f"responses file {str(path)!r} does not exist")
    if not 0 < args.alpha < 1:
        raise InvalidInputError(f"--alpha must be in (0, 1), got {args.alpha}")
    if args.comparisons is not None and not Path(args.comparisons).is_file():
        raise InvalidInputError(f"--comparisons file {args.comparisons!r} does not exist")
    design = load_design(args.design)
    check_output_dir(args.out, "--out")
    options = AnalysisOptions(
        correction=args.correction,
        alpha=args.alpha,
        effsize=args.effsize,
        missing=args.missing,
        adjust=args.adjust,
        error_bars=args.error_bars,
        stages=args.stage,
        figures=not args.no_figures,
        stars=args.stars,
    )
    result = analyze(
        path,
        design,
        args.out,
        options,
        progress=True,
        participants=args.participants,
        comparisons=args.comparisons,
    )
    print(result.summary)
    print(f"wrote {len(result.files)} files to {args.out}")
    return 0

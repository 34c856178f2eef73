"""``crowdstudy power -n 20 --method-effect 0.5 --sims 200 --seed 1``: Monte-Carlo power of
the Method effect and the Density x Method interaction for a study of a given size."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from crowdstudy.errors import InvalidInputError

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-n", "--participants", type=int, default=30, help="participants per simulated study")
    parser.add_argument("--method-effect", type=float, default=1.0,
                        help="Ours - Baseline on QCR at the mid density, Likert points (other composites scale it)")
    parser.add_argument("--density-slope", type=float, default=None,
                        help="relative change of the Method effect per character/m^2 below the mid density")
    parser.add_argument("--noise-sd", type=float, default=None, help="item-level noise SD (points)")
    parser.add_argument("--participant-sd", type=float, default=None, help="participant offset SD (points)")
    parser.add_argument("--sims", type=int, default=200, help="simulated studies (default 200)")
    parser.add_argument("--seed", type=int, default=1, help="base seed (default 1)")
    parser.add_argument("--stage", type=int, default=1, help="stage number analysed (default 1)")
    parser.add_argument("--composite", action="append", default=None, help="composite(s) (default all)")
    parser.add_argument("--alpha", type=float, default=0.05)
    parser.add_argument("--correction", choices=("auto", "always", "never"), default="auto")
    parser.add_argument("--design", default=None, help="study design TOML (default: stimuli/study.toml)")
    parser.add_argument("--out", default=None, help="write the result as JSON to this file")


def run(args: argparse.Namespace) -> int:
    from crowdstudy.design import load_design
    from crowdstudy.paths import check_output_path
    from crowdstudy.tables import format_table
    from crowdstudy.provenance import provenance
    from crowdstudy.stats.power import power_analysis
    from crowdstudy.stats.synthetic import ResponseModel

    if args.seed < 0:
        raise InvalidInputError(f"--seed must be >= 0, got {args.seed}")
    if args.out:
        check_output_path(args.out, "--out")
    design = load_design(args.design)
    extra = {k: getattr(args, k) for k in ("density_slope", "noise_sd", "participant_sd")
             if getattr(args, k) is not None}
    model = ResponseModel.for_design(design, method_effect=args.method_effect, **extra)
    correction = {"auto": "auto", "always": True, "never": False}[args.correction]
    result = power_analysis(design, args.participants, model=model, sims=args.sims, seed=args.seed,
                            stage=args.stage, composites=args.composite, alpha=args.alpha, correction=correction,
                            progress=True)
    print(f"power of a {args.participants}-participant study, stage {args.stage}, method effect "
          f"{args.method_effect} points, {args.sims} simulated studies (alpha = {args.alpha})")
    print(format_table(result.table.to_dict("records"),
                       ["composite", "effect", "power", "mc_se", "ci_low", "ci_high", "n_significant", "sims"]))
    if args.out:
        out = Path(args.out)
        out.write_text(json.dumps({"table": result.table.to_dict("records"), "settings": result.settings,
                                   "provenance": provenance(args.seed)}, indent=2, default=str) + "\n")
        print(f"wrote {out}")
    return 0

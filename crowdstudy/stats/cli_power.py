"""``crowdstudy power -n 20 --method-effect 0.5 --sims 200 --seed 1``: Monte-Carlo power of
the Method effect and the Density x Method interaction for a study of a given size.

The design decides the methods and the stage's task: ``--method-effect NAME=POINTS``
(repeatable) gives each method its effect relative to the reference (``--method-effect
POINTS`` alone means Ours, as before); a 2afc stage reports the power of each pair's
logistic mixed model (:mod:`crowdstudy.stats.power`).

The effect can be given in Likert points (``--method-effect``) or standardised (``--dz``,
``--eta-p2``); ``--pilot responses.csv`` fits the whole simulation model to a pilot study
first (explicit options then override the fitted values). The output table has the power
with its exact (Clopper-Pearson) interval and the median eta_p^2 / d_z of the simulated
studies."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from crowdstudy.errors import InvalidInputError

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-n", "--participants", type=int, default=30, help="participants per simulated study")
    size = parser.add_mutually_exclusive_group()
    size.add_argument(
        "--method-effect",
        action="append",
        default=None,
        metavar="[NAME=]POINTS",
        help="a method's effect relative to the reference on QCR at the mid density, Likert points "
        "(other composites scale it); repeatable, NAME=POINTS per method; POINTS alone means Ours "
        "(default Ours 1.0, or the pilot's)",
    )
    size.add_argument(
        "--dz",
        type=float,
        default=None,
        help="the Method effect as a standardised d_z of the participants' Ours - Baseline means",
    )
    size.add_argument(
        "--eta-p2",
        type=float,
        default=None,
        help="the Method effect as a partial eta squared (converted to d_z = sqrt(e / (1 - e)))",
    )
    parser.add_argument(
        "--pilot",
        default=None,
        help="pilot responses.csv: fit the simulation model (effects, noise, participant SDs) to it",
    )
    parser.add_argument(
        "--density-slope",
        type=float,
        default=None,
        help="relative change of the Method effect per character/m^2 below the mid density",
    )
    parser.add_argument("--noise-sd", type=float, default=None, help="item-level noise SD (points)")
    parser.add_argument("--participant-sd", type=float, default=None, help="participant offset SD (points)")
    parser.add_argument(
        "--participant-density-sd",
        type=float,
        default=None,
        help="SD of the participants' own density slopes, points per character/m^2 (default 0.1; "
        "non-zero: sphericity is not true by construction)",
    )
    parser.add_argument(
        "--participant-viewpoint-sd",
        type=float,
        default=None,
        help="SD of the participants' own viewpoint offsets, points (default 0.2)",
    )
    parser.add_argument("--sims", type=int, default=200, help="simulated studies (default 200)")
    parser.add_argument("--seed", type=int, default=1, help="base seed (default 1)")
    parser.add_argument("--stage", type=int, default=1, help="stage number analysed (default 1)")
    parser.add_argument("--composite", action="append", default=None, help="composite(s) (default all)")
    parser.add_argument("--alpha", type=float, default=0.05)
    parser.add_argument("--correction", choices=("auto", "always", "never"), default="auto")
    parser.add_argument("--design", default=None, help="study design TOML (default: stimuli/study.toml)")
    parser.add_argument("--out", default=None, help="write the result as JSON to this file")


def _model(args, design):
    import dataclasses

    from crowdstudy.stats.inputs import read_csv_file
    from crowdstudy.stats.pilot import fit_pilot
    from crowdstudy.stats.power import method_points
    from crowdstudy.stats.synthetic import ResponseModel

    fitted = None
    if args.pilot:
        model, fitted = fit_pilot(read_csv_file(args.pilot, "pilot responses"), design, source=str(args.pilot))
    else:
        model = ResponseModel.for_design(design, participant_density_sd=0.1, participant_viewpoint_sd=0.2)
    extra = {
        k: getattr(args, k)
        for k in ("density_slope", "noise_sd", "participant_sd", "participant_density_sd", "participant_viewpoint_sd")
        if getattr(args, k) is not None
    }
    if args.method_effect is not None:
        effects = _method_effects(args.method_effect, design)
        treated = model.treated_method
        if treated in effects:
            extra["method_effect"] = effects.pop(treated)
        if effects:
            extra["method_effects"] = {**dict(model.method_effects), **effects}
    model = dataclasses.replace(model, **extra)
    if args.dz is not None or args.eta_p2 is not None:
        points = method_points(model, design, args.stage, dz=args.dz, eta_p2=args.eta_p2)
        model = dataclasses.replace(model, method_effect=points)
    return model, fitted


def _method_effects(values: list[str], design) -> dict[str, float]:
    """``--method-effect`` values as {method: points}: ``NAME=POINTS`` or ``POINTS`` (Ours);
    an unknown method, the reference or a non-number is an error naming the option."""
    out: dict[str, float] = {}
    for text in values:
        name, sep, number = text.rpartition("=")
        name = name.strip() if sep else "Ours"
        try:
            points = float(number)
        except ValueError:
            raise InvalidInputError(f"--method-effect {text!r}: expected POINTS or NAME=POINTS, a number") from None
        if name not in design.methods[1:]:
            raise InvalidInputError(
                f"--method-effect {text!r}: {name!r} is not a method of the design other than its reference "
                f"{design.methods[0]!r}; its methods: {', '.join(design.methods)}"
            )
        if name in out:
            raise InvalidInputError(f"--method-effect: {name!r} is given twice")
        out[name] = points
    return out


def _effects_text(model) -> str:
    """The method effects of the run, for its heading line."""
    effects = {model.treated_method: model.method_effect, **dict(getattr(model, "method_effects", {}))}
    return ", ".join(f"{m} {v:.3g}" for m, v in effects.items())


def run(args: argparse.Namespace) -> int:
    from crowdstudy.design import load_design
    from crowdstudy.paths import check_output_path
    from crowdstudy.provenance import provenance
    from crowdstudy.stats.power import power_analysis
    from crowdstudy.tables import format_table

    if args.seed < 0:
        raise InvalidInputError(f"--seed must be >= 0, got {args.seed}")
    design = load_design(args.design)  # a bad design fails before anything is written
    if args.out:
        check_output_path(args.out, "--out")
    model, fitted = _model(args, design)
    if fitted is not None:
        print(f"model fitted to the pilot {args.pilot} ({fitted.attrs['participants']} participants):")
        print(format_table(fitted.to_dict("records"), ["parameter", "value", "estimated_from"]))
    correction = {"auto": "auto", "always": True, "never": False}[args.correction]
    result = power_analysis(
        design,
        args.participants,
        model=model,
        sims=args.sims,
        seed=args.seed,
        stage=args.stage,
        composites=args.composite,
        alpha=args.alpha,
        correction=correction,
        progress=True,
    )
    print(
        f"power of a {args.participants}-participant study, stage {args.stage} ({result.settings['task']}), "
        f"method effects {_effects_text(model)} points, {args.sims} simulated studies (alpha = {args.alpha}; "
        f"ci: exact Clopper-Pearson 95 %)"
    )
    sizes = ["share_b_median"] if result.settings["task"] == "2afc" else ["np2_median", "dz_median"]
    print(
        format_table(
            result.table.to_dict("records"),
            ["composite", "effect", "power", "ci_low", "ci_high", "n_significant", "sims", *sizes],
        )
    )
    if args.out:
        out = Path(args.out)
        out.write_text(
            json.dumps(
                {
                    "table": result.table.to_dict("records"),
                    "settings": result.settings,
                    "pilot": fitted.to_dict("records") if fitted is not None else None,
                    "provenance": provenance(args.seed),
                },
                indent=2,
                default=str,
            )
            + "\n"
        )
        print(f"wrote {out}")
    return 0

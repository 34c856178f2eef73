"""The ``crowdstudy`` command line.

Each subcommand lives in the stage that owns it, in a module named after the command:
``crowdstudy/<stage>/cli_<command>.py`` (dashes as underscores: ``export-gltf`` is
``crowdstudy/gltf/cli_export_gltf.py``), or ``crowdstudy/cli_<command>.py`` for the commands of
no single stage (``bench``, ``precompile``, ``demo``, whose logic lives in ``bench.py``,
``precompile.py`` and ``demo.py``). The module holds the command line only, two functions::

    def configure(parser: argparse.ArgumentParser) -> None   # add the arguments
    def run(args: argparse.Namespace) -> int                 # do the work, return an exit code

Only the chosen subcommand's module is imported, so ``crowdstudy --help`` stays fast.
The project's own errors (:class:`~crowdstudy.errors.CrowdstudyError`: bad input, a
missing system component) are printed as one line naming what is wrong, with exit code 2.
Anything else is a bug or an unexpected failure: it propagates with its traceback (exit
code 1), so a numpy or pandas ``ValueError`` is never mistaken for a user error. Sub-commands
check their output paths (:func:`crowdstudy.paths.check_output_path`,
:func:`crowdstudy.paths.check_output_dir`) before the long work starts. Progress bars are
drawn only where stderr is a terminal; ``crowdstudy --progress COMMAND`` draws them anyway,
``--no-progress`` never (:mod:`crowdstudy.progress`).
"""

from __future__ import annotations

import argparse
import importlib
import sys

from crowdstudy import __version__
from crowdstudy.errors import CrowdstudyError

__all__ = ["main", "COMMANDS"]

#: (name, module, one-line description), in pipeline order.
COMMANDS: tuple[tuple[str, str, str], ...] = (
    (
        "assets",
        "crowdstudy.body.cli_assets",
        "Fetch and convert the MakeHuman body assets (CC0, from PyPI; set-up runs it).",
    ),
    ("precompile", "crowdstudy.cli_precompile", "Compile the Warp kernels once, ahead of first use (set-up runs it)."),
    (
        "layout",
        "crowdstudy.layout.cli_layout",
        "Place characters in a region as a Poisson-disk set (stationary crowds).",
    ),
    (
        "navigate",
        "crowdstudy.navigation.cli_navigate",
        "Walk a crowd with ORCA (corridor scenario) and write its trajectories.",
    ),
    (
        "animate",
        "crowdstudy.motion.cli_animate",
        "Turn layouts or trajectories into the Baseline full-body crowd animation.",
    ),
    ("motion", "crowdstudy.motion.cli_motion", "The motion-capture clip library: list, rebuild from BVH, measure."),
    (
        "correct",
        "crowdstudy.physics.cli_correct",
        "Resolve character collisions with the physics layer (Baseline -> Ours).",
    ),
    (
        "metrics",
        "crowdstudy.metrics.cli_metrics",
        "Measure overlap volume, tracking error and smoothness of an animation.",
    ),
    ("render", "crowdstudy.render.cli_render", "Render an animation to an MP4 video or a PNG frame (headless EGL)."),
    ("sheet", "crowdstudy.render.cli_sheet", "Contact sheets of characters or clips: 8 frames over 2 s, a row each."),
    (
        "export-gltf",
        "crowdstudy.gltf.cli_export_gltf",
        "Export an animation and its bodies to one binary glTF 2.0 (.glb) file.",
    ),
    (
        "export-usd",
        "crowdstudy.gltf.cli_export_usd",
        "Export an animation and its bodies as a UsdSkel crowd (.usda, .usdc).",
    ),
    (
        "import-gltf",
        "crowdstudy.gltf.cli_import_gltf",
        "Import a skinned glTF character (Mixamo, Blender, VRM...) as a body record.",
    ),
    (
        "import-crowd",
        "crowdstudy.interchange.cli_import_crowd",
        "Import a glTF or USD file's skinned, animated characters as a crowd animation (.npz).",
    ),
    (
        "stimuli",
        "crowdstudy.render.cli_stimuli",
        "Build the whole stimulus video set and its manifest from a study design.",
    ),
    ("serve", "crowdstudy.study.cli_serve", "Run the browser questionnaire server for participant sessions."),
    (
        "export",
        "crowdstudy.study.cli_export",
        "Export participant answers and demographics from the study database to CSV.",
    ),
    (
        "participants",
        "crowdstudy.study.cli_participants",
        "List the study's participants, or withdraw one (audit kept).",
    ),
    (
        "simulate-participants",
        "crowdstudy.study.cli_simulate_participants",
        "Simulated participants answering through the server's API.",
    ),
    (
        "analyze",
        "crowdstudy.stats.cli_analyze",
        "Repeated-measures ANOVA, post hoc tests, tables and figures from responses.",
    ),
    ("power", "crowdstudy.stats.cli_power", "Simulate studies to estimate the power to detect the Method effects."),
    (
        "bench",
        "crowdstudy.cli_bench",
        "Run a benchmark from benchmarks/ (navigation, animation, physics, render, stats).",
    ),
    ("demo", "crowdstudy.cli_demo", "Run the whole pipeline on a small configuration (what `make demo` runs)."),
)


def _build_parser(chosen: str | None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="crowdstudy",
        description="Perception research on dense 3D crowds: stimuli, participant sessions, statistics.",
    )
    parser.add_argument("--version", action="version", version=f"crowdstudy {__version__}")
    bars = parser.add_mutually_exclusive_group()
    bars.add_argument(
        "--progress",
        dest="progress",
        action="store_const",
        const="on",
        default=None,
        help="draw progress bars even when stderr is not a terminal (a log, a pipe)",
    )
    bars.add_argument(
        "--no-progress",
        dest="progress",
        action="store_const",
        const="off",
        help="never draw progress bars (default: only on a terminal)",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")
    for name, module_name, help_text in COMMANDS:
        p = sub.add_parser(name, help=help_text, description=help_text)
        if name == chosen:
            try:
                module = importlib.import_module(module_name)
            except ModuleNotFoundError as exc:
                if exc.name and module_name.startswith(exc.name):
                    parser.exit(2, f"crowdstudy {name}: not available in this installation ({module_name} missing)\n")
                raise
            module.configure(p)
            p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    chosen = next((a for a in argv if not a.startswith("-")), None)
    parser = _build_parser(chosen)
    args = parser.parse_args(argv)
    if getattr(args, "_run", None) is None:
        parser.print_help()
        return 0 if not argv else 2
    if args.progress is not None:  # the environment carries it to the processes the command starts
        from crowdstudy.progress import set_progress_mode

        set_progress_mode(args.progress)
    try:
        return int(args._run(args) or 0)
    except CrowdstudyError as exc:
        print(f"crowdstudy {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"crowdstudy {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

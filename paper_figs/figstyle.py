"""Shared matplotlib style and folders for the paper's figure scripts.

Every ``paper_figs/fig*.py`` script:

* is runnable alone (``.venv/bin/python paper_figs/fig4_damping.py [--quick]``) and through
  ``make figures`` (``paper_figs/make_all.py``);
* caches derived data in ``paper_figs/cache/`` and writes figures to ``paper_figs/out/``
  (both git-ignored), with a JSON sidecar holding the provenance of the run;
* accepts ``--quick`` (small, fast configuration used by the test suite).
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")

HERE = Path(__file__).resolve().parent
OUT_DIR = HERE / "out"
CACHE_DIR = HERE / "cache"

#: Colours used for the two methods in every figure.
METHOD_COLOURS = {"Baseline": "#d1495b", "Ours": "#00798c"}
#: Sequential colours for density levels D1..D5.
DENSITY_COLOURS = ["#c6dbef", "#9ecae1", "#6baed6", "#3182bd", "#08519c"]

__all__ = [
    "apply_style",
    "figure_args",
    "out_path",
    "cache_path",
    "save_figure",
    "METHOD_COLOURS",
    "DENSITY_COLOURS",
    "OUT_DIR",
    "CACHE_DIR",
]


def apply_style() -> None:
    """Apply the shared look: sans-serif, light grid, no top/right spines, 150 dpi."""
    import matplotlib as mpl

    mpl.rcParams.update(
        {
            "figure.dpi": 110,
            "savefig.dpi": 150,
            "savefig.bbox": "tight",
            "font.family": "DejaVu Sans",
            "font.size": 9,
            "axes.titlesize": 10,
            "axes.labelsize": 9,
            "axes.spines.top": False,
            "axes.spines.right": False,
            "axes.grid": True,
            "grid.color": "#e5e5e5",
            "grid.linewidth": 0.6,
            "legend.frameon": False,
            "lines.linewidth": 1.6,
        }
    )


def figure_args(description: str, argv=None, **extra) -> argparse.Namespace:
    """Parse the common arguments: ``--quick``, ``--out`` (figure path) and ``--refresh``."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--quick", action="store_true", help="small, fast configuration (used by the tests)")
    parser.add_argument("--out", type=Path, default=None, help="where to write the figure (PNG)")
    parser.add_argument("--refresh", action="store_true", help="recompute cached data")
    for flag, kwargs in extra.items():
        parser.add_argument(f"--{flag.replace('_', '-')}", **kwargs)
    return parser.parse_args(argv)


def out_path(name: str, args: argparse.Namespace | None = None) -> Path:
    if args is not None and getattr(args, "out", None):
        path = Path(args.out)
    else:
        suffix = "_quick" if args is not None and getattr(args, "quick", False) else ""
        path = OUT_DIR / f"{name}{suffix}.png"
    path.parent.mkdir(parents=True, exist_ok=True)
    return path


def cache_path(name: str) -> Path:
    CACHE_DIR.mkdir(parents=True, exist_ok=True)
    return CACHE_DIR / name


def save_figure(fig, path: Path, *, seed=None, **info) -> Path:
    """Save ``fig`` to ``path`` and a ``.json`` sidecar with provenance and ``info``."""
    from crowdstudy.provenance import provenance

    path = Path(path)
    fig.savefig(path)
    sidecar = path.with_suffix(".json")
    sidecar.write_text(json.dumps({"figure": path.name, "provenance": provenance(seed), **info}, indent=2, default=str))
    print(f"wrote {path}")
    return path

"""Shared pytest set-up: Warp's kernel cache inside build/, headless matplotlib."""

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / "build" / "warp-cache"))
os.environ.setdefault("MPLBACKEND", "Agg")

import pytest  # noqa: E402

SHARED = ROOT.parent / "shared"

#: the slowest test files, slowest first (measured on the 2-core machine), run first: with `-n auto --dist
#: loadfile --no-loadscope-reorder` (the Makefile's) the end-to-end demo starts at once on one
#: worker and the rest of the suite fills the other around it (xdist's default order, most
#: tests first, started the demo last and left one worker idle at the end)
SLOWEST_FIRST = (
    "test_demo.py",
    "test_followup_study.py",
    "test_paper_figs.py",
    "test_study_browser_quality.py",
    "test_study_browser.py",
    "test_study_load.py",
    "test_stimuli.py",
    "test_physics_meta.py",
    "test_live.py",
    "test_physics_solver.py",
)


def pytest_collection_modifyitems(session, config, items):
    rank = {name: i for i, name in enumerate(SLOWEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: the rest keep their order


@pytest.fixture
def shared_dir() -> Path:
    """The folder beside the checkout whose ``data/`` holds the raw data (``../shared/data``: the
    CMU takes); tests that need it skip when it is absent."""
    if not SHARED.is_dir():
        pytest.skip("../shared is not present beside the checkout")
    return SHARED


@pytest.fixture
def saved_figures(monkeypatch):
    """Every matplotlib Figure saved during the test (``Figure.savefig`` still writes the
    file): tests read the plotted data back from the artists instead of the file size."""
    from matplotlib.figure import Figure

    figures = []
    original = Figure.savefig

    def savefig(self, *args, **kwargs):
        figures.append(self)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", savefig)
    return figures

"""Shared pytest set-up: Warp's kernel cache inside build/, headless matplotlib."""

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / "build" / "warp-cache"))
os.environ.setdefault("MPLBACKEND", "Agg")

import pytest  # noqa: E402

SHARED = ROOT.parent / "shared"


@pytest.fixture
def shared_dir() -> Path:
    """``../shared`` beside the checkout; tests that need it skip when it is absent."""
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


@pytest.fixture(scope="module")
def bench():
    """``benchmarks/physics.py`` (``crowdstudy bench physics``) loaded as a module (the benchmarks
    are not a package)."""
    import importlib.util

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "physics.py"
    spec = importlib.util.spec_from_file_location("crowdstudy_benchmarks_physics_test", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module

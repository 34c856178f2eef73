"""Every figure script of paper_figs/ runs alone on its quick preset and writes its PNG."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
FIGS = ROOT / "paper_figs"
EXPECTED = ["fig2_capsules", "fig3_overlap", "fig4_damping", "fig5_frames", "fig7_questionnaire", "fig_results",
            "fig_runtime"]


def test_every_paper_figure_has_a_script():
    present = {p.stem for p in FIGS.glob("fig*.py")}
    assert set(EXPECTED) <= present, f"missing figure scripts: {sorted(set(EXPECTED) - present)}"


@pytest.mark.slow
@pytest.mark.parametrize("name", EXPECTED)
def test_figure_script_quick(name):
    before = {p: p.stat().st_mtime for p in (FIGS / "out").glob("*.png")} if (FIGS / "out").is_dir() else {}
    proc = subprocess.run([sys.executable, str(FIGS / f"{name}.py"), "--quick"], cwd=FIGS, capture_output=True,
                          text=True, timeout=400)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    fresh = [p for p in (FIGS / "out").glob(f"{name}*.png") if before.get(p) != p.stat().st_mtime]
    assert fresh, f"{name} wrote no new PNG in paper_figs/out"
    assert all(p.stat().st_size > 5000 for p in fresh)

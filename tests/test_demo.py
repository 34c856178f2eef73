"""`crowdstudy demo` (what `make demo` runs) end to end on a reduced design."""

import subprocess
import sys

import pytest

from crowdstudy.study.local_server import write_small_design


@pytest.mark.slow
def test_demo_runs_end_to_end_on_a_small_design(tmp_path):
    design = write_small_design(tmp_path / "small.toml", levels=("D1", "D5"))
    out = tmp_path / "demo"
    proc = subprocess.run([sys.executable, "-m", "crowdstudy", "demo", "--out", str(out), "--design", str(design),
                           "--duration", "1", "--participants", "4"], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    for name in ("layouts_and_trajectories.png", "overlap_frame.png", "bodies_capsules.png", "metrics.json",
                 "responses.csv", "demographics.csv", "analysis/summary.md", "stimuli/manifest.csv"):
        assert (out / name).is_file(), name
    assert len(list((out / "videos").glob("*.mp4"))) == 4
    # the overlap table shows the correction at work, and the last lines say how to run the full study
    assert "Baseline" in proc.stdout and "Ours" in proc.stdout
    assert "crowdstudy stimuli" in proc.stdout and "crowdstudy serve" in proc.stdout
    import pandas as pd

    responses = pd.read_csv(out / "responses.csv")
    assert responses["participant_id"].nunique() == 4
    assert len(responses) == 4 * 8          # 2 densities x 1 viewpoint x 2 methods x 2 stages


def test_demo_rejects_bad_arguments(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "crowdstudy", "demo", "--out", str(tmp_path), "--density", "D9"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "--density" in proc.stderr

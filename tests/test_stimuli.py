"""Stimulus-set builder: manifest, resume by hash, local processes and a Dask cluster.

The cell animations are pre-seeded with mannequin crowds (tests/render_fixtures.py) so the
test exercises the builder and the renderer, not motion synthesis and physics.
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from render_fixtures import crowd_animation, grid_positions, mannequin_loader  # noqa: E402

from crowdstudy.design import default_design_path, load_design  # noqa: E402
from crowdstudy.errors import InvalidInputError  # noqa: E402
from crowdstudy.render.stimuli import MANIFEST_COLUMNS, build_stimuli  # noqa: E402


@pytest.fixture(scope="module")
def tiny_design(tmp_path_factory):
    text = default_design_path().read_text()
    start, end = text.index("[densities]"), text.index("[viewpoints.V1]")
    text = text[:start] + "[densities]\nD1 = 0.45\n\n" + text[end:]
    text = text.replace('viewpoints = ["V1", "V2", "V3", "V4"]', 'viewpoints = ["V1", "V4"]')
    text = text.replace('viewpoints = ["V3", "V4"]', 'viewpoints = ["V4"]')
    text = text.replace("fps = 30", "fps = 5")
    path = tmp_path_factory.mktemp("design") / "tiny.toml"
    path.write_text(text)
    return load_design(path)


def _seed_animations(design, out: Path) -> None:
    folder = out / "animations"
    folder.mkdir(parents=True, exist_ok=True)
    n_frames = int(round(2.0 * design.fps))  # the quick preset: 2 s
    for st in design.stages:
        seed = design.cell_seed(st, "D1")
        n = design.n_characters("D1")
        extent = (3.0, 3.0) if st.scenario == "concert" else (4.5, 2.0)
        pos = grid_positions(n, extent=extent, margin=0.5)
        kw = {"scenario": st.scenario, "seed": seed, "n_frames": n_frames, "fps": design.fps}
        if st.scenario == "corridor":
            kw.update(period=4.5, velocity=(1.2, 0.0))
        overlapping = pos.copy()
        overlapping[1] = overlapping[0] + [0.1, 0.05]
        for method, p, vol in (("Baseline", overlapping, 0.004), ("Ours", pos, 0.0002)):
            crowd_animation(p, **kw).save(folder / f"S{st.number}-D1-{method}.npz")
            (folder / f"S{st.number}-D1-{method}.metrics.json").write_text(
                json.dumps({"overlap_mesh": vol, "overlap_capsule": 2 * vol}))


def test_build_manifest_and_resume(tiny_design, tmp_path):
    out = tmp_path / "set"
    _seed_animations(tiny_design, out)
    manifest = build_stimuli(tiny_design, out, preset="quick", workers=0, progress=False,
                             body_loader=mannequin_loader)
    rows = manifest["stimuli"]
    assert [r["stimulus_id"] for r in rows] == [s.stimulus_id for s in tiny_design.stimuli()]
    assert len(rows) == 6 and manifest["preset"] == "quick" and "git_sha" in manifest["provenance"]
    for r in rows:
        assert set(MANIFEST_COLUMNS) <= set(r)
        assert (out / r["file"]).is_file() and len(r["sha256"]) == 64
        assert (r["width"], r["height"], r["duration"], r["fps"]) == (320, 180, 2.0, 5.0)
        assert r["characters"] == 4 and r["seed"] == tiny_design.cell_seed(tiny_design.stage(str(r["stage"])), "D1")
    by_id = {r["stimulus_id"]: r for r in rows}
    assert by_id["S1-D1-V1-Baseline"]["red_pixel_fraction"] > by_id["S1-D1-V1-Ours"]["red_pixel_fraction"]
    assert by_id["S1-D1-V1-Ours"]["overlap_mesh"] == pytest.approx(0.0002)
    with open(out / "manifest.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert list(table[0]) == list(MANIFEST_COLUMNS) and len(table) == 6
    # resume: nothing to do ...
    stamps = {r["file"]: (out / r["file"]).stat().st_mtime_ns for r in rows}
    again = build_stimuli(tiny_design, out, preset="quick", workers=0, progress=False, body_loader=mannequin_loader)
    assert again["stimuli"] == rows
    assert all((out / f).stat().st_mtime_ns == t for f, t in stamps.items())
    # ... and a corrupted video is rendered again (in a spawned worker process), the others kept
    victim = out / by_id["S2-D1-V4-Ours"]["file"]
    victim.write_bytes(b"broken")
    third = build_stimuli(tiny_design, out, preset="quick", workers=1, progress=False, body_loader=mannequin_loader)
    assert {r["stimulus_id"]: r["sha256"] for r in third["stimuli"]} == {r["stimulus_id"]: r["sha256"] for r in rows}
    changed = [f for f, t in stamps.items() if (out / f).stat().st_mtime_ns != t]
    assert changed == [by_id["S2-D1-V4-Ours"]["file"]]


@pytest.mark.slow
def test_dask_cluster_gives_the_same_videos(tiny_design, tmp_path):
    distributed = pytest.importorskip("distributed")
    local, remote = tmp_path / "local", tmp_path / "dask"
    for d in (local, remote):
        _seed_animations(tiny_design, d)
    ref = build_stimuli(tiny_design, local, preset="quick", workers=0, progress=False, body_loader=mannequin_loader)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        got = build_stimuli(tiny_design, remote, preset="quick", scheduler=cluster.scheduler_address,
                            progress=False, body_loader=mannequin_loader)
    assert [r["sha256"] for r in got["stimuli"]] == [r["sha256"] for r in ref["stimuli"]]
    assert all((remote / r["file"]).is_file() for r in got["stimuli"])


def test_bad_stimuli_inputs(tiny_design, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(InvalidInputError, match="output folder"):
        build_stimuli(tiny_design, blocker / "set", preset="quick", workers=0, progress=False)
    with pytest.raises(InvalidInputError, match="preset"):
        build_stimuli(tiny_design, tmp_path / "a", preset="huge", workers=0, progress=False)
    with pytest.raises(InvalidInputError, match="workers"):
        build_stimuli(tiny_design, tmp_path / "b", preset="quick", workers=-1, progress=False)
    with pytest.raises(InvalidInputError, match="does not exist"):
        build_stimuli(tmp_path / "nope.toml", tmp_path / "c", preset="quick", workers=0, progress=False)

"""Stimulus-set builder: manifest, resume by digest and hash, local processes and a Dask cluster.

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
from crowdstudy.render import stimuli as stimuli_module  # noqa: E402
from crowdstudy.render.stimuli import (  # noqa: E402
    MANIFEST_COLUMNS,
    animation_record,
    build_stimuli,
    preset_settings,
)
from crowdstudy.render.stimuli_digests import animation_digest, video_digest  # noqa: E402


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


def _mannequin_cell(design, st, method: str, shift: float = 0.0):
    """A mannequin crowd standing in for the (stage, D1) cell's animation of ``method``, and
    its overlap volume: the Baseline has two overlapping characters, Ours none."""
    n_frames = int(round(2.0 * design.fps))  # the quick preset: 2 s
    extent = (3.0, 3.0) if st.scenario == "concert" else (4.5, 2.0)
    pos = grid_positions(design.n_characters("D1"), extent=extent, margin=0.5)
    kw = {"scenario": st.scenario, "seed": design.cell_seed(st, "D1"), "n_frames": n_frames, "fps": design.fps}
    if st.scenario == "corridor":
        kw.update(period=4.5, velocity=(1.2, 0.0))
    if method == "Baseline":
        pos = pos.copy()
        pos[1] = pos[0] + [0.1, 0.05]
        return crowd_animation(pos, **kw), 0.004
    return crowd_animation(pos + [shift, 0.0], **kw), 0.0002


def _stimulus_of(design, st, method):
    return next(s for s in design.stimuli() if s.stage == st.number and s.method == method)


def _seed_animations(design, out: Path, physics=None) -> None:
    """Pre-seed the cell animations as the animation stage would have written them (with the
    digest a resumed build checks), so the tests skip motion synthesis and physics."""
    folder = out / "animations"
    folder.mkdir(parents=True, exist_ok=True)
    settings = preset_settings(design, "quick")
    for st in design.stages:
        for method in ("Baseline", "Ours"):
            anim, vol = _mannequin_cell(design, st, method)
            path = anim.save(folder / f"S{st.number}-D1-{method}.npz")
            digest = animation_digest(design, _stimulus_of(design, st, method), settings, physics=physics)
            record = animation_record(path, digest, {"overlap_mesh": vol, "overlap_capsule": 2 * vol})
            (folder / f"S{st.number}-D1-{method}.metrics.json").write_text(json.dumps(record))


def test_build_manifest_and_resume(tiny_design, tmp_path):
    out = tmp_path / "set"
    _seed_animations(tiny_design, out)
    manifest = build_stimuli(tiny_design, out, preset="quick", workers=0, progress=False, body_loader=mannequin_loader)
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


def test_resume_remakes_exactly_what_a_change_affects(tiny_design, tmp_path, monkeypatch):
    """A changed physics configuration re-makes the Ours animations and videos only; a
    changed viewpoint only its videos; a changed render setting every video, no animation."""
    import dataclasses

    from crowdstudy.physics.config import PhysicsConfig

    out = tmp_path / "set"
    _seed_animations(tiny_design, out)
    kw = {"preset": "quick", "workers": 0, "progress": False, "body_loader": mannequin_loader}
    first = {r["stimulus_id"]: r for r in build_stimuli(tiny_design, out, **kw)["stimuli"]}
    assert all(len(r["digest"]) == 64 for r in first.values())
    assert len({r["digest"] for r in first.values()}) == len(first)

    def stamps():
        return {sid: (out / r["file"]).stat().st_mtime_ns for sid, r in first.items()}

    jobs = []

    def fake_animation_job(job):  # the animation stage without motion synthesis and physics
        jobs.append((job["cell"], list(job["methods"])))
        st = tiny_design.stage(job["stage"])
        res = {"files": {}, "metrics": {}, "timings": {}}
        for method in job["methods"]:
            anim, vol = _mannequin_cell(tiny_design, st, method, shift=0.3)
            res["files"][f"{job['cell']}-{method}.npz"] = str(
                anim.save(Path(job["out_dir"]) / f"{job['cell']}-{method}.npz")
            )
            res["metrics"][method] = {"overlap_mesh": vol, "overlap_capsule": 2 * vol}
        return res

    monkeypatch.setattr(stimuli_module, "animation_job", fake_animation_job)
    before = stamps()
    physics = PhysicsConfig().with_values(damping=0.007)
    second = {r["stimulus_id"]: r for r in build_stimuli(tiny_design, out, physics=physics, **kw)["stimuli"]}
    assert sorted(jobs) == [("S1-D1", ["Ours"]), ("S2-D1", ["Ours"])]
    remade = {sid for sid, t in stamps().items() if t != before[sid]}
    assert remade == {sid for sid in first if sid.endswith("-Ours")}
    for sid, r in second.items():
        assert (r["digest"] != first[sid]["digest"]) == sid.endswith("-Ours")
        assert (r["sha256"] != first[sid]["sha256"]) == sid.endswith("-Ours")  # the shifted Ours crowd

    # the same settings again: nothing to do
    jobs.clear()
    before = stamps()
    third = build_stimuli(tiny_design, out, physics=physics, **kw)["stimuli"]
    assert jobs == [] and stamps() == before and {r["stimulus_id"]: r for r in third} == second

    # one viewpoint moved: its videos only, no animation
    moved = dataclasses.replace(
        tiny_design,
        viewpoints={**tiny_design.viewpoints, "V1": dataclasses.replace(tiny_design.viewpoints["V1"], elevation=20.0)},
    )
    build_stimuli(moved, out, physics=physics, **kw)
    assert jobs == []
    remade = {sid for sid, t in stamps().items() if t != before[sid]}
    assert remade == {"S1-D1-V1-Baseline", "S1-D1-V1-Ours"}

    # a render setting (encoder quality): every video, no animation
    before = stamps()
    monkeypatch.setitem(stimuli_module.PRESETS, "quick", {**stimuli_module.PRESETS["quick"], "crf": 30})
    build_stimuli(moved, out, physics=physics, **kw)
    assert jobs == [] and all(t != before[sid] for sid, t in stamps().items())


@pytest.mark.slow
def test_dask_cluster_gives_the_same_videos(tiny_design, tmp_path):
    distributed = pytest.importorskip("distributed")
    local, remote = tmp_path / "local", tmp_path / "dask"
    for d in (local, remote):
        _seed_animations(tiny_design, d)
    ref = build_stimuli(tiny_design, local, preset="quick", workers=0, progress=False, body_loader=mannequin_loader)
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        got = build_stimuli(
            tiny_design,
            remote,
            preset="quick",
            scheduler=cluster.scheduler_address,
            progress=False,
            body_loader=mannequin_loader,
        )
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
    for bad in (0.0, -1.0, tiny_design.duration + 1.0, "2"):
        with pytest.raises(InvalidInputError, match="duration"):
            build_stimuli(tiny_design, tmp_path / "d", preset="quick", duration=bad, workers=0, progress=False)


def test_a_shorter_pilot_set_is_its_own_set(tiny_design):
    quick = preset_settings(tiny_design, "quick")
    short = preset_settings(tiny_design, "quick", duration=1.0)
    assert quick["duration"] == 2.0 and short["duration"] == 1.0
    assert {k: v for k, v in short.items() if k != "duration"} == {k: v for k, v in quick.items() if k != "duration"}
    assert preset_settings(tiny_design, "full", duration=3.0)["duration"] == 3.0
    # a resumed build sees every animation and video of the other length as stale
    stim = tiny_design.stimuli()[0]
    assert animation_digest(tiny_design, stim, short) != animation_digest(tiny_design, stim, quick)
    assert video_digest(tiny_design, stim, short, body_loader=mannequin_loader) != video_digest(
        tiny_design, stim, quick, body_loader=mannequin_loader
    )

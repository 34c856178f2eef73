"""A study of one's own: a design's methods made as recipes (crowdstudy.recipes), the stimulus
set following the design's methods, stages and tasks (issue #41), the shipped example
follow-up study and a design with names of its own (tests/data/other_study.toml)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from render_fixtures import crowd_animation, grid_positions  # noqa: E402

from crowdstudy.cli import main  # noqa: E402
from crowdstudy.design import Method, load_design  # noqa: E402
from crowdstudy.errors import InvalidInputError, MissingDependencyError  # noqa: E402
from crowdstudy.recipes import check_method_inputs, make_method_animation  # noqa: E402
from crowdstudy.render.stimuli import build_stimuli, preset_settings  # noqa: E402
from crowdstudy.render.stimuli_digests import animation_digest, digest_inputs, video_digest  # noqa: E402
from crowdstudy.scene import CrowdAnimation  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "stimuli" / "examples" / "followup" / "study.toml"
OTHER = Path(__file__).resolve().parent / "data" / "other_study.toml"


def _crowd(n: int = 4, n_frames: int = 6, shift: float = 0.0) -> CrowdAnimation:
    return crowd_animation(grid_positions(n, extent=(2.0, 2.0)) + shift, n_frames=n_frames, fps=24.0)


# -- the recipes, one by one ------------------------------------------------------------------


def test_none_relabels_the_baseline_and_records_its_recipe(tmp_path):
    base = _crowd()
    raw = make_method_animation(Method("Raw", "none"), base, cell="S1-sparse")
    assert raw.meta["method"] == "Raw" and raw.meta["recipe"] == {"correction": "none"}
    assert np.array_equal(raw.root_translation, base.root_translation)
    assert np.array_equal(raw.joint_rotations, base.joint_rotations)
    assert CrowdAnimation.load(raw.save(tmp_path / "raw.npz")).meta["recipe"] == {"correction": "none"}


def test_files_reads_the_users_animation_of_the_cell(tmp_path):
    base = _crowd()
    (tmp_path / "mine").mkdir()
    _crowd(shift=0.2).replace(meta={"method": "whatever"}).save(tmp_path / "mine" / "S1-sparse.npz")
    method = Method("Mine", "files", path="mine")
    anim = make_method_animation(method, base, cell="S1-sparse", design_dir=tmp_path)
    assert anim.meta["method"] == "Mine" and anim.meta["recipe"] == {"correction": "files", "path": "mine"}
    assert np.allclose(anim.root_translation[..., :2], base.root_translation[..., :2] + 0.2)
    assert anim.meta["scenario"] == "concert"  # the scene comes from the Baseline where the file lacks it
    # another crowd: the error names the file and what differs
    _crowd(n_frames=9).save(tmp_path / "mine" / "S1-packed.npz")
    with pytest.raises(InvalidInputError, match=r"S1-packed\.npz: method 'Mine'.*frames \(9, the Baseline's 6\)"):
        make_method_animation(method, base, cell="S1-packed", design_dir=tmp_path)
    _crowd(n=5).save(tmp_path / "mine" / "S2-sparse.npz")
    with pytest.raises(InvalidInputError, match=r"S2-sparse\.npz.*characters \(5 body records, the Baseline's 4\)"):
        make_method_animation(method, base, cell="S2-sparse", design_dir=tmp_path)
    with pytest.raises(InvalidInputError, match=r"no animation for the cell S3-sparse"):
        make_method_animation(method, base, cell="S3-sparse", design_dir=tmp_path)


def test_mujoco_without_the_package_names_the_method_and_the_extra(monkeypatch):
    from crowdstudy.physics import mujoco_peer

    def missing():
        raise MissingDependencyError("the MuJoCo peer needs the mujoco package")

    monkeypatch.setattr(mujoco_peer, "import_mujoco", missing)
    with pytest.raises(MissingDependencyError, match=r"method 'Peer'.*pip install 'crowdstudy\[peers\]'"):
        make_method_animation(Method("Peer", "mujoco"), _crowd(), cell="S1-D1")


def test_check_method_inputs_before_the_work(tmp_path, capsys):
    text = OTHER.read_text().replace(
        '[methods.Firm]\ncorrection = "physics"\nconfig = { damping = 0.06 }',
        '[methods.Firm]\ncorrection = "files"\npath = "firm"',
    )
    (tmp_path / "firm").mkdir()
    design_path = tmp_path / "study.toml"
    design_path.write_text(text)
    design = load_design(design_path)
    with pytest.raises(InvalidInputError, match=r"methods\.Firm\.path.*no animation S1-sparse\.npz for the cell"):
        check_method_inputs(design, ["Firm"], ["S1-sparse"])
    _crowd(n=5).save(tmp_path / "firm" / "S1-sparse.npz")
    with pytest.raises(InvalidInputError, match=r"S1-sparse\.npz: method 'Firm': 5 characters, but the cell S1-sparse"):
        check_method_inputs(design, ["Firm"], ["S1-sparse"])
    # stimuli: the check runs before anything is written, through the API and the command line
    with pytest.raises(InvalidInputError, match="methods.Firm.path"):
        build_stimuli(design, tmp_path / "set", preset="quick", workers=0, progress=False)
    assert not (tmp_path / "set").exists()
    assert main(["stimuli", "--design", str(design_path), "--out", str(tmp_path / "set"), "--preset", "quick"]) == 2
    assert not (tmp_path / "set").exists()


def test_a_change_of_one_method_changes_only_its_digests():
    import dataclasses

    design = load_design(OTHER)
    firmer = dataclasses.replace(
        design,
        method_recipes={**design.method_recipes, "Firm": Method("Firm", "physics", {"damping": 0.05})},
    )
    settings = preset_settings(design, "quick")
    for s in design.stimuli():
        same = animation_digest(design, s, settings) == animation_digest(firmer, s, settings)
        assert same == (s.method != "Firm"), s.stimulus_id
        same = video_digest(design, s, settings) == video_digest(firmer, s, settings)
        assert same == (s.method != "Firm"), s.stimulus_id
    s = next(s for s in design.stimuli() if s.method == "Firm")
    assert digest_inputs(design, s, settings)["recipe"] == {"correction": "physics", "config": {"damping": 0.06}}
    assert digest_inputs(design, s, settings)["physics"]["control"]["damping"] == 0.06


def test_method_option_names_a_method_of_the_design(tmp_path):
    with pytest.raises(InvalidInputError, match=r"--method: the design .* has no method 'Ours'; its methods are Raw"):
        build_stimuli(load_design(OTHER), tmp_path / "x", preset="quick", methods=["Ours"], progress=False)
    assert not (tmp_path / "x").exists()


def test_layout_navigate_and_animate_follow_named_scenarios(tmp_path, capsys):
    """The design's scenario ``gig`` is a concert under another name: layout and animate
    use it; navigate says the design has no corridor stage, and writes nothing."""
    assert main(["layout", "--design", str(OTHER), "--density", "packed", "--out", str(tmp_path / "l.npz")]) == 0
    args = ["--design", str(OTHER), "--stage", "choice", "--density", "sparse", "--duration", "0.5"]
    assert main(["animate", *args, "--out", str(tmp_path / "a.npz")]) == 0
    meta = CrowdAnimation.load(tmp_path / "a.npz").meta
    assert meta["scenario"] == "concert" and meta["scenario_name"] == "gig" and meta["stage"] == "choice"
    capsys.readouterr()
    assert (
        main(["navigate", "--design", str(OTHER), "--density", "sparse", "--out", str(tmp_path / "n" / "n.npz")]) == 2
    )
    err = capsys.readouterr().err
    assert "no stage of the design is a corridor" in err and str(OTHER) in err
    assert not (tmp_path / "n").exists()


# -- whole stimulus sets on the quick preset --------------------------------------------------


def _meta(folder: Path, name: str) -> dict:
    return CrowdAnimation.load(folder / "animations" / f"{name}.npz").meta


@pytest.mark.slow
@pytest.mark.timeout(1800)  # real motion, physics and rendering: minutes on a busy 2-core machine
def test_a_design_with_names_of_its_own_builds_and_resumes_per_method(tmp_path):
    """Raw / Soft / Firm, densities sparse and packed, one viewpoint, a slider and a 2AFC
    stage: the manifest lists the design's methods, stages and tasks; each animation says its
    method and recipe; a change of Firm's recipe re-makes Firm's animations and videos only."""
    design = load_design(OTHER)
    out = tmp_path / "set"
    kw = {"preset": "quick", "duration": 0.5, "workers": 0, "progress": False}
    manifest = build_stimuli(design, out, **kw)
    assert manifest["methods"] == {
        "Raw": {"correction": "none"},
        "Soft": {"correction": "physics", "config": {}},
        "Firm": {"correction": "physics", "config": {"damping": 0.06}},
    }
    assert manifest["stages"] == [
        {
            "number": 1,
            "key": "rating",
            "scenario": "gig",
            "task": "slider",
            "methods": ["Raw", "Soft", "Firm"],
            "pairs": [],
        },
        {
            "number": 2,
            "key": "choice",
            "scenario": "gig",
            "task": "2afc",
            "methods": ["Raw", "Soft", "Firm"],
            "pairs": [["Raw", "Soft"], ["Raw", "Firm"]],
        },
    ]
    rows = manifest["stimuli"]
    assert [r["stimulus_id"] for r in rows] == [s.stimulus_id for s in design.stimuli()]
    assert all((out / r["file"]).is_file() for r in rows) and len(rows) == 12
    assert {r["method"] for r in rows} == {"Raw", "Soft", "Firm"}
    for cell in ("S1-sparse", "S2-packed"):
        raw, firm = _meta(out, f"{cell}-Raw"), _meta(out, f"{cell}-Firm")
        assert raw["method"] == "Raw" and raw["recipe"] == {"correction": "none"}
        assert raw["scenario"] == "concert" and raw["scenario_name"] == "gig"
        assert firm["method"] == "Firm" and firm["recipe"] == {"correction": "physics", "config": {"damping": 0.06}}
        assert firm["physics"]["config"]["control"]["damping"] == 0.06
        assert _meta(out, f"{cell}-Soft")["physics"]["config"]["control"]["damping"] == 0.006
        assert (out / "animations" / f"{cell}-Firm.timings.json").is_file()
    csv_header = (out / "manifest.csv").read_text().splitlines()[0]
    assert csv_header.startswith("stimulus_id,stage,scenario,density_level")

    # Firm made firmer: its animations and videos only
    firmer = tmp_path / "firmer.toml"
    firmer.write_text(OTHER.read_text().replace("damping = 0.06", "damping = 0.05"))
    stamps = {p.name: p.stat().st_mtime_ns for p in (out / "videos").iterdir()}
    anim_stamps = {p.name: p.stat().st_mtime_ns for p in (out / "animations").glob("*.npz")}
    again = build_stimuli(load_design(firmer), out, **kw)
    remade = {n for n, t in stamps.items() if (out / "videos" / n).stat().st_mtime_ns != t}
    assert remade == {f"{r['stimulus_id']}.mp4" for r in rows if r["method"] == "Firm"}
    remade = {n for n, t in anim_stamps.items() if (out / "animations" / n).stat().st_mtime_ns != t}
    assert remade == {f"S{s}-{lv}-Firm.npz" for s in (1, 2) for lv in ("sparse", "packed")}
    assert again["methods"]["Firm"] == {"correction": "physics", "config": {"damping": 0.05}}
    assert _meta(out, "S1-sparse-Firm")["recipe"]["config"] == {"damping": 0.05}


@pytest.mark.slow
@pytest.mark.timeout(1800)  # real motion, physics and rendering: minutes on a busy 2-core machine
def test_the_example_follow_up_study_builds_on_the_quick_preset(tmp_path, capsys):
    """stimuli/examples/followup: Baseline, Ours and Paper; a Likert and a 2AFC stage; two
    densities; through the command line. ``--method`` builds one method (and the reference
    whose colours every video wears)."""
    out = tmp_path / "followup"
    args = ["stimuli", "--design", str(EXAMPLE), "--out", str(out), "--preset", "quick", "--duration", "0.5"]
    assert main([*args, "--workers", "0", "--quiet", "--method", "Paper"]) == 0
    first = json.loads((out / "manifest.json").read_text())
    assert {r["method"] for r in first["stimuli"]} == {"Paper"}
    assert not list((out / "animations").glob("*-Ours.npz"))
    assert main([*args, "--workers", "0", "--quiet"]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    design = load_design(EXAMPLE)
    assert list(manifest["methods"]) == ["Baseline", "Ours", "Paper"]
    assert manifest["methods"]["Paper"] == {"correction": "paper", "config": {}}
    assert [(s["key"], s["task"]) for s in manifest["stages"]] == [("concert", "likert"), ("corridor", "2afc")]
    assert manifest["stages"][1]["pairs"] == [["Baseline", "Ours"], ["Baseline", "Paper"], ["Ours", "Paper"]]
    assert [r["stimulus_id"] for r in manifest["stimuli"]] == [s.stimulus_id for s in design.stimuli()]
    assert len(manifest["stimuli"]) == 18 and all((out / r["file"]).is_file() for r in manifest["stimuli"])
    by_id = {r["stimulus_id"]: r for r in first["stimuli"]}
    for r in manifest["stimuli"]:  # the Paper videos of the first run were kept
        if r["method"] == "Paper":
            assert r["sha256"] == by_id[r["stimulus_id"]]["sha256"]
    for cell in ("S1-High", "S2-Medium"):
        paper = _meta(out, f"{cell}-Paper")
        assert paper["method"] == "Paper" and paper["recipe"] == {"correction": "paper", "config": {}}
        from crowdstudy.physics.config import PhysicsConfig

        assert paper["physics"]["config"]["contacts"] == PhysicsConfig.paper().as_dict()["contacts"]
        assert _meta(out, f"{cell}-Ours")["recipe"] == {"correction": "physics", "config": {}}
    # the correction removed overlap in the dense cell: Ours below the Baseline
    metrics = {
        m: json.loads((out / "animations" / f"S1-High-{m}.metrics.json").read_text())["overlap_mesh"]
        for m in ("Baseline", "Ours", "Paper")
    }
    assert metrics["Ours"] < metrics["Baseline"] and metrics["Paper"] < metrics["Baseline"], metrics
    _serve_answer_export_analyze(out, design, tmp_path)


def _serve_answer_export_analyze(stimuli: Path, design, tmp_path: Path) -> None:
    """The rest of the chain on the built set: serve it, simulated participants answer through
    the server's participant API, export, analyze. The Likert stage's Method has k - 1 = 2
    degrees of freedom; the effects the participants were given come back out within their
    intervals (the mixed model's contrasts to the reference, each 2AFC pair's logit)."""
    from crowdstudy.stats.options import AnalysisOptions
    from crowdstudy.stats.pipeline import analyze
    from crowdstudy.stats.synthetic import ResponseModel
    from crowdstudy.study.bots import run_simulation
    from crowdstudy.study.export import export_study
    from crowdstudy.study.local_server import LocalServer

    effects = {"Ours": 1.0, "Paper": 0.4}
    db = tmp_path / "study.db"
    with LocalServer(["--stimuli", str(stimuli), "--design", str(EXAMPLE), "--db", f"sqlite:///{db}"]) as srv:
        res = run_simulation(srv.url, 30, admin_token=srv.admin_token, seed=3, method_effects=effects)
    assert res.errors == [] and len(res.participants) == 30
    responses = tmp_path / "export" / "responses.csv"
    summary = export_study(f"sqlite:///{db}", responses, online=EXAMPLE)
    # Likert: 2 densities x 2 viewpoints x 3 methods; 2AFC: 3 pairs x 2 densities x 1 viewpoint
    assert summary["responses"] == 30 * 12 and summary["comparisons"] == 30 * 6
    options = AnalysisOptions(composites=["QCR"], figures=False)
    report = analyze(responses, design, tmp_path / "analysis", options)
    likert = report.results[(1, "QCR")]
    method_row = likert.anova.set_index("Source").loc["Method"]
    assert method_row["ddof1"] == 2
    # Each new database draws its own secret key, so the same draws land on other trials in
    # every run: the checks use 99.9 % intervals (z = 3.29), or a 95 % one would miss one run
    # in twenty. The contrasts' 95 % Wald intervals widen by 3.29 / 1.96.
    # The model scales a method's effect on the ratings by density (stats.synthetic: x(1 +
    # density_slope (reference_density - d)), clipped at 0): the contrast averages that over
    # the design's densities. The 2AFC choices take the effects as given.
    model = ResponseModel()
    scale = np.mean(
        [max(0.0, 1 + model.density_slope * (model.reference_density - d)) for d in design.densities.values()]
    )
    contrasts = likert.robustness.mixed.contrasts.set_index("contrast")
    for name, truth in (("Baseline - Ours", -effects["Ours"] * scale), ("Baseline - Paper", -effects["Paper"] * scale)):
        lo, hi = contrasts.at[name, "lower_CL"], contrasts.at[name, "upper_CL"]
        mid, half = (lo + hi) / 2, (hi - lo) / 2 * 3.29 / 1.96
        assert mid - half < truth < mid + half, (name, truth, contrasts)
    pairs = report.result.choices[2].pairs
    assert len(pairs) == 3
    for pm in pairs:
        truth = model.choice_slope * (effects.get(pm.method_b, 0.0) - effects.get(pm.method_a, 0.0))
        row = pm.fit.fixed.iloc[0]
        assert abs(row["estimate"] - truth) < 3.29 * row["SE"], (pm.pair, row)
    shares = report.result.choices[2].shares.query("cell == 'all'").set_index("method")
    assert (shares["shown"] == 30 * 2 * 2).all()  # each method is in two pairs, two cells
    assert (shares["lower_CL"] < shares["share"]).all() and (shares["share"] < shares["upper_CL"]).all()
    assert shares.at["Ours", "lower_CL"] > 0.5 > shares.at["Baseline", "upper_CL"], shares

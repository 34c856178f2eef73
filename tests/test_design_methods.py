"""Study designs beyond the paper's: methods as recipes, a task per stage, named scenarios."""

from __future__ import annotations

import copy
import tomllib

import pytest

from crowdstudy.design import DEFAULT_METHODS, Method, default_design_path, parse_design
from crowdstudy.errors import InvalidInputError

PAPER = tomllib.loads(default_design_path().read_text())


def _design(edit=None):
    raw = copy.deepcopy(PAPER)
    if edit is not None:
        edit(raw)
    return parse_design(raw, "my.toml")


def _three_methods(raw):
    raw["methods"] = {
        "order": ["Baseline", "Ours", "Stiff"],
        "Stiff": {"correction": "physics", "config": {"damping": 0.06}},
    }


def test_order_alone_keeps_the_papers_meaning():
    design = _design()
    assert design.methods == ("Baseline", "Ours") and design.reference_method == "Baseline"
    assert design.method_recipes == DEFAULT_METHODS
    assert design.method("Ours").recipe() == {"correction": "physics", "config": {}}
    assert design.method("Baseline").physics_config() is None
    assert all(st.task == "likert" and st.methods == ("Baseline", "Ours") for st in design.stages)
    assert len(design.stimuli()) == 60 and design.comparison is None


def test_a_third_method_is_a_recipe_with_its_own_config():
    design = _design(_three_methods)
    assert design.methods == ("Baseline", "Ours", "Stiff")
    stiff = design.method("Stiff")
    assert stiff == Method("Stiff", "physics", {"damping": 0.06})
    assert stiff.physics_config().control.damping == 0.06
    assert stiff.recipe() == {"correction": "physics", "config": {"damping": 0.06}}
    assert len(design.stimuli()) == 90  # 60 videos x 3/2 methods
    assert {s.method for s in design.stimuli()} == {"Baseline", "Ours", "Stiff"}


def test_paper_mujoco_and_files_recipes():
    def edit(raw):
        raw["methods"] = {
            "order": ["Baseline", "Paper", "Peer", "Mine"],
            "Paper": {"correction": "paper", "config": {"control.damping": 0.01}},
            "Peer": {"correction": "mujoco", "setting": "weld0.05"},
            "Mine": {"correction": "files", "path": "my_animations"},
        }

    design = _design(edit)
    paper = design.method("Paper").physics_config()
    assert paper.control.damping == 0.01 and not paper.output.speed_limit  # PhysicsConfig.paper() underneath
    assert design.method("Peer").recipe() == {"correction": "mujoco", "setting": "weld0.05"}
    assert design.method("Mine").recipe() == {"correction": "files", "path": "my_animations"}


@pytest.mark.parametrize(
    "methods, needle",
    [
        ({"order": ["Baseline", "Ours", "Stiff"]}, "names 'Stiff', which has no [methods.Stiff] table"),
        ({"order": ["Baseline", "Ours"], "Stiff": {"correction": "physics"}}, "'methods.Stiff' is a method that"),
        ({"order": ["Baseline", "X"], "X": {"correction": "magic"}}, "'methods.X.correction' must be one of"),
        (
            {"order": ["Baseline", "X"], "X": {"correction": "physics", "config": {"dampng": 0.06}}},
            "methods.X.config: unknown PhysicsConfig field 'dampng' (did you mean damping?)",
        ),
        (
            {"order": ["Baseline", "X"], "X": {"correction": "physics", "config": {"damping": -1}}},
            "methods.X.config: PhysicsConfig.control.damping: expected a finite value >= 0",
        ),
        (
            {"order": ["Baseline", "X"], "X": {"correction": "none", "config": {"damping": 1}}},
            "'methods.X.config' does not apply to correction = 'none'",
        ),
        (
            {"order": ["Baseline", "X"], "X": {"correction": "mujoco", "setting": "soft"}},
            "'methods.X.setting' must be one of",
        ),
        ({"order": ["Baseline", "X"], "X": {"correction": "files"}}, "'methods.X.path' is missing"),
        ({"order": ["Baseline", "X"], "X": {"correction": "physics", "colour": 1}}, "unknown key 'methods.X.colour'"),
        ({"order": ["Baseline", "Baseline"]}, "'methods.order' has duplicate entries"),
    ],
)
def test_bad_methods_name_the_file_and_key(methods, needle):
    def edit(raw):
        raw["methods"] = methods

    with pytest.raises(InvalidInputError) as err:
        _design(edit)
    assert str(err.value).startswith("my.toml: ") and needle in str(err.value)


def test_a_2afc_stage_compares_every_pair_by_default():
    def edit(raw):
        _three_methods(raw)
        raw["stages"]["compare"] = {"number": 3, "scenario": "concert", "viewpoints": ["V1"], "task": "2afc"}
        raw["questionnaire"]["comparison"] = {"text": "In which video do the contacts look more natural?"}

    design = _design(edit)
    stage = design.stage("compare")
    assert stage.task == "2afc" and stage.methods == ("Baseline", "Ours", "Stiff")
    assert stage.pairs == (("Baseline", "Ours"), ("Baseline", "Stiff"), ("Ours", "Stiff"))
    assert design.comparison.text.startswith("In which video")
    assert design.tasks() == ("likert", "2afc")
    assert sum(s.stage == 3 for s in design.stimuli()) == 5 * 1 * 3  # densities x viewpoints x methods


def test_a_2afc_stage_with_its_pairs_shows_only_their_methods():
    def edit(raw):
        _three_methods(raw)
        raw["stages"]["compare"] = {
            "number": 3,
            "scenario": "concert",
            "viewpoints": ["V1", "V3"],
            "task": "2afc",
            "pairs": [["Stiff", "Ours"]],
        }
        raw["questionnaire"]["comparison"] = {"text": "Which looks more natural?"}

    stage = _design(edit).stage("compare")
    assert stage.pairs == (("Stiff", "Ours"),) and stage.methods == ("Ours", "Stiff")


@pytest.mark.parametrize(
    "stage, needle",
    [
        ({"task": "ranking"}, "'stages.compare.task' must be one of likert, slider, 2afc"),
        ({"task": "2afc", "pairs": [["Ours", "Ours"]]}, "compares 'Ours' with itself"),
        ({"task": "2afc", "pairs": [["Ours", "Nobody"]]}, "names unknown method 'Nobody'"),
        ({"task": "2afc", "pairs": [["Ours", "Baseline"], ["Baseline", "Ours"]]}, "repeats the pair"),
        ({"task": "2afc", "pairs": [["Ours"]]}, "must be a list of two method names"),
        ({"task": "likert", "pairs": [["Ours", "Baseline"]]}, "applies to a 2afc stage only"),
        ({"task": "slider", "scenario": "stadium"}, "has no [scenarios.stadium] table"),
    ],
)
def test_bad_stages_name_the_key(stage, needle):
    def edit(raw):
        raw["stages"]["compare"] = {"number": 3, "scenario": "concert", "viewpoints": ["V1"], **stage}
        raw["questionnaire"]["comparison"] = {"text": "Which looks more natural?"}

    with pytest.raises(InvalidInputError, match="my.toml") as err:
        _design(edit)
    assert needle in str(err.value)


def test_a_2afc_stage_needs_the_comparison_statement():
    def edit(raw):
        raw["stages"]["compare"] = {"number": 3, "scenario": "concert", "viewpoints": ["V1"], "task": "2afc"}

    with pytest.raises(InvalidInputError, match=r"'questionnaire.comparison' is missing: stage 'compare'"):
        _design(edit)


def test_the_slider_scale_takes_its_end_labels():
    def edit(raw):
        raw["stages"]["walking"]["task"] = "slider"
        raw["questionnaire"]["slider"] = {"left": "not at all", "right": "completely"}

    design = _design(edit)
    assert design.stage("walking").task == "slider"
    assert (design.slider.left, design.slider.right, design.slider.minimum, design.slider.maximum) == (
        "not at all",
        "completely",
        0,
        100,
    )
    assert _design().slider.left == PAPER["questionnaire"]["labels"][0]


def test_scenarios_have_names_of_their_own_and_a_kind():
    def edit(raw):
        raw["scenarios"]["gig"] = {**raw["scenarios"]["concert"], "kind": "concert", "tempo": 96}
        raw["stages"]["stationary"]["scenario"] = "gig"

    design = _design(edit)
    assert design.scenarios["gig"].kind == "concert" and design.scenarios["concert"].kind == "concert"
    assert design.scenario_of("gig")["tempo"] == 96 and design.scenario_of("corridor").name == "corridor"
    with pytest.raises(InvalidInputError, match="'scenarios.hall.kind' is missing"):
        _design(lambda raw: raw["scenarios"].__setitem__("hall", {"width": 2.0}))
    with pytest.raises(InvalidInputError, match="'scenarios.hall.kind' must be one of"):
        _design(lambda raw: raw["scenarios"].__setitem__("hall", {"kind": "ballroom"}))
    with pytest.raises(InvalidInputError, match="unknown key 'scenarios.concert.tempi'"):
        _design(lambda raw: raw["scenarios"]["concert"].__setitem__("tempi", 100))


def test_a_named_scenario_builds_its_own_crowd():
    """A stage's scenario named by the design drives the Baseline: its parameters, its kind."""
    from crowdstudy.motion.baseline import build_baseline

    def edit(raw):
        raw["scenarios"]["gig"] = {**raw["scenarios"]["concert"], "kind": "concert", "margin": 0.6}
        raw["stages"]["stationary"]["scenario"] = "gig"

    from crowdstudy.layout import concert_layout

    design = _design(edit)
    anim = build_baseline(design, "stationary", "D1", duration=0.2)
    assert anim.meta["scenario"] == "concert" and anim.meta["scenario_name"] == "gig"
    gig = concert_layout(design, "D1", 7, scenario="gig").positions[0]
    paper = concert_layout(design, "D1", 7).positions[0]
    assert abs(gig).max() <= 1.5 - 0.6 + 1e-9 < abs(paper).max()  # the gig's wider margin
    assert "scenario_name" not in build_baseline(_design(), "stationary", "D1", duration=0.2).meta

"""PhysicsConfig: its sections, setting fields by name, the nested dict, the density
profile, the TOML file and ``--config`` of the command line."""

import dataclasses
import json

import pytest

from crowdstudy.errors import InvalidInputError
from crowdstudy.physics.config import PhysicsConfig
from crowdstudy.physics.config_file import config_from_cli, load_config_file
from crowdstudy.physics.config_keys import FORMER_NAMES, RETIRED_NAMES, leaves
from crowdstudy.physics.config_sections import ContactsConfig, ControlConfig, DensityProfile, ProfilePoint


def test_the_sections_hold_every_field_once():
    fields = dataclasses.fields(PhysicsConfig)
    assert len(fields) <= 20
    assert [f.name for f in fields] == ["solver", "body", "control", "feet", "contacts", "skin", "output", "profile"]
    paths = leaves(PhysicsConfig)
    assert "control.damping" in paths and "contacts.stiffness" in paths and "profile.sparse.skin_max" in paths
    assert all(not name.startswith("contact_") for name in dataclasses.asdict(PhysicsConfig().contacts))
    # every former flat name names an existing field
    assert set(FORMER_NAMES.values()) <= set(paths)


def test_the_paper_controller_keeps_its_values():
    paper = PhysicsConfig.paper_controller()
    assert paper.control.root_translation_stiffness == 1.0e4 and paper.control.root_translation_reach == 0.0
    assert paper.control.pose_translation_stiffness == 0.0 and paper.control.pose_translation_damping_scale == 0.0
    assert paper.control.arm_scale == 1.0 and paper.control.damping == 0.006
    changed = PhysicsConfig.paper_controller(arm_scale=0.5, dt=1.0 / 120.0)
    assert changed.control.arm_scale == 0.5 and changed.solver.dt == 1.0 / 120.0
    assert changed.control.root_translation_stiffness == 1.0e4


@pytest.mark.parametrize(
    "overrides", [{"control.damping": 0.06}, {"damping": 0.06}, {"control": {"damping": 0.06}}, {"damping": 6}]
)
def test_a_field_is_named_by_path_leaf_or_table(overrides):
    cfg = PhysicsConfig.from_overrides(overrides)
    assert cfg.control.damping == pytest.approx(0.06 if overrides != {"damping": 6} else 6.0)
    assert isinstance(cfg.control.damping, float)  # an int given for a float is stored as a float
    assert cfg.replace(control=PhysicsConfig().control) == PhysicsConfig()


def test_former_flat_names_keep_working():
    cfg = PhysicsConfig().with_values(
        contact_stiffness=3e4, foot_anchor_stiffness=0.0, sparse_output_hold=1.0, max_contacts_per_character=64
    )
    assert cfg.contacts.stiffness == 3e4 and cfg.feet.anchor_stiffness == 0.0
    assert cfg.profile.sparse.output_hold == 1.0 and cfg.contacts.max_per_character == 64
    for name in RETIRED_NAMES:
        with pytest.raises(InvalidInputError, match=f"'{name}' is no longer a PhysicsConfig field"):
            PhysicsConfig.from_overrides({name: 0.02 if name != "crowd_adaptive" else False})


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"dampng": 0.06}, r"study\.toml: unknown PhysicsConfig field 'dampng' \(did you mean damping\?\)"),
        (
            {"control.dampng": 0.06},
            r"unknown PhysicsConfig field 'control\.dampng' \(did you mean control\.damping\?\)",
        ),
        ({"stiffness": 1e5}, r"'stiffness' is ambiguous; name one of control\.stiffness, contacts\.stiffness"),
        ({"release_distance": 0.1}, r"ambiguous; name one of feet\.release_distance, contacts\.release_distance"),
        ({"contacts.stiffness": -1}, r"PhysicsConfig\.contacts\.stiffness: expected a finite value >= 0, got -1"),
        ({"solver.dt": 0.0}, r"PhysicsConfig\.solver\.dt: expected a positive value"),
        ({"damping": True}, r"PhysicsConfig\.control\.damping: expected a number, got True"),
        ({"damping": "0.06"}, r"PhysicsConfig\.control\.damping: expected a number, got '0\.06'"),
        ({"intra_body": 1}, r"PhysicsConfig\.contacts\.intra_body: expected true or false, got 1"),
        ({"cg_max_iterations": 60.0}, r"PhysicsConfig\.solver\.cg_max_iterations: expected an integer, got 60\.0"),
        ({"damping": float("nan")}, r"control\.damping: expected a finite value >= 0"),
        ({"contacts": 1}, r"'contacts' is a section of PhysicsConfig, not a field"),
        ({"sparse": {"skin_max": 0.05}}, r"\[sparse\] is not a section of PhysicsConfig"),
        ({"damping": 0.01, "control": {"damping": 0.02}}, r"control\.damping is given twice"),
        ({"profile.sparse.crowd_density": 7.0}, r"profile\.dense\.crowd_density: expected more than"),
    ],
)
def test_bad_overrides_name_where_and_the_key(overrides, message):
    with pytest.raises(InvalidInputError, match=message) as err:
        PhysicsConfig.from_overrides(overrides, where="study.toml")
    assert str(err.value).startswith("study.toml: ")


def test_strings_are_parsed_for_the_command_line():
    cfg = PhysicsConfig.from_overrides(
        {"damping": "0.01", "intra_body": "no", "cg_max_iterations": "80", "skin.max": "0.02", "output.hold": "none"},
        strings=True,
    )
    assert cfg.control.damping == 0.01 and cfg.contacts.intra_body is False and cfg.solver.cg_max_iterations == 80
    assert cfg.skin.max == 0.02 and cfg.output.hold is None
    with pytest.raises(InvalidInputError, match="solver.cg_max_iterations expects an integer, got '8.5'"):
        PhysicsConfig.from_overrides({"cg_max_iterations": "8.5"}, strings=True)
    with pytest.raises(InvalidInputError, match="contacts.intra_body expects true or false"):
        PhysicsConfig.from_overrides({"intra_body": "maybe"}, strings=True)
    with pytest.raises(InvalidInputError, match="control.damping expects a number, got 'none'"):
        PhysicsConfig.from_overrides({"damping": "none"}, strings=True)


def test_sections_check_their_fields_when_made():
    with pytest.raises(InvalidInputError, match=r"PhysicsConfig\.contacts\.stiffness: expected a finite value >= 0"):
        ContactsConfig(stiffness=-1.0)
    with pytest.raises(InvalidInputError, match=r"PhysicsConfig\.control"):
        PhysicsConfig(control=ContactsConfig())
    with pytest.raises(InvalidInputError, match=r"profile\.dense\.crowd_density"):
        DensityProfile(sparse=ProfilePoint(6.0, 0.04, 1.0, 0.8))
    assert ControlConfig(stiffness=1000).stiffness == 1000.0
    with pytest.raises(InvalidInputError, match="unknown section"):
        PhysicsConfig().replace(damping=0.01)
    with pytest.raises(dataclasses.FrozenInstanceError):
        PhysicsConfig().control.damping = 0.01


@pytest.mark.parametrize(
    "cfg",
    [
        PhysicsConfig(),
        PhysicsConfig().for_density(5.0),
        PhysicsConfig.paper_controller(intra_body=False, cg_max_iterations=7),
    ],
)
def test_the_nested_dict_round_trips(cfg):
    d = cfg.as_dict()
    assert d["control"]["damping"] == cfg.control.damping and d["profile"]["dense"]["crowd_density"] == 6.0
    assert PhysicsConfig.from_dict(json.loads(json.dumps(d))) == cfg
    assert PhysicsConfig.from_dict(d).as_dict() == d
    # only the nested form: a flat or former name is not a key of the dict
    with pytest.raises(InvalidInputError, match="unknown PhysicsConfig field 'damping'"):
        PhysicsConfig.from_dict({"damping": 0.01})


def test_the_profile_interpolates_bit_for_bit():
    profile = PhysicsConfig().profile
    sp, dp = profile.sparse, profile.dense
    for density, want in ((0.0, sp), (sp.crowd_density, sp), (dp.crowd_density, dp), (12.0, dp)):
        got = profile.at(density)
        assert (got.skin_max, got.skin_hand_scale, got.output_hold) == (
            want.skin_max,
            want.skin_hand_scale,
            want.output_hold,
        )
    w = profile.weight(5.0)
    assert profile.at(5.0).skin_max == float((1.0 - w) * sp.skin_max + w * dp.skin_max)


def test_a_toml_file_and_items_on_top(tmp_path):
    path = tmp_path / "physics.toml"
    path.write_text(
        "[control]\ndamping = 0.01\n[contacts]\nstiffness = 30000\n[profile.sparse]\nskin_max = 0.05\n"
        "[solver]\ncg_tolerance = 1e-3\n"
    )
    cfg = load_config_file(path)
    assert (cfg.control.damping, cfg.contacts.stiffness, cfg.profile.sparse.skin_max, cfg.solver.cg_tolerance) == (
        0.01,
        3e4,
        0.05,
        1e-3,
    )
    both = config_from_cli(["control.damping=0.02", str(path), "intra_body=false"])
    assert both.control.damping == 0.02 and both.contacts.stiffness == 3e4 and both.contacts.intra_body is False
    assert config_from_cli([]) == PhysicsConfig()


@pytest.mark.parametrize(
    "text, items, message",
    [
        (None, ["missing.toml"], r"--config '.*missing\.toml': no such file"),
        ("[control\ndamping = 0.01\n", None, r"--config '.*physics\.toml': not valid TOML"),
        (
            "[control]\ndampng = 0.01\n",
            None,
            r"physics\.toml': unknown PhysicsConfig field 'control\.dampng' "
            r"\(did you mean control\.damping\?\)",
        ),
        ('damping = "0.01"\n', None, r"physics\.toml': PhysicsConfig\.control\.damping: expected a number"),
        ("", ["damping"], r"--config 'damping': no such file"),
        ("", ["a.toml", "b.toml"], r"--config: expected at most one TOML file"),
        ("", ["damping=0.1", "damping=0.2"], r"--config: damping is given twice"),
        ("", ["=0.1"], r"--config: expected KEY=VALUE"),
        ("", ["dampng=0.1"], r"--config: unknown PhysicsConfig field 'dampng' \(did you mean damping\?\)"),
    ],
)
def test_bad_config_options_name_file_and_key(tmp_path, monkeypatch, text, items, message):
    monkeypatch.chdir(tmp_path)
    if text is not None:
        (tmp_path / "physics.toml").write_text(text)
    with pytest.raises(InvalidInputError, match=message):
        config_from_cli(items if items is not None else ["physics.toml"])


@pytest.mark.parametrize(
    "config_args, message",
    [
        (["dampng=0.01"], "unknown PhysicsConfig field 'dampng' (did you mean damping?)"),
        (["nothere.toml"], "no such file"),
        (["stiffness=1"], "ambiguous"),
    ],
)
def test_correct_cli_refuses_a_bad_config_before_writing(tmp_path, capsys, config_args, message):
    """One line on stderr naming the key, exit 2, nothing written (the input is not even read)."""
    from crowdstudy.cli import main

    out = tmp_path / "out.npz"
    rc = main(["correct", str(tmp_path / "in.npz"), str(out), "--no-progress", "--config", *config_args])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and message in err and "--config" in err and len(err.splitlines()) == 1
    assert not out.exists() and not list(tmp_path.iterdir())


def test_stimuli_cli_takes_the_same_config(tmp_path, capsys):
    from crowdstudy.cli import main

    rc = main(["stimuli", "--out", str(tmp_path / "set"), "--config", "contact_stiffnes=1"])
    err = capsys.readouterr().err
    assert rc == 2 and "unknown PhysicsConfig field 'contact_stiffnes' (did you mean contact_stiffness?)" in err


def test_the_help_documents_the_file_and_the_keys(capsys):
    from crowdstudy.cli import main

    with pytest.raises(SystemExit):
        main(["correct", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "FILE.toml" in text and "[control] damping = 0.01" in text and "control.damping" in text
    assert "skin.max=0.015 skin.hand_scale=0.5 output.hold=0.6" in text


def test_the_paper_preset_switches_off_every_addition():
    """PhysicsConfig.paper(): the paper's method alone (plain prediction with gravity, Eq. 4
    with d = 0.006 and stiffer pelvis and feet, the four penalty contacts on bare capsules,
    no output stage), whatever the defaults say."""
    paper, default = PhysicsConfig.paper(), PhysicsConfig()
    assert paper.control.damping == 0.006 and paper.control.pelvis_scale > 1 and paper.control.feet_scale > 1
    assert paper.control.arm_scale == paper.control.trunk_scale == paper.control.hips_scale == 1.0
    assert not paper.solver.feedforward and paper.body.gravity > 0 and paper.solver.dt == 1.0 / 60.0
    assert paper.control.pose_translation_stiffness == paper.control.feet_translation_stiffness == 0
    assert paper.feet.anchor_stiffness == 0
    c = paper.contacts
    assert min(c.stiffness, c.intra_stiffness, c.ground_stiffness, c.wall_stiffness) > 0
    assert c.speculative_distance == c.pass_ahead == c.stiffening_depth == c.activation == c.margin == 0
    assert not paper.follows_profile and paper.skin.max == 0 and paper.skin.percentile == 0
    o = paper.output
    assert o.smoothing == o.smoothing_root == o.hold == 0 and not o.speed_limit and not o.foot_lock
    assert paper.for_density(6.5) == paper  # no density profile to follow
    assert PhysicsConfig.paper(damping=0.06).control.damping == 0.06
    assert default.output.speed_limit and default.follows_profile  # the defaults are untouched

"""Body-shape draws (``crowdstudy.body.shapes``): the paper's design keeps its bodies byte for
byte, a design's ``[bodies] shapes = "population"`` gets the population's spread of BMI, and
those bodies hold the capsule and hand bars."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from crowdstudy.body import load_body, sample_bodies
from crowdstudy.body.capsules import capsule_mesh_iou
from crowdstudy.body.shapes import MACRO_GRID, MESH_BMI, POPULATION_LIMITS, bmi, mesh_bmi
from crowdstudy.design import load_design, parse_design, read_toml
from crowdstudy.errors import InvalidInputError

FOLLOWUP = Path(__file__).resolve().parent.parent / "stimuli" / "examples" / "followup" / "study.toml"

#: sha256 (first 16 hex) of ``sample_bodies(n, seed)`` for every cell of the paper's design,
#: taken before the draws became a choice: the paper's animations keep these bodies.
PAPER_CELL_BODIES = {
    "stationary-D1": (20, 20241917, "c04269389f7acc51"),
    "stationary-D2": (30, 20241918, "3423f1dd03b56a22"),
    "stationary-D3": (40, 20241919, "e4e5437225723a1c"),
    "stationary-D4": (50, 20241920, "c9c6cf052377b6f1"),
    "stationary-D5": (60, 20241921, "b60167ece15fd769"),
    "walking-D1": (20, 20242917, "f6bda52b8abdb81d"),
    "walking-D2": (30, 20242918, "e8bcd8c6893420c6"),
    "walking-D3": (40, 20242919, "80125c8c97ab9c84"),
    "walking-D4": (50, 20242920, "6822e6e8f00ebe5b"),
    "walking-D5": (60, 20242921, "8f1038e0d6b18acc"),
}


def _digest(records) -> str:
    return hashlib.sha256(json.dumps(records, sort_keys=True).encode()).hexdigest()


def _mesh_bmi(rec: dict) -> float:
    """BMI measured on the body's mesh: volume x 1010 kg/m^3 / height^2."""
    return float(load_body(rec).mesh().volume * 1010.0 / rec["height"] ** 2)


def test_the_papers_design_keeps_its_bodies_byte_for_byte():
    design = load_design()
    assert design.body_shapes == "study"
    for st in design.stages:
        for level in design.densities:
            n, seed, digest = PAPER_CELL_BODIES[f"{st.key}-{level}"]
            assert (design.n_characters(level), design.cell_seed(st, level)) == (n, seed)
            assert _digest(sample_bodies(n, seed))[:16] == digest
            assert _digest(sample_bodies(n, seed, shapes="study"))[:16] == digest
    many = [sample_bodies(60, s) for s in (0, 1, 7, 11)]
    assert _digest(many) == "adfbdad5a0d8bcdfd80575900fbfc070354e5503c5b61f831d92654c8104fde7"


def test_the_followup_design_asks_for_the_population_spread():
    design = load_design(FOLLOWUP)
    assert design.body_shapes == "population"
    # everything but weight and muscle is the same draw
    study, pop = sample_bodies(30, 5), sample_bodies(30, 5, shapes="population")
    strip = [{k: v for k, v in r.items() if k not in ("weight", "muscle")} for r in study]
    assert strip == [{k: v for k, v in r.items() if k not in ("weight", "muscle")} for r in pop]
    assert [r["weight"] for r in study] != [r["weight"] for r in pop]
    # the open model has no weight macro: its records are the same
    assert sample_bodies(8, 5, model="open") == sample_bodies(8, 5, model="open", shapes="population")


@pytest.mark.parametrize(
    ("bodies", "message"),
    [
        ({"shapes": "heavy"}, "key 'bodies.shapes' must be one of 'study', 'population', got 'heavy'"),
        ({"shapes": 3}, "key 'bodies.shapes' must be str"),
        ({"shape": "population"}, "unknown key 'bodies.shape'"),
    ],
)
def test_a_bad_bodies_table_names_the_file_and_the_key(bodies, message):
    raw = read_toml(FOLLOWUP, "missing")
    raw["bodies"] = bodies
    with pytest.raises(InvalidInputError, match="followup.toml: ") as err:
        parse_design(raw, "followup.toml")
    assert message in str(err.value)
    with pytest.raises(InvalidInputError, match="shapes: expected one of study, population"):
        sample_bodies(3, 0, shapes="heavy")  # type: ignore[arg-type]


def test_the_mesh_bmi_table_is_the_mesh():
    """:data:`MESH_BMI` (what the population draw inverts) is what the meshes measure."""
    for sex in ("male", "female"):
        height = 1.71 if sex == "male" else 1.595
        for i, j in ((0, 4), (2, 2), (4, 0), (1, 3)):
            rec = {"model": "makehuman", "sex": sex, "height": height, "age": 25.0}
            rec |= {"weight": MACRO_GRID[j], "muscle": MACRO_GRID[i], "proportions": 0.5, "race": [0.34, 0.33, 0.33]}
            assert _mesh_bmi(rec) == pytest.approx(MESH_BMI[sex][i][j], abs=0.15)
    assert mesh_bmi("male", 0.5, 0.5) == pytest.approx(MESH_BMI["male"][2][2])
    assert bmi("female", 60.0, 0.0) > bmi("female", 25.0, 0.0) and bmi("male", 40.0, 1.0) > 27.0


#: BMI quantiles (5, 25, 50, 75, 95 %) measured on the meshes of ``sample_bodies(400, 3)``
#: per sex (200 each): the table of docs/guides/characters.md.
DOCUMENTED_BMI = {
    ("study", "male"): (20.1, 21.4, 22.1, 23.2, 24.8),
    ("study", "female"): (17.5, 18.8, 19.8, 20.8, 22.0),
    ("population", "male"): (19.1, 22.2, 24.2, 26.6, 30.8),
    ("population", "female"): (18.0, 20.8, 23.8, 26.9, 31.3),
}


def test_population_bodies_spread_wider_than_the_study_draw():
    """The meshes' BMI: the population draw's interquartile range is wider than the study
    draw's and its quantiles are the documented ones."""
    iqr = {}
    for shapes in ("study", "population"):
        recs = sample_bodies(400, 3, shapes=shapes)
        for sex in ("male", "female"):
            values = np.array([_mesh_bmi(r) for r in recs if r["sex"] == sex])
            q = np.quantile(values, [0.05, 0.25, 0.5, 0.75, 0.95])
            np.testing.assert_allclose(q, DOCUMENTED_BMI[shapes, sex], atol=0.06)
            iqr[shapes, sex] = q[3] - q[1]
    for sex in ("male", "female"):
        assert iqr["population", sex] > 1.8 * iqr["study", sex], iqr
    recs = sample_bodies(400, 3, shapes="population")
    lo_w, hi_w = POPULATION_LIMITS["weight"]
    lo_m, hi_m = POPULATION_LIMITS["muscle"]
    assert all(lo_w <= r["weight"] <= hi_w and lo_m <= r["muscle"] <= hi_m for r in recs)


def test_population_bodies_keep_the_capsule_fit():
    """The capsule proxies fit the population's bodies as the study's (IoU >= 0.75): the six
    bodies of test_capsules' seed, and the three heaviest of a crowd of 60."""
    crowd = sample_bodies(60, 20241921, shapes="population")
    by_bmi = sorted(crowd, key=lambda r: mesh_bmi(r["sex"], r["weight"], r["muscle"]))
    records = sample_bodies(6, seed=11, shapes="population") + by_bmi[-3:]
    assert max(_mesh_bmi(r) for r in by_bmi[-3:]) > 30.0  # the crowd has heavy bodies
    ious = [capsule_mesh_iou(load_body(r), resolution=0.012)["iou"] for r in records]
    assert min(ious) >= 0.75, ious


def _hands_depth(records: list[dict]) -> np.ndarray:
    """Per body, the 95th percentile (m) of its hands' depth in its own torso after
    ``clear_hands`` on test_mocap's fist pumps."""
    from crowdstudy.motion.mocap_library import load_mocap
    from crowdstudy.motion.selfcontact import clear_hands, hand_penetration

    take = load_mocap("cheer").resample(30.0)
    rot, root = take.joint_rotations[:, None], take.root_translation[:, None]
    out = []
    for rec in records:
        body = load_body(rec)
        fixed = clear_hands(rot, root, [body], take.fps)
        out.append(np.percentile(hand_penetration(body, fixed[:, 0], root[:, 0]).max(axis=1), 95))
    return np.array(out)


def test_population_bodies_keep_the_hands_out_of_the_belly():
    """test_mocap's fist pumps: the hands of the heaviest bodies of a population crowd clear
    the belly (95th percentile depth < 7 mm), and over a crowd the population's bodies miss
    that bar no more often than the study draw's (clear_hands misses it on some bodies of
    either draw: soft, average-muscle torsos)."""
    crowd = sample_bodies(60, 20241921, shapes="population")
    heavy = sorted(crowd, key=lambda r: mesh_bmi(r["sex"], r["weight"], r["muscle"]))[-4:]
    assert _hands_depth(heavy).max() < 0.007
    study = _hands_depth(sample_bodies(60, 20241921))
    assert np.mean(_hands_depth(crowd) > 0.007) <= np.mean(study > 0.007), study


def test_a_population_design_animates_and_records_its_bodies(tmp_path):
    """build_baseline draws the design's shapes and says so in meta["bodies"] (the file
    keeps it); the study draw writes no such key; the cell's animation digest follows it."""
    import dataclasses

    from crowdstudy.motion.baseline import build_baseline
    from crowdstudy.render.stimuli_digests import animation_digest
    from crowdstudy.scene import CrowdAnimation
    from crowdstudy.scene_meta import check_meta

    design = load_design(FOLLOWUP)
    anim = build_baseline(design, "concert", "Medium", duration=0.5, fps=30)
    seed = design.cell_seed(design.stage("concert"), "Medium")
    assert list(anim.bodies) == sample_bodies(anim.n_characters, seed, shapes="population")
    assert anim.meta["bodies"] == {"shapes": "population"}
    anim.save(tmp_path / "a.npz")
    assert CrowdAnimation.load(tmp_path / "a.npz").meta["bodies"] == {"shapes": "population"}
    study = build_baseline(design, "concert", "Medium", duration=0.5, fps=30, body_shapes="study")
    assert "bodies" not in study.meta and list(study.bodies) == sample_bodies(study.n_characters, seed)
    with pytest.raises(InvalidInputError, match=r"meta\.bodies\.shapes: expected one of study, population"):
        check_meta({"bodies": {"shapes": "fat"}})
    from crowdstudy.body.shapes import BODY_SHAPES
    from crowdstudy.scene_meta import _BODY_SHAPES

    assert _BODY_SHAPES == BODY_SHAPES  # the meta schema's copy of the names
    stim = design.stimuli()[0]
    settings = {"duration": 1.0, "fps": 30, "metric_frames": 10}
    as_study = dataclasses.replace(design, body_shapes="study")
    assert animation_digest(design, stim, settings) != animation_digest(as_study, stim, settings)


def test_the_cli_names_the_design_file_and_key(tmp_path, capsys):
    from crowdstudy.cli import main

    text = FOLLOWUP.read_text(encoding="utf-8").replace('shapes = "population"', 'shapes = "round"')
    bad = tmp_path / "bad.toml"
    bad.write_text(text, encoding="utf-8")
    out = tmp_path / "out"
    assert main(["animate", "--design", str(bad), "--stage", "concert", "--density", "Medium", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "bad.toml: key 'bodies.shapes' must be one of 'study', 'population', got 'round'" in err
    assert len(err.splitlines()) == 1 and not out.exists()

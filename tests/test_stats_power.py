"""Power in standardised terms, the model fitted to a pilot, random slopes, exact intervals."""

import dataclasses
import json

import numpy as np
import pytest

from crowdstudy.cli import main as cli_main
from crowdstudy.design import load_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.stats.anova import rm_anova
from crowdstudy.stats.pilot import fit_pilot
from crowdstudy.stats.power import clopper_pearson, method_points, power_analysis
from crowdstudy.stats.scoring import cell_means, composite_scores
from crowdstudy.stats.synthetic import ResponseModel, simulate_responses


@pytest.fixture(scope="module")
def design():
    return load_design()


@pytest.mark.parametrize(
    "hits, n, r_low, r_high",
    [  # R 4.2.2: binom.test(hits, n)$conf.int
        (7, 20, 0.15390920478454115, 0.59218853453282816),
        (0, 10, 0.0, 0.30849710781876083),
        (10, 10, 0.69150289218123917, 1.0),
        (93, 200, 0.39435273526145675, 0.53670014221167894),
    ],
)
def test_clopper_pearson_matches_binom_test(hits, n, r_low, r_high):
    lo, hi = clopper_pearson(hits, n)
    assert lo == pytest.approx(r_low, rel=1e-10, abs=1e-15) and hi == pytest.approx(r_high, rel=1e-10)


def test_power_table_has_exact_intervals_and_standardised_sizes(design):
    model = ResponseModel.for_design(design, participant_density_sd=0.1, participant_viewpoint_sd=0.2)
    target = 0.8
    pts = method_points(model, design, 2, dz=target)
    assert method_points(model, design, 2, eta_p2=target**2 / (1 + target**2)) == pytest.approx(pts)
    res = power_analysis(
        design, 40, model=dataclasses.replace(model, method_effect=pts), sims=6, seed=2, stage=2, composites=["QCR"]
    )
    row = res.table.set_index("effect").loc["Method"]
    assert (row["ci_low"], row["ci_high"]) == pytest.approx(clopper_pearson(int(row["n_significant"]), 6))
    # the conversion ignores clipping at the scale's ends: realised d_z within 15 % of the plan
    assert row["dz_median"] == pytest.approx(target, rel=0.15)
    assert 0 < row["np2_median"] < 1 and np.isnan(res.table.set_index("effect").at["Density:Method", "dz_median"])
    with pytest.raises(InvalidInputError, match="exactly one"):
        method_points(model, design, 2, dz=0.5, eta_p2=0.2)


def test_random_density_slopes_break_sphericity(design):
    def density_row(sd):
        model = ResponseModel.for_design(design, participant_density_sd=sd, noise_sd=0.6)
        df = simulate_responses(design, 30, model, seed=8, stages=[2])
        long = cell_means(composite_scores(df, design), "QCR", design, stage=2)
        return (
            rm_anova(long, "QCR", ["Density", "Viewpoint", "Method"], "participant_id")
            .set_index("Source")
            .loc["Density"]
        )

    flat, sloped = density_row(0.0), density_row(0.4)
    assert flat["p_spher"] > 0.05 and flat["eps_GG"] > 0.8
    assert sloped["p_spher"] < 0.001 and sloped["eps_GG"] < 0.5


def test_pilot_fit_recovers_the_model(design):
    true = ResponseModel.for_design(
        design, method_effect=0.8, participant_density_sd=0.15, participant_viewpoint_sd=0.25, noise_sd=0.8
    )
    model, table = fit_pilot(simulate_responses(design, 40, true, seed=1), design)
    got = table.set_index("parameter")["value"]
    for name, tol in [
        ("method_effect", 0.2),
        ("noise_sd", 0.05),
        ("participant_sd", 0.1),
        ("participant_method_sd", 0.1),
        ("participant_density_sd", 0.06),
        ("participant_viewpoint_sd", 0.06),
        ("base_score", 0.15),
        ("density_penalty", 0.05),
    ]:
        assert got[name] == pytest.approx(getattr(true, name), abs=tol), name
    assert model.scenario_offsets["corridor"] == pytest.approx(-0.2, abs=0.1)
    with pytest.raises(InvalidInputError, match="at least 3 participants"):
        fit_pilot(simulate_responses(design, 2, true, seed=1), design)


def test_cli_power_from_a_pilot(design, tmp_path, capsys):
    pilot = tmp_path / "pilot.csv"
    simulate_responses(design, 8, seed=4).to_csv(pilot, index=False)
    out = tmp_path / "power.json"
    assert (
        cli_main(
            [
                "power",
                "--pilot",
                str(pilot),
                "-n",
                "6",
                "--sims",
                "2",
                "--stage",
                "2",
                "--composite",
                "QCR",
                "--dz",
                "0.6",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    data = json.loads(out.read_text())
    assert {r["parameter"] for r in data["pilot"]} >= {"noise_sd", "participant_method_sd", "method_effect"}
    assert "dz_median" in data["table"][0] and "Clopper-Pearson" in capsys.readouterr().out
    assert cli_main(["power", "--pilot", str(tmp_path / "none.csv"), "--sims", "1"]) == 2
    assert "none.csv" in capsys.readouterr().err

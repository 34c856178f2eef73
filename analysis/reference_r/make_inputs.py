"""Write the input datasets of the R reference (deterministic seeds; committed beside it).

    .venv/bin/python analysis/reference_r/make_inputs.py     # -> analysis/reference_r/*.csv
    Rscript analysis/reference_r/afex_reference.R             # -> analysis/reference_r/ref_*.csv

Datasets (long format: subject, factor columns, y):
- spherical_5x4x2.csv: 20 subjects, Density (5) x Viewpoint (4) x Method (2), i.i.d.
  errors plus a subject intercept: sphericity holds.
- violated_5x4x2.csv: 20 subjects, same factors; subject-specific slopes over Density and
  error variance growing with Density and Viewpoint: sphericity clearly violated.
- likert_5x2x2.csv: 16 simulated participants of the study's walking stage (Density x
  Viewpoint V3/V4 x Method): QCR composite from crowdstudy's synthetic ResponseModel, so
  every factor of the interaction Viewpoint:Method has only two levels and scores are
  half-integers as in real Likert data.
- likert_incomplete_5x2x2.csv: likert_5x2x2 with 32 of its 320 rows removed at random
  (seed 21): most participants lack some cell, so the ANOVA would drop them and the mixed
  model keeps them (robust_reference.R).
- likert_5x2x3.csv: 14 participants, Density (5) x Viewpoint (V1, V2) x Method (3:
  Baseline, the reference, Ours, Stiff): a composite of two 1..6 items (half-integer
  scores), Ours +0.8 and Stiff +0.4 points over Baseline with participant deviations.
- likert_incomplete_5x2x3.csv: likert_5x2x3 with 30 of its 420 rows removed (seed 22).
- comparisons_2afc.csv: 20 participants' 2AFC trials in comparisons.csv's schema (stage 2,
  the corridor, as a 2afc stage of the paper's design with a third method Stiff), three
  methods, every pair in each Density (5) x Viewpoint (V3, V4) cell once, left/right at random;
  P(choose b over a) = logistic(1.2 (effect_b - effect_a + participant deviation)) with
  effects Baseline 0, Ours 0.8, Stiff 0.3 and a 0.1 logit bias to the left.
"""

from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent


def _grid(n, levels):
    idx = pd.MultiIndex.from_product(
        [[f"s{i + 1:02d}" for i in range(n)], *levels.values()], names=["subject", *levels]
    )
    return idx.to_frame(index=False)


def spherical(seed=11, n=20):
    rng = np.random.default_rng(seed)
    df = _grid(
        n,
        {
            "Density": [f"D{i}" for i in range(1, 6)],
            "Viewpoint": [f"V{i}" for i in range(1, 5)],
            "Method": ["Baseline", "Ours"],
        },
    )
    subj = dict(zip(df.subject.unique(), rng.normal(0, 1.0, n), strict=True))
    d = df.Density.str[1].astype(int).to_numpy()
    v = df.Viewpoint.str[1].astype(int).to_numpy()
    m = (df.Method == "Ours").to_numpy()
    y = 3.5 + df.subject.map(subj).to_numpy() - 0.15 * d + 0.05 * (v == 4) + m * (0.9 - 0.1 * d)
    df["y"] = y + rng.normal(0, 0.8, len(df))
    return df


def violated(seed=12, n=20):
    rng = np.random.default_rng(seed)
    df = _grid(
        n,
        {
            "Density": [f"D{i}" for i in range(1, 6)],
            "Viewpoint": [f"V{i}" for i in range(1, 5)],
            "Method": ["Baseline", "Ours"],
        },
    )
    subjects = df.subject.unique()
    slope = dict(zip(subjects, rng.normal(0, 0.8, n), strict=True))
    vslope = dict(zip(subjects, rng.normal(0, 0.6, n), strict=True))
    inter = dict(zip(subjects, rng.normal(0, 1.0, n), strict=True))
    d = df.Density.str[1].astype(int).to_numpy()
    v = df.Viewpoint.str[1].astype(int).to_numpy()
    m = (df.Method == "Ours").to_numpy()
    sd = 0.2 * d**1.5 * (1 + 0.5 * (v == 4))
    y = (
        3.0
        + df.subject.map(inter).to_numpy()
        + df.subject.map(slope).to_numpy() * d**2 / 5
        + df.subject.map(vslope).to_numpy() * (v == 4) * d
        - 1.0 * d
        + m * (0.4 * d)
    )
    df["y"] = y + rng.normal(0, 1, len(df)) * sd
    return df


def likert(seed=13, n=16):
    from crowdstudy.design import load_design
    from crowdstudy.stats.synthetic import simulate_responses

    raw = simulate_responses(load_design(), n, seed=seed)
    raw = raw[raw.stage == 2]
    out = pd.DataFrame(
        {
            "subject": raw.participant_id,
            "Density": raw.density_level,
            "Viewpoint": raw.viewpoint,
            "Method": raw.method,
            "y": (raw.Q1 + 7 - raw.Q2) / 2.0,
        }
    )
    return out.sort_values(["subject", "Density", "Viewpoint", "Method"]).reset_index(drop=True)


def incomplete(full: pd.DataFrame, seed=21, n_drop=32):
    rng = np.random.default_rng(seed)
    drop = np.sort(rng.choice(len(full), n_drop, replace=False))
    return full.drop(full.index[drop]).reset_index(drop=True)


def _composite(rng, mu):
    """Mean of two 1..6 items around ``mu`` (noise SD 0.9, rounded, clipped)."""
    items = np.clip(np.round(mu[:, None] + rng.normal(0, 0.9, (len(mu), 2))), 1, 6)
    return items.mean(axis=1)


def three_methods(seed=14, n=14):
    rng = np.random.default_rng(seed)
    df = _grid(
        n,
        {
            "Density": [f"D{i}" for i in range(1, 6)],
            "Viewpoint": ["V1", "V2"],
            "Method": ["Baseline", "Ours", "Stiff"],
        },
    )
    subjects = df.subject.unique()
    inter = dict(zip(subjects, rng.normal(0, 0.5, n), strict=True))
    ours = dict(zip(subjects, rng.normal(0, 0.3, n), strict=True))
    stiff = dict(zip(subjects, rng.normal(0, 0.3, n), strict=True))
    d = df.Density.str[1].astype(int).to_numpy()
    mu = 4.2 - 0.3 * (d - 3) + df.subject.map(inter).to_numpy()
    mu = mu + (df.Method == "Ours").to_numpy() * (0.8 + df.subject.map(ours).to_numpy())
    mu = mu + (df.Method == "Stiff").to_numpy() * (0.4 + df.subject.map(stiff).to_numpy())
    df["y"] = _composite(rng, mu)
    return df


def comparisons(seed=15, n=20):
    """2AFC trials in comparisons.csv's schema (see the module docstring)."""
    rng = np.random.default_rng(seed)
    effects = {"Baseline": 0.0, "Ours": 0.8, "Stiff": 0.3}
    pairs = [("Baseline", "Ours"), ("Baseline", "Stiff"), ("Ours", "Stiff")]
    densities = {f"D{i}": round(2.22 + 1.11 * (i - 1), 2) for i in range(1, 6)}
    rows = []
    for s in range(n):
        pid = f"p{s + 1:02d}"
        dev = rng.normal(0, 0.5)  # the participant's deviation of every non-reference method
        trial = 0
        for level, density in densities.items():
            for view in ("V3", "V4"):
                for a, b in pairs:
                    eff_a = effects[a] + (dev if a != "Baseline" else 0.0)
                    eff_b = effects[b] + (dev if b != "Baseline" else 0.0)
                    left_is_a = bool(rng.random() < 0.5)
                    left, right = (a, b) if left_is_a else (b, a)
                    logit = 1.2 * (eff_b - eff_a) + (0.1 if left == b else -0.1)
                    chose_b = bool(rng.random() < 1.0 / (1.0 + np.exp(-logit)))
                    chosen = b if chose_b else a
                    rows.append(
                        {
                            "participant_id": pid,
                            "stage": 2,
                            "scenario": "corridor",
                            "task": "2afc",
                            "trial_index": trial,
                            "density_level": level,
                            "density": density,
                            "viewpoint": view,
                            "stimulus_left": f"S2-{level}-{view}-{left}",
                            "stimulus_right": f"S2-{level}-{view}-{right}",
                            "method_left": left,
                            "method_right": right,
                            "choice": "left" if chosen == left else "right",
                            "chosen_method": chosen,
                            "rt_ms": int(rng.integers(1500, 9000)),
                            "shown_at": "",
                            "answered_at": "",
                        }
                    )
                    trial += 1
    return pd.DataFrame(rows)


def main():
    three = three_methods()
    for name, df in [
        ("likert_5x2x3", three),
        ("likert_incomplete_5x2x3", incomplete(three, seed=22, n_drop=30)),
        ("comparisons_2afc", comparisons()),
    ]:
        df.to_csv(HERE / f"{name}.csv", index=False, float_format="%.17g")
        print(name, df.shape)
    lik = likert()
    for name, df in [
        ("spherical_5x4x2", spherical()),
        ("violated_5x4x2", violated()),
        ("likert_5x2x2", lik),
        ("likert_incomplete_5x2x2", incomplete(lik)),
    ]:
        df.to_csv(HERE / f"{name}.csv", index=False, float_format="%.17g")
        print(name, df.shape)


if __name__ == "__main__":
    main()

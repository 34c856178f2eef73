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


def main():
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

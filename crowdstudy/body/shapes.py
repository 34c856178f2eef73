"""Sampling a population of body shapes.

Heights: Gaussians per sex with the world mean adult heights of the 1996 birth cohort
estimated by the NCD Risk Factor Collaboration ("A century of trends in adult human
height", eLife 5:e13410, 2016): men 171.0 cm, women 159.5 cm (as summarised by Our World
in Data), and within-population standard deviations of 7.0 cm (men) and 6.5 cm (women),
typical of national surveys. Heights are truncated to mean +- 3 SD.

Build: the open model's two shape parameters (``build``, ``proportion``) are standard
normal, truncated to +- 2 (``build`` is also mildly correlated with height, r = 0.2).

MakeHuman bodies (the default): the same sexes and heights; age uniform in 18-70 years;
weight and muscle (MakeHuman's 0-1 values, 0.5 average) 0.5 + 0.13 x the build draw and an
independent normal, clipped to 0.15-0.85 (weight also rises 0.05 per decade over 30, as
adult weight does); proportions 0.5 +- 0.1; the african / asian / caucasian blend from a
symmetric Dirichlet(0.35) (mostly one dominant ancestry, some mixed), which also sets the
skin tone the renderer paints.
"""

from __future__ import annotations

import numpy as np

from crowdstudy.errors import InvalidInputError

__all__ = ["HEIGHT_STATS", "sample_bodies"]

#: (mean, sd) stature in metres per sex.
HEIGHT_STATS = {"male": (1.710, 0.070), "female": (1.595, 0.065)}
_SHAPE_LIMIT = 2.0


MODELS = ("makehuman", "open", "smpl")
AGE_RANGE = (18.0, 70.0)


def sample_bodies(
    n: int, seed, *, model: str = "makehuman", height_stats: dict | None = None, smpl_path: str | dict | None = None
) -> list[dict]:
    """N body records, half female and half male (the odd one out is female), in a
    seeded random order.

    Args:
        n: number of bodies (>= 0).
        seed: int or ``numpy.random.Generator``; the same seed gives the same records.
        model: "makehuman" (default: the MakeHuman body, :mod:`crowdstudy.body.makehuman`),
            "open" (the generated mannequin) or "smpl": then ``smpl_path`` is the model file, or a
            dict ``{"female": path, "male": path}``; betas 1 and 2 are the build and
            proportion draws halved, and beta 0 is solved so the stature is the sampled
            height (``crowdstudy.body.smpl.betas_for_height``).
        height_stats: optional ``{"male": (mean, sd), "female": (mean, sd)}`` in metres.

    Returns:
        ``[{"model", "sex", "height" (m), "shape" (list of float)}, ...]`` (SMPL records
        carry ``"path"`` and ``"betas"`` instead of ``"shape"``).
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
        raise InvalidInputError(f"n: expected a non-negative integer, got {n!r}")
    if model not in MODELS:
        raise InvalidInputError(f"model: expected one of {', '.join(MODELS)}, got {model!r}")
    if model == "smpl" and not smpl_path:
        raise InvalidInputError("smpl_path: required with model='smpl' (the user's SMPL model file)")
    stats = dict(HEIGHT_STATS)
    if height_stats is not None:
        for sex, val in height_stats.items():
            if sex not in stats or len(val) != 2 or not (0.5 < float(val[0]) < 2.5 and 0 <= float(val[1]) < 0.5):
                raise InvalidInputError(
                    f"height_stats[{sex!r}]: expected (mean, sd) in metres for 'male'/'female', got {val!r}"
                )
            stats[sex] = (float(val[0]), float(val[1]))
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    sexes = np.array(["female"] * ((n + 1) // 2) + ["male"] * (n // 2))
    rng.shuffle(sexes)
    z = np.clip(rng.standard_normal(n), -3.0, 3.0)
    shape = np.clip(rng.standard_normal((n, 2)), -_SHAPE_LIMIT, _SHAPE_LIMIT)
    shape[:, 0] = np.clip(0.2 * z + np.sqrt(1 - 0.04) * shape[:, 0], -_SHAPE_LIMIT, _SHAPE_LIMIT)
    if model == "makehuman":  # drawn after the open model's draws: those stay as they were
        age = rng.uniform(*AGE_RANGE, size=n)
        extra = np.clip(rng.standard_normal((n, 3)), -2.5, 2.5)
        race = rng.dirichlet(np.full(3, 0.35), size=n)
    records = []
    for i in range(n):
        sex = str(sexes[i])
        mean, sd = stats[sex]
        height = round(float(mean + sd * z[i]), 4)
        rec = {"model": model, "sex": sex, "height": height, "shape": [round(float(s), 4) for s in shape[i]]}
        if model == "makehuman":
            weight = 0.5 + 0.13 * shape[i][0] + 0.08 * extra[i, 0] + 0.05 * max(0.0, (age[i] - 30.0) / 10.0)
            rec = {
                "model": "makehuman",
                "sex": sex,
                "height": height,
                "age": round(float(age[i]), 1),
                "weight": round(float(np.clip(weight, 0.15, 0.85)), 4),
                "muscle": round(float(np.clip(0.5 + 0.08 * shape[i][0] + 0.12 * extra[i, 1], 0.15, 0.85)), 4),
                "proportions": round(float(np.clip(0.5 + 0.1 * extra[i, 2], 0.2, 0.8)), 4),
                "race": [round(float(r), 4) for r in race[i]],
            }
        if model == "smpl":
            from crowdstudy.body.smpl import betas_for_height, smpl_model

            path = smpl_path.get(sex) if isinstance(smpl_path, dict) else smpl_path
            if not path:
                raise InvalidInputError(f"smpl_path: no model file for sex {sex!r}")
            smpl = smpl_model(path)
            start = np.zeros(min(3, smpl.n_betas))
            start[1:] = 0.5 * shape[i][: len(start) - 1]
            betas = [round(float(b), 6) for b in betas_for_height(smpl, height, start)]
            rec = {"model": "smpl", "sex": sex, "height": height, "path": str(path), "betas": betas}
        records.append(rec)
    return records

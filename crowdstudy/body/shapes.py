"""Sampling a population of body shapes.

Heights: Gaussians per sex with the world mean adult heights of the 1996 birth cohort
estimated by the NCD Risk Factor Collaboration ("A century of trends in adult human
height", eLife 5:e13410, 2016): men 171.0 cm, women 159.5 cm (as summarised by Our World
in Data), and within-population standard deviations of 7.0 cm (men) and 6.5 cm (women),
typical of national surveys. Heights are truncated to mean +- 3 SD.

Build: the open model's two shape parameters (``build``, ``proportion``) are standard
normal, truncated to +- 2 (``build`` is also mildly correlated with height, r = 0.2).

MakeHuman bodies (the default): the same sexes and heights; age uniform in 18-70 years;
proportions 0.5 +- 0.1; the african / asian / caucasian blend from a symmetric
Dirichlet(0.35) (mostly one dominant ancestry, some mixed), which also sets the skin tone
the renderer paints. Weight and muscle (MakeHuman's 0-1 macros, 0.5 average) come from one
of two draws (:data:`BodyShapes`), the same random numbers for both:

``"study"`` (the default; the paper's study design)
    weight and muscle 0.5 + 0.13 (0.08) x the build draw and an independent normal, clipped
    to 0.15-0.85 (weight also rises 0.05 per decade over 30, as adult weight does): a narrow
    spread, most bodies of one slim build.
``"population"``
    each body's body-mass index (BMI, kg/m^2) is drawn from adult populations
    (:data:`BMI_STATS`): a log-normal per sex around the global age-standardised mean BMI of
    the NCD Risk Factor Collaboration ("Trends in adult body-mass index in 200 countries
    from 1975 to 2014", Lancet 387:1377-1396, 2016: 24.2 men, 24.4 women in 2014), its
    median rising with age (:data:`BMI_AGE_SLOPE`), correlated with the build draw
    (r = 0.6). The spread within a population (sd of ln BMI) and the age slope are this
    module's assumptions, not figures of that paper. The weight and muscle macros are then
    those whose mesh has that BMI (:func:`macros_for_bmi`, on :data:`MESH_BMI`, the mesh
    measured): MakeHuman's weight macro alone spans only BMI 19-24 at average muscle, a
    heavy body is also a softer one (lower muscle). Both macros stay within
    :data:`POPULATION_LIMITS`, where the capsule proxies fit the heavy meshes as well as
    the study's (intersection over union >= 0.75) and the hands clear the belly as often
    (``crowdstudy.motion.selfcontact``); the heaviest women's tail stops near BMI 31.
"""

from __future__ import annotations

import functools
from typing import Literal, get_args

import numpy as np

from crowdstudy.errors import InvalidInputError

__all__ = [
    "BMI_AGE_SLOPE",
    "BMI_STATS",
    "BODY_SHAPES",
    "BodyShapes",
    "HEIGHT_STATS",
    "MACRO_GRID",
    "MESH_BMI",
    "POPULATION_LIMITS",
    "bmi",
    "macros_for_bmi",
    "mesh_bmi",
    "sample_bodies",
]

#: (mean, sd) stature in metres per sex.
HEIGHT_STATS = {"male": (1.710, 0.070), "female": (1.595, 0.065)}
_SHAPE_LIMIT = 2.0

#: Which draw gives MakeHuman bodies their weight and muscle: ``"study"`` the narrow draw
#: of the paper's study design (its animations stay the same bytes), ``"population"`` the
#: spread of adult body-mass indices (see the module docstring).
BodyShapes = Literal["study", "population"]
BODY_SHAPES: tuple[BodyShapes, ...] = get_args(BodyShapes)

#: (median BMI kg/m^2 at 40 years, sd of ln BMI) per sex: NCD-RisC's 2014 global
#: age-standardised means taken as the medians; the sds are assumptions (about 3.7 and
#: 4.7 kg/m^2 at the median).
BMI_STATS = {"male": (24.2, 0.15), "female": (24.4, 0.19)}
#: ln(BMI) per decade of age from 20 to 60 years (flat outside), relative to 40 years (an assumption).
BMI_AGE_SLOPE = 0.04
#: ``{"weight": (lo, hi), "muscle": (lo, hi)}``: the population draw's macro limits.
POPULATION_LIMITS = {"weight": (0.15, 0.95), "muscle": (0.1, 0.8)}
#: The weight (columns) and muscle (rows) macro values of :data:`MESH_BMI`'s grid.
MACRO_GRID = (0.0, 0.25, 0.5, 0.75, 1.0)
#: BMI (kg/m^2) of MakeHuman's mesh on :data:`MACRO_GRID`, per sex: its volume x 1010 kg/m^3
#: over height^2, measured at the sex's mean height, age 25, proportions 0.5 (age 60 moves
#: it by at most 0.8). Muscle 0 is a soft body, 0.5 an average one whose weight macro
#: spans only BMI 19-24.
MESH_BMI = {
    "male": (
        (13.9, 18.6, 24.1, 31.7, 40.8),
        (16.5, 19.5, 22.7, 26.8, 31.3),
        (19.4, 20.4, 21.4, 22.4, 23.5),
        (18.9, 19.8, 20.9, 23.8, 27.0),
        (18.4, 19.3, 20.4, 25.3, 31.1),
    ),
    "female": (
        (12.3, 16.4, 21.6, 27.7, 34.5),
        (14.2, 17.2, 20.6, 24.2, 28.1),
        (16.5, 17.9, 19.5, 20.9, 22.4),
        (16.6, 17.9, 19.3, 21.3, 23.4),
        (16.7, 17.9, 19.1, 21.8, 24.8),
    ),
}
#: Weight, muscle steps of the search in :func:`macros_for_bmi`.
_SEARCH = (np.linspace(0.0, 1.0, 201), np.linspace(0.0, 1.0, 101))

MODELS = ("makehuman", "open", "smpl")
AGE_RANGE = (18.0, 70.0)


def mesh_bmi(sex: str, weight: np.ndarray | float, muscle: np.ndarray | float) -> np.ndarray:
    """BMI (kg/m^2) of MakeHuman's mesh at macros ``weight`` and ``muscle`` (0..1, arrays of
    one broadcast shape): :data:`MESH_BMI` interpolated bilinearly."""
    from scipy.interpolate import RegularGridInterpolator

    grid = np.asarray(MACRO_GRID)
    interp = RegularGridInterpolator((grid, grid), np.asarray(MESH_BMI[sex]))
    w, m = np.broadcast_arrays(np.asarray(weight, dtype=np.float64), np.asarray(muscle, dtype=np.float64))
    return interp(np.stack([m.ravel(), w.ravel()], axis=1)).reshape(w.shape)


@functools.lru_cache(maxsize=2)
def _search_grid(sex: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weights (W,), muscles (M,) within :data:`POPULATION_LIMITS` and their mesh BMI (M, W)."""
    (w_lo, w_hi), (m_lo, m_hi) = POPULATION_LIMITS["weight"], POPULATION_LIMITS["muscle"]
    ws = _SEARCH[0][(_SEARCH[0] >= w_lo - 1e-9) & (_SEARCH[0] <= w_hi + 1e-9)]
    ms = _SEARCH[1][(_SEARCH[1] >= m_lo - 1e-9) & (_SEARCH[1] <= m_hi + 1e-9)]
    return ws, ms, mesh_bmi(sex, ws[None, :], ms[:, None])


def macros_for_bmi(sex: str, target: float, hint: tuple[float, float] = (0.5, 0.5)) -> tuple[float, float]:
    """(weight, muscle) macros within :data:`POPULATION_LIMITS` whose mesh has BMI ``target``
    (kg/m^2, :func:`mesh_bmi`, to 0.1), the nearest such pair to ``hint`` (weight, muscle);
    a target out of reach gets the nearest BMI the limits allow.

    A heavy target needs a softer body (lower muscle): at average muscle the weight macro
    spans only BMI 19-24 (:data:`MESH_BMI`)."""
    ws, ms, grid = _search_grid(sex)
    err = np.abs(grid - target)
    ok = err <= max(float(err.min()), 0.1)
    dist = (ws[None, :] - hint[0]) ** 2 + (ms[:, None] - hint[1]) ** 2
    i, j = np.unravel_index(int(np.argmin(np.where(ok, dist, np.inf))), grid.shape)
    return float(ws[j]), float(ms[i])


def bmi(sex: str, age: float, z: float) -> float:
    """The population's BMI (kg/m^2) at standard-normal score ``z`` within ``sex`` and
    ``age`` (years): the median of :data:`BMI_STATS` moved by :data:`BMI_AGE_SLOPE`."""
    median, sd = BMI_STATS[sex]
    decades = (min(max(float(age), 20.0), 60.0) - 40.0) / 10.0
    return float(median * np.exp(BMI_AGE_SLOPE * decades + sd * z))


def _study_macros(build: float, extra: np.ndarray, age: float, sex: str) -> tuple[float, float]:
    """(weight, muscle) of the ``"study"`` draw."""
    weight = 0.5 + 0.13 * build + 0.08 * extra[0] + 0.05 * max(0.0, (age - 30.0) / 10.0)
    muscle = 0.5 + 0.08 * build + 0.12 * extra[1]
    return float(np.clip(weight, 0.15, 0.85)), float(np.clip(muscle, 0.15, 0.85))


def _population_macros(build: float, extra: np.ndarray, age: float, sex: str) -> tuple[float, float]:
    """(weight, muscle) of the ``"population"`` draw: the macros whose mesh has the BMI drawn
    from the population, the muscle near its own draw."""
    z_bmi = 0.6 * build + 0.8 * extra[0]  # unit variance, r = 0.6 with the build draw
    hint = (0.5 + 0.2 * z_bmi, 0.5 + 0.1 * build + 0.15 * extra[1])
    return macros_for_bmi(sex, bmi(sex, age, z_bmi), hint)


_MACROS = {"study": _study_macros, "population": _population_macros}


def sample_bodies(
    n: int,
    seed,
    *,
    model: str = "makehuman",
    height_stats: dict | None = None,
    smpl_path: str | dict | None = None,
    shapes: BodyShapes = "study",
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
        shapes: :data:`BodyShapes`, the MakeHuman bodies' weight and muscle draw (the
            other models ignore it); ``"study"`` gives the records it always gave.

    Returns:
        ``[{"model", "sex", "height" (m), "shape" (list of float)}, ...]`` (SMPL records
        carry ``"path"`` and ``"betas"`` instead of ``"shape"``).
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
        raise InvalidInputError(f"n: expected a non-negative integer, got {n!r}")
    if model not in MODELS:
        raise InvalidInputError(f"model: expected one of {', '.join(MODELS)}, got {model!r}")
    if shapes not in BODY_SHAPES:
        raise InvalidInputError(f"shapes: expected one of {', '.join(BODY_SHAPES)}, got {shapes!r}")
    if model == "smpl" and not smpl_path:
        raise InvalidInputError("smpl_path: required with model='smpl' (the user's SMPL model file)")
    stats = _height_stats(height_stats)
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
            weight, muscle = _MACROS[shapes](float(shape[i][0]), extra[i], float(age[i]), sex)
            rec = {
                "model": "makehuman",
                "sex": sex,
                "height": height,
                "age": round(float(age[i]), 1),
                "weight": round(weight, 4),
                "muscle": round(muscle, 4),
                "proportions": round(float(np.clip(0.5 + 0.1 * extra[i, 2], 0.2, 0.8)), 4),
                "race": [round(float(r), 4) for r in race[i]],
            }
        if model == "smpl":
            rec = _smpl_record(sex, height, shape[i], smpl_path)
        records.append(rec)
    return records


def _height_stats(height_stats: dict | None) -> dict[str, tuple[float, float]]:
    """:data:`HEIGHT_STATS` with the caller's ``height_stats`` checked and applied."""
    stats = dict(HEIGHT_STATS)
    if height_stats is not None:
        for sex, val in height_stats.items():
            if sex not in stats or len(val) != 2 or not (0.5 < float(val[0]) < 2.5 and 0 <= float(val[1]) < 0.5):
                raise InvalidInputError(
                    f"height_stats[{sex!r}]: expected (mean, sd) in metres for 'male'/'female', got {val!r}"
                )
            stats[sex] = (float(val[0]), float(val[1]))
    return stats


def _smpl_record(sex: str, height: float, shape: np.ndarray, smpl_path) -> dict:
    """An SMPL body record: the model file of ``sex``, betas solved for ``height``."""
    from crowdstudy.body.smpl import betas_for_height, smpl_model

    path = smpl_path.get(sex) if isinstance(smpl_path, dict) else smpl_path
    if not path:
        raise InvalidInputError(f"smpl_path: no model file for sex {sex!r}")
    smpl = smpl_model(path)
    start = np.zeros(min(3, smpl.n_betas))
    start[1:] = 0.5 * shape[: len(start) - 1]
    betas = [round(float(b), 6) for b in betas_for_height(smpl, height, start)]
    return {"model": "smpl", "sex": sex, "height": height, "path": str(path), "betas": betas}

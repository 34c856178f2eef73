"""The acceptance bars of a corrected crowd: what Ours must keep against its own Baseline.

The study shows Baseline and Ours side by side, so the only difference a participant may see
is the contacts: the correction must remove nearly all of the interpenetration while
following the animation closely and moving as smoothly as the Baseline does.
:class:`BarTolerances` holds each bar's tolerance (a frozen dataclass: the defaults are the
project's bars; a study may tighten or loosen one with :func:`dataclasses.replace`), and
:func:`check_bars` says which bars one measured crowd meets. The measurements are those of
:mod:`crowdstudy.metrics`: mesh overlap (:func:`~crowdstudy.metrics.overlap_volume`),
tracking error (:func:`~crowdstudy.metrics.tracking_error`) and smoothness
(:func:`~crowdstudy.metrics.smoothness`, as :func:`smoothness_columns` lays it out).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal, get_args

from crowdstudy.errors import InvalidInputError

__all__ = ["BarName", "BAR_NAMES", "BarTolerances", "check_bars", "failed_bars", "loop_mode", "smoothness_columns"]

#: the bars, in the order of the reports
BarName = Literal["jerk", "hf", "speed", "pelvis", "slide", "overlap", "tracking", "seam"]
BAR_NAMES: tuple[BarName, ...] = get_args(BarName)


@dataclass(frozen=True)
class BarTolerances:
    """The tolerance of each bar of Ours against its Baseline (the same cell: same
    characters, clips and seed). Ratios are Ours / Baseline; every field is positive."""

    #: mesh overlap volume kept, as a fraction of the Baseline's (0.05: at most 5 % left):
    #: the interpenetration is what the correction is for, and what a viewer sees
    overlap_ratio: float = 0.05
    #: mean tracking error at the sparsest density level, cm: few contacts, so Ours should
    #: follow its animation almost exactly
    tracking_sparsest_cm: float = 1.5
    #: mean tracking error at the densest density level, cm: the characters must make room,
    #: but by less than a limb's width
    tracking_densest_cm: float = 5.0
    #: mean joint jerk (m/s^3), Ours / Baseline: contacts may not add visible shaking
    jerk_ratio: float = 1.3
    #: share of the joints' velocity energy above the smoothness cutoff, Ours / Baseline:
    #: no high-frequency buzz from the solver
    hf_share_ratio: float = 1.5
    #: largest single-frame joint speed, m/s above the Baseline's: no limb snaps in one frame
    joint_speed_increase_m_s: float = 0.5
    #: 99th percentile of the pelvis acceleration, as a multiple of the Baseline's ...
    pelvis_accel_ratio: float = 2.0
    #: ... plus this much, m/s^2 (a still Baseline has a p99 near 0, so a pure ratio would
    #: forbid any push)
    pelvis_accel_increase_m_s2: float = 0.5
    #: 99th percentile of the horizontal speed of a foot the Baseline has planted, m/s:
    #: planted feet stay planted (no skating)
    foot_slide_p99_m_s: float = 0.05
    #: loop seam of a looped concert: the jump from the last frame to the first, as a multiple
    #: of the median frame step (the larger of Baseline's and Ours'): the loop is not seen
    seam_ratio: float = 1.5

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise InvalidInputError(f"BarTolerances.{field.name}: expected a positive number, got {value!r}")

    def tracking_cm(self, level_index: int, n_levels: int) -> float | None:
        """The tracking bar of density level ``level_index`` of ``n_levels``, cm: the sparsest
        and the densest level have one, the levels between none (None)."""
        if not 0 <= level_index < n_levels:
            raise InvalidInputError(
                f"level_index: expected 0 <= level_index < n_levels = {n_levels}, got {level_index!r}"
            )
        if level_index == 0:
            return self.tracking_sparsest_cm
        return self.tracking_densest_cm if level_index == n_levels - 1 else None

    def text(self, sparsest: str = "D1", densest: str = "D5") -> dict[BarName, str]:
        """Each bar in words, for reports (``sparsest``/``densest``: the names of the density
        levels the tracking bars apply to)."""
        return {
            "jerk": f"mean jerk <= {self.jerk_ratio:g}x",
            "hf": f"HF share <= {self.hf_share_ratio:g}x",
            "speed": f"max joint speed <= +{self.joint_speed_increase_m_s:g} m/s",
            "pelvis": f"pelvis accel p99 <= {self.pelvis_accel_ratio:g}x + {self.pelvis_accel_increase_m_s2:g} m/s^2",
            "slide": f"planted-foot slide p99 <= {100 * self.foot_slide_p99_m_s:g} cm/s",
            "overlap": f"mesh overlap <= {100 * self.overlap_ratio:g} %",
            "tracking": f"tracking <= {self.tracking_sparsest_cm:g} cm at {sparsest}, "
            f"<= {self.tracking_densest_cm:g} cm at {densest}",
            "seam": f"seam <= {self.seam_ratio:g}x median step (a looped concert)",
        }


def check_bars(
    row: Mapping[str, object], tolerances: BarTolerances, level_index: int, n_levels: int
) -> dict[BarName, bool]:
    """Which bars one measured crowd meets: ``{bar: passed}``.

    ``row`` holds the measurements of Ours against its Baseline: the columns of
    :func:`smoothness_columns` (``jerk_ratio``, ``hf_share_*``, ``max_joint_speed_*``,
    ``pelvis_p99_*``, ``foot_slide_p99_ours``, ``seam_ratio_*``), ``mesh_ratio`` (Ours' mean
    mesh overlap over the Baseline's), ``tracking_cm`` and ``loop`` (:func:`loop_mode`).
    The tracking bar is checked at the sparsest and densest of ``n_levels`` levels only
    (:meth:`BarTolerances.tracking_cm`), the seam on a periodic (looped concert) clip only: a
    clip too short to loop has no seam a viewer sees, the corridor dissolves instead.
    """
    missing = [
        k
        for k in (
            "jerk_ratio",
            "hf_share_ours",
            "hf_share_baseline",
            "max_joint_speed_ours",
            "max_joint_speed_baseline",
            "pelvis_p99_ours",
            "pelvis_p99_baseline",
            "foot_slide_p99_ours",
            "mesh_ratio",
            "loop",
        )
        if k not in row
    ]
    if missing:
        raise InvalidInputError(f"row: missing the measurements {missing}")
    t = tolerances
    r: Mapping = row
    checks: dict[BarName, bool] = {
        "jerk": r["jerk_ratio"] <= t.jerk_ratio,
        "hf": r["hf_share_ours"] <= t.hf_share_ratio * r["hf_share_baseline"],
        "speed": r["max_joint_speed_ours"] <= r["max_joint_speed_baseline"] + t.joint_speed_increase_m_s,
        "pelvis": (
            r["pelvis_p99_ours"] <= t.pelvis_accel_ratio * r["pelvis_p99_baseline"] + t.pelvis_accel_increase_m_s2
        ),
        "slide": r["foot_slide_p99_ours"] <= t.foot_slide_p99_m_s,
        "overlap": r["mesh_ratio"] <= t.overlap_ratio,
    }
    bar = t.tracking_cm(level_index, n_levels)
    if bar is not None:
        checks["tracking"] = r["tracking_cm"] <= bar
    if r["loop"] == "periodic":
        checks["seam"] = max(r["seam_ratio_baseline"], r["seam_ratio_ours"]) <= t.seam_ratio
    return checks


def failed_bars(checks: Mapping[BarName, bool]) -> str:
    """The failed bars of :func:`check_bars`, comma-separated, or ``"-"`` when every bar is met."""
    return ",".join(k for k, ok in checks.items() if not ok) or "-"


def loop_mode(anim) -> str:
    """How the animation's video loops: ``meta["loop"]["mode"]`` (``"periodic"``,
    ``"dissolve"`` or ``"none"``)."""
    return str((anim.meta.get("loop") or {}).get("mode", "none"))


def smoothness_columns(base, ours, bodies: Sequence | None = None) -> dict[str, float]:
    """The smoothness columns :func:`check_bars` reads (:func:`crowdstudy.metrics.smoothness`
    of the Baseline ``base`` and of Ours against it): each measure's ``NAME_baseline`` and
    ``NAME_ours`` (jerk m/s^3, hf_share, max_joint_speed m/s, pelvis_p99 m/s^2,
    foot_slide_p99 m/s, seam_ratio), ``jerk_ratio`` and ``foot_slide_over_5cm_s_ours``
    (the fraction of planted-foot samples sliding faster than 5 cm/s)."""
    from crowdstudy.metrics.smoothness import smoothness

    sb, so = smoothness(base, base, bodies=bodies).as_dict(), smoothness(ours, base, bodies=bodies).as_dict()
    cols = {}
    for key, name in (
        ("jerk_m_s3", "jerk"),
        ("hf_share", "hf_share"),
        ("max_joint_speed_m_s", "max_joint_speed"),
        ("pelvis_accel_p99_m_s2", "pelvis_p99"),
        ("foot_slide_p99_m_s", "foot_slide_p99"),
        ("seam_ratio", "seam_ratio"),
    ):
        cols[f"{name}_baseline"], cols[f"{name}_ours"] = sb[key], so[key]
    cols["jerk_ratio"] = so["jerk_m_s3"] / sb["jerk_m_s3"]
    cols["foot_slide_over_5cm_s_ours"] = so["foot_slide_fraction_over_5cm_s"]
    return cols

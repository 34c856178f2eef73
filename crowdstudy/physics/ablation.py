"""What the toolkit adds to the paper's method, in named groups of
:class:`~crowdstudy.physics.config.PhysicsConfig` fields (issue #41).

:meth:`PhysicsConfig.paper() <crowdstudy.physics.config.PhysicsConfig.paper>` is the paper's
method alone (Section 3, Eq. 4); the defaults add to it. Each :class:`Addition` of
:data:`ADDITIONS` is one such addition: the dotted field changes that switch it off from the
defaults (``changes``) and every field that belongs to it (``fields``: the switch and the
sub-parameters that do nothing once it is off). :func:`without` applies some of them.

Every field of the configuration is accounted for exactly once: in one addition, in
:data:`PAPER_FIELDS` (what the paper states or leaves open, and the value taken), in
:data:`KEPT_IN_PAPER` (not the paper's, but kept by its preset) or in
:data:`OFF_BY_DEFAULT` (an addition the defaults leave off). With every addition off the
defaults are the preset but for :data:`INERT_IN_PAPER`: fields that differ and do nothing
there. ``tests/test_ablation.py`` checks both, so the groups and the preset cannot drift
apart.

``crowdstudy bench physics --ablation`` (:mod:`crowdstudy.evaluation.ablation_run`) corrects
the study's cells with the paper's method, the defaults, and the defaults without each
addition, and measures the bars of each (what each addition buys).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping

from crowdstudy.errors import InvalidInputError
from crowdstudy.physics.config import PhysicsConfig
from crowdstudy.physics.config_sections import DensityProfile

__all__ = [
    "Addition",
    "ADDITIONS",
    "PAPER_FIELDS",
    "KEPT_IN_PAPER",
    "OFF_BY_DEFAULT",
    "INERT_IN_PAPER",
    "without",
    "parse_additions",
]


@dataclasses.dataclass(frozen=True)
class Addition:
    """One addition to the paper's method.

    Attributes:
        name: its identifier (``crowdstudy bench physics --ablation --groups NAME,...``).
        description: what it does and why, in one or two sentences.
        changes: {dotted path: value}: the changes to the defaults that switch it off (the
            paper's value, or "off").
        fields: every dotted path that belongs to the addition: those of ``changes`` first,
            then the sub-parameters that do nothing once it is off (they keep their
            defaults in :meth:`PhysicsConfig.paper`).
    """

    name: str
    description: str
    changes: Mapping[str, object]
    fields: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "changes", dict(self.changes))
        object.__setattr__(self, "fields", tuple(dict.fromkeys([*self.changes, *self.fields])))


_DENSE = DensityProfile().dense


def _additions(*items: Addition) -> dict[str, Addition]:
    return {a.name: a for a in items}


#: The additions, in the order of the pipeline: prediction, control, contact geometry,
#: contact shaping, output stage.
ADDITIONS: dict[str, Addition] = _additions(
    Addition(
        "feedforward",
        "The inertial prediction continues the animation's own acceleration and gravity is taken "
        "as balanced by it, so that with no contact the output reproduces the input; off: the "
        "paper's plain prediction x + h v with gravity.",
        {"solver.feedforward": False},
    ),
    Addition(
        "settle",
        "Half a second simulated on the first frame before the clip, so the clip starts without "
        "the Baseline's overlaps; off: the clip starts from the Baseline's first pose.",
        {"solver.settle_time": 0.0},
    ),
    Addition(
        "root_spring",
        "A stiff root translation spring (3e5 N/m within 1 cm, 2e5 beyond): a dense crowd makes "
        "room with the limbs that touch rather than whole bodies; off: the preset's linear "
        "1e4 N/m root spring.",
        {"control.root_translation_stiffness": 1.0e4, "control.root_translation_reach": 0.0},
        ("control.root_translation_far_stiffness",),
    ),
    Addition(
        "pose_springs",
        "Every body other than the root and the feet held in world space where the animation "
        "puts it by a damped spring: a pushed limb returns in place, not only through its "
        "joint's rotation; off: joint rotations only (Eq. 4).",
        {"control.pose_translation_stiffness": 0.0, "control.pose_translation_damping_scale": 0.0},
        ("control.pose_translation_reach",),
    ),
    Addition(
        "foot_anchor",
        "A planted foot held where it touched down (static friction with a slip limit, a "
        "corrective step when pushed far) and the feet's weak translation springs: no foot "
        "skate in the simulation; off: the feet follow Eq. 4 only.",
        {
            "feet.anchor_stiffness": 0.0,
            "control.feet_translation_stiffness": 0.0,
            "control.feet_translation_damping_scale": 0.0,
        },
        (
            "feet.anchor_damping",
            "feet.anchor_max_force",
            "feet.planted_speed",
            "feet.release_distance",
            "feet.rejoin_distance",
        ),
    ),
    Addition(
        "soft_arms",
        "The arms' Eq. 4 gains at a quarter of the body's: a contact on a hand bends the arm "
        "rather than shoving the character (the upper trunk's own scale is the body's already); "
        "off: the body's k and d.",
        {"control.arm_scale": 1.0},
        ("control.trunk_scale",),
    ),
    Addition(
        "stiff_hips",
        "The hips and the lower spine as stiff as the pelvis (Eq. 4 gains x8); off: the body's k "
        "and d, the paper's (it names the pelvis and the feet only).",
        {"control.hips_scale": 1.0},
    ),
    Addition(
        "mesh_skin",
        "Each capsule grown by how far its bone's mesh reaches outside it (a percentile, capped) "
        "for contacts between characters: the meshes stay apart, not only the capsules; off: "
        "the bare capsules.",
        {"skin.percentile": 0.0},
    ),
    Addition(
        "margin",
        "5 mm added to every capsule for contacts between characters and with static objects, "
        "on top of the skin; off: none.",
        {"contacts.margin": 0.0},
    ),
    Addition(
        "density_profile",
        "The skins' cap, the hands' share of their skin and the output's hold follow how crowded "
        "the crowd is (thicker skins and a longer hold in sparse crowds); off: the dense end "
        "for every crowd.",
        {
            "skin.max": _DENSE.skin_max,
            "skin.hand_scale": _DENSE.skin_hand_scale,
            "output.hold": _DENSE.output_hold,
        },
        (
            "profile.sparse.crowd_density",
            "profile.sparse.skin_max",
            "profile.sparse.skin_hand_scale",
            "profile.sparse.output_hold",
            "profile.dense.crowd_density",
            "profile.dense.skin_max",
            "profile.dense.skin_hand_scale",
            "profile.dense.output_hold",
        ),
    ),
    Addition(
        "speculative",
        "Capsule pairs within 2 cm kept as contacts with their depth linearised to the predicted "
        "state, so a fast limb is stopped before it penetrates; off: penetrating pairs only.",
        {"contacts.speculative_distance": 0.0},
    ),
    Addition(
        "activation",
        "A 5 mm band over which a contact's stiffness ramps in (a C2 penalty), so contacts do not "
        "switch on and off from step to step; off: the plain (k/2) depth^2.",
        {"contacts.activation": 0.0},
    ),
    Addition(
        "release",
        "A contact lets go of a limb held farther than 15 cm from where its animation puts it, so "
        "a pinned limb slides through instead of whipping back later; off: never let go.",
        {"contacts.release_width": 0.0},
        ("contacts.release_distance",),
    ),
    Addition(
        "passing",
        "Two capsules that the animation passes through each other within a frame are let "
        "through instead of held; off: every contact holds.",
        {"contacts.pass_ahead": 0.0},
        ("contacts.pass_width",),
    ),
    Addition(
        "stiffening",
        "A contact between characters stiffens with its depth beyond 1 cm, so a limb pressed "
        "deep meets a stiffer neighbour; off: the quadratic penalty.",
        {"contacts.stiffening_depth": 0.0},
    ),
    Addition(
        "relative_self_contacts",
        "Ground and intra-body contacts push only with the depth beyond the animation's own, so "
        "a clip whose feet dip into the floor or whose limbs touch is not fought; off: absolute "
        "depths.",
        {"contacts.target_relative_self": False},
    ),
    Addition(
        "output_smoothing",
        "The output's deviation from the input low-passed in time (50 ms, the root's 80 ms), held "
        "at its peaks first: Ours as smooth as its Baseline; off: the simulated poses.",
        {"output.smoothing": 0.0, "output.smoothing_root": 0.0},
    ),
    Addition(
        "speed_limit",
        "Where a joint of the output moves faster than the input crowd's fastest joint (plus "
        "0.3 m/s), the correction is spread over more frames; off: no limit.",
        {"output.speed_limit": False},
        ("output.speed_limit_margin",),
    ),
    Addition(
        "foot_lock",
        "The output's ankles held still while the input's are planted (two-bone leg IK); off: no lock.",
        {"output.foot_lock": False},
        ("output.foot_lock_speed",),
    ),
)

#: The fields of the paper's method, {dotted path: what the paper says, and the value
#: taken where it gives none}: :meth:`PhysicsConfig.paper` keeps the defaults' values.
PAPER_FIELDS: dict[str, str] = {
    "solver.dt": "the paper gives no step: 1/60 s, two steps per 30 fps frame",
    "solver.cg_tolerance": "solved by CG, no tolerance given: a relative residual of 3e-3",
    "solver.cg_max_iterations": "no cap given: 60 iterations",
    "solver.damping_reference_dt": "the h of Eq. 4's d/(2 h^2); equal to the step, so Eq. 4 as written",
    "body.density": "no density given: 1000 kg/m^3",
    "body.gravity": "gravity: 9.81 m/s^2",
    "body.joint_stiffness": "soft joints, no stiffness given: 6e5 N/m",
    "control.stiffness": "Eq. 4's k, not given: 2000 J",
    "control.damping": "Eq. 4's d = 0.006, the paper's",
    "control.pelvis_scale": "a stiffer pelvis, no value: 8x k and d",
    "control.feet_scale": "stiffer feet, no value: 4x k and d",
    "control.root_translation_damping_scale": "the root's absolute translation is PD-coupled, no values: "
    "a damper of 0.006 x 4250 J s^2/m^2 (the preset's spring: 1e4 N/m, see root_spring)",
    "contacts.stiffness": "the penalty (k/2) depth^2 between characters, no k given: 6e4 N/m",
    "contacts.intra_stiffness": "within a character: 1e4 N/m",
    "contacts.ground_stiffness": "with the ground: 5e4 N/m",
    "contacts.environment_stiffness": "with point-sampled static objects: 2e4 N/m per point",
    "contacts.wall_stiffness": "with the scene's walls (static objects, as planes): 5e4 N/m",
    "contacts.intra_body": "intra-body contacts, pairs touching in the T-pose skipped: on",
    "contacts.max_per_character": "the contact buffer's size (no effect unless it overflows): 256",
}

#: Not the paper's, but kept by :meth:`PhysicsConfig.paper`: {dotted path: why}.
KEPT_IN_PAPER: dict[str, str] = {
    "output.loop_warmup": "the study's concert videos loop: a periodic clip is simulated from before its start ...",
    "output.loop_blend": "... and cross-faded into it, so the paper's method loops as the stimuli must",
}

#: Additions the defaults leave off (nothing to ablate): {dotted path: what it would do}.
OFF_BY_DEFAULT: dict[str, str] = {
    "contacts.ground_friction": "viscous friction of capsule-ground contacts; 0 in the paper and the "
    "defaults (the foot anchor handles foot skate)",
}

#: Fields that differ between the defaults with every addition off and
#: :meth:`PhysicsConfig.paper`, and why the difference does nothing: {dotted path: why}.
INERT_IN_PAPER: dict[str, str] = {
    "skin.max": "the skins' cap: no skin at skin.percentile 0 (mesh_skin off)",
    "skin.hand_scale": "the hands' share of their skin: no skin at skin.percentile 0",
    "output.hold": "the low-pass's hold: no low-pass at output.smoothing = smoothing_root = 0",
}


def without(names: Iterable[str], base: PhysicsConfig | None = None) -> PhysicsConfig:
    """``base`` (None: the defaults) with the additions ``names`` (keys of
    :data:`ADDITIONS`) switched off; the additions own disjoint fields, so the order does
    not matter. An unknown name is an :class:`InvalidInputError` naming it."""
    base = PhysicsConfig() if base is None else base
    changes: dict[str, object] = {}
    for name in names:
        if name not in ADDITIONS:
            raise InvalidInputError(f"addition {name!r}: unknown; expected one of {', '.join(ADDITIONS)}")
        changes.update(ADDITIONS[name].changes)
    return base.with_values(changes) if changes else base


def parse_additions(text: str, where: str = "--groups") -> list[str]:
    """``"feedforward, foot_lock"`` -> ["feedforward", "foot_lock"] in :data:`ADDITIONS`'
    order; ``""`` or ``"all"`` -> every addition. An unknown or repeated name is an
    :class:`InvalidInputError` naming ``where``."""
    items = [item.strip() for item in text.split(",") if item.strip()]
    if not items or items == ["all"]:
        return list(ADDITIONS)
    unknown = [item for item in items if item not in ADDITIONS]
    if unknown:
        raise InvalidInputError(f"{where}: unknown addition(s) {unknown}; expected some of {', '.join(ADDITIONS)}")
    if len(set(items)) != len(items):
        raise InvalidInputError(f"{where}: an addition is named twice in {text!r}")
    return [name for name in ADDITIONS if name in items]

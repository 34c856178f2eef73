"""The sections of :class:`~crowdstudy.physics.config.PhysicsConfig`: small frozen dataclasses,
one per part of the method, each field documented with its unit.

Control terms follow paper Eq. 4::

    E_control(R) = k/2 |R - R^|_F^2 + d/(2 h^2) |R - R_old - R^ + R^_old|_F^2

with k the spring and d the damping coefficient. ``|R - R^|_F^2 = 8 sin^2(theta/2)``, so k
is an energy (J = N m) per unit squared Frobenius distance, and d is k times a squared time
(J s^2).

Every section checks its fields when it is made: booleans are ``bool``, integers ``int``,
every number finite and >= 0 (some > 0); an ``int`` given for a float field is stored as a
``float``, so :meth:`~crowdstudy.physics.config.PhysicsConfig.as_dict` is plain JSON. An
error names the field by its dotted path (``PhysicsConfig.contacts.stiffness: expected a
finite value >= 0, got -1``).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import typing
from typing import ClassVar

import numpy as np

from crowdstudy.body.capsules import SKIN_HAND_SCALE, SKIN_MAX, SKIN_PERCENTILE
from crowdstudy.errors import InvalidInputError

__all__ = [
    "SolverConfig",
    "BodyConfig",
    "ControlConfig",
    "FeetConfig",
    "ContactsConfig",
    "SkinConfig",
    "OutputConfig",
    "ProfilePoint",
    "DensityProfile",
    "check_value",
]


@functools.cache
def field_types(cls: type) -> dict[str, object]:
    """{field name: its resolved annotation} of a dataclass (``float``, ``int``, ``bool``,
    ``float | None`` or a section class)."""
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls)}


def check_value(value: object, kind: object, path: str, *, positive: bool = False) -> object:
    """``value`` checked against the field type ``kind`` and returned in its stored form
    (a float field's ``int`` as ``float``); :class:`InvalidInputError` naming ``path``."""
    if kind is bool:
        if not isinstance(value, (bool, np.bool_)):
            raise InvalidInputError(f"{path}: expected true or false, got {value!r}")
        return bool(value)
    if isinstance(kind, type) and dataclasses.is_dataclass(kind):
        if not isinstance(value, kind):
            raise InvalidInputError(f"{path}: expected a {kind.__name__}, got {type(value).__name__}")
        return value
    optional = kind == (float | None)
    if optional and value is None:
        return None
    if isinstance(value, (bool, np.bool_)):
        raise InvalidInputError(f"{path}: expected a number, got {value!r}")
    if kind is int:
        if not isinstance(value, numbers.Integral):
            raise InvalidInputError(f"{path}: expected an integer, got {value!r}")
        num: float | int = int(value)
    else:
        if not isinstance(value, numbers.Real):
            none = " (or none: follow the density profile)" if optional else ""
            raise InvalidInputError(f"{path}: expected a number{none}, got {value!r}")
        num = float(value)
    if not math.isfinite(num) or num < 0:
        raise InvalidInputError(f"{path}: expected a finite value >= 0, got {value!r}")
    if positive and num <= 0:
        raise InvalidInputError(f"{path}: expected a positive value, got {value!r}")
    return num


class _Section:
    """Checks and normalises the fields of a section dataclass when it is made."""

    #: the dotted path the section's errors name its fields by
    WHERE: ClassVar[str] = ""
    #: fields that must be > 0 (the others >= 0)
    POSITIVE: ClassVar[frozenset[str]] = frozenset()

    def __post_init__(self) -> None:
        for name, kind in field_types(type(self)).items():
            value = check_value(getattr(self, name), kind, f"{self.WHERE}.{name}", positive=name in self.POSITIVE)
            object.__setattr__(self, name, value)


@dataclasses.dataclass(frozen=True)
class SolverConfig(_Section):
    """The time step and its one Newton iteration.

    Attributes:
        dt: s, the time step h (1/60: two steps per 30 fps frame; the corrector rounds it so
            that a whole number of steps fills a frame).
        cg_tolerance: relative residual |r|/|b| at which CG stops. The one Newton step of a
            frame needs no tight solve: 3e-3 leaves the same overlap, tracking and
            smoothness as 1e-3 on the study's cells in fewer iterations.
        cg_max_iterations: CG iteration cap per step.
        feedforward: the inertial prediction continues the animation's own acceleration
            (``predict_kernel``), and gravity is taken as balanced by the animation (not
            applied): with no contact the output reproduces its input, and the physics
            answers contacts and the PD terms only. False: the paper's plain prediction
            x + h v with gravity.
        damping_reference_dt: s, the step h0 at which the damping coefficients of the
            d/(2 h^2) form (Eq. 4 and the translational dampers) are quoted: the solver uses
            d h / h0, so the damping force (d / h0 times the velocity difference) is the
            same whatever the step.
        settle_time: s simulated on the first frame, the target frozen, before the clip
            starts (so the corrected clip starts without the Baseline's overlaps); 0 starts
            from the Baseline's first pose.
    """

    WHERE: ClassVar[str] = "PhysicsConfig.solver"
    POSITIVE: ClassVar[frozenset[str]] = frozenset({"dt", "cg_tolerance", "cg_max_iterations", "damping_reference_dt"})

    dt: float = 1.0 / 60.0
    cg_tolerance: float = 3e-3
    cg_max_iterations: int = 60
    feedforward: bool = True
    damping_reference_dt: float = 1.0 / 60.0
    settle_time: float = 0.5


@dataclasses.dataclass(frozen=True)
class BodyConfig(_Section):
    """The rigid bodies (one capsule per bone) and the joints between them.

    Attributes:
        density: kg/m^3, the bone capsules' density (their masses and inertias).
        gravity: m/s^2, gravitational acceleration along -z (not applied with
            ``solver.feedforward``).
        joint_stiffness: N/m, soft ball joints: k_j/2 |anchor seen from parent - anchor
            seen from child|^2. The output drops the joints' stretch (forward kinematics of
            the rotations), so a soft joint shows as sliding feet: 6e5 (rather than 2e5)
            roughly halves the remaining foot skate; the per-character preconditioner
            factors the joints exactly, so the CG cost does not change.
    """

    WHERE: ClassVar[str] = "PhysicsConfig.body"
    POSITIVE: ClassVar[frozenset[str]] = frozenset({"density", "joint_stiffness"})

    density: float = 1000.0
    gravity: float = 9.81
    joint_stiffness: float = 6.0e5


@dataclasses.dataclass(frozen=True)
class ControlConfig(_Section):
    """The PD terms that couple the simulation to the animation (paper Eq. 4).

    The paper states d = 0.006 and that pelvis and feet are stiffer; it gives no other
    value. The root is coupled in absolute rotation (Eq. 4 with the pelvis group's k, d)
    and absolute translation (a spring and damper of the same form on the pelvis bone's
    centre of mass); the foot bones get a weaker translational coupling of the same form,
    and every other body a world-space spring and damper towards where the animation puts
    it (the paper couples those through their joint rotations only).

    Attributes:
        stiffness: k of Eq. 4 for the body joints (not pelvis/feet), J per unit squared
            Frobenius distance (the restoring torque at a small angle theta is 2 k theta,
            N m).
        damping: d of Eq. 4 for the body joints, J s^2 (the paper's 0.006). The Fig. 4
            study varies it; every group's damping and the translational dampers scale with
            it.
        pelvis_scale: multiplies k and d for the root's absolute rotation (the pelvis: trunk
            alignment; the paper's stiffer pelvis).
        feet_scale: multiplies k and d for the ankles and feet (no foot skate; the paper's
            stiffer feet).
        hips_scale: multiplies k and d for the hips and the lower spine (left_hip,
            right_hip, spine1: the pelvis' joints to its children), which the paper keeps at
            the body's k; above 1 the thighs and the lower trunk hold their animation as the
            pelvis does.
        arm_scale: multiplies k and d for the arms (collars, shoulders, elbows, wrists,
            hands). Below 1 a contact on a hand bends the arm rather than pushing the whole
            character, while the damped world-space pose springs below hold each arm body
            where the animation puts it; 1 = the paper's single body k.
        trunk_scale: multiplies k and d for the upper trunk, neck and head (spine2, spine3,
            neck, head); 1 = the paper's single body k.
        root_translation_stiffness: N/m, spring of the root's absolute translation near the
            animation.
        root_translation_damping_scale: the root translation damper is ``damping`` times
            this, J s^2/m^2 (the term d_t/(2 h^2) |x - x_old - x^ + x^_old|^2): a damping
            force of d_t / h N s/m relative to the animation's velocity.
        root_translation_reach: m; the root's spring softens from
            ``root_translation_stiffness`` near the animation to
            ``root_translation_far_stiffness`` beyond about this deviation (a pseudo-Huber
            term on top of the far spring); 0 = a linear spring.
        root_translation_far_stiffness: N/m, see ``root_translation_reach``. Stiff: a dense
            crowd held in place makes room with the limbs that touch rather than whole
            bodies, and tracks its animation closer.
        feet_translation_stiffness: N/m, absolute translation spring of each foot body
            (ankle and toe bones) towards the animation, like the root's; 0 = off.
        feet_translation_damping_scale: its damper is ``damping`` times this (J s^2/m^2).
        pose_translation_stiffness: N/m, absolute translation spring of every other body
            (trunk, head, arms, legs) towards where the animation puts it in the world: with
            it a pushed limb returns in world space, not only through its joint's rotation
            spring; 0 = off (the paper: joint rotations only).
        pose_translation_damping_scale: its damper is ``damping`` times this (J s^2/m^2): a
            force of ``damping * this / solver.damping_reference_dt`` N s/m (360 at the
            default 1000) against the body's velocity relative to the animation's, near
            critical for a hand on the 8000 N/m spring; undamped, a pushed limb overshoots
            on its way back.
        pose_translation_reach: m; the pose spring saturates beyond about this deviation (a
            pseudo-Huber energy: its force never exceeds ``pose_translation_stiffness *
            pose_translation_reach`` N), so it holds a brushed limb in place but yields where
            a dense crowd needs room; 0 = a linear spring.
    """

    WHERE: ClassVar[str] = "PhysicsConfig.control"

    stiffness: float = 2000.0
    damping: float = 0.006
    pelvis_scale: float = 8.0
    feet_scale: float = 4.0
    hips_scale: float = 8.0
    arm_scale: float = 0.25
    trunk_scale: float = 1.0
    root_translation_stiffness: float = 3.0e5
    root_translation_damping_scale: float = 4.25e3
    root_translation_reach: float = 0.01
    root_translation_far_stiffness: float = 2.0e5
    feet_translation_stiffness: float = 5.0e3
    feet_translation_damping_scale: float = 300.0
    pose_translation_stiffness: float = 8000.0
    pose_translation_damping_scale: float = 1000.0
    pose_translation_reach: float = 0.0


@dataclasses.dataclass(frozen=True)
class FeetConfig(_Section):
    """The stance-foot anchor: no foot skate.

    While the ANIMATION's foot is planted (slow horizontally), each foot body (ankle and
    toe bones) is held horizontally where it touched down by a stiff anchor (a lagged
    static-friction anchor with a Coulomb slip limit; ``foot_anchor_kernel`` in
    :mod:`crowdstudy.physics.kernels`) that replaces its horizontal coupling to the
    animation (``control.feet_translation_*``); height is left to the ground contact. A
    foot pushed far from the animation's foot takes a corrective step.

    Attributes:
        anchor_stiffness: N/m, the anchor's horizontal spring; 0 = no anchor.
        anchor_damping: N s/m, horizontal damper of the planted foot's velocity relative to
            the animation's foot (independent of ``control.damping``).
        anchor_max_force: N per foot body, the Coulomb limit of the anchor: beyond
            ``anchor_max_force / anchor_stiffness`` m the anchor slips with the foot.
        planted_speed: m/s; the animation's foot body counts as planted (full anchor) below
            this horizontal speed and free above twice it (linear in between).
        release_distance: m; a foot body pushed farther than this (horizontally) from the
            animation's foot takes a corrective step: its anchor is released (the weak
            ``control.feet_translation_stiffness`` pulls it back) until it is back within
            ``rejoin_distance``. 0 = never released. (The Fig. 4 character, held 0.25 m
            behind its animation, steps back this way.)
        rejoin_distance: m, see ``release_distance``.
    """

    WHERE: ClassVar[str] = "PhysicsConfig.feet"
    POSITIVE: ClassVar[frozenset[str]] = frozenset({"planted_speed"})

    anchor_stiffness: float = 3.0e5
    anchor_damping: float = 0.0
    anchor_max_force: float = 1000.0
    planted_speed: float = 0.1
    release_distance: float = 0.2
    rejoin_distance: float = 0.02


@dataclasses.dataclass(frozen=True)
class ContactsConfig(_Section):
    """The penalty contacts: between characters (inter-body), within one (intra-body), with
    the ground, static objects and the scene's walls.

    Attributes:
        stiffness: N/m, the inter-body penalty k_c of (k_c/2) depth^2.
        intra_stiffness: N/m, the intra-body (self) penalty.
        ground_stiffness: N/m, the capsule-ground penalty.
        ground_friction: N s/m per contact point, viscous friction of capsule-ground
            contacts (a force against the contact point's sliding velocity). Off by
            default, as in the paper: it damps the whole body's recovery (the Fig. 4 study
            then no longer separates the values of d); the stance-foot anchor
            (:class:`FeetConfig`) handles foot skate instead.
        environment_stiffness: N/m per sample point, the capsule-static object penalty
            (static objects given as points, e.g. the Fig. 4 plane of
            :mod:`crowdstudy.physics.damping`).
        wall_stiffness: N/m per capsule end sphere, the capsule-wall penalty: the scene's
            walls (``meta["obstacles"]``) are one-sided vertical planes, the free side the
            one the character's root stands on (``wall_kernel`` in
            :mod:`crowdstudy.physics.collision_kernels`).
        margin: m added to the capsule radii (on top of the mesh skin) for inter-body and
            environment contacts (not ground, not intra-body).
        speculative_distance: m; capsule pairs closer than this are kept as (inactive)
            contacts; the solver linearises their depth to the predicted state, so fast
            limbs are stopped before they penetrate.
        activation: m, width of the band over which a contact's penalty stiffness ramps
            from 0 to its full value as the (predicted) depth goes from -activation to 0: a
            C2 penalty (``contact_assemble_kernel`` in :mod:`crowdstudy.physics.linear`),
            so contacts do not switch on and off from step to step (0: the plain
            (k/2) depth^2 on positive depths).
        release_distance: m; an inter-body contact lets go gradually of a limb held farther
            than this from where its animation puts it relative to its character's root
            (centres of mass), fully at ``release_distance + release_width``: a limb pinned
            behind a neighbour slides through instead of whipping back later.
        release_width: m, see ``release_distance``; 0 = never let go.
        pass_ahead: s; an inter-body contact whose two capsules the animation has passed
            through each other and apart again this long ahead (their closest points on the
            other side, ``narrowphase_kernel``) lets them pass instead of holding them (the
            arms of two dancers that swing through each other in one frame of the
            Baseline); 0 = off. Offline (:func:`~crowdstudy.physics.corrector.correct`) the
            whole clip is ahead; fed one frame at a time (``CrowdCorrector.step``) the
            look-ahead reaches the frame given.
        pass_width: m, the look-ahead pose's band over which that pass fades in: by how far
            the capsules are through along the contact's normal and apart there.
        stiffening_depth: m; an inter-body contact stiffens with its depth d beyond the
            activation band: the penalty gains k d^3 / (3 d0) (force + k d^2 / d0,
            stiffness + 2 k d / d0, d0 this depth), so a limb pressed deep meets a stiffer
            neighbour while a light touch stays as soft as ``stiffness`` (C2 at d = 0); 0 =
            the plain quadratic penalty (the paper's). It costs CG iterations where contacts
            are deep.
        target_relative_self: ground and intra-body contacts push only with the depth
            beyond the animation's target pose's own (plus ``activation``): a clip whose own
            capsules interpenetrate, or whose feet dip into the floor, is not fought by the
            physics. Inter-body and environment contacts are absolute.
        intra_body: handle intra-body collisions (pairs touching in the T-pose and
            parent-child pairs are always skipped).
        max_per_character: the contact capacity is this times the characters (plus ground
            and environment contacts); overflowing contacts are dropped and counted.
    """

    WHERE: ClassVar[str] = "PhysicsConfig.contacts"
    POSITIVE: ClassVar[frozenset[str]] = frozenset({"max_per_character"})

    stiffness: float = 6.0e4
    intra_stiffness: float = 1.0e4
    ground_stiffness: float = 5.0e4
    ground_friction: float = 0.0
    environment_stiffness: float = 2.0e4
    wall_stiffness: float = 5.0e4
    margin: float = 0.005
    speculative_distance: float = 0.02
    activation: float = 0.005
    release_distance: float = 0.15
    release_width: float = 0.15
    pass_ahead: float = 1.0 / 30.0
    pass_width: float = 0.04
    stiffening_depth: float = 0.01
    target_relative_self: bool = True
    intra_body: bool = True
    max_per_character: int = 256


@dataclasses.dataclass(frozen=True)
class SkinConfig(_Section):
    """The mesh skin added to the capsule radii for inter-body and environment contacts
    (:func:`crowdstudy.body.capsules.capsule_skin`), so the MESHES stay apart, not only the
    capsules.

    Attributes:
        percentile: each capsule's skin is this percentile of how far its mesh reaches
            beyond it; 0 = bare capsules.
        max: m, no capsule's skin exceeds this. None (the default): follow the crowd's
            density (``profile``); a number fixes it for every crowd. The skin grows a
            capsule in every direction to cover a protrusion on one side (a chest, a
            shoulder blade, a thumb): a dense crowd has no room for such skins, a sparse
            one has, and thin skins there leave arms in trunks.
        hand_scale: the palm and finger bones take this share of their skin
            (``capsule_skin``'s ``hand_scale``): their percentile is the thumb and spread
            fingers, 2-4 cm beside a hand 3-4 cm thick, and a whole skin stops a hand
            pressed on a neighbour's back short of it. None (the default): follow the
            crowd's density (``profile``); a number fixes it for every crowd.
    """

    WHERE: ClassVar[str] = "PhysicsConfig.skin"

    percentile: float = SKIN_PERCENTILE
    max: float | None = None
    hand_scale: float | None = None


@dataclasses.dataclass(frozen=True)
class OutputConfig(_Section):
    """The output stage (:mod:`crowdstudy.physics.output_stage`): the simulated poses ->
    the "Ours" animation. Measured overlaps and tracking are of its result.

    Attributes:
        loop_warmup: s; a periodic input (``meta["loop"]["mode"] == "periodic"``) is
            simulated from this long before its first frame (the loop's end), so the
            output's first frame is a settled one ...
        loop_blend: s; ... and this long past its last frame, the continuation cross-faded
            into the output's first frames: the corrected loop is periodic too
            (:func:`crowdstudy.physics.finish.close_loop`).
        smoothing: s, standard deviation of the zero-phase Gaussian low-pass of the
            output's DEVIATION from its input (joint rotations relative to the input's and
            the root offset; :func:`crowdstudy.physics.finish.smooth_deviation`); 0 = off.
        smoothing_root: s, the same for the root's offset (whole-body pushes: the pelvis
            acceleration), which may be smoothed more than the joints (limbs clearing
            neighbours).
        hold: before the low-pass each deviation component is held at its largest
            magnitude within +-``hold`` kernel widths (a dilation), so the low-pass does not
            shave the separation a contact needed: the correction eases in a little before
            a contact and out after it (0 = a plain low-pass). None (the default): follow
            the crowd's density (``profile``); a number fixes it for every crowd.
        speed_limit: the last step of the output stage
            (:func:`crowdstudy.physics.speed_limit.limit_joint_speed`): where a joint of the
            output moves faster than the input crowd's fastest joint plus
            ``speed_limit_margin``, the correction of its upper-body chain is spread over
            more frames (a limb that rejoins its animation after a contact does not outrun
            every limb of the captured performance).
        speed_limit_margin: m/s, see ``speed_limit``.
        foot_lock: hold the output's ankles still while the input's are planted (two-bone
            leg IK, :func:`crowdstudy.physics.finish.lock_planted_feet`).
        foot_lock_speed: m/s, the input's ankle counts as planted below this speed.
    """

    WHERE: ClassVar[str] = "PhysicsConfig.output"

    loop_warmup: float = 1.0
    loop_blend: float = 0.5
    smoothing: float = 0.05
    smoothing_root: float = 0.08
    hold: float | None = None
    speed_limit: bool = True
    speed_limit_margin: float = 0.3
    foot_lock: bool = True
    foot_lock_speed: float = 0.02


@dataclasses.dataclass(frozen=True)
class ProfilePoint(_Section):
    """One end of the density profile: the values of the fields that follow a crowd's
    density (``skin.max``, ``skin.hand_scale``, ``output.hold`` left None) at one density.

    Attributes:
        crowd_density: characters per m^2 (the
            :func:`~crowdstudy.physics.crowding.crowd_density` measure) at which these values
            hold whole.
        skin_max: m, ``skin.max`` at this density.
        skin_hand_scale: ``skin.hand_scale`` at this density.
        output_hold: ``output.hold`` at this density (kernel widths).
    """

    WHERE: ClassVar[str] = "ProfilePoint"

    crowd_density: float
    skin_max: float
    skin_hand_scale: float
    output_hold: float


@dataclasses.dataclass(frozen=True)
class DensityProfile(_Section):
    """How the skins and the output's hold follow how crowded a crowd is.

    :func:`~crowdstudy.physics.corrector.correct` measures its input's density
    (:func:`~crowdstudy.physics.crowding.crowd_density`) and corrects it with
    ``config.for_density(density)``: every field left None takes :meth:`at` that density,
    the ``sparse`` point's values at and below its density, the ``dense`` point's at and
    above its, linear between. A dense crowd has no room for skins that over-cover the
    meshes (thick skins cost the densest study cells their tracking), while a sparser one
    has the room, and thin skins there leave arms in trunks.

    Attributes:
        sparse: the sparse end. 4.5 per m^2: the concert's D3 crowds and a D3 stadium take
            it whole; 4 cm of skin, the hands' whole, the root held two frames and the
            joints one (a hold of 0.8).
        dense: the dense end. 6.0 per m^2: the D5 crowds take it whole and the D4 crowds lie
            between; at most 1.5 cm of skin, the hands' halved, everything held one frame.
    """

    WHERE: ClassVar[str] = "PhysicsConfig.profile"

    sparse: ProfilePoint = ProfilePoint(crowd_density=4.5, skin_max=0.04, skin_hand_scale=1.0, output_hold=0.8)
    dense: ProfilePoint = ProfilePoint(
        crowd_density=6.0, skin_max=SKIN_MAX, skin_hand_scale=SKIN_HAND_SCALE, output_hold=0.6
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.dense.crowd_density > self.sparse.crowd_density:
            raise InvalidInputError(
                f"{self.WHERE}.dense.crowd_density: expected more than "
                f"profile.sparse.crowd_density ({self.sparse.crowd_density!r}), "
                f"got {self.dense.crowd_density!r}"
            )

    def weight(self, density: float) -> float:
        """How far ``density`` (characters per m^2) lies towards the dense end: 0 at the
        sparse end's density and below, 1 at the dense end's and above, linear between."""
        density = float(density)
        if not density == density or density < 0:
            raise InvalidInputError(f"density: expected characters per m^2 >= 0, got {density!r}")
        span = self.dense.crowd_density - self.sparse.crowd_density
        return float(np.clip((density - self.sparse.crowd_density) / span, 0.0, 1.0))

    def at(self, density: float) -> ProfilePoint:
        """The profile's point at ``density`` characters per m^2: exactly either end at and
        beyond it, linear between (``weight``)."""
        w = self.weight(density)

        def mix(sparse: float, dense: float) -> float:
            return float((1.0 - w) * sparse + w * dense)  # exactly either end at its weight

        s, d = self.sparse, self.dense
        return ProfilePoint(
            crowd_density=float(density),
            skin_max=mix(s.skin_max, d.skin_max),
            skin_hand_scale=mix(s.skin_hand_scale, d.skin_hand_scale),
            output_hold=mix(s.output_hold, d.output_hold),
        )

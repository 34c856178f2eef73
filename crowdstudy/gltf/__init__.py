"""glTF 2.0 both ways: export a CrowdAnimation with its bodies to one binary glTF (.glb),
and the ``crowdstudy import-gltf`` command, which turns a user's skinned character (Blender,
Mixamo, Ready Player Me, VRM names) into a body record ``{"model": "gltf", "path": ...}``
(the reader is the body model :mod:`crowdstudy.body.gltf_model`; the GLB container is
:mod:`crowdstudy.body.gltf_container`); ``crowdstudy export-usd`` writes the same layout as
UsdSkel (:mod:`crowdstudy.gltf.export_usd`).
"""

from crowdstudy.gltf.export import export_gltf

__all__ = ["export_gltf"]

"""glTF 2.0 both ways: export a CrowdAnimation with its bodies to one binary glTF (.glb),
and import a user's skinned character (Blender, Mixamo, Ready Player Me, VRM names) as a
body record ``{"model": "gltf", "path": ...}``.
"""

from crowdstudy.gltf.export import export_gltf

__all__ = ["export_gltf"]

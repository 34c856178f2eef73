"""``crowdstudy export-usd``: a CrowdAnimation and its bodies as a UsdSkel crowd.

The animation is laid out as glTF (:func:`crowdstudy.gltf.export.build_gltf`: the bodies'
skins on the 24-joint physics skeleton), then written as UsdSkel by
:func:`crowdstudy.interchange.usd_export.gltf_to_usd`; ``crowdstudy import-crowd`` reads it back.
"""

from __future__ import annotations

from pathlib import Path

from crowdstudy.body.gltf_container import GltfFile
from crowdstudy.errors import InvalidInputError

__all__ = ["export_usd"]


def export_usd(anim, path: str | Path, *, bodies=None, up_axis: str = "Z", meters_per_unit: float = 1.0) -> Path:
    """Write ``anim`` (on the 24-joint skeleton, with its bodies) as a UsdSkel crowd."""
    from crowdstudy.gltf.export import build_gltf
    from crowdstudy.interchange.usd_export import gltf_to_usd, usd_layer_bytes

    path = Path(path)
    if path.suffix.lower() not in (".usd", ".usda", ".usdc"):
        raise InvalidInputError(f"output: expected a .usda, .usdc or .usd file, got {str(path)!r}")
    b = build_gltf(anim, bodies=bodies)
    doc = dict(b.doc)
    doc["buffers"] = [{"byteLength": len(b._bin)}]
    gltf = GltfFile(doc, [bytes(b._bin)], path)
    custom = doc["asset"].get("extras", {}).get("crowdstudy", {})
    stage = gltf_to_usd(gltf, up_axis=up_axis, meters_per_unit=meters_per_unit, custom=custom)
    data = usd_layer_bytes(stage, path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(data)
    tmp.replace(path)
    return path

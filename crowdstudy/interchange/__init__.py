"""Crowds made by other tools: import a file's skinned, animated characters as a
:class:`~crowdstudy.scene.CrowdAnimation` on the 24-joint physics skeleton, and write a
corrected animation back into the same file's scene.

* :mod:`crowdstudy.interchange.retarget`: a rig's joint motion <-> the 24 joints' (format
  independent: world matrices of the rig's joints in, world matrices out);
* :mod:`crowdstudy.interchange.gltf_sampling`: glTF animation channels sampled at a frame rate;
* :mod:`crowdstudy.interchange.gltf_crowd`: a glTF file's characters as a CrowdAnimation;
* :mod:`crowdstudy.interchange.gltf_write`: the corrected motion written into the file's scene;
* USD (UsdSkel): :mod:`crowdstudy.body.usd_stage` reads a stage's characters as glTF, so the
  modules above serve it too; :mod:`crowdstudy.interchange.usd_write` writes the corrected
  motion into the stage, :mod:`crowdstudy.interchange.usd_export` writes skinned glTF
  characters as UsdSkel;
* ``crowdstudy import-crowd`` (:mod:`crowdstudy.interchange.cli_import_crowd`).

The joint mapping itself is :mod:`crowdstudy.body.rig_map` (the bodies need it too).
"""

#!/usr/bin/env bash
# Optional: a Python with Blender's bpy module (PyPI wheel, Blender 4.2, about 520 MB) in
# build/bpy-venv, for the tests that have Blender's own USD exporter write UsdSkel files
# and Blender import the corrected ones (tests/test_import_usd.py; they skip without it).
# Debian's blender 3.4 is built without USD. Another Python with bpy: CROWDSTUDY_BPY_PYTHON.
set -euo pipefail
cd "$(dirname "$0")/.."
py="${PYTHON:-python3.11}"
"$py" -m venv build/bpy-venv
build/bpy-venv/bin/pip install --quiet "bpy==4.2.0"
build/bpy-venv/bin/python -c "import bpy; print('bpy', bpy.app.version_string, 'in build/bpy-venv')"

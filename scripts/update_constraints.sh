#!/usr/bin/env bash
# Regenerate constraints.txt: the newest versions that pyproject.toml allows, resolved in a
# throw-away virtual environment, then frozen. Run `make test` afterwards (setup.sh sees the
# new constraints.txt and re-installs .venv with them) and commit constraints.txt.
set -euo pipefail
cd "$(dirname "$0")/.."
LOCK_VENV=build/lock-venv
rm -rf "$LOCK_VENV"
python3 -m venv "$LOCK_VENV"
"$LOCK_VENV/bin/python" -m pip install -q --upgrade pip
"$LOCK_VENV/bin/python" -m pip install -q -e ".[all]"
{
    echo "# Versions tested together (Linux x86_64, Python $("$LOCK_VENV/bin/python" -c 'import sys; print(*sys.version_info[:2], sep=".")')),"
    echo "# used by scripts/setup.sh: pip install -c constraints.txt -e \".[all]\"."
    echo "# Regenerate with scripts/update_constraints.sh (docs/getting-started.md: \"Pinned versions\")."
    "$LOCK_VENV/bin/python" -m pip freeze --all --exclude-editable --exclude pip
} > constraints.txt.new
mv constraints.txt.new constraints.txt
rm -rf "$LOCK_VENV"
echo "[constraints] wrote constraints.txt ($(grep -vc '^#' constraints.txt) packages)"

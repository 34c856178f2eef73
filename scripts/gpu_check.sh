#!/bin/sh
# The GPU checks, in one go, for a machine with an NVIDIA GPU (CUDA for Warp, NVIDIA's EGL
# for the renderer), in about a quarter of an hour:
#
#   1. the gpu-marked tests (tests/test_gpu.py: physics, metrics and renderer against the CPU);
#   2. `crowdstudy bench physics` on the study's sizes (CPU and CUDA rows side by side);
#   3. `crowdstudy bench render` (a frame's passes, the encoder) and its SSIM check;
#   4. `crowdstudy bench render --set` on a sample of the stimulus set.
#
# Usage: scripts/gpu_check.sh [OUT]   (after `make setup`; OUT defaults to build/gpu-check)
# Each step's output goes to OUT/NAME.txt and its report to OUT/NAME.json; a failing step is
# recorded and the others still run. Publish with `make results RESULTS="..."` after copying
# the reports you keep into build/bench/ under new names (e.g. render_set_gpu).
set -u
OUT=${1:-build/gpu-check}
VENV=${VENV:-.venv}
mkdir -p "$OUT"
export CROWDSTUDY_CACHE="${CROWDSTUDY_CACHE:-$PWD/build/cache}"
export WARP_CACHE_PATH="${WARP_CACHE_PATH:-$PWD/build/warp-cache}"
export MPLBACKEND=Agg
nvidia-smi > "$OUT/nvidia-smi.txt" 2>&1 || echo "nvidia-smi: not found (no NVIDIA driver?)" > "$OUT/nvidia-smi.txt"

status=0
step() {  # step NAME REPORT COMMAND...: run it with a time limit, keep its output and report
    name=$1; report=$2; shift 2
    echo "[gpu-check] $name: $*"
    start=$(date +%s)
    timeout 420 "$@" > "$OUT/$name.txt" 2>&1
    rc=$?
    echo "[gpu-check] $name: exit $rc after $(( $(date +%s) - start )) s"
    [ "$rc" -eq 0 ] || status=1
    if [ -n "$report" ] && [ -f "build/bench/$report.json" ]; then cp "build/bench/$report.json" "$OUT/$name.json"; fi
}

step pytest-gpu "" "$VENV/bin/python" -m pytest -m gpu -q -rs tests/test_gpu.py
step bench-physics physics "$VENV/bin/crowdstudy" bench physics --steps 50 --sizes 20,60,200
step bench-render render "$VENV/bin/crowdstudy" bench render --frames 8
step bench-render-ssim render_ssim "$VENV/bin/crowdstudy" bench render --ssim --frames 4
step bench-render-set render_set "$VENV/bin/crowdstudy" bench render --set --videos 6 --frames 30
echo "[gpu-check] outputs in $OUT"
exit $status

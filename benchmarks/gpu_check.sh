#!/usr/bin/env bash
# The CUDA path on a new GPU node, in at most five minutes, offline: installs the wheelhouse
# (benchmarks/device_wheels.sh, carried beside the checkout) into a --target folder, runs the
# cuda tests (pytest -m cuda tests/test_cuda.py), then measures the GPU rows, and writes them as
# JSON (gpu_check.json, with cuda_tests.log and this script's log beside it) to a folder:
#
#   bash benchmarks/gpu_check.sh OUT_DIR          # or OUT=OUT_DIR bash benchmarks/gpu_check.sh
#   bash benchmarks/gpu_check.sh OUT_DIR --no-install   # this Python's packages, no wheelhouse
#   PYTHON=/path/to/python bash benchmarks/gpu_check.sh OUT_DIR
#
# Options after OUT_DIR go to benchmarks/gpu_rows.py (python benchmarks/gpu_rows.py --help):
# --wheels DIR, --target DIR, --budget SECONDS (default 300), --sections a,b, --cpu-rows.
# Every section runs in a child process under its own timeout, and a hang (mujoco issue #3444:
# EGL renderers hanging in mjr_readPixels with 8 spawned envs on an H200) ends as a failed
# section naming it. Without CUDA the GPU sections are written as skipped, saying that no GPU
# was found, and the check exits 0 when its CPU part (install, imports, EGL context, cuda tests'
# collection) passed; otherwise it exits 1 when any section failed.
# See docs/guides/gpu.md.
set -uo pipefail
started=$(date +%s.%N)
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PYTHON=${PYTHON:-python3}
if [[ $# -gt 0 && $1 != -* ]]; then
    OUT=$1
    shift
fi
if [[ -z ${OUT:-} ]]; then
    echo "gpu_check.sh: name the output folder: bash benchmarks/gpu_check.sh OUT_DIR (or set" \
         "OUT)" >&2
    exit 2
fi
if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 10))' 2>/dev/null; then
    echo "gpu_check.sh: PYTHON=$PYTHON is not a Python 3.10+ (the node's, with torch)" >&2
    exit 2
fi
mkdir -p "$OUT"
# Headless rendering through EGL. A driver mounted under /usr/local/nvidia (containers) is not
# where glvnd looks for its EGL vendor file: point glvnd at it when the usual places have none.
export MUJOCO_GL=${MUJOCO_GL:-egl} PYOPENGL_PLATFORM=${PYOPENGL_PLATFORM:-egl}
vendor=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
if [[ -z ${__EGL_VENDOR_LIBRARY_FILENAMES:-} && -f $vendor ]] \
        && ! ls /usr/share/glvnd/egl_vendor.d/10_nvidia.json \
                /etc/glvnd/egl_vendor.d/10_nvidia.json >/dev/null 2>&1; then
    export __EGL_VENDOR_LIBRARY_FILENAMES=$vendor
fi
cd "$ROOT" || exit 2
"$PYTHON" benchmarks/gpu_rows.py --out "$OUT" --started "$started" "$@" 2>&1 \
    | tee "$OUT/gpu_check.log"

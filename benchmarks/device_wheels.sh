#!/usr/bin/env bash
# The wheels an offline GPU node lacks, for CPython 3.12 on manylinux x86_64, in one folder.
#
#   bash benchmarks/device_wheels.sh [FOLDER]       # default: wheelhouse/ (git-ignored)
#   bash benchmarks/device_wheels.sh --skip scipy   # the node's image has scipy already
#
# The node to plan for (docs/guides/gpu.md): an image with PyTorch 2.11 on Python 3.12, numpy,
# matplotlib, pandas, huggingface_hub, timm (hence torchvision, safetensors, pyyaml) and pytest,
# no network, and a 64 MiB transfer for the checkout and the wheels together. This script
# downloads the project's runtime dependencies that such an image does not have, pinned to the
# versions this project is tested with, without pip's resolver (--no-deps): the closure below
# was worked out by hand from each package's Requires-Dist, so that `pip install --no-index
# --no-deps --target` on the node needs nothing else. It prints the total size and fails when
# it is 64 MiB or more.
#
# PYTHON (default python3) runs pip; any Python with pip will do, the wheels are chosen for
# CPython 3.12 by the flags below, not by the Python that downloads them.
set -euo pipefail

HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PYTHON=${PYTHON:-python3}
DEST=""
SKIP=()
while (($#)); do
    case $1 in
        --skip) SKIP+=("${2:?--skip needs a package name}"); shift 2 ;;
        -h|--help) sed -n '2,17p' "${BASH_SOURCE[0]}"; exit 0 ;;
        -*) echo "device_wheels.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
        *) DEST=$1; shift ;;
    esac
done
DEST=${DEST:-$HERE/wheelhouse}

# The closure, each pinned (name==version), grouped by the package that needs it. Versions: the
# ones the project's venv runs (torch 2.14.1); a Python 3.12 venv with torch 2.11 ran the test
# suite with the same ones (but scipy 1.18.1), and the GPU check's CPU path from these wheels.
WHEELS=(
    # TorchRL and TensorDict. tensordict's compiled part (_C.so) does not link against torch,
    # so it loads under any torch; torchrl's (_torchrl.so, only the prioritized replay's segment
    # trees, which the project does not use) is built against one torch release and is skipped
    # by torchrl with a warning when it does not load: both work on torch 2.11.
    torchrl==0.14.1 tensordict==0.14.3 hoptorch==0.1.4 pyvers==0.2.3 cloudpickle==3.1.3
    orjson==3.13.0 importlib_metadata==10.2.0 lazy-importer==0.1.0 zipp==4.1.2
    # MuJoCo (its own Requires-Dist: absl-py, etils[epath] -> fsspec, typing_extensions (both
    # torch's, so on the node), zipp; glfw; PyOpenGL, which the EGL renderer calls).
    mujoco==3.3.0 absl-py==2.5.1 etils==1.15.0 glfw==2.11.0 PyOpenGL==3.1.10
    # Metaworld: gymnasium, scipy (every env module imports scipy.spatial.transform when
    # metaworld is imported), imageio (pillow: matplotlib's and torchvision's, so on the node).
    metaworld==3.1.1 scipy==1.17.1 imageio==2.38.2 gymnasium==1.4.0 farama-notifications==0.0.6
    # OpenCLIP (huggingface_hub, safetensors, timm, torchvision, tqdm: on the node).
    open_clip_torch==3.3.0 ftfy==6.3.1 regex==2026.11.19 wcwidth==0.9.4
    # Hydra, its joblib launcher (the studies' local sweeps) and OmegaConf (pyyaml: on the node;
    # antlr4-python3-runtime is built below, it has no wheel on PyPI).
    hydra-core==1.3.8 omegaconf==2.3.1 hydra-joblib-launcher==1.2.0 joblib==1.6.0
)
# Not downloaded, deliberately: the GPU check (benchmarks/gpu_check.sh) runs without them.
#   wandb (logger.backend=wandb only), rliable and its arch/statsmodels (the reports),
#   hydra-submitit-launcher and submitit (Slurm sweeps), pytest-xdist, pytest-benchmark and
#   ruff (the check runs pytest in one process, on the cuda tests alone).
# Not downloaded, the node's image has them: torch, torchvision, numpy, matplotlib, pandas,
#   huggingface_hub, timm, safetensors, pyyaml, pytest, and what those require: filelock,
#   fsspec, typing_extensions, sympy, jinja2 (torch), tqdm, packaging (huggingface_hub),
#   pillow (matplotlib, torchvision), iniconfig and pluggy (pytest).
SDISTS=(antlr4-python3-runtime==4.9.3)  # hydra-core and omegaconf pin 4.9.*; sdist only

keep() {  # keep NAME==VERSION unless --skip named it
    local name=${1%%==*} skipped
    for skipped in "${SKIP[@]}"; do
        [[ ${name,,} == "${skipped,,}" ]] && return 1
    done
    return 0
}

mkdir -p "$DEST"
rm -f "$DEST"/*.whl  # exactly this list: a wheel left from another version would stop the install
selected=()
for wheel in "${WHEELS[@]}"; do keep "$wheel" && selected+=("$wheel"); done
# pip matches platform tags exactly: every manylinux glibc level up to 2.28 (RHEL 8, the oldest
# glibc a cluster node commonly has), so that a wheel tagged for any of them is found.
platforms=(--platform manylinux1_x86_64 --platform manylinux2010_x86_64
           --platform manylinux2014_x86_64)
for minor in $(seq 17 28); do platforms+=(--platform "manylinux_2_${minor}_x86_64"); done
"$PYTHON" -m pip download --quiet --disable-pip-version-check --no-deps --only-binary=:all: \
    --python-version 3.12 --implementation cp --abi cp312 --abi abi3 --abi none \
    "${platforms[@]}" --platform any -d "$DEST" "${selected[@]}"
for sdist in "${SDISTS[@]}"; do
    keep "$sdist" || continue
    # Pure Python: the wheel built here (py3-none-any) installs on the node's Python 3.12.
    "$PYTHON" -m pip wheel --quiet --disable-pip-version-check --no-deps -w "$DEST" "$sdist"
done
# metaworld's wheel is 35 MiB, 34 of them PNG textures, most of which no model file uses: the
# wheel is rewritten without the images that no XML in it names (each reference resolved against
# every XML's folder: a superset of what MuJoCo loads), and without their RECORD lines. The
# models, and the frames they render, stay the same.
if keep metaworld==; then
    "$PYTHON" - "$DEST"/metaworld-*.whl <<'PY'
"""Rewrite a metaworld wheel (argv[1]) without the images that none of its XML files names."""
import os
import posixpath
import re
import sys
import zipfile

path = sys.argv[1]
with zipfile.ZipFile(path) as wheel:
    members = {info.filename: wheel.read(info) for info in wheel.infolist()}
folders = {posixpath.dirname(name) for name in members if name.endswith(".xml")}
named = {posixpath.normpath(posixpath.join(folder, reference.decode()))
         for name, data in members.items() if name.endswith(".xml")
         for reference in re.findall(rb'file="([^"]+)"', data) for folder in folders}
dropped = {name for name in members
           if name.lower().endswith((".png", ".jpg", ".jpeg")) and name not in named}
record = next(name for name in members if name.endswith(".dist-info/RECORD"))
members[record] = b"".join(line for line in members[record].splitlines(keepends=True)
                           if line.split(b",")[0].decode() not in dropped)
before = os.path.getsize(path)
with zipfile.ZipFile(path + ".tmp", "w", zipfile.ZIP_DEFLATED) as wheel:
    for name, data in members.items():
        if name not in dropped:
            wheel.writestr(name, data)
os.replace(path + ".tmp", path)
print(f"metaworld: {len(dropped)} images that no model file names dropped, "
      f"{before / 2**20:.1f} -> {os.path.getsize(path) / 2**20:.1f} MiB")
PY
fi
for wheel in "$DEST"/*.whl; do
    case $(basename "$wheel") in
        # CPython 3.12's ABI, the stable ABI, or no ABI at all (pure Python, or glfw's bundled
        # C library, which Python never links: py2.py3-none-manylinux2014)
        *-cp312-cp312-*|*-abi3-*|*py3-none-*) ;;
        *) echo "device_wheels.sh: $(basename "$wheel") is not for CPython 3.12" >&2; exit 1 ;;
    esac
done

count=$(find "$DEST" -maxdepth 1 -name '*.whl' | wc -l)
expected=$(( ${#selected[@]} + ${#SDISTS[@]} ))
for sdist in "${SDISTS[@]}"; do keep "$sdist" || expected=$((expected - 1)); done
if ((count != expected)); then
    echo "device_wheels.sh: $count wheels in $DEST, expected $expected (one per pin)" >&2
    exit 1
fi
total=$(find "$DEST" -maxdepth 1 -name '*.whl' -printf '%s\n' | awk '{s += $1} END {print s}')
limit=$((64 * 1024 * 1024))
find "$DEST" -maxdepth 1 -name '*.whl' -printf '%s %f\n' | sort -rn \
    | awk '{printf "%9.2f MiB  %s\n", $1 / 1048576, $2}'
tracked=$(git -C "$HERE" ls-files -z | (cd "$HERE" && xargs -0 stat -c %s 2>/dev/null) \
          | awk '{s += $1} END {print s + 0}')
largest=$(find "$DEST" -maxdepth 1 -name '*.whl' -printf '%s %f\n' | sort -rn | head -1)
awk -v t="$total" -v c="$count" -v k="$tracked" -v d="${DEST#"$HERE"/}" -v l="$largest" 'BEGIN {
    printf "%d wheels, %.1f MiB in %s (the checkout'"'"'s tracked files: %.1f MiB more)\n",
           c, t / 1048576, d, k / 1048576
    if (t + k >= 64 * 1048576)
        printf "note: with the checkout %.1f MiB, over a 64 MiB transfer that carries both:" \
               " --skip what the node'"'"'s image has (the largest: %s, %.1f MiB)\n",
               (t + k) / 1048576, substr(l, index(l, " ") + 1), l / 1048576 }'
if ((total >= limit)); then
    echo "device_wheels.sh: the wheels take 64 MiB or more; a node's transfer holds 64 MiB" \
         "with the checkout (--skip what its image has)" >&2
    exit 1
fi

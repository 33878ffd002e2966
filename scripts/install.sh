#!/usr/bin/env bash
# Set up zbuf_occlude on a fresh Linux machine: system OpenGL (Mesa EGL + llvmpipe, and
# OSMesa as the fallback) if missing, then a virtual environment in .venv.  Safe to run again.
#
#   bash scripts/install.sh          the package and what `generate` needs (no PyTorch)
#   bash scripts/install.sh --test   also the extras test, learn (PyTorch) and docs, to run the tests
#
# --test keeps a PyTorch that .venv already has.  Otherwise, on a machine without an NVIDIA
# GPU it installs PyTorch's CPU build first (from PyTorch's CPU index; where that cannot be
# reached, torch==$TORCH_CPU_FALLBACK, which a local wheel folder may serve as the CPU build),
# so that the learn extra's version range is already met and pip never pulls the multi-GB
# CUDA build.  With an NVIDIA GPU, the learn extra takes PyPI's (CUDA) build.
set -euo pipefail
cd "$(dirname "$0")/.."

usage() { sed -n '5,6s/^#   //p' "$0"; }
mode=core
case "${1:-}" in
    "") ;;
    --test) mode=test ;;
    -h | --help) usage; exit 0 ;;
    *) echo "install.sh: unknown option '$1'" >&2; usage >&2; exit 2 ;;
esac
[ $# -le 1 ] || { echo "install.sh: one option at most, got: $*" >&2; exit 2; }

need_apt=()
ldconfig -p | grep -q 'libEGL_mesa.so' || need_apt+=(libegl1 libegl-mesa0 libgl1-mesa-dri)
ldconfig -p | grep -q 'libOSMesa.so' || need_apt+=(libosmesa6)
if [ ${#need_apt[@]} -gt 0 ]; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "installing system packages: ${need_apt[*]}"
        apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_apt[@]}" >/dev/null \
            || echo "warning: could not install ${need_apt[*]}; OpenGL may be unavailable" >&2
    else
        echo "warning: missing system packages ${need_apt[*]} (install them with apt-get as root)" >&2
    fi
fi

PYTHON=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
    echo "creating the virtual environment .venv ($("$PYTHON" --version 2>&1))"
    "$PYTHON" -m venv .venv
fi
pip=(.venv/bin/python -m pip)
echo "upgrading pip in .venv"
"${pip[@]}" install -q --upgrade pip

if [ "$mode" = core ]; then
    echo "installing zbuf_occlude and its dependencies into .venv (numpy, trimesh, embreex, numba, moderngl, ...; a minute or more, quiet)"
    "${pip[@]}" install -q -e .
else
    # The CPU build where PyTorch's index is out of reach (this version's CPU wheel may be in a local wheel folder).
    TORCH_CPU_FALLBACK=${TORCH_CPU_FALLBACK:-2.13.0}
    TORCH_CPU_INDEX=${TORCH_CPU_INDEX:-https://download.pytorch.org/whl/cpu}
    if .venv/bin/python -c 'import torch' 2>/dev/null; then
        echo "keeping the installed PyTorch $(.venv/bin/python -c 'import torch; print(torch.__version__)')"
    elif command -v nvidia-smi >/dev/null && nvidia-smi -L 2>/dev/null | grep -q '^GPU'; then
        echo "NVIDIA GPU found: the learn extra installs PyTorch's CUDA build"
    else
        echo "no NVIDIA GPU: installing PyTorch's CPU build"
        # --isolated and no config file: only the CPU index, never another index's CUDA build
        PIP_CONFIG_FILE=/dev/null "${pip[@]}" install -q --isolated --timeout 30 --retries 1 torch \
            --index-url "$TORCH_CPU_INDEX" 2>/dev/null \
            || { echo "PyTorch's CPU index is out of reach: installing torch==$TORCH_CPU_FALLBACK"
                 "${pip[@]}" install -q "torch==$TORCH_CPU_FALLBACK"; }
    fi
    echo "installing zbuf_occlude with the test, learn and docs extras into .venv (several minutes, quiet)"
    "${pip[@]}" install -q -e ".[test,learn,docs]"
fi
# The package is installed in place, so pip compiles none of it: compile it here, or where
# PYTHONDONTWRITEBYTECODE is set every command compiles it anew (0.4 s a start on 2 cores).
echo "compiling the package's Python files"
.venv/bin/python -m compileall -q zbuf_occlude
# numba compiles the kernels on their first call (seconds on the first mesh): compile them now
# into numba's on-disk cache, which every later process loads (zbuf_occlude/visibility/warmup.py,
# zbuf_occlude/sensors/warmup.py).
echo "compiling the numba kernels (once, into numba's cache; a minute or two, quiet)"
{ .venv/bin/python -m zbuf_occlude.visibility.warmup -q && .venv/bin/python -m zbuf_occlude.sensors.warmup -q; } \
    || echo "warning: the numba kernels were not all compiled now; they compile on first use" >&2
echo "checking the OpenGL context and the visibility methods (zbuf-occlude info)"
.venv/bin/zbuf-occlude info

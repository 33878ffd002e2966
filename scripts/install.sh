#!/usr/bin/env bash
# Set up zbuf_occlude on a fresh Linux machine: system OpenGL (Mesa EGL + llvmpipe, and
# OSMesa as the fallback) if missing, then a virtual environment in .venv with the package
# and its test extras.  Safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."

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
[ -x .venv/bin/python ] || "$PYTHON" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e ".[test,learn]"  # learn: torch==2.13.0, the CPU wheel here
.venv/bin/zbuf-occlude info

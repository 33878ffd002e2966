#!/usr/bin/env bash
# The GPU benchmark in one command: bash benchmarks/gpu.sh OUT [--smoke] [--allow-software] [--force]
#                                     [--points N,N,...] [--poses SPEC] [--no-farm]
#
# On a machine with an NVIDIA GPU: checks that EGL renders on the NVIDIA driver (not a
# software rasteriser such as llvmpipe; exit 3 otherwise, unless --allow-software), then
#   1. visibility at 100k, 1M and 10M points, 15 poses, methods interleaved pose by pose:
#      zbuffer-exact, zbuffer, embree-fast (one-shot and kept scene), auto's choice after its
#      calibration (ZBUF_OCCLUDE_AUTO=calibrate), and the peers (Open3D RaycastingScene,
#      NVIDIA Warp on CPU and CUDA, trimesh + Embree) -- benchmarks/bench_visibility_peers.py;
#   2. zbuffer-exact stage by stage (bin passes, prefix sum, points pass, read-back, unpacking)
#      at the same point counts -- benchmarks/profile_gpu_exact.py;
#   3. the farm at the paper's shape: 200 objects x paper100 poses x 10 samples x 2048 points
#      (the meshes of ../shared/data/modelnet_subset, else the shipped data/samples, repeated
#      as distinct objects), one worker per CPU, dense and compact storage -- benchmarks/bench_farm.py;
#   4. occlusion on the fly: DataLoader samples/s beside a stored data set -- benchmarks/bench_on_the_fly.py;
#   5. point-splat visibility: the GPU z-buffer's masks and buffers against the CPU's on the shipped
#      meshes, 2,048 and 10,000 points, 16 poses -- benchmarks/agreement_point_splats.py; and a GPU
#      view part by part beside the CPU's whole view, up to 100,000 points -- benchmarks/profile_point_splats.py;
# and writes OUT/gpu.md: a Markdown report naming the device (OpenGL renderer string,
# nvidia-smi's GPU name and driver), with the tables.  --smoke: tiny sizes, any renderer
# (the CPU half runs in CI: tests/test_benchmarks.py).  --force: measure even when the load
# average exceeds the CPU count (the visibility table is then flagged; without it, exit 3).
set -euo pipefail

usage() { echo "usage: bash benchmarks/gpu.sh OUT [--smoke] [--allow-software] [--force] [--points N,N,...] [--poses SPEC] [--no-farm]" >&2; }
out="" smoke=0 allow_sw=0 force=() points_arg="" poses_arg="" farm_run=1 next=""
for arg in "$@"; do
    if [ -n "$next" ]; then printf -v "$next" '%s' "$arg"; next=""; continue; fi
    case "$arg" in
        --points) next=points_arg ;;
        --poses) next=poses_arg ;;
        --no-farm) farm_run=0 ;;
        --smoke) smoke=1; allow_sw=1 ;;
        --allow-software) allow_sw=1 ;;
        --force) force=(--force) ;;
        -h|--help) usage; exit 0 ;;
        -*) echo "gpu.sh: unknown option '$arg'" >&2; usage; exit 2 ;;
        *) if [ -n "$out" ]; then echo "gpu.sh: one OUT folder, got '$out' and '$arg'" >&2; exit 2; fi; out="$arg" ;;
    esac
done
if [ -z "$out" ] || [ -n "$next" ]; then usage; exit 2; fi

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
py="${PYTHON:-$root/.venv/bin/python}"
[ -x "$py" ] || py="$(command -v python3)"
export PYTHONPATH="$root${PYTHONPATH:+:$PYTHONPATH}"
mkdir -p "$out"

gpu_name="$(nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>/dev/null | head -n 1 || true)"
[ -n "$gpu_name" ] || gpu_name="none (nvidia-smi not found or no GPU)"
renderer="$("$py" -c "
from zbuf_occlude.render.context import shared_context
info = shared_context().info
print(f\"{info['GL_RENDERER']}, OpenGL {info['GL_VERSION']}\")
" 2>&1 | tail -n 1)" || { echo "gpu.sh: no OpenGL context: $renderer" >&2; exit 3; }
software="$("$py" -c "
import sys
from zbuf_occlude.render.context import is_software_renderer
print(int(is_software_renderer(sys.argv[1])))
" "$renderer")"
echo "gpu.sh: GPU: $gpu_name; OpenGL renderer: $renderer" >&2
if [ "$software" = 1 ] && [ "$allow_sw" = 0 ]; then
    echo "gpu.sh: EGL renders with a software rasteriser ($renderer), not the NVIDIA driver: check the driver's EGL" \
         "vendor library (__EGL_VENDOR_LIBRARY_FILENAMES=/usr/share/glvnd/egl_vendor.d/10_nvidia.json), or pass --allow-software" >&2
    exit 3
fi

meshes="$root/../shared/data/modelnet_subset"
[ -d "$meshes" ] || meshes="$root/data/samples"
if [ "$smoke" = 1 ]; then
    points="2000" poses="fibonacci:3" farm=(--objects 2 --views fibonacci:2 --samples-per-view 2 --points 256 --dense-points 4096 --workers 1 --storage dense)
    peers=(--smoke) on_the_fly=(--views 2 --points 256 --dense 2048 --batch 4 --width 0.125 --repeats 1)
    splat_agreement=(--points 256 --poses fibonacci:2 --meshes 2) splat_profile=(--points 256 --poses fibonacci:2 --meshes 1)
else
    workers="$(nproc)"
    points="100000,1000000,10000000" poses="fibonacci:15" farm=(--objects 200 --views paper100 --samples-per-view 10 --workers "$workers" --storage dense,compact)
    splat_agreement=(--points 2048,10000 --poses fibonacci:16) splat_profile=(--points 2048,10000,100000 --poses fibonacci:16)
    peers=() on_the_fly=(--views 16 --workers "$(( workers / 2 > 1 ? workers / 2 : 1 ))" --threads "$(( workers / 2 > 1 ? workers / 2 : 1 ))" --width 0.25 --repeats 2)
fi
[ -z "$points_arg" ] || points="$points_arg"
[ -z "$poses_arg" ] || poses="$poses_arg"

auto_choice="$(ZBUF_OCCLUDE_AUTO=calibrate "$py" -c "
from zbuf_occlude.visibility.auto import calibrate, choose_method
print(f'kept session: {choose_method()} (s per view: {calibrate()}); one-shot call: '
      f'{choose_method(one_shot=True)} (s per view: {calibrate(one_shot=True)})')
" 2>/dev/null | tail -n 1)"

ZBUF_OCCLUDE_AUTO=calibrate "$py" "$root/benchmarks/bench_visibility_peers.py" "${peers[@]}" "${force[@]}" --gpu-methods \
    --points "$points" --poses "$poses" > "$out/visibility.md"
"$py" "$root/benchmarks/profile_gpu_exact.py" --points "$points" --poses "$poses" > "$out/profile.md"
"$py" "$root/benchmarks/agreement_point_splats.py" "${splat_agreement[@]}" > "$out/point_splat_agreement.md"
"$py" "$root/benchmarks/profile_point_splats.py" "${splat_profile[@]}" > "$out/point_splat_profile.md"
if [ "$farm_run" = 1 ]; then
    "$py" "$root/benchmarks/bench_farm.py" --root "$meshes" "${farm[@]}" --markdown > "$out/farm.md"
    "$py" "$root/benchmarks/bench_on_the_fly.py" "${on_the_fly[@]}" > "$out/on_the_fly.md"
else
    echo "# not run (--no-farm)" > "$out/farm.md"; echo "# not run (--no-farm)" > "$out/on_the_fly.md"
fi

{
    echo "# GPU benchmark$([ "$smoke" = 1 ] && echo " (smoke: tiny sizes)")"
    echo
    echo "| device | |"
    echo "|---|---|"
    echo "| GPU (nvidia-smi: name, driver, memory) | $gpu_name |"
    echo "| OpenGL renderer (EGL) | $renderer |"
    echo "| CPU | $(grep -m 1 'model name' /proc/cpuinfo 2>/dev/null | cut -d: -f2- | sed 's/^ //') ($(nproc) CPUs) |"
    echo "| \`auto\`'s choice after calibration | $auto_choice |"
    echo "| date, commit | $(date -u +%Y-%m-%dT%H:%MZ), $(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown) |"
    echo
    echo "Command: \`bash benchmarks/gpu.sh $*\`"
    echo
    cat "$out/visibility.md"
    echo
    sed 's/^# /## /' "$out/profile.md"
    echo
    echo "## The farm at the paper's shape"
    echo
    sed 's/^# /- /' "$out/farm.md"  # (its comment lines as a list, not headings)
    echo
    echo "## Occlusion on the fly"
    echo
    sed 's/^# /- /' "$out/on_the_fly.md"
    echo
    echo "## Point-splat visibility: GPU against CPU"
    echo
    sed 's/^# /- /' "$out/point_splat_agreement.md"
    echo
    sed 's/^# /- /; s/^## /### /' "$out/point_splat_profile.md"
} > "$out/gpu.md"
echo "gpu.sh: wrote $out/gpu.md" >&2

#!/usr/bin/env bash
# Six `zbuf-occlude experiment sim2real` runs in one command on a borrowed GPU machine: voxnet, pointnet
# and 3dmfv, each without and with ON_ARGS, 5 seeds, side by side, training on CUDA.
#
#   bash docs/results/sim2real/returns/device_runs.sh ON_ARGS...      e.g.  --returns 2
#
# The runs are those of docs/results/sim2real.md, "With several returns per pulse" (--scale quick --seeds 5
# --up-map 'bush/openglforest__*=+y' --no-progress), with --threads 2 --device cuda and their own --out each.
# First a smoke run (voxnet, ON_ARGS, 1 epoch, 8 clouds per class, 64 points, 1 seed) that must pass; then the
# six in parallel, each pinned to 2 cores (the core count of the 2-core machine the documented runs had), each
# stopped when the script's time limit is near so that what they wrote still comes back.  At the end each
# run's folder (without its *.pt checkpoints) is packed into $OUT/NAME.tar.gz, every log into $OUT/logs.tar.gz,
# and the six table.md files are printed.  Exit status 0 when all six finished with status 0.
#
# On the GPU machine (DEVICE_LOCAL unset), run from the repository root with .whl/ and .devdata/ carried:
#   - .whl/*.whl: the runtime dependencies that machine lacks (Python 3.12 manylinux x86-64 wheels), installed
#     with --no-deps into $SITE; .whl/fallback/*.whl: each installed only where that machine's own copy is
#     missing or older than this package (or pydantic) needs (typing_extensions, filelock, lazy_loader);
#   - .devdata/data.tar.xz: street_objects/ and lidarnet_v2_partial/ (research-only data; never committed),
#     unpacked into $DATA_DIR.
# Where the working tree with both is over the device tool's 64 MiB, two calls on one warm machine: the first
# carries .whl and copies it (`mkdir -p /tmp/whl && cp -r .whl/. /tmp/whl/`), the second carries .devdata and
# sets WHEEL_DIR=/tmp/whl.  The machine goes back after 30 s idle, so make the second call at once.
#
# The occluded set's HSR method stays `auto` (settings.json: method "auto"), and auto is made to pick
# embree-fast (ZBUF_OCCLUDE_AUTO): the method auto picks on a machine with a software OpenGL renderer, as the
# documented runs had (zbuf_occlude.visibility.auto), and one that needs no OpenGL.  Left to itself on a GPU
# machine auto would try an EGL context and, where one comes up, time zbuffer-exact against embree-fast.
# moderngl is still carried: zbuf_occlude.visibility.auto imports zbuf_occlude.render.context, which imports
# it; no context is made.
#
# Environment (defaults on the GPU machine / with DEVICE_LOCAL=1):
#   DEVICE_LOCAL   1: this machine's .venv and ../shared/data, no install, no unpacking (a rehearsal)
#   SMOKE          1: the six runs also take the smoke run's tiny sizes (a rehearsal)
#   DEVICE         torch device of every run (cuda / cpu)
#   OUT            where the packed results go (the device tool's $OUT / /tmp/device_runs/out)
#   RUNS_DIR       the runs' folders and logs; must not exist yet (/tmp/runs / /tmp/device_runs/runs)
#   DATA_DIR       holds street_objects/ and lidarnet_v2_partial/ (/tmp/data / ../shared/data)
#   PY             Python (python3 / .venv/bin/python);  SITE  where the wheels go (/tmp/site)
#   WHEEL_DIR      (.whl);  DATA_TAR  (.devdata/data.tar.xz)
#   SEEDS          (5);  CORES_PER_RUN  (2);  LIMIT_S  seconds the whole script may take (510)
#   OFF_LABEL, ON_LABEL   run names are MODEL_OFF_LABEL and MODEL_ON_LABEL (off, on)
set -euo pipefail

t_start=$(date +%s)
die() { echo "device_runs: $*" >&2; exit 1; }
say() { echo "device_runs: [$(($(date +%s) - t_start)) s] $*"; }

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../../../.." && pwd)
cd "$ROOT"
{ [ -f pyproject.toml ] && [ -d zbuf_occlude ]; } || die "not the repository root: $ROOT"
[ $# -gt 0 ] || die "usage: bash docs/results/sim2real/returns/device_runs.sh ON_ARGS... (e.g. --returns 2): the 'on' runs' extra options"
ON_ARGS=("$@")

MODELS=(voxnet pointnet 3dmfv)
SMOKE_MODEL=voxnet
SMOKE_SIZES=(--epochs 1 --per-class 8 --points 64 --seeds 1)
SMOKE_LIMIT_S=120     # the smoke run is stopped after this; it should take under 60 s
PACK_MARGIN_S=30      # left at the end for packing and printing
COMMON=(--scale quick --up-map 'bush/openglforest__*=+y' --no-progress)
LIMIT_S=${LIMIT_S:-510}
SEEDS=${SEEDS:-5}
CORES_PER_RUN=${CORES_PER_RUN:-2}
OFF_LABEL=${OFF_LABEL:-off}
ON_LABEL=${ON_LABEL:-on}
[ "$OFF_LABEL" != "$ON_LABEL" ] || die "OFF_LABEL and ON_LABEL must differ"

if [ "${DEVICE_LOCAL:-}" = 1 ]; then
    PY=${PY:-$ROOT/.venv/bin/python}
    DEVICE=${DEVICE:-cpu}
    OUT=${OUT:-/tmp/device_runs/out}
    RUNS_DIR=${RUNS_DIR:-/tmp/device_runs/runs}
    DATA_DIR=${DATA_DIR:-$ROOT/../shared/data}
else
    PY=${PY:-python3}
    DEVICE=${DEVICE:-cuda}
    [ -n "${OUT:-}" ] || die "\$OUT is not set (the device tool sets it; or set DEVICE_LOCAL=1 for a rehearsal here)"
    RUNS_DIR=${RUNS_DIR:-/tmp/runs}
    DATA_DIR=${DATA_DIR:-/tmp/data}
fi
SITE=${SITE:-/tmp/site}
WHEEL_DIR=${WHEEL_DIR:-.whl}
DATA_TAR=${DATA_TAR:-.devdata/data.tar.xz}
command -v "$PY" >/dev/null || die "no Python at '$PY'"
[ ! -e "$RUNS_DIR" ] || die "RUNS_DIR $RUNS_DIR exists: remove it, or set RUNS_DIR to a new folder"
mkdir -p "$OUT" "$RUNS_DIR/logs"
LOGS=$RUNS_DIR/logs

# -- install and unpack (the GPU machine only) -------------------------------------------------------
if [ "${DEVICE_LOCAL:-}" != 1 ]; then
    compgen -G "$WHEEL_DIR/*.whl" >/dev/null || die "no wheels in $WHEEL_DIR/ (carry .whl)"
    [ -f "$DATA_TAR" ] || die "no $DATA_TAR (carry .devdata)"
    # which fallback wheels this Python needs: its own copy missing or older than required (before $SITE is on the path)
    mapfile -t fallback < <("$PY" - "$WHEEL_DIR/fallback" <<'EOF'
import importlib.metadata as md
import pathlib
import sys

try:
    from packaging.version import Version
except ImportError:
    from pip._vendor.packaging.version import Version

# the least version pyproject.toml (filelock, lazy-loader) or the carried pydantic (typing_extensions) needs
NEED = {"typing_extensions": "4.16.0", "filelock": "4.2", "lazy_loader": "0.6"}
for whl in sorted(pathlib.Path(sys.argv[1]).glob("*.whl")):
    name = whl.name.split("-")[0]
    try:
        have = md.version(name)
    except md.PackageNotFoundError:
        have = None
    if name not in NEED or have is None or Version(have) < Version(NEED[name]):
        print(whl)
    print(f"fallback {name}: this machine has {have}, needs {NEED.get(name)}", file=sys.stderr)
EOF
    ) || die "could not read this machine's package versions"
    say "installing $(compgen -G "$WHEEL_DIR/*.whl" | wc -l) wheels and ${#fallback[@]} fallback wheels into $SITE"
    "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target "$SITE" \
        "$WHEEL_DIR"/*.whl ${fallback[@]+"${fallback[@]}"} >"$LOGS/pip.log" 2>&1 \
        || { cat "$LOGS/pip.log" >&2; die "pip install of $WHEEL_DIR failed"; }
    export PYTHONPATH=$SITE:$ROOT
    say "unpacking $DATA_TAR into $DATA_DIR"
    mkdir -p "$DATA_DIR"
    # Python's tarfile, not tar -J: no xz program needed (filter "data" where this Python has it: 3.12, 3.11.4)
    "$PY" -c 'import sys, tarfile
tarfile.open(sys.argv[1]).extractall(sys.argv[2], **({"filter": "data"} if hasattr(tarfile, "data_filter") else {}))' \
        "$DATA_TAR" "$DATA_DIR" || die "could not unpack $DATA_TAR"
else
    export PYTHONPATH=$ROOT
fi
for d in street_objects lidarnet_v2_partial; do [ -d "$DATA_DIR/$d" ] || die "no $DATA_DIR/$d"; done

# -- the environment every run shares ------------------------------------------------------------------
export ZBUF_OCCLUDE_AUTO=embree-fast          # see the header: auto's choice on the documented runs' machine
export NUMBA_CACHE_DIR=$RUNS_DIR/numba_cache  # the smoke run compiles the kernels once; the six load them
export PYTHONUNBUFFERED=1 MPLBACKEND=Agg
export OMP_NUM_THREADS=$CORES_PER_RUN MKL_NUM_THREADS=$CORES_PER_RUN OPENBLAS_NUM_THREADS=$CORES_PER_RUN NUMBA_NUM_THREADS=$CORES_PER_RUN

# versions, the GPU, and an import of every module the sim2real path needs (fails here, not in six logs)
"$PY" - "$DEVICE" <<'EOF' 2>&1 | tee "$LOGS/environment.txt" || die "the environment check failed (above)"
import hashlib
import importlib
import importlib.metadata as md
import os
import pathlib
import platform
import sys

device = sys.argv[1]
print(f"python {platform.python_version()} at {sys.executable}; {os.cpu_count()} CPUs, {len(os.sched_getaffinity(0))} usable")
for dist in ("numpy", "scipy", "torch", "numba", "llvmlite", "h5py", "networkx", "pillow", "tqdm", "charset-normalizer",
             "filelock", "lazy-loader", "typing_extensions", "scikit-learn", "matplotlib", "lxml", "python-dateutil",
             "trimesh", "moderngl", "glcontext", "embreex", "rtree", "pydantic", "pydantic-core", "annotated-types",
             "typing-inspection", "pycollada", "laspy", "lazrs", "pypcd4", "python-neo-lzf"):
    try:
        where = md.distribution(dist).locate_file("")
        print(f"  {dist} {md.version(dist)} ({where})")
    except md.PackageNotFoundError:
        print(f"  {dist} MISSING")
modules = ["numpy", "scipy", "torch", "numba", "h5py", "networkx", "PIL", "tqdm", "charset_normalizer", "filelock", "lazy_loader",
           "trimesh", "moderngl", "embreex", "rtree", "pydantic", "collada", "laspy", "lazrs", "pypcd4", "sklearn", "matplotlib",
           "zbuf_occlude.cli.main", "zbuf_occlude.experiments.sim2real", "zbuf_occlude.visibility.embree_fast",
           "zbuf_occlude.dataset.schema", "zbuf_occlude.learn.training"]
bad = []
for name in modules:
    try:
        importlib.import_module(name)
    except Exception as exc:  # noqa: BLE001 - every failure is reported, then the script stops
        bad.append(f"{name}: {type(exc).__name__}: {exc}")
import zbuf_occlude

print(f"zbuf_occlude {zbuf_occlude.__version__} from {pathlib.Path(zbuf_occlude.__file__).parent}")
code, package = hashlib.sha256(), pathlib.Path(zbuf_occlude.__file__).parent
for path in sorted(package.rglob("*.py")):
    code.update(path.relative_to(package).as_posix().encode() + b"\0" + path.read_bytes())
print(f"sha256 of zbuf_occlude/**/*.py (relative path, NUL, bytes; sorted): {code.hexdigest()}")
if not bad:
    import torch

    from zbuf_occlude.learn.training import resolve_device
    from zbuf_occlude.visibility.auto import choose_method

    print(f"torch {torch.__version__}, built with CUDA {torch.version.cuda}, cuda available {torch.cuda.is_available()}")
    if torch.cuda.is_available():
        print(f"GPU {torch.cuda.get_device_name(0)}, {torch.cuda.get_device_properties(0).total_memory / 2**30:.0f} GiB")
    try:
        resolve_device(device)
    except Exception as exc:  # noqa: BLE001
        bad.append(f"--device {device}: {exc}")
    print(f"auto method: {choose_method()} (ZBUF_OCCLUDE_AUTO={os.environ.get('ZBUF_OCCLUDE_AUTO')})")
    print("glcontext imported (an OpenGL context was made):", "glcontext" in sys.modules)
    try:  # every subcommand's parser, as a run builds it
        from zbuf_occlude.cli.main import build_parser

        build_parser()
    except Exception as exc:  # noqa: BLE001
        bad.append(f"zbuf-occlude's argument parser: {type(exc).__name__}: {exc}")
for line in bad:
    print(f"FAILED {line}")
sys.exit(1 if bad else 0)
EOF
read -ra CPUS <<<"$("$PY" -c 'import os; print(*sorted(os.sched_getaffinity(0)))')"  # the CPUs this script may use
say "nproc $(nproc), usable CPUs ${CPUS[*]}; device $DEVICE; data $DATA_DIR; runs $RUNS_DIR; out $OUT; ON_ARGS: ${ON_ARGS[*]}"
if command -v nvidia-smi >/dev/null; then
    nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader | tee -a "$LOGS/environment.txt" || true
fi

sim2real() {  # sim2real MODEL OUT_FOLDER EXTRA_ARGS...: sets CMD to the command of one run
    local model=$1 out=$2
    shift 2
    CMD=("$PY" -m zbuf_occlude experiment sim2real "$DATA_DIR/street_objects" --real "$DATA_DIR/lidarnet_v2_partial"
         --model "$model" --out "$out" --threads "$CORES_PER_RUN" --device "$DEVICE" "${COMMON[@]}" "$@")
}

pack_and_exit() {  # pack_and_exit STATUS: every run folder (no checkpoints) and the logs into $OUT, then exit
    local status=$1 name
    for name in "${NAMES[@]}"; do
        if [ -d "$RUNS_DIR/$name" ]; then
            tar -czf "$OUT/$name.tar.gz" -C "$RUNS_DIR" --exclude='*.pt' "$name" || echo "device_runs: could not pack $name" >&2
        fi
    done
    tar -czf "$OUT/logs.tar.gz" -C "$RUNS_DIR" logs || echo "device_runs: could not pack the logs" >&2
    ls -l "$OUT"
    exit "$status"
}

# -- the smoke run ------------------------------------------------------------------------------------
NAMES=()
say "smoke run: $SMOKE_MODEL ${ON_ARGS[*]} ${SMOKE_SIZES[*]} (limit $SMOKE_LIMIT_S s)"
sim2real "$SMOKE_MODEL" "$RUNS_DIR/smoke" "${SMOKE_SIZES[@]}" "${ON_ARGS[@]}"
t0=$(date +%s)
if ! timeout --kill-after=10 "$SMOKE_LIMIT_S" "${CMD[@]}" >"$LOGS/smoke.log" 2>&1; then
    tail -n 40 "$LOGS/smoke.log" >&2
    echo "device_runs: the smoke run failed (exit status above; log in $OUT/logs.tar.gz): no real run started" >&2
    pack_and_exit 1
fi
smoke_s=$(($(date +%s) - t0))
say "smoke run passed in $smoke_s s$([ "$smoke_s" -lt 60 ] || echo ' (over the 60 s it should take)')"

# -- the six runs, in parallel ------------------------------------------------------------------------
sizes=(--seeds "$SEEDS")
[ "${SMOKE:-}" = 1 ] && sizes=("${SMOKE_SIZES[@]}")
left=$((LIMIT_S - ($(date +%s) - t_start) - PACK_MARGIN_S))
[ "$left" -ge 60 ] || die "only $left s left of LIMIT_S=$LIMIT_S for the six runs"
say "six runs, sizes ${sizes[*]}, each stopped after $left s"
declare -A PID
i=0
for label in "$ON_LABEL" "$OFF_LABEL"; do  # the 'on' runs first: the slower ones get the first cores
    for model in "${MODELS[@]}"; do
        name=${model}_$label
        NAMES+=("$name")
        if [ "$label" = "$ON_LABEL" ]; then sim2real "$model" "$RUNS_DIR/$name" "${sizes[@]}" "${ON_ARGS[@]}"
        else sim2real "$model" "$RUNS_DIR/$name" "${sizes[@]}"; fi
        cmd=("${CMD[@]}")
        pin=() cores=all
        if command -v taskset >/dev/null; then  # the usable CPUs i*CORES_PER_RUN ..., wrapped round
            cores=${CPUS[$((i * CORES_PER_RUN % ${#CPUS[@]}))]}
            for ((c = 1; c < CORES_PER_RUN; c++)); do cores+=,${CPUS[$(((i * CORES_PER_RUN + c) % ${#CPUS[@]}))]}; done
            if taskset -c "$cores" true 2>/dev/null; then pin=(taskset -c "$cores"); else cores=all; fi
        fi
        (
            set +e
            start=$(date -u +%FT%TZ)
            s0=$(date +%s)
            ${pin[@]+"${pin[@]}"} timeout --kill-after=10 "$left" "${cmd[@]}" >"$LOGS/$name.log" 2>&1
            rc=$?
            stopped=$([ $rc = 124 ] || [ $rc = 137 ] && echo " (stopped at the time limit)")
            printf 'start %s\nend %s\nwall_s %s\nrc %s%s\ncores %s\ncommand %s\n' "$start" "$(date -u +%FT%TZ)" \
                "$(($(date +%s) - s0))" "$rc" "$stopped" "$cores" "${cmd[*]}" >"$LOGS/$name.wall.txt"
            [ -d "$RUNS_DIR/$name" ] && cp "$LOGS/$name.wall.txt" "$RUNS_DIR/$name/wall.txt"
            exit $rc
        ) &
        PID[$name]=$!
        say "started $name (pid ${PID[$name]}, cores $cores): ${cmd[*]}"
        i=$((i + 1))
    done
done

failed=0
for name in "${NAMES[@]}"; do
    rc=0
    wait "${PID[$name]}" || rc=$?
    echo "$name $rc" >>"$LOGS/exit_codes.txt"
    say "$name finished: exit status $rc"
    [ "$rc" = 0 ] || failed=$((failed + 1))
done

for name in "${NAMES[@]}"; do
    echo "================ $name ($(tr '\n' ' ' <"$LOGS/$name.wall.txt" | cut -c1-200))"
    # the table's own lines, not its notes: six of them stay inside the device tool's last 12,000 characters
    if [ -f "$RUNS_DIR/$name/table.md" ]; then grep -E '^(model|\|)' "$RUNS_DIR/$name/table.md"; else tail -n 15 "$LOGS/$name.log"; fi
done
say "$((${#NAMES[@]} - failed)) of ${#NAMES[@]} runs finished with status 0"
pack_and_exit $((failed > 0))

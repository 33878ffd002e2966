#!/usr/bin/env bash
# Mutation testing of the pure-Python core with mutmut 3 (pip install -e '.[dev]').
#
#   scripts/mutation.sh [MODULE ...]      default: every module below
#
# Each MODULE is mutated in its own scratch copy of the working tree (so ./mutants/ and
# the original sources are never touched), against the fast tests that exercise it, and
# a line "MODULE killed/total = score %" is printed and appended to $SCRATCH/scores.txt.
# Survivors are listed in $SCRATCH/MODULE/survivors.txt; `cd $SCRATCH/MODULE && mutmut
# show NAME` prints one as a diff.  Too slow for CI (minutes to hours per module on two
# cores); see docs/development/testing.md for the scores and the survivors judged equivalent.
#
# Environment: PYTHON (default: python), MUTATION_SCRATCH (default: $TMPDIR/zbuf_mutation),
# MUTATION_JOBS (parallel mutants, default 2), NICE (default 10).
set -euo pipefail -f  # -f: mutant-name globs are passed to mutmut, not expanded

ROOT=$(git -C "$(dirname "$0")" rev-parse --show-toplevel)
PYTHON=${PYTHON:-python}
SCRATCH=${MUTATION_SCRATCH:-${TMPDIR:-/tmp}/zbuf_mutation}
JOBS=${MUTATION_JOBS:-2}
NICE=${NICE:-10}

# module -> source file | tests that exercise it (fast ones: mutmut reruns them per mutant)
declare -A SOURCE=(
  [io]=zbuf_occlude/io/clouds.py
  [atomic]=zbuf_occlude/io/atomic.py
  [samples]=zbuf_occlude/geometry/samples.py
  [mesh_cache]=zbuf_occlude/mesh/cache.py
  [cameras]=zbuf_occlude/geometry/cameras.py
  [sampling]=zbuf_occlude/geometry/sampling.py
  [mesh]=zbuf_occlude/mesh/load.py
  [occlude]=zbuf_occlude/pipeline.py
  [oracle]=zbuf_occlude/visibility/oracle.py
  [segment_triangle]=zbuf_occlude/visibility/segment_triangle.py
  [farm_worker]=zbuf_occlude/farm/worker.py
  [dataset]=zbuf_occlude/dataset/reader.py
  [storage]=zbuf_occlude/dataset/storage.py
)
# modules that are part of a file: only these mutants (mutmut name globs) are run and scored
# (none now: the oracle's kernel has its own file, visibility/segment_triangle.py)
declare -A ONLY=()
# modules whose tests open OpenGL contexts: a context inherited across fork hangs, so the
# mutant workers are forked from a server that never ran a test (mutmut's forkserver)
declare -A FORKSERVER=([occlude]=1 [samples]=1 [farm_worker]=1 [dataset]=1 [storage]=1 [oracle]=1)
# pytest -k expressions for modules whose test file has slow parts mutmut need not rerun
declare -A KEXPR=(
  [farm_worker]="not dask and not worker_count"
  [segment_triangle]="not large_mesh and not convex and not same_inputs and not built_once and not cull_drops"
)
declare -A TESTS=(
  [io]="tests/io/test_clouds.py"
  [atomic]="tests/io/test_clouds.py"
  [samples]="tests/geometry/test_samples.py tests/test_pipeline.py tests/dataset/test_reader.py"
  [mesh_cache]="tests/mesh/test_cache.py"
  [cameras]="tests/geometry/test_cameras.py"
  [sampling]="tests/geometry/test_sampling.py"
  [mesh]="tests/mesh/test_load.py"
  [occlude]="tests/test_pipeline.py"
  [oracle]="tests/visibility/test_oracle.py"
  [farm_worker]="tests/farm/test_run.py tests/farm/test_sensor_crops.py"
  [dataset]="tests/dataset/test_reader.py"
  [storage]="tests/dataset/test_storage.py tests/dataset/test_reader.py"
  [segment_triangle]="tests/visibility/test_oracle.py"
)
ORDER=(io atomic mesh_cache cameras sampling samples mesh occlude segment_triangle oracle farm_worker dataset storage)

modules=("$@")
[ ${#modules[@]} -eq 0 ] && modules=("${ORDER[@]}")
for m in "${modules[@]}"; do
  [ -n "${SOURCE[$m]:-}" ] || { echo "unknown module '$m'; choose from: ${ORDER[*]}" >&2; exit 2; }
done
"$PYTHON" -c "import mutmut" 2>/dev/null || { echo "mutmut not installed: pip install -e '.[dev]'" >&2; exit 2; }
MUTMUT=("$PYTHON" -m mutmut)
mkdir -p "$SCRATCH"

for m in "${modules[@]}"; do
  dir="$SCRATCH/$m"
  rm -rf "$dir" && mkdir -p "$dir"
  # the working tree as git sees it: tracked and untracked-but-not-ignored files
  (cd "$ROOT" && git ls-files -z --cached --others --exclude-standard) |
    (cd "$ROOT" && xargs -0 cp --parents -t "$dir" 2>/dev/null || true)
  # tests find ../shared beside the repository (mutmut runs them in $dir/mutants)
  [ -d "$ROOT/../shared" ] && ln -s "$(cd "$ROOT/../shared" && pwd)" "$dir/shared"
  # this module only, against its own tests
  "$PYTHON" - "$dir/pyproject.toml" "${FORKSERVER[$m]:-}" "${KEXPR[$m]:-}" "${SOURCE[$m]}" ${TESTS[$m]} <<'PY'
import re, sys
path, forkserver, kexpr, source, tests = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4], sys.argv[5:]
text = open(path, encoding="utf-8").read()
def toml_list(items):
    return "[" + ", ".join(f'"{x}"' for x in items) + "]"
text = re.sub(r"(?ms)^only_mutate = \[.*?\]\n", f"only_mutate = {toml_list([source])}\n", text)
text = re.sub(r"(?ms)^pytest_add_cli_args_test_selection = \[.*?\]\n",
              f"pytest_add_cli_args_test_selection = {toml_list(tests)}\n", text)
if kexpr:
    text = re.sub(r"(?m)^pytest_add_cli_args = \[(.*?)\]$", lambda m: f"pytest_add_cli_args = [{m.group(1)}, \"-k\", \"{kexpr}\"]", text)
if forkserver:
    text = text.replace("[tool.mutmut]\n", '[tool.mutmut]\nprocess_isolation = "forkserver"\n', 1)
open(path, "w", encoding="utf-8").write(text)
PY
  echo "== $m: mutating ${SOURCE[$m]} against ${TESTS[$m]} (scratch: $dir)"
  start=$(date +%s)
  # PYTHONPATH must not point at the original sources: mutmut puts ./mutants first
  # shellcheck disable=SC2086  # ONLY holds several globs
  (cd "$dir" && env -u PYTHONPATH nice -n "$NICE" "${MUTMUT[@]}" run --max-children "$JOBS" ${ONLY[$m]:-} > run.log 2>&1) || true
  (cd "$dir" && env -u PYTHONPATH "${MUTMUT[@]}" results --all true > results.txt 2>&1) || true
  "$PYTHON" - "$dir/results.txt" "$m" "$(( $(date +%s) - start ))" "$dir/survivors.txt" "$SCRATCH/scores.txt" ${ONLY[$m]:-} <<'PY'
import collections, fnmatch, sys
results, module, seconds, survivors_path, scores_path, *only = sys.argv[1:]
status = {}
for line in open(results, encoding="utf-8"):
    name, sep, state = line.strip().rpartition(": ")
    if sep and "__mutmut_" in name and (not only or any(fnmatch.fnmatch(name, g) for g in only)):
        status[name] = state
count = collections.Counter(status.values())
total = len(status)
killed = count["killed"] + count["timeout"]
score = 100.0 * killed / total if total else float("nan")
with open(survivors_path, "w", encoding="utf-8") as fh:
    for name, state in sorted(status.items()):
        if state not in ("killed", "timeout"):
            fh.write(f"{name}: {state}\n")
detail = ", ".join(f"{k} {v}" for k, v in sorted(count.items()))
line = f"{module}: {killed}/{total} killed = {score:.1f} % ({detail}; {seconds} s)"
print(line)
with open(scores_path, "a", encoding="utf-8") as fh:
    fh.write(line + "\n")
PY
done

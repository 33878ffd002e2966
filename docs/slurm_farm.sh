#!/bin/bash
# Render an occluded data set on a SLURM cluster: N array tasks, then one merge job.
#
#   bash docs/slurm_farm.sh submit        # from the login node: submits the array and the merge
#   sbatch --array=0-15 docs/slurm_farm.sh  # or just the array (then: zbuf-occlude farm-merge "$OUT")
#
# Each task renders the objects i with i mod N == task id (`--shard I/N`), writing one shard
# per object into the shared $OUT.  A task that is killed (time limit, preemption) is simply
# resubmitted: it skips the objects it finished.  The merge checks that every object has a
# result and writes the manifest, the train/test file lists and the data set card.
# Every task must use the same options (they are checked: a mismatch is refused).
#
#SBATCH --job-name=zbuf-farm
#SBATCH --array=0-15
#SBATCH --cpus-per-task=4
#SBATCH --mem=8G
#SBATCH --time=02:00:00
#SBATCH --output=zbuf-farm-%A_%a.log
# On GPU nodes add:  #SBATCH --gres=gpu:1   (EGL then uses the NVIDIA driver, no display needed)

set -euo pipefail

ROOT=${ROOT:-$HOME/data/ModelNet40}        # ROOT/<class>/<split>/<name>.off
OUT=${OUT:-/scratch/$USER/modelnet40_occluded}   # must be on a file system all nodes share
TASKS=${TASKS:-16}                         # keep equal to the --array size above
# Every mesh of ROOT is rendered.  To try the pipeline on a subset first, set e.g. SUBSET="--per-class 5"
# (the first 5 meshes of each class and split) or SUBSET="--classes chair,table"; empty: all meshes.
SUBSET=${SUBSET:-}
# shellcheck disable=SC2206  # SUBSET is split into options on purpose
FARM_OPTIONS=(--views paper100 --samples-per-view 10 --points 2048 --storage dense --seed 0 $SUBSET)

case "${1:-task}" in
submit)
    job=$(sbatch --parsable --array=0-$((TASKS - 1)) --export=ALL,ROOT="$ROOT",OUT="$OUT",TASKS="$TASKS",SUBSET="$SUBSET" "$0" task)
    # afterany: a task whose meshes partly failed exits 1, and the merge should still run
    sbatch --dependency=afterany:"$job" --job-name=zbuf-farm-merge --output=zbuf-farm-merge-%j.log \
        --wrap "zbuf-occlude farm-merge '$OUT' --no-progress"
    ;;
task)
    zbuf-occlude farm "$ROOT" --out "$OUT" "${FARM_OPTIONS[@]}" \
        --shard "${SLURM_ARRAY_TASK_ID}/${TASKS}" --workers "${SLURM_CPUS_PER_TASK:-1}" --no-progress
    ;;
*)
    echo "usage: $0 [submit|task]" >&2
    exit 2
    ;;
esac

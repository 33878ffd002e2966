#!/bin/bash
# One model of the fit-half-validated sim2real runs, timed, with the load before and after:
#   bash docs/results/sensor_fit/sim2real_realval/run.sh voxnet [more options]   (from the repository root, ../shared beside it)
# the meshes: ${MESHES:-../shared/data/street_objects}
# writes ${ROOT:-runs/s2r_realval}/MODEL/ and .../MODEL.wall.txt
set -u
m=$1; out=${ROOT:-runs/s2r_realval}/$m
mkdir -p "$out"
{
echo "start $(date -u +%FT%TZ) uptime: $(uptime)"
/usr/bin/time -v .venv/bin/zbuf-occlude experiment sim2real "${MESHES:-../shared/data/street_objects}" --real ../shared/data/lidarnet_v2_partial \
    --model "$m" --out "$out" --seeds 5 --threads 1 --scale quick --fit-sensor --sensor hdl32e --validate-on fit-half \
    --up-map 'bush/openglforest__*=+y' --no-progress "${@:2}" > "$out.log" 2> "$out.time"
echo "rc=$?"
echo "end $(date -u +%FT%TZ) uptime: $(uptime)"
grep -E "User time|System time|Percent of CPU|Elapsed|Maximum resident" "$out.time"
} > "$out.wall.txt"

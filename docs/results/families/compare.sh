#!/bin/bash
# Shape statistics of HDL-32E crops of the procedural families and of the street meshes against the real
# LiDARNet v2 crops, per class (pole: LiDARNet's Trunk folder; bush: its Bush folder; pedestrian: its
# Pedestrian folder), before any fitting:
#   street        the street meshes of the class, the preset recipe of docs/results/sensor_fit/realism.sh
#                 (hdl32e preset, sensor 5-25 m away at 1.6-2.0 m, the mesh scaled to the class's sizes:
#                 largest dimension 3-9 m for poles, 0.4-2.5 m for bushes, 1.5-1.95 m for pedestrians);
#                 the classes of the families run (pole and bush by default);
#   FAMILY        COUNT objects of the family (zbuf-occlude families, seed 0), the same placements and sensor,
#                 each object kept at its own size (--size its height, --size-of height: a scale of 1).
# usage: bash docs/results/families/compare.sh SHARED_DATA OUT [KEEP]   (zbuf-occlude on PATH)
#        writes OUT/meshes, OUT/scans/SET_CLASS/CLASS/I/*.npz, OUT/realism_SET_CLASS/ (realism.md, .csv, .png);
#        with KEEP, copies each run's realism.csv, realism_classes.csv and realism.png there, and draws
#        shape_pole.png, shape_bush.png and crops.png there (figure.py); OUT/heights.md: heights.py's table.
#        COUNT=12 (default) objects per family; FAMILIES="trunk shrub" runs only those, and the street meshes
#        of their classes.
#        FIT=fitted_families.json draws each family as that fit chose (zbuf-occlude families --fit; the sets are
#        named FAMILY-fitted); SIZING=class scans the family objects as the street meshes are scanned (the class's
#        sizes, as experiment sim2real's lidar set sizes every mesh) instead of at their own size.
set -euo pipefail
data=$1; out=$2; keep=${3:-}
count=${COUNT:-12}
families=${FAMILIES:-trunk utility_pole street_light sign_post shrub hedge}
fit=${FIT:-}; sizing=${SIZING:-own}
mkdir -p "$out"; : > "$out/left_out.txt"
declare -A REAL=([pole]=Trunk [bush]=Bush [pedestrian]=Pedestrian)
declare -A SIZE=([pole]=3:9 [bush]=0.4:2.5 [pedestrian]=1.5:1.95)  # the preset recipe's (sim2real's CLASS_SIZES_M)
declare -A CLASS=([trunk]=pole [utility_pole]=pole [street_light]=pole [sign_post]=pole [shrub]=bush [hedge]=bush [tree]=tree
                  [pedestrian]=pedestrian)
scan() {  # scan SET CLASS I MESH UP SIZE SIZE_OF: four crops of one mesh, the preset recipe's placements
  local rc=0
  zbuf-occlude scan "$4" --sensor hdl32e --distance 5:25 --height 1.6:2.0 --size "$6" --azimuth=-180:180 \
    --yaw 0:360 --samples 4 --crop --seed "$3" --up "$5" --size-of "$7" --no-progress \
    --out "$out/scans/$1_$2/$2/$3" > /dev/null || rc=$?
  # 1: written, but some scans hold no return of the object (named on stderr); 2: refused
  if [ $rc = 2 ]; then echo "left out: $1 $4" >> "$out/left_out.txt"; fi
  if [ $rc = 1 ]; then echo "some scans empty: $1 $4" >> "$out/left_out.txt"; fi
}
sets=()
classes=$(for fam in $families; do echo "${CLASS[$fam]}"; done | awk '!seen[$0]++')
for cls in $classes; do  # the street meshes of the families' classes, exactly as realism.sh's preset tag
  [ -n "${REAL[$cls]:-}" ] || continue
  i=0
  for mesh in "$data"/street_objects/$cls/*.{glb,gltf,dae,obj} "$data"/street_objects/$cls/*/*.{glb,gltf,dae,obj}; do
    [ -f "$mesh" ] || continue
    i=$((i + 1))
    up=auto; case $mesh in */bush/openglforest__*) up=+y;; esac  # as sim2real's --up-map
    scan street $cls $i "$mesh" $up "${SIZE[$cls]}" max
  done
  sets+=("street_$cls")
done
for fam in $families; do
  cls=${CLASS[$fam]}
  [ -n "${REAL[$cls]:-}" ] || { echo "no real class for $fam ($cls): skipped" >&2; continue; }
  name=$fam; [ -z "$fit" ] || name=$fam-fitted
  zbuf-occlude families "$fam" --count "$count" --seed 0 --out "$out/meshes" ${fit:+--fit "$fit"} > /dev/null
  i=0
  # each file's height from the family's manifest (extent_m[2], metres): scanned at its own size, or at the class's
  while read -r path height; do
    i=$((i + 1))
    if [ "$sizing" = class ]; then scan "$name" "$cls" $i "$out/meshes/$path" +z "${SIZE[$cls]}" max
    else scan "$name" "$cls" $i "$out/meshes/$path" +z "$height" height; fi
  done < <(python3 -c 'import json, sys
for f in json.load(open(sys.argv[1]))["files"]: print(f["path"], "%.4f" % f["extent_m"][2])' "$out/meshes/$cls/$fam.manifest.json")
  sets+=("${name}_$cls")
done
for set in "${sets[@]}"; do
  cls=${set##*_}
  zbuf-occlude realism "$out/scans/$set" "$data/lidarnet_v2_partial/${REAL[$cls]}" --out "$out/realism_$set" > /dev/null
  if [ -n "$keep" ]; then
    mkdir -p "$keep"
    cp "$out/realism_$set/realism.csv" "$keep/realism_$set.csv"
    cp "$out/realism_$set/realism_classes.csv" "$keep/realism_classes_$set.csv"
    cp "$out/realism_$set/realism.png" "$keep/realism_$set.png"
  fi
done
# how much of each family object its crops show (the crops' height against the manifest's)
python3 "$(dirname "$0")/heights.py" "$out" > "$out/heights.md"
# the shape figures (with KEEP): vertical profile, points by range, height / width per set; side views of crops
if [ -n "$keep" ]; then python3 "$(dirname "$0")/figure.py" "$out" "$keep"; fi

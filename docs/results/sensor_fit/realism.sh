#!/bin/bash
# Realism of HDL-32E crops of the street meshes against the real scans, five ways:
#   preset  the hdl32e preset, sensor 5-25 m away;
#   fitted  the fitted sensor, the same placements;
#   placed  the fitted sensor at each class's fitted distances (fit.crops in the JSON), poles as tall as fitted;
#   physics placed, with return physics: a 7-ray beam footprint and echoes within 0.75 m merged (mixed pixels);
#   ground  physics, and the ground within 0.25 m of the object's footprint kept in the crop (and counted);
#   hidden  placed, and each crop's bottom hidden up to a height drawn from the class's fitted interval (fit.crops.hidden_below_m);
#   widths  hidden, and each mesh stretched horizontally to the class's fitted widths across the line of sight (fit.crops.across_sight_width_m);
#   train   widths with every class, cars too, as tall as its fitted heights: the crops sim2real --fit-sensor trains fitted+placed on.
#   occluded hidden, and one side of each mesh hidden behind panels so that its crops are as wide as the fitted widths
#           where it shows wider (scan --occlude; cars keep their lengths, as in placed).
# usage: bash docs/results/sensor_fit/realism.sh SHARED_DATA FITTED_SENSOR.json OUT   (zbuf-occlude on PATH)
#        TAGS="physics ground" bash ...   runs only those; CLASSES="pedestrian bush" bash ... other classes (default: car pole)
set -euo pipefail
data=$1; fitted=$2; out=$3
mkdir -p "$out"
crops() {  # crops CLASS KEY -> LO:HI from the fitted sensor's fit.crops block
  python3 -c 'import json, sys; lo, hi = json.load(open(sys.argv[1]))["fit"]["crops"][sys.argv[3]][sys.argv[2]]; print(f"{lo:.2f}:{hi:.2f}")' "$fitted" "$1" "$2"
}
tags=${TAGS:-preset fitted placed physics ground hidden widths}
classes=${CLASSES:-car pole}
declare -A REAL=([car]=Car [pole]=Trunk [pedestrian]=Pedestrian [bush]=Bush)
declare -A SIZE=([car]=3.5:5.0 [pole]=3:9 [pedestrian]=1.5:1.95 [bush]=0.4:2.5)  # the preset recipe's (sim2real's CLASS_SIZES_M)
for tag in $tags; do
  sensor=$([ $tag = preset ] && echo hdl32e || echo "$fitted")
  for cls in $classes; do
    distance=5:25; size=${SIZE[$cls]}
    physics=()
    [ $tag = physics ] && physics=(--footprint --echo-separation 0.75)
    [ $tag = ground ] && physics=(--footprint --echo-separation 0.75 --ground-margin 0.25)
    [ $tag = hidden ] && physics=(--hidden-below "$(crops $cls hidden_below_m)")
    case $tag in widths|train|occluded) physics=(--hidden-below "$(crops $cls hidden_below_m)" --across-sight-width "$(crops $cls across_sight_width_m)");; esac
    [ $tag = occluded ] && physics+=(--occlude)
    size_of=max
    if [ $tag != preset ] && [ $tag != fitted ]; then
      distance=$(crops $cls distance_m)
      [ $cls != car ] && size=$(crops $cls object_height_m)  # the largest dimension of a pole, a person or a bush is its height (cars keep their lengths)
      [ $tag = train ] && size=$(crops $cls object_height_m) && size_of=height
    fi
    i=0
    for mesh in "$data"/street_objects/$cls/*.{glb,gltf,dae,obj} "$data"/street_objects/$cls/*/*.{glb,gltf,dae,obj}; do
      [ -f "$mesh" ] || continue
      i=$((i + 1))
      up=auto; case $mesh in */bush/openglforest__*) up=+y;; esac  # as sim2real's --up-map
      # a mesh stretched wider than twice the nearest distance is refused (the sensor could stand inside it): listed, left out
      rc=0
      zbuf-occlude scan "$mesh" --sensor "$sensor" --distance "$distance" --height 1.6:2.0 --size "$size" --azimuth=-180:180 \
        --yaw 0:360 --samples 4 --crop "${physics[@]}" --seed $i --up $up --size-of $size_of --out "$out/scans_${tag}_$cls/$i" > /dev/null || rc=$?
      # 1: written, but some scans hold no return of the object (named on stderr); 2: refused
      if [ $rc = 2 ]; then echo "left out: $tag $mesh" >> "$out/left_out.txt"; fi
      if [ $rc = 1 ]; then echo "some scans empty: $tag $mesh" >> "$out/left_out.txt"; fi
    done
  done
done
for cls in $classes; do
  real=${REAL[$cls]}
  for tag in $tags; do
    ground=(); [ $tag = ground ] && ground=(--ground-in-crops)  # its crops hold the ground under the object
    zbuf-occlude realism "$out/scans_${tag}_$cls" "$data/lidarnet_v2_partial/$real" --out "$out/realism_${tag}_$cls" --no-figure "${ground[@]}"
  done
done

#!/usr/bin/env bash
# Predicted against measured point error of automatic bakes (src/guide/performance.md, "How good --explain's prediction is").
#   examples/dev/predict_figures.sh BIN OUT REFS [QUALITIES]
# Bakes each corpus scene with `BIN bake --quality Q --explain` into OUT, compares the output with
# the point reference REFS/<stem>.csv (made once with
#   BIN reference fixtures/<scene> --points 2048 --spp 4096 --pass 32 --target-error 0.01 -o REFS/<stem>.csv)
# and prints one line per bake: wall seconds, the --explain prediction, the compare figure.
set -u
bin="$1"; out="$2"; refs="$3"; quals="${4:-draft medium}"; mkdir -p "$out"
for s in cornell_box.gltf two_rooms.gltf sphere_on_floor.gltf lamp_room.gltf spot_and_directional.gltf courtyard.gltf furnished_interior.glb; do
  stem="${s%.*}"
  [ -e "$refs/$stem.csv" ] || "$bin" reference "fixtures/$s" --points 2048 --spp 4096 --pass 32 --target-error 0.01 --quiet -o "$refs/$stem.csv"
  for q in $quals; do
    d="$out/$stem-$q"; rm -rf "$d"
    /usr/bin/time -f "%e" -o "$d.time" "$bin" bake "fixtures/$s" -o "$d" --quality "$q" --explain > "$d.explain" 2>&1
    f=$(ls "$d"/*.gl* | head -1)
    "$bin" compare "$f" --points "$refs/$stem.csv" > "$d.compare" 2>&1
    echo "$stem $q $(cat "$d.time")s | $(grep -o 'prediction [0-9.]*%[^—]*' "$d.explain" | head -1) | $(grep 'relative RMSE' "$d.compare")"
  done
done

#!/usr/bin/env bash
# Junction splitting as a renderer shows it (src/guide/performance.md, "Lightmap quality"): the two-room
# fixtures baked at every preset with the split on and off, read along the wall's dark side and
# rendered from room B, against path-traced references.
#   examples/dev/junction_figures.sh BIN OUT [PRESETS]
# References (made once into OUT): per scene a strip reference, 8192 points within 12.5 cm of
# the wall on room B's side (`reference --points --strip`, 2048 paths each), and 160 × 120 views
# at 4096 paths per pixel. Each preset is read in the strip one of its texels wide (8, 16, 32
# texels/m: the split bakes keep these densities), over the whole strip and "along the wall"
# (more than 10 cm from the doorway's span, which the strip crosses on the floor: there the
# jambs cast a penumbra across it). PRESETS (default all): draft, medium, high, and dense —
# high at 64 texels/m with 2048 rays and 512 light samples a texel, to see whether the bake
# converges to the references.
set -eu
bin="$1"; out="$2"; presets="${3:-draft medium high dense}"; mkdir -p "$out"
# scene, the wall plane's normal towards room B, the wall's direction (along it), its views
# (the glTF camera, or NAME=EYE:TARGET)
cases=("two_rooms 1,0,0 0,0,1 camera foot=1.5,1.2,0.6:0,0.2,-1"
       "two_rooms_angled 0.9396926,0,-0.3420201 0.3420201,0,0.9396926 camera")
# The camera options of a view.
camera() { case $1 in camera) ;; *=*) IFS=: read -r eye target <<< "${1#*=}"
                                      echo "--eye $eye --target $target" ;; esac; }
for c in "${cases[@]}"; do
  read -r s n a views <<< "$c"
  strip="$out/$s-strip.csv"
  [ -e "$strip" ] || "$bin" reference "fixtures/$s.gltf" --points 8192 --spp 2048 \
      --strip "0,0,0,$n,0.125" --quiet -o "$strip"
  for v in $views; do
    ref="$out/$s-${v%%=*}-ref.exr"
    [ -e "$ref" ] || "$bin" reference "fixtures/$s.gltf" --view $(camera "$v") --size 160x120 \
        --spp 4096 --quiet -o "$ref"
  done
  for q in $presets; do
    settings=(--quality "$q")
    case $q in draft) w=0.125 ;; medium) w=0.0625 ;; high) w=0.03125 ;;
      dense) w=0.015625
             settings=(--quality high --texels-per-unit 64 --rays 2048 --light-samples 512) ;;
    esac
    # The strip a texel wide, and its part along the wall (away from the doorway).
    IFS=, read -r nx _ nz <<< "$n"; IFS=, read -r ax _ az <<< "$a"
    for part in all wall; do
      awk -F, -v w="$w" -v nx="$nx" -v nz="$nz" -v ax="$ax" -v az="$az" -v part="$part" \
        '/^#/ || /^x,/ { print; next }
         { d = $1 * nx + $3 * nz; t = $1 * ax + $3 * az
           if (d > 0 && d <= w && (part == "all" || t < -0.5 || t > 0.5)) print }' \
        "$strip" > "$out/$s-$q-$part.csv"
    done
    for split in on off; do
      d="$out/$s-$q-$split"; rm -rf "$d"
      flag=(); [ $split = off ] && flag=(--no-split-junctions)
      "$bin" bake "fixtures/$s.gltf" -o "$d" "${settings[@]}" --quiet "${flag[@]}"
      line="$s $q split $split:"
      for part in all wall; do
        r=$("$bin" compare "$d/$s.gltf" --points "$out/$s-$q-$part.csv")
        line+=" strip $part $(grep -o 'RMSE *[0-9.]*%' <<< "$r" | grep -o '[0-9.]*%')"
        line+=" (noise $(grep -o 'noise *[0-9.]*%' <<< "$r" | grep -o '[0-9.]*%'), $(grep -o 'compared *[0-9]*' <<< "$r" | grep -o '[0-9]*') points)"
      done
      for v in $views; do
        img="$d/${v%%=*}.exr"
        "$bin" render "$d/$s.gltf" $(camera "$v") --size 160x120 --spp 64 --quiet -o "$img"
        r=$("$bin" compare "$img" --view "$out/$s-${v%%=*}-ref.exr")
        line+=" | view ${v%%=*} $(grep -o 'diff\. *[0-9.]*%' <<< "$r" | grep -o '[0-9.]*%')"
        line+=" (noise $(grep -o 'noise *[0-9.]*%' <<< "$r" | grep -o '[0-9.]*%'))"
      done
      echo "$line"
    done
  done
done

#!/usr/bin/env bash
# Hedberg's (2022) three test maps (smooth, average, uneven; config/hedberg_*.toml: procedural
# 4097² at 10 m, his maps are not published) on the GPU machine at 1920x1080 (docs/chunked.md
# "Three maps"):
#  1. GPU chunked LOD's selection and frame time per map: `bench`, naive walk and CBT, drawn
#     instanced and by mesh shading (Hedberg's four combinations), 90 frames after 30 warm-up.
#  2. Error against the exact surface per map: `eval` brute force, UDLOD (tau 1) and chunked
#     LOD at 1 and 4 px (Hedberg's threshold), 60 frames of the default flight.
# No data files needed (generated in memory). About 3 minutes.
# Here, before carrying: a release build and `../shared/device-vulkan/prepare.sh
# target/release/vkterrain`. Run there from the repository root:
#   bash scripts/device/hedberg_maps.sh > $OUT/hedberg_maps.txt 2>&1
set -u
. .device-vk/env.sh
bin=.device-vk/vkterrain
out=out/device/hedberg_maps
mkdir -p "$out"
log() { echo "### $*"; }
for map in smooth average uneven; do
  for traversal in naive cbt; do
    for draw in instanced mesh; do
      cfg="$out/${map}_${traversal}_${draw}.toml"
      sed -e "s/^name = \"chunked\"/name = \"chunked\"\ntraversal = \"$traversal\"\ndraw = \"$draw\"/" \
        -e "s#scenarios/default.toml#$PWD/config/scenarios/default.toml#" "config/hedberg_$map.toml" > "$cfg"
      log "bench chunked $map $traversal $draw 1920x1080"
      timeout 90 "$bin" bench --config "$cfg" --resolutions 1920x1080 --compare-frames-in-flight 2 \
        --frames 90 --warmup 30 --json "$out/bench_${map}_${traversal}_${draw}.json" || log "exit $?"
    done
  done
  log "eval $map: brute, udlod tau 1, chunked 1 and 4 px, 1920x1080"
  timeout 150 "$bin" eval --config "config/hedberg_$map.toml" --width 1920 --height 1080 --frames 60 \
    --warmup 10 --methods brute,udlod,chunked --sweep tau_px=1 --sweep error_px=1,4 \
    --out "$out/eval_$map" --force || log "exit $?"
done
for map in smooth average uneven; do
  echo "## $map"
  grep '^|' "$out/eval_$map/report.md" 2>/dev/null | head -8
done

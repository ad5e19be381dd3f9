#!/usr/bin/env bash
# Issue 18's sixteenth round ("Grid 2 with walks past the tile", docs/udlod.md) on the GPU
# machine: this build (.device-vk/vkterrain) at grid 4 (the default) and grid 2 in one `eval`
# per data set, 1920x1080, tau 0.5-4, 60 frames of the default flight, flat world
# (`DATA="ci puget"` by default: the CI terrain and Puget Sound, its heights in
# .device-vk/data as scripts/device/udlod_before_after.sh says). Prints the UDLOD rows; the
# reports stay in $OUT/grid2-DATA when OUT is set. Frame times setting against setting:
# `VARIANTS="new new-g2" bash scripts/device/udlod_binaries_ab.sh`.
# Run there from the repository root: `bash scripts/device/udlod_grid2.sh > $OUT/g2.txt 2>&1`
set -u
. .device-vk/env.sh
. scripts/device/puget_config.sh
for data in ${DATA:-ci puget}; do
  cfg=config/ci.toml
  [ "$data" = puget ] && cfg=$PUGET
  out=${OUT:-$(mktemp -d)}/grid2-$data
  echo "### $data"
  .device-vk/vkterrain eval --config "$cfg" --earth flat --methods udlod \
    --sweep grid_size=4,2 --sweep tau_px=0.5,1,2,4 --width 1920 --height 1080 --out "$out" 2>&1 |
    grep -E '^(variant|udlod|eval)'
done
rm -f "$PUGET"

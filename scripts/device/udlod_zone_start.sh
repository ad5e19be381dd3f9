#!/usr/bin/env bash
# Issue 18's fourteenth round ("The zone's start", docs/udlod.md) on the GPU machine: UDLOD of
# the build before it (.device-vk/vkterrain-main, 53314a4) against this build
# (.device-vk/vkterrain), one `eval` each at 1920x1080, tau 0.5-4, 60 frames of the default
# flight, flat world, per data set (`DATA="ci puget"` by default: the CI terrain and Puget
# Sound, its heights in .device-vk/data as scripts/device/udlod_before_after.sh says). Prints
# each binary's UDLOD rows; the reports stay in $OUT/zone-start-{before,after}-DATA when OUT
# is set. Frame times binary against binary: `VARIANTS="main new" bash
# scripts/device/udlod_binaries_ab.sh`.
# Run there from the repository root: `bash scripts/device/udlod_zone_start.sh > $OUT/zs.txt 2>&1`
set -u
. .device-vk/env.sh
. scripts/device/puget_config.sh
for data in ${DATA:-ci puget}; do
  cfg=config/ci.toml
  [ "$data" = puget ] && cfg=$PUGET
  for who in before after; do
    bin=.device-vk/vkterrain
    [ "$who" = before ] && bin=.device-vk/vkterrain-main
    out=${OUT:-$(mktemp -d)}/zone-start-$who-$data
    echo "### $data $who ($bin)"
    "$bin" eval --config "$cfg" --earth flat --methods udlod --sweep tau_px=0.5,1,2,4 \
      --width 1920 --height 1080 --out "$out" 2>&1 | grep -E '^(variant|udlod|eval)'
  done
done

#!/usr/bin/env bash
# Issue 18, coarse pixels on the GPU machine: UDLOD at its defaults, tau 0.5-4, 60 frames of
# the default flight at 1920x1080 on the CI terrain and Puget Sound (when its heights are
# carried); the summary table's `coarse px p99.9 (share)` is the 99.9th percentile over the
# pixels drawn by tiles coarser than level 0 (docs/eval.md, "Coarse pixels"), beside the
# frame's own p99.9 (`error px`).
#
# Here, before carrying: a release build copied to .device-vk/vkterrain
# (`../shared/device-vulkan/prepare.sh target/release/vkterrain`, stripped), and
#   mkdir -p .device-vk/data && cp ../shared/data/puget_sound/ps_height_1k.png .device-vk/data/
# Run there from the repository root: `bash scripts/device/udlod_coarse.sh > $OUT/coarse.txt 2>&1`.
# `HEDBERG=1` runs Hedberg's uneven map (procedural alpine 4097², generated there) instead, at
# tau 1, 2 and 4.
set -u
. .device-vk/env.sh
log() { echo "### $*"; }
. scripts/device/puget_config.sh
if [ "${HEDBERG:-0}" = 1 ]; then
  log "eval config/hedberg_uneven.toml, tau 1-4, 1920x1080"
  .device-vk/vkterrain eval --config config/hedberg_uneven.toml --methods udlod --sweep tau_px=1,2,4 \
    --width 1920 --height 1080 --out "$(mktemp -d)" --force 2>&1 | tail -6
  rm -f "$PUGET"
  exit 0
fi
cfgs=(config/ci.toml)
if [ -f .device-vk/data/ps_height_1k.png ]; then cfgs+=("$PUGET"); else log "Puget Sound heights absent: skipped"; fi
for cfg in "${cfgs[@]}"; do
  log "eval $cfg, tau 0.5-4, 1920x1080"
  .device-vk/vkterrain eval --config "$cfg" --methods udlod --sweep tau_px=0.5,1,2,4 \
    --width 1920 --height 1080 --out "$(mktemp -d)" --force 2>&1 | tail -7
done
rm -f "$PUGET"

#!/usr/bin/env bash
# Issue 18, the morph cascade on the GPU machine: UDLOD with `morph_levels = 1` (one level
# step: the CDLOD-style chain before the cascade, the same selection) against the default
# (`morph_levels = 0`: as many levels as keep a tile's vertices inside it), tau 0.5-4, 60
# frames of each flight at 1920x1080, both in one `eval` run (frames interleaved, so the GPU
# times compare within the run). Data: the CI terrain (procedural, in memory), Puget Sound when
# its heights are carried, Fischer S3 when out/datasets/pyrenees is.
#
# Here, before carrying: a release build copied to .device-vk/vkterrain
# (`../shared/device-vulkan/prepare.sh target/release/vkterrain`, stripped), and
#   mkdir -p .device-vk/data && cp ../shared/data/puget_sound/ps_height_1k.png .device-vk/data/
# Run there from the repository root: `bash scripts/device/udlod_cascade.sh > $OUT/cascade.txt 2>&1`.
# `HEDBERG=1` runs Hedberg's uneven map (procedural alpine 4097², generated there) instead, at
# tau 1, 2 and 4 (a call of its own: the device's per-call limit).
set -u
. .device-vk/env.sh
log() { echo "### $*"; }
. scripts/device/puget_config.sh
if [ "${HEDBERG:-0}" = 1 ]; then
  log "eval config/hedberg_uneven.toml morph_levels 1 vs 0, tau 1-4, 1920x1080"
  .device-vk/vkterrain eval --config config/hedberg_uneven.toml --methods udlod --sweep morph_levels=1,0 \
    --sweep tau_px=1,2,4 --width 1920 --height 1080 --out "$(mktemp -d)" --force 2>&1 | tail -9
  rm -f "$PUGET"
  exit 0
fi
cfgs=(config/ci.toml)
if [ -f .device-vk/data/ps_height_1k.png ]; then cfgs+=("$PUGET"); else log "Puget Sound heights absent: skipped"; fi
if [ -f out/datasets/pyrenees/manifest.json ]; then cfgs+=(config/pyrenees.toml); else log "out/datasets/pyrenees absent: Fischer S3 skipped"; fi
for cfg in "${cfgs[@]}"; do
  log "eval $cfg morph_levels 1 vs 0, tau 0.5-4, 1920x1080"
  .device-vk/vkterrain eval --config "$cfg" --methods udlod --sweep morph_levels=1,0 \
    --sweep tau_px=0.5,1,2,4 --width 1920 --height 1080 --out "$(mktemp -d)" --force 2>&1 | tail -11
done
rm -f "$PUGET"

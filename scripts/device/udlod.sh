#!/usr/bin/env bash
# Issue 18 (tau means tau) on the GPU machine: UDLOD triangles, error and frame time per tau,
# for this branch's binary and, when present, main's binary before the change.
# The branch's eval sweeps grid 8 (the default) and grid 4 (better on lavapipe, not the default
# for its host memory) in one run, each at tau 0.5, 0.7, 1, 1.4, 2, 2.8, 4, 5.6: grid 8 at
# tau 0.5/1/2/4 is the default (share 0.7), grid 8 at 0.7/1.4/2.8/5.6 selects exactly what
# main (share 0.5) selects at 0.5/1/2/4 (the share only rescales tau: docs/udlod-rounds.md, "Issue 18,
# third round"), grid 4 at 0.5/1/2/4 is grid 4 with its share 0.72. Watch the frame time of
# grid 4 against grid 8 (small instances) and whether grid 4 at tau 0.5 reaches max_tiles.
# The bench (wall frame time, 2 frames in flight) runs each binary's default.
#
# Here, before carrying: a release build, `../shared/device-vulkan/prepare.sh
# target/release/vkterrain`, optionally main's release binary copied to
# .device-vk/vkterrain-before, the Puget Sound heights copied into the carried folder, and the
# Fischer S1/S3 data sets (`make data-franconia data-pyrenees`: out/datasets/franconia and
# out/datasets/pyrenees, each two SRTM1 tiles as a tile pyramid; carry both folders: the
# GPU machine has no GDAL to build them from the .hgt.zip files):
#   mkdir -p .device-vk/data && cp ../shared/data/puget_sound/ps_height_1k.png .device-vk/data/
# Data sets that are absent are skipped with a line saying so (the CI terrain is procedural,
# generated in memory).
# Run there from the repository root: `bash scripts/device/udlod.sh > $OUT/udlod.txt 2>&1`.
set -u
. .device-vk/env.sh
log() { echo "### $*"; }
. scripts/device/puget_config.sh
cfgs=(config/ci.toml)
if [ -f .device-vk/data/ps_height_1k.png ]; then cfgs+=("$PUGET"); else log "Puget Sound heights absent: skipped"; fi
for ds in franconia pyrenees; do
  if [ -f "out/datasets/$ds/manifest.json" ]; then cfgs+=("config/$ds.toml"); else log "out/datasets/$ds absent: Fischer $ds skipped"; fi
done
for bin in .device-vk/vkterrain .device-vk/vkterrain-before; do
  [ -x "$bin" ] || { log "$bin absent: skipped"; continue; }
  for cfg in "${cfgs[@]}"; do
    for tau in 0.5 1 2 4; do
      log "$bin bench $cfg udlod tau $tau 1920x1080"
      "$bin" bench --config "$cfg" --method udlod --tau-px "$tau" --resolutions 1920x1080 \
        --compare-frames-in-flight 2 --frames 300 --warmup 20
    done
    if [ "$bin" = .device-vk/vkterrain ]; then
      log "$bin eval $cfg grid 8 (default) vs 4, tau sweep 1920x1080"
      "$bin" eval --config "$cfg" --methods udlod --sweep grid_size=4,8 \
        --sweep tau_px=0.5,0.7,1,1.4,2,2.8,4,5.6 --width 1920 --height 1080 \
        --out "$(mktemp -d)" --force 2>&1 | tail -20
    else
      log "$bin eval $cfg tau sweep 1920x1080"
      "$bin" eval --config "$cfg" --methods udlod --sweep tau_px=0.5,1,2,4 --width 1920 \
        --height 1080 --out "$(mktemp -d)" --force 2>&1 | tail -6
    fi
  done
done
rm -f "$PUGET"

#!/usr/bin/env bash
# Issue 18 (tau means tau) on the GPU machine: UDLOD triangles, error and frame time per tau,
# for this branch's binary and, when present, main's binary before the change.
#
# Here, before carrying: a release build, `../shared/device-vulkan/prepare.sh
# target/release/vkterrain`, optionally main's release binary copied to
# .device-vk/vkterrain-before, and the Puget Sound heights copied into the carried folder:
#   mkdir -p .device-vk/data && cp ../shared/data/puget_sound/ps_height_1k.png .device-vk/data/
# Run there from the repository root: `bash scripts/device/udlod.sh > $OUT/udlod.txt 2>&1`.
set -u
. .device-vk/env.sh
log() { echo "### $*"; }
# Puget Sound through a config pointing at the carried copy (no albedo: geometry only).
PUGET=$(mktemp --suffix=.toml)
printf '[dataset]\nkind = "png16"\npath = "%s"\nspacing = 160.0\nvertical_scale = 0.1\n[scenario]\npath = "%s"\n' \
  "$PWD/.device-vk/data/ps_height_1k.png" "$PWD/config/scenarios/default.toml" > "$PUGET"
for bin in .device-vk/vkterrain .device-vk/vkterrain-before; do
  [ -x "$bin" ] || { log "$bin absent: skipped"; continue; }
  for cfg in config/ci.toml "$PUGET"; do
    for tau in 0.5 1 2 4; do
      log "$bin bench $cfg udlod tau $tau 1920x1080"
      "$bin" bench --config "$cfg" --method udlod --tau-px "$tau" --resolutions 1920x1080 \
        --compare-frames-in-flight 2 --frames 300 --warmup 20
    done
    log "$bin eval $cfg tau sweep 1920x1080"
    "$bin" eval --config "$cfg" --methods udlod --sweep tau_px=0.5,1,2,4 --width 1920 \
      --height 1080 --out "$(mktemp -d)" --force 2>&1 | tail -6
  done
done
rm -f "$PUGET"

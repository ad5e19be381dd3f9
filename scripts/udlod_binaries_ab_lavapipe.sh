#!/usr/bin/env bash
# UDLOD's frame time on lavapipe, binary against binary: `bench` (640x360, 2 frames in flight,
# 200 frames after 10 of warm-up) on the CI terrain and Puget Sound at tau 1 and 4, three
# rounds, the order swapped in the second. Prints `bench`'s row per data set, tau, round and
# binary; compare GPU ms within a round (the machine is noisy).
# Usage: scripts/udlod_binaries_ab_lavapipe.sh OLD NEW
#   e.g. the GPU machine's pair: .device-vk/vkterrain-main .device-vk/vkterrain (built without
#   GDAL, they run here too; the Puget Sound heights from .device-vk/data, as the device
#   scripts read them: scripts/device/udlod_before_after.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -eq 2 ] || { echo "usage: $0 OLD NEW" >&2; exit 2; }
old=$1 new=$2
# Nothing to export with the system's lavapipe (a bare `export` would list the environment).
lvp=$(scripts/lavapipe.sh)
# shellcheck disable=SC2086 # NAME=VALUE words
[ -z "$lvp" ] || export $lvp
. scripts/device/puget_config.sh
. scripts/device/udlod_config.sh
for round in 1 2 3; do
  for base in config/ci.toml "$PUGET"; do
    for tau in 1 4; do
      order="old new"
      [ "$round" = 2 ] && order="new old"
      for v in $order; do
        bin=$new
        [ "$v" = old ] && bin=$old
        cfg=$(udlod_config "$base")
        r=$("$bin" bench --config "$cfg" --method udlod --tau-px "$tau" --resolutions 640x360 \
          --compare-frames-in-flight 2 --frames 200 --warmup 10 --out "$(mktemp -d)" 2>&1 |
          grep -E '640x360   2|rror')
        echo "$(basename "$base") tau $tau round $round $v: $r"
        rm -f "$cfg"
      done
    done
  done
done
rm -f "$PUGET"

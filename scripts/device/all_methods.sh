#!/usr/bin/env bash
# Issue 16's report: every method of the harness and its sweep on Fischer S3 and S1, the
# Improved-PGM flight and the low-horizon scenario, at 1920x1080 on the GPU machine: eval's
# frame-time vs error chart (Pareto front), triangles, popping, swimming, holes per variant.
#
# Run from the repository root on the device (`. .device-vk/env.sh` is sourced here), with the
# prepared binary in .device-vk/ (../shared/device-vulkan/prepare.sh) and the data carried:
#   CASES="s3 ipgm low"  needs out/datasets/pyrenees and .device-vk/data/ps_height_1k.png
#   CASES="s1"           needs out/datasets/franconia (64 MiB carry limit: a second call)
# All cases render the flat world (`--earth flat`), as when PGM refused the ellipsoid: one world
# keeps the six methods and earlier runs comparable (docs/eval.md "On the earth" has the ellipsoid's effect).
# Output: $OUT/all_methods/<case>/ (report.md, summary.csv, charts) and a summary per case.
set -uo pipefail
cd "$(dirname "$0")/../.."
. .device-vk/env.sh
BIN=${BIN:-.device-vk/vkterrain}
FRAMES=${FRAMES:-240}
CASES=${CASES:-s3 ipgm low}
# METHODS / SWEEPS: a subset (e.g. METHODS=brute,udlod,chunked SWEEPS="--sweep tau_px=0.5,1,2
# --sweep error_px=1,4" for UDLOD against chunked LOD alone).
METHODS=${METHODS:-brute,udlod,pgm,tessellation,geomipmap,chunked}
SWEEPS=${SWEEPS:---sweep tau_px=0.5,1,2,4 --sweep grid_scale=0.5,1 --sweep warp_rows=0,1 --sweep edge_px=1,4,16 --sweep distance_factor=1,4,8 --sweep error_px=1,4,16}
KEEP=${OUT:-out/device}/all_methods
mkdir -p "$KEEP"
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
# Puget Sound through a config pointing at the carried copy (heights only).
puget() {
  printf '[dataset]\nkind = "png16"\npath = "%s"\nspacing = 160.0\nvertical_scale = 0.1\n[scenario]\npath = "%s"\n' \
    "$PWD/.device-vk/data/ps_height_1k.png" "$PWD/config/scenarios/$1.toml" >"$TMP/$1.toml"
  echo "$TMP/$1.toml"
}
"$BIN" info | head -3
for c in $CASES; do
  case $c in
    s3) cfg=config/pyrenees.toml; need=out/datasets/pyrenees/manifest.json ;;
    s1) cfg=config/franconia.toml; need=out/datasets/franconia/manifest.json ;;
    ipgm) cfg=$(puget puget_improved_pgm_flight); need=.device-vk/data/ps_height_1k.png ;;
    low) cfg=$(puget puget_low_horizon_down00); need=.device-vk/data/ps_height_1k.png ;;
    *) echo "unknown case $c"; continue ;;
  esac
  [ -f "$need" ] || { echo "### $c: $need absent, skipped"; continue; }
  echo "### $c ($cfg), $FRAMES frames, 1920x1080"
  s=$(date +%s)
  "$BIN" eval --config "$cfg" --earth flat --width 1920 --height 1080 --frames "$FRAMES" --warmup 20 \
    --methods "$METHODS" $SWEEPS --flip-every 60 \
    --out "$KEEP/$c" --force >"$KEEP/$c.log" 2>&1 || { echo "eval $c failed:"; tail -5 "$KEEP/$c.log"; }
  echo "wall $(( $(date +%s) - s )) s"
  [ -f "$KEEP/$c/summary.csv" ] && grep -A40 "^variant" "$KEEP/$c.log" | grep -v "^evaluated\|^wrote"
done

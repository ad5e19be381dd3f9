#!/usr/bin/env bash
# Hardware tessellation (Fischer 2024) and GeoMipMapping (Tabakovic) against brute force and
# UDLOD on the GPU machine, at 1920x1080 (docs/tessellation.md, docs/geomipmap.md). Runs from the repository root on the device after
#   ../shared/device-vulkan/prepare.sh target/release/vkterrain   (here, after a release build)
# Needs no data files: config/ci.toml generates its procedural 513² terrain in memory.
# Output: out/device/tessellation/all/ (report.md, summary.csv, charts).
set -euo pipefail
. .device-vk/env.sh
bin=.device-vk/vkterrain
out=out/device/tessellation
mkdir -p "$out"
$bin info | head -20
# Every method the harness has (brute, UDLOD, PGM, tessellation, GeoMipMapping) in one run,
# with the sweeps: UDLOD's tau, PGM's grid scale and row warp (plain vs warped grid, issue 16),
# tessellation's target edge size in pixels (fractional_odd, 64-sample patches),
# GeoMipMapping's distance factor. (GPU chunked LOD, issue 16 item 2: scripts/device/chunked.sh.)
$bin eval --config config/ci.toml --width 1920 --height 1080 --frames 240 --warmup 20 \
  --methods brute,udlod,pgm,tessellation,geomipmap --sweep tau_px=1,2,4 \
  --sweep grid_scale=0.5,1 --sweep warp_rows=0,1 --sweep edge_px=1,2,4,8,16 \
  --sweep distance_factor=1,2,4,8 --out "$out/all" --force

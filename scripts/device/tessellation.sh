#!/usr/bin/env bash
# Hardware tessellation (Fischer 2024) against brute force and UDLOD on the GPU machine, at
# 1920x1080 (docs/tessellation.md). Runs from the repository root on the device after
#   ../shared/device-vulkan/prepare.sh target/release/vkterrain   (here, after a release build)
# Needs no data files: config/ci.toml generates its procedural 513² terrain in memory.
# Output: out/device/tessellation/{main,sweep}/ (report.md, summary.csv, charts).
set -euo pipefail
. .device-vk/env.sh
bin=.device-vk/vkterrain
out=out/device/tessellation
mkdir -p "$out"
$bin info | head -20
# Methods side by side, default settings (tessellation: edge_px 8, fractional_odd, 64-sample patches).
$bin eval --config config/ci.toml --width 1920 --height 1080 --frames 240 --warmup 20 \
  --methods brute,udlod,tessellation --out "$out/main" --force
# Tessellation's sweep: target edge size in pixels.
$bin eval --config config/ci.toml --width 1920 --height 1080 --frames 240 --warmup 20 \
  --methods tessellation --sweep edge_px=1,2,4,8,16 --out "$out/sweep" --force

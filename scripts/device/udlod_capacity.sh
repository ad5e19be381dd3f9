#!/usr/bin/env bash
# UDLOD's tile budget on Hedberg's uneven map (config/hedberg_uneven.toml: procedural alpine
# 4097² at 10 m) at 1920x1080 on the GPU machine (docs/udlod.md "Capacity"): `eval` of UDLOD
# at tau 1 with max_tiles 16,384 (the old default, which overflows there) and 65,536 (the
# default), and tau 0.5 / 2 at the default; brute force is the reference. Holes, error,
# triangles, GPU ms and the overflowing frames per variant. About a minute.
#   bash scripts/device/udlod_capacity.sh > $OUT/udlod_capacity.txt 2>&1
set -u
. .device-vk/env.sh
bin=${BIN:-.device-vk/vkterrain}
out=out/device/udlod_capacity
mkdir -p "$out"
timeout 200 "$bin" eval --config config/hedberg_uneven.toml --width 1920 --height 1080 --frames 60 \
  --warmup 10 --methods brute,udlod --sweep tau_px=1 --sweep max_tiles=16384,65536 \
  --out "$out/tau1" --force || echo "### exit $?"
timeout 200 "$bin" eval --config config/hedberg_uneven.toml --width 1920 --height 1080 --frames 60 \
  --warmup 10 --methods udlod --sweep tau_px=0.5,2 --out "$out/tau" --force || echo "### exit $?"
grep -h '^|' "$out/tau1/report.md" "$out/tau/report.md"
grep -h -i 'warning' "$out/tau1/report.md" "$out/tau/report.md"

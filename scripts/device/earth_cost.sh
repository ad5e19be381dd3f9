#!/usr/bin/env bash
# Issue 14: what the earth costs on the GPU machine (docs/coordinates.md "The earth's cost on the GPU
# machine"): a build against the one before it. Two parts, 1920x1080, UDLOD:
# 1. `vkterrain bench` (300 frames after 20) of .device-vk/vkterrain (this tree) and
#    .device-vk/vkterrain-before (a build before the change) alternated, ROUNDS rounds: Fischer
#    S3 and the anchored CI terrain on the ellipsoid, the clipmap fast flight (4097^2 procedural
#    pyramid anchored at 42 N 1 E, generated here) on the ellipsoid; each case's flat world
#    once per build (round 1).
# 2. Where the earth's cost lies: `vkterrain eval --methods udlod` of both builds on Fischer
#    S3 and the clipmap fast flight, flat and ellipsoid, 120 frames after 10; results.json to
#    $OUT/split-{build}-{case}-{flat,ellipsoid}.json (per-frame `gpu_prepass_ms`,
#    `gpu_terrain_ms`).
# Needs out/datasets/pyrenees carried. Run there:
# `bash scripts/device/earth_cost.sh > $OUT/earth_cost.txt 2>&1`.
set -u
. .device-vk/env.sh
ROUNDS=${ROUNDS:-2}
# The builds to compare (.device-vk/vkterrain-* files that are absent are skipped).
BINS=${BINS:-.device-vk/vkterrain .device-vk/vkterrain-before}
OUT=${OUT:-out/device-earth-cost}
mkdir -p "$OUT"
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
BIN=.device-vk/vkterrain
sed -e 's#"\.\./out/datasets/pyrenees"#"'"$PWD"'/out/datasets/pyrenees"#' \
  -e 's#"scenarios/#"'"$PWD"'/config/scenarios/#' config/pyrenees.toml >"$TMP/s3.toml"
sed -e 's#"scenarios/#"'"$PWD"'/config/scenarios/#' config/ci_earth.toml >"$TMP/ci_earth.toml"
[ -f target/data/proc4k/manifest.json ] ||
  "$BIN" preprocess --procedural --size 4097 --node-size 64 --out target/data/proc4k | tail -1
sed -e 's#"\.\./target/data/proc4k"#"'"$PWD"'/target/data/proc4k"#' \
  -e 's#"scenarios/#"'"$PWD"'/config/scenarios/#' config/clipmap.toml >"$TMP/clipmap.toml"
sed -i '/^\[dataset\]/a anchor = { lat_deg = 42.0, lon_deg = 1.0 }' "$TMP/clipmap.toml"
for round in $(seq "$ROUNDS"); do
  for bin in $BINS; do
    [ -x "$bin" ] || continue
    for case in s3 ci_earth clipmap; do
      for earth in ellipsoid flat; do
        [ "$earth" = flat ] && [ "$round" != 1 ] && continue
        echo "round $round $(basename "$bin") $case $earth (resolution N triangles median p99 gpu readback overlap):"
        "$bin" bench --config "$TMP/$case.toml" --earth "$earth" --method udlod \
          --resolutions 1920x1080 --frames 300 --warmup 20 2>&1 | grep -E '^ *1920x1080'
      done
    done
  done
done
for bin in $BINS; do
  [ -x "$bin" ] || continue
  for case in s3 clipmap; do
    for earth in flat ellipsoid; do
      name="$(basename "$bin")-$case-$earth"
      echo "eval split: $name"
      "$bin" eval --config "$TMP/$case.toml" --earth "$earth" --methods udlod --width 1920 \
        --height 1080 --frames 120 --warmup 10 --out "$TMP/eval-$name" --force 2>&1 |
        grep -E '^udlod'
      cp "$TMP/eval-$name/results.json" "$OUT/split-$name.json"
    done
  done
done

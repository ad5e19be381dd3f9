#!/usr/bin/env bash
# Issue 18: UDLOD frame times of two builds on the GPU machine: bench at 1920x1080 on the flat world
# (300 frames after 20): the CI terrain, Puget Sound (.device-vk/data/ps_height_1k.png) and Fischer
# S3 (out/datasets/pyrenees carried), .device-vk/vkterrain against .device-vk/vkterrain-before,
# alternated, two rounds. Run there: `bash scripts/device/udlod_ab.sh > $OUT/udlod_ab.txt 2>&1`.
set -u
. .device-vk/env.sh
. scripts/device/puget_config.sh
S3=$(mktemp --suffix=.toml)
sed -e 's#"\.\./out/datasets/pyrenees"#"'"$PWD"'/out/datasets/pyrenees"#' -e 's#"scenarios/#"'"$PWD"'/config/scenarios/#' config/pyrenees.toml > "$S3"
for round in 1 2; do
  for bin in .device-vk/vkterrain .device-vk/vkterrain-before; do
    for cfg in config/ci.toml "$PUGET" "$S3"; do
      name=$(basename "$cfg"); [ "$cfg" = "$PUGET" ] && name=puget; [ "$cfg" = "$S3" ] && name=s3
      echo "round $round $(basename $bin) $name flat"
      "$bin" bench --config "$cfg" --earth flat --method udlod --resolutions 1920x1080 --frames 300 --warmup 20 2>&1 | grep -E '^ *1920x1080'
    done
  done
done

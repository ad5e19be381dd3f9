#!/usr/bin/env bash
# Issue 14: the cost of the normals' frame on the earth (`world_normal`, docs/coordinates.md
# "Normals on the earth") on the GPU machine: `vkterrain bench` of UDLOD at 1920x1080 on
# Fischer S3 (on the ellipsoid by its georeferencing) and the anchored CI terrain
# (config/ci_earth.toml), .device-vk/vkterrain (this tree) and .device-vk/vkterrain-before (a
# build before the change) alternated, ROUNDS rounds; the flat world of S3 once per build.
# Needs out/datasets/pyrenees carried. Run there: `bash scripts/device/earth_normals.sh > $OUT/earth_normals.txt 2>&1`.
set -u
. .device-vk/env.sh
ROUNDS=${ROUNDS:-2}
TMP=$(mktemp -d)
sed -e 's#"\.\./out/datasets/pyrenees"#"'"$PWD"'/out/datasets/pyrenees"#' \
  -e 's#"scenarios/#"'"$PWD"'/config/scenarios/#' config/pyrenees.toml >"$TMP/s3.toml"
for round in $(seq "$ROUNDS"); do
  for bin in .device-vk/vkterrain .device-vk/vkterrain-before; do
    [ -x "$bin" ] || continue
    for case in "s3 ellipsoid" "ci_earth ellipsoid" "s3 flat"; do
      set -- $case
      [ "$2" = flat ] && [ "$round" != 1 ] && continue
      cfg="$TMP/s3.toml"; [ "$1" = ci_earth ] && cfg=config/ci_earth.toml
      echo "round $round $(basename "$bin") $1 $2 (resolution N triangles median p99 gpu readback overlap):"
      "$bin" bench --config "$cfg" --earth "$2" --method udlod --resolutions 1920x1080 \
        --frames 300 --warmup 20 2>&1 | grep -E '^ *1920x1080'
    done
  done
done
rm -rf "$TMP"

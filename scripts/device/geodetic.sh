#!/usr/bin/env bash
# Issue 14b (the terrain on the WGS84 ellipsoid) on the GPU machine: GPU frame time of the flat
# mapping vs the geodetic one (the geolocation lattice, docs/coordinates.md "Geodetic
# geometry"), same binary, same scenario, 1920x1080. The geodetic mapping is switched on with
# VKTERRAIN_GEO_ANCHOR=LAT,LON (the data set's sample (0, 0) placed at that latitude/longitude).
#
# Needs: out/datasets/pyrenees carried (here: `make data-pyrenees`, a few MB) for Fischer S3;
# the clipmap's 4097^2 procedural pyramid is generated there.
# Run there from the repository root: `bash scripts/device/geodetic.sh > $OUT/geodetic.txt 2>&1`.
set -u
. .device-vk/env.sh
log() { echo "### $*"; }
BIN=.device-vk/vkterrain
TMP=$(mktemp -d)
if [ -f out/datasets/pyrenees/manifest.json ]; then
  sed -e 's#"\.\./out/datasets/pyrenees"#"'"$PWD"'/out/datasets/pyrenees"#' \
    -e 's#"scenarios/#"'"$PWD"'/config/scenarios/#' config/pyrenees.toml >"$TMP/pyrenees.toml"
else
  log "out/datasets/pyrenees absent: Fischer S3 skipped"
fi
[ -f target/data/proc4k/manifest.json ] ||
  "$BIN" preprocess --procedural --size 4097 --node-size 64 --out target/data/proc4k | tail -2
sed -e 's#"\.\./target/data/proc4k"#"'"$PWD"'/target/data/proc4k"#' \
  -e 's#"scenarios/#"'"$PWD"'/config/scenarios/#' config/clipmap.toml >"$TMP/clipmap.toml"
for round in 1 2; do
  for anchor in flat 42.0,1.0; do
    if [ "$anchor" = flat ]; then unset VKTERRAIN_GEO_ANCHOR; else export VKTERRAIN_GEO_ANCHOR=$anchor; fi
    if [ -f "$TMP/pyrenees.toml" ]; then
      for method in udlod brute; do
        log "round $round $anchor: Fischer S3 $method 1920x1080"
        "$BIN" bench --config "$TMP/pyrenees.toml" --method "$method" --resolutions 1920x1080 \
          --frames 300 --warmup 20
      done
    fi
    log "round $round $anchor: clipmap fast flight udlod 1920x1080"
    "$BIN" bench --config "$TMP/clipmap.toml" --resolutions 1920x1080 --frames 300 --warmup 20
  done
done
unset VKTERRAIN_GEO_ANCHOR
rm -rf "$TMP"

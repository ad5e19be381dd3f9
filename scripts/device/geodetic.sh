#!/usr/bin/env bash
# Issue 14b (the terrain on the WGS84 ellipsoid) on the GPU machine: GPU frame time of the flat
# mapping vs the geodetic one (the geolocation lattice, docs/coordinates.md "Geodetic
# geometry"), same binary, same scenario, 1920x1080: `[render] earth = "flat"` against the
# default `ellipsoid`. Fischer S3 (SRTM3, EPSG:4326: placed on the earth without PROJ) is on the
# earth by its georeferencing; the procedural clipmap pyramid through `[dataset] anchor`.
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
sed -i '/^\[dataset\]/a anchor = { lat_deg = 42.0, lon_deg = 1.0 }' "$TMP/clipmap.toml"
# One copy per geometry: `earth = ...` right under [render] (added when a file has none).
for c in pyrenees clipmap; do
  [ -f "$TMP/$c.toml" ] || continue
  grep -q '^\[render\]' "$TMP/$c.toml" || printf '\n[render]\n' >>"$TMP/$c.toml"
  for earth in flat ellipsoid; do
    sed "/^\[render\]/a earth = \"$earth\"" "$TMP/$c.toml" >"$TMP/$c-$earth.toml"
  done
done
for round in 1 2; do
  for earth in flat ellipsoid; do
    if [ -f "$TMP/pyrenees-$earth.toml" ]; then
      for method in udlod brute; do
        log "round $round $earth: Fischer S3 $method 1920x1080"
        "$BIN" bench --config "$TMP/pyrenees-$earth.toml" --method "$method" \
          --resolutions 1920x1080 --frames 300 --warmup 20
      done
    fi
    log "round $round $earth: clipmap fast flight udlod 1920x1080"
    "$BIN" bench --config "$TMP/clipmap-$earth.toml" --resolutions 1920x1080 --frames 300 \
      --warmup 20
  done
done
rm -rf "$TMP"

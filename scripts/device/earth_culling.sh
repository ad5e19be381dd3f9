#!/usr/bin/env bash
# Issues 14/16 (culling on the earth, one curved box for every method: docs/coordinates.md
# "Culling with curvature") on the GPU machine: `vkterrain eval` on the ellipsoid at 1920x1080,
# brute force + UDLOD + GeoMipMapping + chunked LOD with the curved box (the default), against
# the old behaviour in the same binary: GeoMipMapping with `cull_box = "grid"` (the grid-frame
# box it culled with before) and chunked LOD with `cull = false` (it culled nothing on the
# earth before). Per case: each method's GPU ms, triangles, holes and error from the summary
# table (compare within a round).
#
# Cases: the CI terrain anchored on the earth (config/ci_earth.toml); Fischer S3 over the
# Pyrenees (SRTM3, georeferenced) when out/datasets/pyrenees was carried, else a procedural
# alpine stand-in anchored at 42.5 N 1 E (the report says which).
# Run from the repository root: `bash scripts/device/earth_culling.sh > $OUT/earth_culling.txt 2>&1`.
set -u
. .device-vk/env.sh
log() { echo "### $*"; }
BIN=${BIN:-.device-vk/vkterrain}
FRAMES=${FRAMES:-96}
W=${W:-1920}
H=${H:-1080}
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
KEEP=${OUT:-out/device-earth-culling}
mkdir -p "$KEEP"

sed -e 's#"scenarios/#"'"$PWD"'/config/scenarios/#' config/ci_earth.toml >"$TMP/ci_earth.toml"
if [ -f out/datasets/pyrenees/manifest.json ]; then
  S3DATA="the Pyrenees (SRTM3, out/datasets/pyrenees, georeferenced)"
  sed -e 's#"\.\./out/datasets/pyrenees"#"'"$PWD"'/out/datasets/pyrenees"#' \
    -e 's#"scenarios/#"'"$PWD"'/config/scenarios/#' config/pyrenees.toml >"$TMP/s3.toml"
else
  S3DATA="a procedural alpine stand-in (2401^2 at 92.56 m) anchored at 42.5 N 1 E"
  "$BIN" preprocess --procedural --style alpine --size 2401 --spacing 92.56 --max-height 2600 \
    --seed 3 --out "$TMP/s3data" >"$TMP/s3data.log" 2>&1 ||
    { echo "stand-in data failed:"; tail -5 "$TMP/s3data.log"; exit 1; }
  sed -e 's#"\.\./out/datasets/pyrenees"#"'"$TMP"'/s3data"#' \
    -e 's#"scenarios/#"'"$PWD"'/config/scenarios/#' config/pyrenees.toml >"$TMP/s3.toml"
  sed -i '/^\[dataset\]/a anchor = { lat_deg = 42.5, lon_deg = 1.0 }' "$TMP/s3.toml"
fi
log "Fischer S3 data: $S3DATA"
# The old behaviours as [method] sections (eval's --methods takes a listed method's settings
# from the config's [method] when the names match).
for c in ci_earth s3; do
  sed -e '/^\[method\]/,/^$/d' "$TMP/$c.toml" >"$TMP/$c.base.toml"
  printf '\n[method]\nname = "geomipmap"\ncull_box = "grid"\n' | cat "$TMP/$c.base.toml" - >"$TMP/${c}_gm_grid.toml"
  printf '\n[method]\nname = "chunked"\ncull = false\n' | cat "$TMP/$c.base.toml" - >"$TMP/${c}_ch_nocull.toml"
done
run() { # case config methods label
  local out="$KEEP/$4_r$round"
  "$BIN" eval --config "$2" --earth ellipsoid --width "$W" --height "$H" --frames "$FRAMES" \
    --methods "$3" --out "$out" --force >"$out.log" 2>&1 ||
    { echo "$4 failed:"; tail -5 "$out.log"; return; }
  log "round $round $4"
  grep -A5 '^variant' "$out.log" | sed 's/^/    /'
}
for round in 1 2; do
  for c in ci_earth s3; do
    run "$c" "$TMP/$c.toml" brute,udlod,geomipmap,chunked "${c}_curved_box"
    run "$c" "$TMP/${c}_gm_grid.toml" brute,geomipmap "${c}_geomipmap_grid_box"
    run "$c" "$TMP/${c}_ch_nocull.toml" brute,chunked "${c}_chunked_no_cull"
  done
done

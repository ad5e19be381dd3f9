#!/usr/bin/env bash
# Issue 14 (the evaluator's exact surface on the earth) on the GPU machine: `vkterrain eval`
# with `--earth flat` (the grid on the tangent plane, what eval always did before) against
# `--earth ellipsoid` (drawn through the geolocation lattice, each pixel mapped back through
# its inverse: docs/eval.md "On the earth"), same binary, same scenario, 1920x1080, brute
# force (the reference) + UDLOD (its default tau, 1 px). Per case and geometry: wall time per
# frame and renderer, the evaluator's own GPU time ("eval GPU ms") and each method's p99.9
# error, from the summary table.
#
# Cases: the CI terrain anchored on the earth (config/ci_earth.toml, in memory); Fischer S3
# over the Pyrenees (SRTM3, georeferenced) when out/datasets/pyrenees was carried, else over a
# procedural alpine stand-in generated here and anchored at 42.5 N 1 E (the report says which).
# Run from the repository root: `bash scripts/device/eval_earth.sh > $OUT/eval_earth.txt 2>&1`.
set -u
. .device-vk/env.sh
log() { echo "### $*"; }
BIN=${BIN:-.device-vk/vkterrain}
FRAMES=${FRAMES:-96}
W=${W:-1920}
H=${H:-1080}
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
KEEP=${OUT:-out/device-eval-earth}
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
for round in 1 2; do
  for c in ci_earth s3; do
    for earth in flat ellipsoid; do
      out="$KEEP/${c}_${earth}_r$round"
      s=$(date +%s.%N)
      "$BIN" eval --config "$TMP/$c.toml" --earth "$earth" --width "$W" --height "$H" \
        --frames "$FRAMES" --methods brute,udlod --out "$out" --force \
        >"$out.log" 2>&1 || { echo "$c $earth failed:"; tail -5 "$out.log"; continue; }
      e=$(date +%s.%N)
      awk -v n="$c" -v g="$earth" -v s="$s" -v e="$e" -v f="$FRAMES" \
        'BEGIN { printf "### round '"$round"' %s %s: %.1f s wall, %.2f ms per frame and renderer (2 renderers, incl. start-up)\n", n, g, e - s, 1000 * (e - s) / (2 * f) }'
      grep -A3 '^variant' "$out.log" | sed 's/^/    /'
    done
  done
done

#!/usr/bin/env bash
# PGM on the earth (issue 14, docs/pgm.md "On the earth") on the GPU machine: brute force and
# PGM evaluated on the ellipsoid and on the flat world, same binary, same scenarios, 1920x1080:
# Fischer S3 over the Pyrenees (SRTM3, on the earth by its georeferencing) and the CI terrain
# anchored at 46.5 N (config/ci_earth.toml). p99.9 error, holes, triangles and GPU ms per
# variant, twice each (the machine's noise).
#
# Needs: out/datasets/pyrenees carried (`make data-pyrenees`, a few MB) for Fischer S3.
# Run there from the repository root: `bash scripts/device/pgm_earth.sh > $OUT/pgm_earth.txt 2>&1`.
# BIN=path runs another build (an A/B of two builds: alternate them with ROUNDS=1).
set -u
. .device-vk/env.sh
log() { echo "### $*"; }
BIN=${BIN:-.device-vk/vkterrain}
TMP=$(mktemp -d)
configs=()
if [ -f out/datasets/pyrenees/manifest.json ]; then
  sed -e 's#"\.\./out/datasets/pyrenees"#"'"$PWD"'/out/datasets/pyrenees"#' \
    -e 's#"scenarios/#"'"$PWD"'/config/scenarios/#' config/pyrenees.toml >"$TMP/pyrenees.toml"
  configs+=("$TMP/pyrenees.toml")
else
  log "out/datasets/pyrenees absent: Fischer S3 skipped"
fi
sed -e 's#"scenarios/#"'"$PWD"'/config/scenarios/#' config/ci_earth.toml >"$TMP/ci_earth.toml"
configs+=("$TMP/ci_earth.toml")
for round in $(seq "${ROUNDS:-2}"); do
  for c in "${configs[@]}"; do
    for earth in ellipsoid flat; do
      log "round $round $(basename "$c" .toml) $earth: brute,pgm 1920x1080"
      "$BIN" eval --config "$c" --earth "$earth" --methods brute,pgm --frames 120 --warmup 10 \
        --width 1920 --height 1080 --out "$TMP/eval-$round-$earth" --force 2>&1 | tail -4
    done
  done
done
rm -rf "$TMP"

#!/usr/bin/env bash
# Issue 14 (UDLOD's per-axis metric on native geographic grids) on the GPU machine: `vkterrain
# eval` of UDLOD with `lod_metric = "axis"` (each axis its own smallest metric spacing, the
# default) against `lod_metric = "smallest"` (the one smallest spacing: what UDLOD did before),
# same binary, brute force as the reference, 1920x1080, tau 1 and 2. Per case: triangles,
# error (p99.9 / max), holes and GPU ms from the summary table.
#
# Cases (on the ellipsoid, the default): the Pyrenees pair (out/datasets/pyrenees, SRTM3
# N41E001 + N42E001, native 1201 x 2401 at 3 arc seconds) with the long north-north-east view
# (config/scenarios/pyrenees_far_view_nne_down08.toml, far 60 km) and with Fischer S4 (the
# 20-degree view, 4 km); skipped with a line when the data set was not carried. Control: the
# CI terrain anchored on the earth (config/ci_earth.toml: a square grid, whose selection the
# setting must not change: identical rows).
# Run from the repository root: `bash scripts/device/udlod_geo_spacing.sh > $OUT/udlod_geo_spacing.txt 2>&1`.
set -u
. .device-vk/env.sh
log() { echo "### $*"; }
BIN=${BIN:-.device-vk/vkterrain}
FRAMES=${FRAMES:-40}
W=${W:-1920}
H=${H:-1080}
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
cases=()
if [ -f out/datasets/pyrenees/manifest.json ]; then
  for sc in pyrenees_far_view_nne_down08 pyrenees_fischer_s4_rough_steep_down20; do
    sed -e 's#"\.\./out/datasets/pyrenees"#"'"$PWD"'/out/datasets/pyrenees"#' \
      -e 's#"scenarios/[^"]*"#"'"$PWD"'/config/scenarios/'"$sc"'.toml"#' \
      config/pyrenees.toml >"$TMP/$sc.toml"
    cases+=("$sc")
  done
else
  log "out/datasets/pyrenees absent: the Pyrenees skipped"
fi
sed -e 's#"scenarios/#"'"$PWD"'/config/scenarios/#' -e '/^\[method\]/,/^$/d' \
  config/ci_earth.toml >"$TMP/ci_earth.toml"
cases+=(ci_earth)
for c in "${cases[@]}"; do
  for metric in axis smallest; do
    cfg="$TMP/${c}_$metric.toml"
    cp "$TMP/$c.toml" "$cfg"
    printf '\n[method]\nname = "udlod"\nlod_metric = "%s"\n' "$metric" >>"$cfg"
    for tau in 1 2; do
      log "$c lod_metric $metric tau $tau ${W}x$H, $FRAMES frames"
      "$BIN" eval --config "$cfg" --methods brute,udlod --tau-px "$tau" --width "$W" \
        --height "$H" --frames "$FRAMES" --out "$TMP/out" --force 2>&1 |
        grep -A2 '^variant' | sed 's/^/    /'
    done
  done
done

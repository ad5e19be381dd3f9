#!/usr/bin/env bash
# Issue 16's lavapipe report: every method of the harness and its sweep on Fischer S3 and S1,
# the Improved-PGM flight and the low-horizon scenario at 1280x720 on this machine's lavapipe
# (the GPU machine's twin: scripts/device/all_methods.sh). Flat world, as there.
#
# Needs a release build (make data, or at least out/datasets/pyrenees and
# out/datasets/franconia from `vkterrain preprocess`, and ../shared/data/puget_sound).
# Output: $KEEP/<case>/ (report.md, summary.csv, charts) and $KEEP/<case>.log.
# Slow: about 10 minutes per case on 2 cores with the defaults; keep the machine otherwise
# idle, frame times are compared within a run.
set -uo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-target/release/vkterrain}
FRAMES=${FRAMES:-96}
WARMUP=${WARMUP:-8}
CASES=${CASES:-s3 s1 ipgm low}
METHODS=${METHODS:-brute,udlod,pgm,tessellation,geomipmap,chunked}
# Tessellation at 1 px edges takes about 4 s per frame here on the Improved-PGM flight: the
# sweep starts at 2.
SWEEPS=${SWEEPS:---sweep tau_px=0.5,1,2,4 --sweep grid_scale=0.5,1 --sweep warp_rows=0,1 --sweep edge_px=2,4,16 --sweep distance_factor=1,4,8 --sweep error_px=1,4,16}
KEEP=${KEEP:-out/all_methods_lavapipe}
mkdir -p "$KEEP"
lvp_env=$(scripts/lavapipe.sh)
env $lvp_env "$BIN" info 2>/dev/null | head -3
for c in $CASES; do
  case $c in
    s3) args=(--config config/pyrenees.toml) ;;
    s1) args=(--config config/franconia.toml) ;;
    ipgm) args=(--config config/puget.toml --scenario config/scenarios/puget_improved_pgm_flight.toml) ;;
    low) args=(--config config/puget.toml --scenario config/scenarios/puget_low_horizon_down00.toml) ;;
    *) echo "unknown case $c"; continue ;;
  esac
  echo "### $c (${args[*]}), $FRAMES frames after $WARMUP, 1280x720"
  s=$(date +%s)
  # shellcheck disable=SC2086
  env $lvp_env "$BIN" eval "${args[@]}" --earth flat --width 1280 --height 720 \
    --frames "$FRAMES" --warmup "$WARMUP" --methods "$METHODS" $SWEEPS --flip-every 32 \
    --out "$KEEP/$c" --force >"$KEEP/$c.log" 2>&1 || { echo "eval $c failed:"; tail -5 "$KEEP/$c.log"; }
  echo "wall $(( $(date +%s) - s )) s"
  [ -f "$KEEP/$c/summary.csv" ] && grep -A40 "^variant" "$KEEP/$c.log" | grep -v "^evaluated\|^wrote"
done

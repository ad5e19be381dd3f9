#!/usr/bin/env bash
# Issue 18's report on lavapipe: UDLOD before the issue (main at 3ab4290: grid 16, per-level
# split distances) against this build, tau 0.5-4, 640x360, each data set's default flight,
# the two binaries alternated per data set. The CSVs land in OUT/{before,after}-DATA;
# scripts/udlod_before_after_table.py turns them into the report's rows.
#
# Usage: scripts/udlod_before_after_lavapipe.sh BEFORE_TREE NEW_BIN OUT [DATA...]
#   BEFORE_TREE  a worktree of 3ab4290 (`git worktree add ../before 3ab4290`) with its release
#                binary built in target/release or $BEFORE_BIN, and its own data sets
#                preprocessed by it under the paths its configs name (it cannot read today's
#                manifests): target/data/n48w125, out/datasets/{franconia,pyrenees}
#   NEW_BIN      this build's `vkterrain`
#   DATA         ci puget srtm franconia pyrenees (the default: all five)
# SRTM1 runs 30 frames, as the report's earlier rounds did; the rest their config's flight. The
# old binary has no `--earth` (it had no earth); this one runs `--earth flat` for the same
# surface.
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -ge 3 ] || { echo "usage: $0 BEFORE_TREE NEW_BIN OUT [DATA...]" >&2; exit 2; }
before_tree=$(realpath "$1") new=$(realpath "$2") out=$3
shift 3
before=${BEFORE_BIN:-$before_tree/target/release/vkterrain}
[ -x "$before" ] || { echo "$before: no binary (build 3ab4290 first)" >&2; exit 2; }
lvp=$(scripts/lavapipe.sh)
# shellcheck disable=SC2086 # NAME=VALUE words
[ -z "$lvp" ] || export $lvp
mkdir -p "$out"
out=$(realpath "$out")
data=("$@")
[ ${#data[@]} -gt 0 ] || data=(ci puget srtm franconia pyrenees)
for d in "${data[@]}"; do
  frames=()
  [ "$d" = srtm ] && frames=(--frames 30)
  echo "### before $d $(date +%T)"
  (cd "$before_tree" && "$before" eval --config "config/$d.toml" --methods udlod \
    --sweep tau_px=0.5,1,2,4 --width 640 --height 360 "${frames[@]}" \
    --out "$out/before-$d" --force 2>&1 | tail -3)
  echo "### after $d $(date +%T)"
  "$new" eval --config "config/$d.toml" --earth flat --methods udlod \
    --sweep tau_px=0.5,1,2,4 --width 640 --height 360 "${frames[@]}" \
    --out "$out/after-$d" --force 2>&1 | tail -3
done

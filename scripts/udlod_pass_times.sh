#!/usr/bin/env bash
# UDLOD's GPU time per pass on lavapipe, from `vkterrain render`'s summary.json: the medians
# of the prepass and the terrain pass over frames 5 on (after lavapipe's lazy compiles), and
# the prepass per third frame (llvmpipe's slow dispatch mode shows as stretches of frames:
# docs/udlod-rounds.md, "Measured this round, not built"). The config's method becomes UDLOD with
# LINES added to its `[method]` table; the copy sits beside the config, so its relative
# paths hold. THREADS sets LP_NUM_THREADS, FRAMES the frame count (60).
# Usage: [LINES="collapse = false"] [THREADS=1] [FRAMES=100] scripts/udlod_pass_times.sh BIN CONFIG [render args]
#   e.g. scripts/udlod_pass_times.sh target/release/vkterrain config/franconia.toml --earth flat
#   (the build before issue 18 has no --earth; its own configs and data sets)
set -euo pipefail
[ $# -ge 2 ] || { echo "usage: $0 BIN CONFIG [render args]" >&2; exit 2; }
bin=$1 base=$2
shift 2
here=$(cd "$(dirname "$0")/.." && pwd)
# Nothing to export with the system's lavapipe (a bare `export` would list the environment).
lvp=$("$here/scripts/lavapipe.sh")
# shellcheck disable=SC2086 # NAME=VALUE words
[ -z "$lvp" ] || export $lvp
[ -n "${THREADS:-}" ] && export LP_NUM_THREADS=$THREADS
. "$here/scripts/device/udlod_config.sh"
tmp=$(udlod_config "$base" "${LINES:-}")
cfg=$(dirname "$base")/.udlod-pass-times-$$.toml
mv "$tmp" "$cfg"
out=$(mktemp -d)
trap 'rm -rf "$cfg" "$out"' EXIT
"$bin" render --config "$cfg" --width 640 --height 360 --frames "${FRAMES:-60}" --out "$out" "$@" > /dev/null
python3 - "$out/summary.json" <<'PY'
import json, statistics, sys
frames = json.load(open(sys.argv[1]))["per_frame"][5:]
prepass = [f["timings"]["gpu_prepass_ms"] for f in frames]
terrain = [f["timings"]["gpu_terrain_ms"] for f in frames]
print("triangles %d prepass median %.2f ms terrain median %.2f ms; prepass per third frame: %s"
      % (frames[0]["triangles"], statistics.median(prepass), statistics.median(terrain),
         " ".join("%.2f" % p for p in prepass[::3])))
PY

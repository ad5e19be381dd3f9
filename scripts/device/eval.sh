#!/usr/bin/env bash
# Evaluator wall time per frame and variant, before (the session-start build dcfa0d7: metrics
# on the CPU) and after (metrics on the GPU), on the GPU machine at 1920x1080 (issue 17's
# target: evaluation adds <= 2 ms per frame and variant). Prints a table.
#
# Run from the repository root on the device after `. .device-vk/env.sh`, with in .device-vk/:
#   vkterrain         this branch's release build (../shared/device-vulkan/prepare.sh)
#   vkterrain-before  /work/bin-old/vkterrain-dcfa0d7 (the "before" binary; optional)
# Data: the procedural CI terrain (config/ci.toml, generated in memory: nothing to carry);
# Fischer S3 over the Pyrenees too when out/datasets/pyrenees exists (carry that folder; built
# here by `make data-pyrenees`, a few MB).
#
# Per case: wall time of the whole `eval` (brute force reference + UDLOD, FRAMES frames),
# divided by frames x renderers; for "after" also the evaluator's own GPU time per frame and
# renderer ("eval GPU ms": analysis pass + readback copy, from timestamps) and the methods'
# GPU times (the chart's speed axis) next to `vkterrain bench`'s for the same frames.
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN=${BIN:-.device-vk/vkterrain}
BEFORE=${BEFORE:-.device-vk/vkterrain-before}
FRAMES=${FRAMES:-96}
W=${W:-1920}
H=${H:-1080}
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
# The "after" evaluations (report.md, charts, images) stay here ($OUT on the device machine).
KEEP=${OUT:-out/device-eval}
mkdir -p "$KEEP"

# The before binary reads the older config format: no [method] section.
mkdir -p "$TMP/old/scenarios"
grep -v '^\[method\]\|^name = "brute"' config/ci.toml >"$TMP/old/ci.toml"
cp config/scenarios/*.toml "$TMP/old/scenarios/"
sed -e 's#"\.\./out/datasets/pyrenees"#"'"$PWD"'/out/datasets/pyrenees"#' config/pyrenees.toml >"$TMP/old/pyrenees.toml"

cases=("ci:config/ci.toml:$TMP/old/ci.toml")
[ -f out/datasets/pyrenees/manifest.json ] && cases+=("fischer_s3:config/pyrenees.toml:$TMP/old/pyrenees.toml")

row() { printf '%-12s %-7s %8s %10s %22s\n' "$@"; }
# case, build, start and end (s): wall time, per frame, per frame and renderer (awk: no bc there).
timed() {
  awk -v n="$1" -v b="$2" -v s="$3" -v e="$4" -v f="$FRAMES" -v r="$renderers" \
    'BEGIN { w = e - s; printf "%-12s %-7s %8.1f %10.3f %22.1f\n", n, b, w, w / f, 1000 * w / (f * r) }'
}
row case build wall_s "s/frame" "ms/(frame x renderer)"
for c in "${cases[@]}"; do
  IFS=: read -r name cfg oldcfg <<<"$c"
  renderers=2 # brute force (the reference) + UDLOD
  if [ -x "$BEFORE" ]; then
    s=$(date +%s.%N)
    "$BEFORE" eval --config "$oldcfg" --width "$W" --height "$H" --frames "$FRAMES" \
      --methods brute,udlod --out "$TMP/before_$name" --force >"$TMP/before_$name.log" 2>&1 \
      || { echo "before $name failed:"; tail -5 "$TMP/before_$name.log"; }
    e=$(date +%s.%N)
    timed "$name" before "$s" "$e"
  fi
  s=$(date +%s.%N)
  "$BIN" eval --config "$cfg" --width "$W" --height "$H" --frames "$FRAMES" \
    --methods brute,udlod --out "$KEEP/after_$name" --force >"$KEEP/after_$name.log" 2>&1 \
    || { echo "after $name failed:"; tail -5 "$KEEP/after_$name.log"; continue; }
  e=$(date +%s.%N)
  timed "$name" after "$s" "$e"
  grep -A2 '^variant' "$KEEP/after_$name.log" | sed 's/^/    /'
  # The speed axis against a plain benchmark loop (columns: resolution, frames in flight,
  # triangles, median ms, p99 ms, gpu ms, readback, overlap).
  for m in brute udlod; do
    printf '    bench %-6s' "$m"
    "$BIN" bench --config "$cfg" --width "$W" --height "$H" --frames "$FRAMES" --method "$m" 2>&1 \
      | grep -E "^ *${W}x${H} +1 " | head -1 || echo "(bench has no ${W}x${H} row)"
  done
done

# The issue's chart: Fischer S3 (Pyrenees), every method and sweep, frame time vs error.
if [ -f out/datasets/pyrenees/manifest.json ]; then
  s=$(date +%s.%N)
  "$BIN" eval --config config/pyrenees.toml --width "$W" --height "$H" --frames "$FRAMES" \
    --methods brute,udlod,pgm --sweep tau_px=0.5,1,2,4 --sweep grid_scale=0.5,1 \
    --out "$KEEP/fischer_s3_all" --force >"$KEEP/fischer_s3_all.log" 2>&1 \
    || { echo "fischer_s3_all failed:"; tail -5 "$KEEP/fischer_s3_all.log"; exit 1; }
  e=$(date +%s.%N)
  renderers=7 # brute force + UDLOD at 4 taus + PGM at 2 grids
  timed fischer_all after "$s" "$e"
  grep -A8 '^variant' "$KEEP/fischer_s3_all.log" | sed 's/^/    /'
  echo "chart: $KEEP/fischer_s3_all/frame_time_vs_error.png"
fi

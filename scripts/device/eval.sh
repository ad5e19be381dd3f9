#!/usr/bin/env bash
# Evaluator wall time per frame and variant, before (the session-start build dcfa0d7: metrics
# on the CPU) and after (metrics on the GPU), on the GPU machine at 1920x1080 (issue 17's
# target: evaluation adds <= 2 ms per frame and variant). Prints a table.
#
# Run from the repository root on the device after `. .device-vk/env.sh`, with in .device-vk/:
#   vkterrain         this branch's release build (../shared/device-vulkan/prepare.sh)
#   vkterrain-before  /work/bin-old/vkterrain-dcfa0d7 (the "before" binary; optional)
# Data, all built here: the procedural CI terrain (config/ci.toml, generated in memory) and
# Fischer S3 (config/pyrenees.toml's scenario) over out/datasets/pyrenees when it was carried
# (`make data-pyrenees` builds it where the SRTM tiles are), else over a procedural stand-in
# that `vkterrain preprocess --procedural --style alpine` generates here (2401² samples at the
# Pyrenees' 92.56 m, peaks below the flight's 3550 m; a few seconds, ~30 MB, deleted at the
# end). The report says which one was used.
#
# Per case: wall time of the whole `eval` (brute force reference + UDLOD, FRAMES frames),
# divided by frames x renderers; for "after" also the evaluator's own GPU time per frame and
# renderer ("eval GPU ms": analysis pass + readback copy, from timestamps) and the methods'
# GPU times (the chart's speed axis) next to `vkterrain bench`'s for the same frames, and the
# evaluation's added time per frame and renderer two ways: "eval GPU ms" (the analysis'
# GPU time, timestamps) and the wall time per frame and renderer minus the bench loop's
# median frame time at one frame in flight (mean of the methods): the issue's target is
# <= 2 ms at 1920x1080.
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

# Fischer S3's data: the real Pyrenees when carried, else the procedural stand-in.
S3CFG=config/pyrenees.toml
S3DATA="the Pyrenees (SRTM, out/datasets/pyrenees)"
if [ ! -f out/datasets/pyrenees/manifest.json ]; then
  "$BIN" preprocess --procedural --style alpine --size 2401 --spacing 92.56 --max-height 2600 \
    --seed 3 --out "$TMP/s3data" >"$TMP/s3data.log" 2>&1 \
    || { echo "stand-in data failed:"; tail -5 "$TMP/s3data.log"; exit 1; }
  sed -e 's#"\.\./out/datasets/pyrenees"#"'"$TMP"'/s3data"#' \
    -e 's#"scenarios/#"'"$PWD"'/config/scenarios/#' config/pyrenees.toml >"$TMP/s3.toml"
  sed -e 's#"\.\./out/datasets/pyrenees"#"'"$TMP"'/s3data"#' "$TMP/old/pyrenees.toml" >"$TMP/old/s3.toml"
  S3CFG="$TMP/s3.toml"
  S3DATA="a procedural alpine stand-in (2401² at 92.56 m, generated here)"
  cp "$TMP/old/s3.toml" "$TMP/old/pyrenees.toml"
fi
echo "Fischer S3 data: $S3DATA"
cases=("ci:config/ci.toml:$TMP/old/ci.toml" "fischer_s3:$S3CFG:$TMP/old/pyrenees.toml")

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
  bench_sum=0
  for m in brute udlod; do
    line=$("$BIN" bench --config "$cfg" --width "$W" --height "$H" --frames "$FRAMES" --method "$m" 2>&1 \
      | grep -E "^ *${W}x${H} +1 " | head -1 || true)
    printf '    bench %-6s %s\n' "$m" "${line:-(bench has no ${W}x${H} row)}"
    bench_sum=$(awk -v a="$bench_sum" -v l="$line" 'BEGIN { split(l, f, " +"); n = (f[1] == "" ? 5 : 4); print a + f[n] }')
  done
  awk -v s="$s" -v e="$e" -v f="$FRAMES" -v r="$renderers" -v b="$bench_sum" \
    'BEGIN { w = 1000 * (e - s) / (f * r); printf "    added by the evaluation (wall): %.1f ms per frame and renderer (eval %.1f - bench %.1f; includes start-up)\n", w - b / r, w, b / r }'
done

# The issue's chart: Fischer S3, every method and sweep, frame time vs error (flat, as when PGM
# refused the earth; scripts/device/eval_earth.sh and pgm_earth.sh measure on the ellipsoid).
if true; then
  s=$(date +%s.%N)
  "$BIN" eval --config "$S3CFG" --width "$W" --height "$H" --frames "$FRAMES" \
    --methods brute,udlod,pgm --sweep tau_px=0.5,1,2,4 --sweep grid_scale=0.5,1 --earth flat \
    --out "$KEEP/fischer_s3_all" --force >"$KEEP/fischer_s3_all.log" 2>&1 \
    || { echo "fischer_s3_all failed:"; tail -5 "$KEEP/fischer_s3_all.log"; exit 1; }
  e=$(date +%s.%N)
  renderers=7 # brute force + UDLOD at 4 taus + PGM at 2 grids
  timed fischer_all after "$s" "$e"
  grep -A8 '^variant' "$KEEP/fischer_s3_all.log" | sed 's/^/    /'
  echo "chart: $KEEP/fischer_s3_all/frame_time_vs_error.png (data: $S3DATA)"
fi

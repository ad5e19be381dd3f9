#!/usr/bin/env bash
# The evaluator's analysis time (eval GPU ms: the analysis passes and the readback copy, from
# timestamps) of two builds on the GPU machine at 1920x1080, alternating: .device-vk/vkterrain
# (this tree) and .device-vk/vkterrain-before (a previous build, prepared the same way).
# Per round and build: the median eval GPU ms and method GPU ms per renderer over FRAMES
# frames of the CI terrain (flat) and, when out/datasets/pyrenees was carried, Fischer S3 on
# the ellipsoid. Prints one line per round, build and case.
#   bash scripts/device/analysis_ab.sh > $OUT/analysis_ab.txt 2>&1
set -u
. .device-vk/env.sh
FRAMES=${FRAMES:-96}
ROUNDS=${ROUNDS:-2}
out=out/device/analysis_ab
mkdir -p "$out"
cases="ci"
[ -d out/datasets/pyrenees ] && cases="ci s3"
medians() { # results.json -> "variant: eval med / method med" per variant
  python3 - "$1" <<'PY'
import json, statistics as st, sys
d = json.load(open(sys.argv[1]))
for v in sorted({r['variant'] for r in d['rows']}):
    rows = [r for r in d['rows'] if r['variant'] == v and r['frame'] >= d['warmup']]
    print(f"  {v}: eval GPU ms {st.median(r['gpu_eval_ms'] for r in rows):.3f}, method GPU ms {st.median(r['gpu_ms'] for r in rows):.3f}")
PY
}
for round in $(seq "$ROUNDS"); do
  for build in before after; do
    bin=.device-vk/vkterrain
    [ "$build" = before ] && bin=.device-vk/vkterrain-before
    for c in $cases; do
      if [ "$c" = ci ]; then cfg=config/ci.toml; earth=flat; else cfg=config/pyrenees.toml; earth=ellipsoid; fi
      dir="$out/${c}_${build}_$round"
      timeout 120 "$bin" eval --config "$cfg" --earth "$earth" --width 1920 --height 1080 \
        --frames "$FRAMES" --warmup 10 --methods brute,udlod --out "$dir" --force > "$dir.log" 2>&1 \
        || { echo "round $round $build $c: exit $?"; tail -3 "$dir.log"; continue; }
      echo "round $round $build $c"
      medians "$dir/results.json"
    done
  done
done

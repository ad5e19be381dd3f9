#!/usr/bin/env bash
# Whole-run wall time of `vkterrain eval` of two builds on the GPU machine at 1920x1080,
# alternating: .device-vk/vkterrain (this tree: FLIP in parallel strips, image PNGs encoded in
# parallel) and .device-vk/vkterrain-before (main before it, prepared the same way). The change
# is CPU-side only (FLIP and the report), so what it can move is the wall time, most of all
# the tail after the last frame (that frame's FLIP ran on one core); the results must be
# identical (checked: every results.json column but the timings).
# Per round and build: wall of the whole command, the frame loop's wall (results.json
# wall_s) and the median eval GPU ms per renderer over FRAMES frames of the CI terrain.
#   bash scripts/device/eval_speed.sh > $OUT/eval_speed.txt 2>&1
set -u
. .device-vk/env.sh
FRAMES=${FRAMES:-96}
ROUNDS=${ROUNDS:-3}
out=out/device/eval_speed
mkdir -p "$out"
summary() { # results.json, wall -> one line
  python3 - "$1" "$2" <<'PY'
import json, statistics as st, sys
d = json.load(open(sys.argv[1]))
frames = len({r['frame'] for r in d['rows']})
runs = len({r['variant'] for r in d['rows']})
parts = [f"wall {float(sys.argv[2]):.2f} s ({1e3 * float(sys.argv[2]) / (frames * runs):.1f} ms per frame and renderer), frame loop {d['wall_s']:.2f} s"]
for v in sorted({r['variant'] for r in d['rows']}):
    rows = [r for r in d['rows'] if r['variant'] == v and r['frame'] >= d['warmup']]
    parts.append(f"{v}: eval GPU ms {st.median(r['gpu_eval_ms'] for r in rows):.3f}")
print("  " + "; ".join(parts))
PY
}
same() { # two results.json: identical but for the timings?
  python3 - "$1" "$2" <<'PY'
import json, sys
timing = {'gpu_ms', 'gpu_prepass_ms', 'gpu_terrain_ms', 'gpu_eval_ms', 'cpu_record_ms'}
a, b = (json.load(open(p)) for p in sys.argv[1:3])
diff = sum(1 for ra, rb in zip(a['rows'], b['rows']) for k in ra if k not in timing and ra[k] != rb[k])
print(f"  metric columns differing between the builds: {diff} (of {len(a['rows'])} rows)")
PY
}
for round in $(seq "$ROUNDS"); do
  for build in before after; do
    bin=.device-vk/vkterrain
    [ "$build" = before ] && bin=.device-vk/vkterrain-before
    dir="$out/ci_${build}_$round"
    start=$(date +%s.%N)
    timeout 300 "$bin" eval --config config/ci.toml --earth flat --width 1920 --height 1080 \
      --frames "$FRAMES" --warmup 10 --methods brute,udlod --out "$dir" --force > "$dir.log" 2>&1 \
      || { echo "round $round $build: exit $?"; tail -3 "$dir.log"; continue; }
    wall=$(awk -v a="$start" -v b="$(date +%s.%N)" 'BEGIN { print b - a }') # no bc there
    echo "round $round $build"
    summary "$dir/results.json" "$wall"
  done
  same "$out/ci_before_$round/results.json" "$out/ci_after_$round/results.json"
done

#!/usr/bin/env bash
# What `vkterrain eval` adds to rendering the same frames on the GPU machine (issue 17's
# target: <= 2 ms per 1920x1080 frame and variant), as a marginal cost: per build and round,
# `eval` of brute force + UDLOD and `render` of each method alone (one frame in flight, as
# `eval` renders), at F_HI and F_LO frames of the CI terrain. Start-up and the report cancel
# in the differences:
#   added per frame and variant = ((eval_hi - eval_lo) - sum over methods (render_hi - render_lo))
#                                 / ((F_HI - F_LO) * 2)
# The same with `--flip-every 0` (no FLIP but the image frames') isolates FLIP's share.
# The lavapipe version of this measurement: scripts/eval_speed_lavapipe.sh.
#
# Run from the repository root on the device after `. .device-vk/env.sh`, with in .device-vk/:
#   vkterrain              this tree's release build (../shared/device-vulkan/README.md)
#   vkterrain-before.xz    optional: another build (xz) to compare with
# Env: ROUNDS (3), F_HI (96), F_LO (16), W (1920), H (1080); BEFORE_FORMAT=old runs the before
# build with the older config format (no [method] section; e.g. dcfa0d7, metrics on the CPU,
# which has no --earth and no FLIP).
# Prints CSV: build,round,command,frames,wall_s; then the added time per round.
set -euo pipefail
cd "$(dirname "$0")/../.."
ROUNDS=${ROUNDS:-3}
HI=${F_HI:-96}
LO=${F_LO:-16}
size=(--width "${W:-1920}" --height "${H:-1080}")
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
builds=(after)
if [ -f .device-vk/vkterrain-before.xz ]; then
  xz -dc .device-vk/vkterrain-before.xz >"$TMP/before" && chmod +x "$TMP/before"
  mkdir -p "$TMP/old/scenarios"
  grep -v '^\[method\]\|^name = "brute"' config/ci.toml >"$TMP/old/ci.toml"
  cp config/scenarios/*.toml "$TMP/old/scenarios/"
  builds=(before after)
fi

# timed BUILD ROUND NAME FRAMES command...: one CSV line (awk: no bc on the device).
timed() {
  local build=$1 round=$2 name=$3 frames=$4 s e
  shift 4
  s=$(date +%s.%N)
  "$@" >"$TMP/log" 2>&1 || { echo "error: $build $name $frames failed:" >&2; tail -5 "$TMP/log" >&2; exit 1; }
  e=$(date +%s.%N)
  [ "$round" = 0 ] || awk -v a="$s" -v b="$e" -v l="$build,$round,$name,$frames" \
    'BEGIN { printf "%s,%.3f\n", l, b - a }' | tee -a "$TMP/csv"
}

echo "build,round,command,frames,wall_s"
for round in $(seq 0 "$ROUNDS"); do # round 0 warms the driver's shader cache, not printed
  for build in "${builds[@]}"; do
    if [ "$build" = before ] && [ "${BEFORE_FORMAT:-new}" = old ]; then
      bin=$TMP/before cfg=$TMP/old/ci.toml flips=() earth=()
    else
      bin=.device-vk/vkterrain cfg=config/ci.toml flips=("" "--flip-every 0") earth=(--earth flat)
      [ "$build" = before ] && bin=$TMP/before
    fi
    for f in "$HI" "$LO"; do
      for flip in "${flips[@]:-}"; do
        name="eval${flip:+ $flip}"
        # shellcheck disable=SC2086
        timed $build "$round" "$name" "$f" "$bin" eval --config "$cfg" "${size[@]}" "${earth[@]}" \
          --frames "$f" --warmup 2 --methods brute,udlod $flip --out "$TMP/eval" --force
        [ "$name $f" = "eval $HI" ] && cp "$TMP/eval/results.json" "$TMP/results_$build.json"
      done
      for m in brute udlod; do
        rm -rf "$TMP/render"
        timed $build "$round" "render $m" "$f" "$bin" render --config "$cfg" "${size[@]}" \
          "${earth[@]}" --frames "$f" --warmup 2 --frames-in-flight 1 --method $m --out "$TMP/render"
      done
    done
  done
done

echo
echo "added per frame and variant (ms): build, round, eval command, added"
awk -F, -v hi="$HI" -v lo="$LO" '
  { t[$1 "|" $2 "|" $3 "|" $4] = $5; if ($3 ~ /^eval/) e[$1 "|" $2 "|" $3] = 1 }
  END {
    for (k in e) {
      split(k, p, "|"); b = p[1]; r = p[2]
      de = t[k "|" hi] - t[k "|" lo]
      dr = 0
      for (m = 1; m <= 2; m++) {
        n = (m == 1 ? "render brute" : "render udlod")
        dr += t[b "|" r "|" n "|" hi] - t[b "|" r "|" n "|" lo]
      }
      printf "%s, %s, %s, %.2f\n", b, r, p[3], 1000 * (de - dr) / ((hi - lo) * 2)
    }
  }' "$TMP/csv" | sort

# Both builds' last default evaluation at F_HI: every metric column equal?
if [ -f "$TMP/results_before.json" ] && [ "${BEFORE_FORMAT:-new}" = new ]; then
  python3 - "$TMP/results_before.json" "$TMP/results_after.json" <<'PY'
import json, sys
timing = {'gpu_ms', 'gpu_prepass_ms', 'gpu_terrain_ms', 'gpu_eval_ms', 'cpu_record_ms'}
a, b = (json.load(open(p)) for p in sys.argv[1:3])
diff = sum(1 for ra, rb in zip(a['rows'], b['rows']) for k in ra if k not in timing and ra[k] != rb[k])
flips = sum(1 for r in b['rows'] if r.get('flip'))
print(f"metric columns differing between the builds: {diff} (of {len(a['rows'])} rows; {flips} with FLIP)")
PY
fi

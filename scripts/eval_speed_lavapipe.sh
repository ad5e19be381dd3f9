#!/usr/bin/env bash
# What an evaluation costs on lavapipe, before and after (issue 17's lavapipe target), as
# time added to rendering the same frames: per build and round, `eval` of brute force + UDLOD
# and `render` of each method alone (one frame in flight, like `eval`), both at F_HI and F_LO
# frames of the CI terrain at 1280x720. The differences between the two frame counts cancel
# start-up and the report; what `eval` adds per frame and variant is
#   ((eval_hi - eval_lo) - sum over methods of (render_hi - render_lo)) / ((F_HI - F_LO) * 2).
# Builds alternate within each round (the machine is shared and noisy: compare within a round).
# Warm Mesa's shader cache first (a cold cache costs ~10 s per new binary): one warm-up round
# is run and not printed.
#
# Usage: scripts/eval_speed_lavapipe.sh BEFORE_BIN BEFORE_TREE [AFTER_BIN [AFTER_TREE]]
#   BEFORE_TREE: the checkout whose config/ci.toml the before binary reads (older builds have
#   an older config format). Env: ROUNDS (3), F_HI (24), F_LO (4), WIDTH (1280), HEIGHT (720).
# Prints one CSV line per build, round and command: build,round,command,frames,wall_s,cpu_s.
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -ge 2 ] || { echo "usage: $0 BEFORE_BIN BEFORE_TREE [AFTER_BIN [AFTER_TREE]]" >&2; exit 2; }
before_bin=$(realpath "$1")
before_tree=$(realpath "$2")
after_bin=$(realpath "${3:-target/release/vkterrain}")
after_tree=$(realpath "${4:-.}")
rounds=${ROUNDS:-3}
hi=${F_HI:-24}
lo=${F_LO:-4}
size=(--width "${WIDTH:-1280}" --height "${HEIGHT:-720}")
lvp_env=$(scripts/lavapipe.sh)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# timed BUILD ROUND NAME FRAMES -- command...: runs it in the build's tree, prints the CSV line.
timed() {
    local build=$1 round=$2 name=$3 frames=$4 tree
    shift 5
    [ "$build" = before ] && tree=$before_tree || tree=$after_tree
    (cd "$tree" && env $lvp_env /usr/bin/time -f "%e %U %S" -o "$tmp/time" "$@" >"$tmp/log" 2>&1) \
        || { echo "error: $build $name failed:" >&2; tail -5 "$tmp/log" >&2; exit 1; }
    read -r wall user sys <"$tmp/time"
    [ "$round" = 0 ] || echo "$build,$round,$name,$frames,$wall,$(echo "$user + $sys" | bc)"
}

echo "build,round,command,frames,wall_s,cpu_s"
for round in $(seq 0 "$rounds"); do
    for build in before after; do
        [ "$build" = before ] && bin=$before_bin || bin=$after_bin
        for f in "$hi" "$lo"; do
            timed $build "$round" eval "$f" -- "$bin" eval --config config/ci.toml "${size[@]}" \
                --frames "$f" --warmup 2 --methods brute,udlod --out "$tmp/eval" --force
            for m in brute udlod; do
                rm -rf "$tmp/render"
                timed $build "$round" "render $m" "$f" -- "$bin" render --config config/ci.toml \
                    "${size[@]}" --frames "$f" --warmup 2 --frames-in-flight 1 --method $m \
                    --out "$tmp/render"
            done
        done
    done
done

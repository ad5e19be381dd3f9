#!/usr/bin/env bash
# The system's lavapipe against the one scripts/lavapipe.sh provides, same binary, alternating
# A B A B per method (the machines are noisy: compare within a round). Prints `bench`'s 1280x720
# row (one frame in flight, 25 frames, 5 warm-up) per method, driver and round.
# Usage: scripts/compare-lavapipe.sh [BIN]   (default target/release/vkterrain)
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${1:-target/release/vkterrain}
new_env=$(VKTERRAIN_LAVAPIPE=25 scripts/lavapipe.sh)
[ -n "$new_env" ] || { echo "error: scripts/lavapipe.sh provides no other lavapipe here" >&2; exit 1; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for m in brute udlod pgm tessellation geomipmap; do
    for round in 1 2; do
        for drv in system new; do
            if [ $drv = new ]; then run=(env $new_env "$bin"); else run=("$bin"); fi
            driver=$("${run[@]}" info | sed -n 's/^driver: *//p')
            row=$("${run[@]}" bench --config config/ci.toml --frames 25 --warmup 5 \
                --resolutions 1280x720 --compare-frames-in-flight 1 --method "$m" --out "$tmp" | grep 1280x720)
            echo "$m | $driver | round $round | $row"
        done
    done
done

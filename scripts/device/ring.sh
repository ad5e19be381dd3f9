#!/usr/bin/env bash
# Ring publishing on the GPU machine (H200, Vulkan): copy vs zero-copy (VK_EXT_external_memory_host)
# at 1280x720 and 1920x1080 with 0 and 4 consumers, plus the CPU-only ring numbers, and serve's
# Zenoh path over loopback (TCP and shared memory).
#
# Build here first (release), then carry .device-vk:
#   cargo bench --bench ring --no-run --message-format=json \
#     | python3 -c 'import json,sys; [print(m["executable"]) for m in map(json.loads, sys.stdin) if m.get("executable") and "/ring-" in m["executable"]]' \
#     | xargs -I{} cp {} .device-vk/ring-bench
#   cargo build --release && ../shared/device-vulkan/prepare.sh target/release/vkterrain
# Run there from the repository root (no data needed: the benchmark renders a 65x65 plane and
# serve uses config/ci.toml's procedural terrain):
#   bash scripts/device/ring.sh
set -euo pipefail
. .device-vk/env.sh
export VKTERRAIN_BENCH_SECONDS=3
echo "== ring benchmark (release), device:"; .device-vk/vkterrain info | head -3
.device-vk/ring-bench --bench
# Zenoh over loopback: 1280x720 frames/s and publish->subscriber latency, TCP vs shared memory.
dir=$(mktemp -d /dev/shm/vkt-dev-XXXXXX); chmod 700 "$dir"
export VKTERRAIN_RING_DIR=$dir
.device-vk/vkterrain serve --config config/ci.toml --width 1280 --height 720 --ring dev \
    --zenoh --zenoh-listen tcp/127.0.0.1:17447 --status-file "$dir/status.json" &
pid=$!
sleep 8
for mode in shm no-shm; do
    extra=(); [ "$mode" = no-shm ] && extra=(--no-shm)
    echo "== zenoh $mode: 10 s"
    .device-vk/vkterrain subscribe --ring dev --connect tcp/127.0.0.1:17447 --seconds 10 --quiet "${extra[@]}"
done
kill -TERM $pid; wait $pid || true
cat "$dir/status.json"; rm -rf "$dir"

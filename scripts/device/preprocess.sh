#!/usr/bin/env bash
# Preprocessing at scale on the GPU machine (16 cores, no GDAL there: the benchmarks are built
# without the `gdal` feature and use procedural data only; ../shared is not available there).
#
# Here, from the project root (builds the two benchmark binaries and copies them into the
# git-ignored .device-vk/, about 15 MB):
#     scripts/device/preprocess.sh prepare
# There, from the project root, with .device-vk carried (each part fits in one 10-minute call):
#     scripts/device/preprocess.sh small   # 4097² and 16385²: 1, 4 and 16 threads; start-up
#     scripts/device/preprocess.sh large   # 65537²: 16 threads (peak RSS); start-up
# Each part prints markdown tables: seconds, source MB/s (f32 samples generated), output
# samples per second per thread, peak RSS of each run (its own child process), and UDLOD
# start-up (stored statistics vs computed from level 0). Needs about 24 GiB of disk for
# `large` (deleted afterwards); set VKT_BENCH_OUT to put the data sets elsewhere.
set -euo pipefail
cd "$(dirname "$0")/../.."
part=${1:-small}
out=${VKT_BENCH_OUT:-$PWD/.device-vk/data}

if [ "$part" = prepare ]; then
    cargo bench --locked --no-default-features --bench preprocess --bench startup --no-run
    mkdir -p .device-vk
    for b in preprocess startup; do
        exe=$(ls -t target/release/deps/$b-* | grep -v '\.d$' | head -1)
        cp "$exe" .device-vk/bench-$b
        strip .device-vk/bench-$b 2>/dev/null || true
    done
    du -sh .device-vk
    exit 0
fi

nproc=$(nproc)
echo "machine: $(nproc) cores, $(grep MemTotal /proc/meminfo | awk '{print $2/1048576 " GiB"}') memory, disk free $(df -h . | awk 'NR==2 {print $4}')"
mkdir -p "$out"
export VKT_BENCH_OUT="$out" VKT_BENCH_KEEP=1 VKT_BENCH_CASES=procedural
case "$part" in
small)
    VKT_BENCH_PROCEDURAL_SIZES=4097,16385 VKT_BENCH_THREADS=1,4,$nproc .device-vk/bench-preprocess
    VKT_STARTUP_DATASETS="$out/p4097,$out/p16385" .device-vk/bench-startup
    rm -rf "$out/p4097" "$out/p16385"
    ;;
large)
    VKT_BENCH_PROCEDURAL_SIZES=65537 VKT_BENCH_THREADS=$nproc .device-vk/bench-preprocess
    du -sh "$out/p65537"
    # (b), the level-0 computation on one thread, takes tens of minutes at this size.
    VKT_STARTUP_BEFORE=0 VKT_STARTUP_DATASETS="$out/p65537" .device-vk/bench-startup
    rm -rf "$out/p65537"
    ;;
*)
    echo "usage: $0 prepare|small|large" >&2
    exit 1
    ;;
esac

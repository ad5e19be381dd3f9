#!/usr/bin/env bash
# Issue 18: UDLOD grid 4 against grid 8 on the GPU machine, split into the selection prepass
# and the terrain pass (GPU timestamps), to see where grid 4's extra GPU time goes (small
# instances or the deeper tree). Runs .device-vk/vkterrain (this tree) and, when present,
# .device-vk/vkterrain-before (a build before level 0's statistics were dropped: the
# selections should match, culling of level-0 tiles aside).
# Per binary and data set: one eval at 1920x1080, 60 frames after 10 of the default flight,
# --sweep grid_size=4,8 --sweep tau_px=$TAUS; prints per variant the medians of prepass and
# terrain GPU ms, triangles, p99.9 px, holes and UDLOD/oracle.
# Here, before carrying: the device build prepared into .device-vk (../shared/device-vulkan),
# and the Puget Sound heights in .device-vk/data/ps_height_1k.png (skipped when absent).
# Run there: `bash scripts/device/udlod_grid4.sh > $OUT/udlod_grid4.txt 2>&1`.
set -u
. .device-vk/env.sh
. scripts/device/puget_config.sh
# CASES: which data sets (ci, puget, hedberg: Hedberg's uneven map, procedural 4097² at 10 m;
# pyrenees: Fischer S3, when out/datasets/pyrenees was carried). TAUS: the tau sweep.
CASES=${CASES:-ci puget}
TAUS=${TAUS:-0.5,1,2}
cfgs=()
for c in $CASES; do
  case $c in
    ci) cfgs+=(config/ci.toml) ;;
    puget) if [ -f .device-vk/data/ps_height_1k.png ]; then cfgs+=("$PUGET"); else echo "### Puget Sound heights absent: skipped"; fi ;;
    hedberg) cfgs+=(config/hedberg_uneven.toml) ;;
    pyrenees) if [ -f out/datasets/pyrenees/manifest.json ]; then cfgs+=(config/pyrenees.toml); else echo "### out/datasets/pyrenees absent: skipped"; fi ;;
  esac
done
summarize() { # results.json + summary.csv -> one line per variant
  python3 - "$1" <<'PY'
import csv, json, statistics as st, sys, os
d = json.load(open(os.path.join(sys.argv[1], 'results.json')))
summ = {r['variant']: r for r in csv.DictReader(open(os.path.join(sys.argv[1], 'summary.csv')))}
print("variant | prepass ms | terrain ms | total ms | triangles | p99.9 px | max px | holes | UDLOD/oracle | overflow frames")
for v in sorted({r['variant'] for r in d['rows']}):
    rows = [r for r in d['rows'] if r['variant'] == v and r['frame'] >= d['warmup']]
    m = lambda k: st.median(r[k] for r in rows)
    s = summ[v]
    print(f"{v} | {m('gpu_prepass_ms'):.3f} | {m('gpu_terrain_ms'):.3f} | {m('gpu_ms'):.3f} | {s['triangles_median']} | {s['err_px_p999']} | {s['err_px_max']} | {s['holes']} | {s['oracle_ratio_median']} | {s['budget_overflow_frames']}")
PY
}
for bin in .device-vk/vkterrain .device-vk/vkterrain-before; do
  [ -x "$bin" ] || { echo "### $bin absent: skipped"; continue; }
  for cfg in "${cfgs[@]}"; do
    dir=$(mktemp -d)
    echo "### $bin eval $(basename "$cfg") grid 4/8, tau $TAUS, 1920x1080"
    timeout 280 "$bin" eval --config "$cfg" --methods udlod --sweep grid_size=4,8 \
      --sweep tau_px="$TAUS" --width 1920 --height 1080 --frames 70 --warmup 10 \
      --flip-every 0 --images 0 --out "$dir" --force > "$dir.log" 2>&1 \
      || { echo "exit $?"; tail -5 "$dir.log"; continue; }
    summarize "$dir"
  done
done
rm -f "$PUGET"

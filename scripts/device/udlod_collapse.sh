#!/usr/bin/env bash
# Collapsed tiles (docs/udlod-rounds.md, "Collapsed tiles") on the GPU machine, 1920x1080: one `eval`
# per data set (the CI terrain, Puget Sound) with `--sweep collapse=0,1 --sweep
# tau_px=0.5,1,2,4` (error, triangles, UDLOD/oracle; CSVs to $OUT/eval-*), then `bench` with
# collapsing off and on, alternated, two rounds (frames back to back, 300 after 20 of warm-up).
#
# Here, before carrying: today's release build as .device-vk/vkterrain (prepare.sh, stripped)
# and  mkdir -p .device-vk/data && cp ../shared/data/puget_sound/ps_height_1k.png .device-vk/data/
# (Configs are written into config/ for a while, where the CI config's scenario path resolves.)
# Run there from the repository root:
#   bash scripts/device/udlod_collapse.sh > $OUT/collapse.txt 2>&1        (the evals)
#   PART=bench bash scripts/device/udlod_collapse.sh > $OUT/bench.txt 2>&1 (the frame times)
set -u
. .device-vk/env.sh
log() { echo "### $*"; }
. scripts/device/puget_config.sh
base_config() {
  case "$1" in
    ci) sed '/^\[method\]/,/^$/d' config/ci.toml ;;
    puget) cat "$PUGET" ;;
  esac
}
if [ "${PART:-eval}" = eval ]; then
for data in ci puget; do
  cfg=$(mktemp -p "$PWD/config" --suffix=.toml)
  base_config "$data" > "$cfg"
  log "eval $data, collapse 0/1, tau 0.5-4, 1920x1080"
  timeout 240 .device-vk/vkterrain eval --config "$cfg" --methods udlod --sweep collapse=0,1 \
    --sweep tau_px=0.5,1,2,4 --width 1920 --height 1080 --out "$OUT/eval-$data" --force 2>&1 | tail -10
  rm -f "$cfg"
done
rm -f "$PUGET"
exit 0
fi
for round in 1 2; do
  for data in ci puget; do
    for tau in 1 4; do
      for collapse in false true; do
        cfg=$(mktemp -p "$PWD/config" --suffix=.toml)
        base_config "$data" > "$cfg"
        printf '[method]\nname = "udlod"\ncollapse = %s\n' "$collapse" >> "$cfg"
        log "round $round bench $data tau $tau collapse $collapse 1920x1080"
        timeout 60 .device-vk/vkterrain bench --config "$cfg" --tau-px "$tau" \
          --resolutions 1920x1080 --compare-frames-in-flight 2 --frames 300 --warmup 20 \
          --out "$(mktemp -d)" 2>&1 | tail -4
        rm -f "$cfg"
      done
    done
  done
done
rm -f "$PUGET"

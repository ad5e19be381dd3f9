#!/usr/bin/env bash
# UDLOD's split field with one node per tile corner (`field_density = 1`, the default until issue
# 18's nineteenth round) against two per tile side (2, the default's at grid 4 since: docs/udlod.md,
# "A finer split field") on the GPU machine, one binary,
# 1920x1080, the CI terrain and Puget Sound (its heights carried in .device-vk/data).
# `PART=bench` (default): `bench` frame times (2 in flight, 300 frames after 20 of warm-up),
# tau 1 and 4, the densities alternated, two rounds. `PART=eval`: one `eval` per data set
# with `--sweep field_density=1,2 --sweep tau_px=0.5,1,2,4` (triangles, p99.9, UDLOD/oracle);
# the CSVs go to $OUT/eval-DATA.
# Here, before carrying: a release build as .device-vk/vkterrain (prepare.sh, stripped) and
#   mkdir -p .device-vk/data && cp ../shared/data/puget_sound/ps_height_1k.png .device-vk/data/
# Run there from the repository root:
#   bash scripts/device/udlod_field_density.sh > $OUT/fd.txt 2>&1
set -u
. .device-vk/env.sh
log() { echo "### $*"; }
. scripts/device/puget_config.sh
bin=.device-vk/vkterrain
# A copy of config $1 drawing UDLOD with field_density $2 (a temporary file in config/, where
# the CI config's relative paths resolve).
with_density() {
  local out
  out=$(mktemp -p config --suffix=.toml)
  grep -v '^\[method\]\|^name = ' "$1" > "$out"
  printf '[method]\nname = "udlod"\nfield_density = %s\n' "$2" >> "$out"
  echo "$out"
}
if [ "${PART:-bench}" = eval ]; then
  for data in ci puget; do
    cfg=config/ci.toml
    [ "$data" = puget ] && cfg="$PUGET"
    dir=$(mktemp -d)
    log "eval $data, field_density 1 and 2, tau 0.5-4, 1920x1080"
    "$bin" eval --config "$cfg" --methods udlod --sweep field_density=1,2 \
      --sweep tau_px=0.5,1,2,4 --width 1920 --height 1080 --out "$dir/ev" --force 2>&1 | tail -10
    mkdir -p "$OUT/eval-$data"
    cp "$dir"/ev/*.csv "$OUT/eval-$data/"
  done
  rm -f "$PUGET"
  exit 0
fi
for round in 1 2; do
  for data in ci puget; do
    base=config/ci.toml
    [ "$data" = puget ] && base="$PUGET"
    for tau in 1 4; do
      for d in 1 2; do
        cfg=$(with_density "$base" "$d")
        log "round $round: bench $data udlod field_density $d tau $tau 1920x1080"
        "$bin" bench --config "$cfg" --tau-px "$tau" --resolutions 1920x1080 \
          --compare-frames-in-flight 2 --frames 300 --warmup 20 --out "$(mktemp -d)" 2>&1 | tail -12
        rm -f "$cfg"
      done
    done
  done
done
rm -f "$PUGET"

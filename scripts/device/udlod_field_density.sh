#!/usr/bin/env bash
# UDLOD's split field with one node per tile corner (`field_density = 1`, the default until issue
# 18's nineteenth round) against two per tile side (2, the default's at grid 4 since: docs/udlod.md,
# "A finer split field") on the GPU machine, one binary, 1920x1080, the data sets named in
# `DATA` (default `ci puget`): the CI terrain, Puget Sound (its heights carried in
# .device-vk/data) and `srtm`, SRTM1 N48W125 (flat, 30 frames in `eval`; its preprocessed
# data set carried packed, below).
# `PART=bench` (default): `bench` frame times (2 in flight, 300 frames after 20 of warm-up),
# tau 1 and 4, the densities alternated, two rounds. `PART=eval`: one `eval` per data set
# with `--sweep field_density=1,2 --sweep tau_px=0.5,1,2,4` (triangles, p99.9, UDLOD/oracle);
# the CSVs go to $OUT/eval-DATA.
# Here, before carrying: a release build as .device-vk/vkterrain (prepare.sh, stripped) and
#   mkdir -p .device-vk/data && cp ../shared/data/puget_sound/ps_height_1k.png .device-vk/data/
# and for `srtm` this build's `vkterrain preprocess` output (`make data-srtm`), packed:
#   tar cf - -C target/data n48w125 | xz -T2 -6 > .device-vk/data/n48w125.tar.xz
# Run there from the repository root:
#   bash scripts/device/udlod_field_density.sh > $OUT/fd.txt 2>&1
set -u
. .device-vk/env.sh
log() { echo "### $*"; }
. scripts/device/puget_config.sh
bin=.device-vk/vkterrain
data_sets=(${DATA:-ci puget})
# The config of data set $1 in CFG and its extra flags in EXTRA (SRTM1 unpacked once).
config_of() {
  EXTRA=()
  case "$1" in
    ci) CFG=config/ci.toml ;;
    puget) CFG="$PUGET" ;;
    srtm)
      if [ -z "${SRTM:-}" ]; then
        local work
        work=$(mktemp -d)
        xz -dc .device-vk/data/n48w125.tar.xz | tar xf - -C "$work" || exit 1
        SRTM="$work/srtm.toml"
        printf '[dataset]\nkind = "tiles"\npath = "%s"\n[scenario]\npath = "%s"\n' \
          "$work/n48w125" "$PWD/config/scenarios/default.toml" > "$SRTM"
      fi
      CFG=$SRTM EXTRA=(--earth flat) ;;
    *) log "DATA names ci, puget or srtm, not $1"; exit 2 ;;
  esac
}
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
  for data in "${data_sets[@]}"; do
    config_of "$data"
    [ "$data" = srtm ] && EXTRA+=(--frames 30)
    dir=$(mktemp -d)
    log "eval $data, field_density 1 and 2, tau 0.5-4, 1920x1080"
    "$bin" eval --config "$CFG" "${EXTRA[@]}" --methods udlod --sweep field_density=1,2 \
      --sweep tau_px=0.5,1,2,4 --width 1920 --height 1080 --out "$dir/ev" --force 2>&1 | tail -10
    mkdir -p "$OUT/eval-$data"
    cp "$dir"/ev/*.csv "$OUT/eval-$data/"
  done
  rm -f "$PUGET"
  exit 0
fi
for round in 1 2; do
  for data in "${data_sets[@]}"; do
    config_of "$data"
    for tau in 1 4; do
      for d in 1 2; do
        cfg=$(with_density "$CFG" "$d")
        log "round $round: bench $data udlod field_density $d tau $tau 1920x1080"
        "$bin" bench --config "$cfg" "${EXTRA[@]}" --tau-px "$tau" --resolutions 1920x1080 \
          --compare-frames-in-flight 2 --frames 300 --warmup 20 --out "$(mktemp -d)" 2>&1 | tail -12
        rm -f "$cfg"
      done
    done
  done
done
rm -f "$PUGET"

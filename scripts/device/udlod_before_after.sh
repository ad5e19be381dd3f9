#!/usr/bin/env bash
# Issue 18's report on the GPU machine: UDLOD before the issue (main at 3ab4290: grid 16,
# per-level split distances) against today's defaults, tau 0.5-4, 60 frames of the default
# flight at 1920x1080, one `eval` per binary and data set. The old evaluator measures on the
# CPU (minutes per run at 1080p), so one data set per call: `DATA=ci` (the CI terrain) or
# `DATA=puget` (Puget Sound, its heights carried). The old binary has no oracle column and
# times frames by wall interval: its GPU time (prepass + terrain pass, medians after
# warm-up) and its ratio to today's oracle (the same frames and tau) come from the CSVs
# copied to $OUT/before-$DATA and $OUT/after-$DATA.
#
# Here, before carrying: today's release build as .device-vk/vkterrain (prepare.sh, stripped),
# the old one built from 3ab4290 (`git worktree add ../before 3ab4290`, `cargo build --release
# --locked --bin vkterrain` there) stripped and copied to .device-vk/vkterrain-before, and
#   mkdir -p .device-vk/data && cp ../shared/data/puget_sound/ps_height_1k.png .device-vk/data/
# Run there from the repository root:
#   DATA=ci bash scripts/device/udlod_before_after.sh > $OUT/ba.txt 2>&1
# Without .device-vk/vkterrain-before (every part) only this build runs: the "after" side.
# `PART=bench` instead times each binary's `bench` (frames back to back, 2 in flight, 300
# frames after 20 of warm-up) per tau on both data sets: the old evaluator's GPU times come
# from frames seconds apart, when the GPU's clocks may have fallen, so they do not time the
# work alone.
#
# `DATA=srtm` (SRTM1 N48W125, 30 frames of the default flight, flat; with `PART=bench` that
# data set alone): the old binary preprocesses its data set there from
# .device-vk/data/srtm/N48W125.hgt.zip; this build, without GDAL there, unpacks the one
# `vkterrain preprocess` wrote here (113 MB, over the carry's limit unpacked):
#   mkdir -p .device-vk/data/srtm && cp ../shared/data/srtm/N48W125.hgt.zip .device-vk/data/srtm/
#   tar cf - -C target/data n48w125 | xz -T2 -6 > .device-vk/data/n48w125.tar.xz
set -u
. .device-vk/env.sh
log() { echo "### $*"; }
. scripts/device/puget_config.sh
# SRTM1's configs, one per binary (each reads its own data set), in SRTM_BEFORE / SRTM_AFTER.
srtm_configs() {
  local work
  work=$(mktemp -d)
  if [ -x .device-vk/vkterrain-before ]; then
    .device-vk/vkterrain-before preprocess .device-vk/data/srtm/N48W125.hgt.zip \
      --out "$work/before" > /dev/null || exit 1
  fi
  xz -dc .device-vk/data/n48w125.tar.xz | tar xf - -C "$work" || exit 1
  for side in before after; do
    dir="$work/before"
    [ "$side" = after ] && dir="$work/n48w125"
    printf '[dataset]\nkind = "tiles"\npath = "%s"\n[scenario]\npath = "%s"\n' \
      "$dir" "$PWD/config/scenarios/default.toml" > "$work/$side.toml"
  done
  SRTM_BEFORE="$work/before.toml" SRTM_AFTER="$work/after.toml"
}
if [ "${PART:-eval}" = bench ]; then
  if [ "${DATA:-}" = srtm ]; then
    srtm_configs
    for tau in 0.5 1 2 4; do
      for side in before after; do
        bin=.device-vk/vkterrain cfg=$SRTM_AFTER earth="--earth flat"
        [ "$side" = before ] && bin=.device-vk/vkterrain-before cfg=$SRTM_BEFORE earth=""
        [ -x "$bin" ] || continue
        log "$bin bench srtm udlod tau $tau 1920x1080"
        # shellcheck disable=SC2086 # no flag for the old binary
        "$bin" bench --config "$cfg" $earth --method udlod --tau-px "$tau" --resolutions 1920x1080 \
          --compare-frames-in-flight 2 --frames 300 --warmup 20 --out "$(mktemp -d)" 2>&1 | tail -12
      done
    done
    rm -f "$PUGET"
    exit 0
  fi
  for cfg in config/ci.toml "$PUGET"; do
    for tau in 0.5 1 2 4; do
      for bin in .device-vk/vkterrain-before .device-vk/vkterrain; do
        [ -x "$bin" ] || continue
        log "$bin bench $cfg udlod tau $tau 1920x1080"
        "$bin" bench --config "$cfg" --method udlod --tau-px "$tau" --resolutions 1920x1080 \
          --compare-frames-in-flight 2 --frames 300 --warmup 20 --out "$(mktemp -d)" 2>&1 | tail -12
      done
    done
  done
  rm -f "$PUGET"
  exit 0
fi
extra=()
case "${DATA:-ci}" in
  ci) cfg=config/ci.toml ;;
  puget) cfg="$PUGET" ;;
  srtm) srtm_configs; extra=(--frames 30) ;;
  *) log "DATA must be ci, puget or srtm"; exit 2 ;;
esac
for side in before after; do
  bin=.device-vk/vkterrain
  [ "$side" = before ] && bin=.device-vk/vkterrain-before
  [ -x "$bin" ] || { log "$bin absent: skipped"; continue; }
  if [ "${DATA:-ci}" = srtm ]; then
    cfg=$SRTM_BEFORE
    # The old binary has no earth; this one renders the same flat surface.
    [ "$side" = after ] && cfg=$SRTM_AFTER && extra+=(--earth flat)
  fi
  dir=$(mktemp -d)
  log "$bin eval ${DATA:-ci}, tau 0.5-4, 1920x1080"
  "$bin" eval --config "$cfg" --methods udlod --sweep tau_px=0.5,1,2,4 --width 1920 \
    --height 1080 "${extra[@]}" --out "$dir/ev" --force 2>&1 | tail -6
  mkdir -p "$OUT/$side-${DATA:-ci}"
  cp "$dir"/ev/*.csv "$OUT/$side-${DATA:-ci}/"
done
rm -f "$PUGET"

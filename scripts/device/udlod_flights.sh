#!/usr/bin/env bash
# Issue 18, fold evidence on the GPU machine: UDLOD with one level step (`morph_levels = 1`)
# against the morph cascade (the default, `morph_levels = 0`), tau 0.5-4, 30 frames of each
# flight at 1920x1080, both in one `eval` run per flight. Flights: Puget Sound's low horizon,
# edge orbit, fast pan, looking up at the peaks and rotation in place (heights carried in
# .device-vk/data), the CI data's valley and fast flights.
#
# Here, before carrying: as in scripts/device/udlod_cascade.sh (a release build without GDAL
# in .device-vk/vkterrain, Puget Sound's heights in .device-vk/data). Run there from the
# repository root: `bash scripts/device/udlod_flights.sh > $OUT/flights.txt 2>&1`.
# `BIN=.device-vk/OTHER` runs another build; `SWEEP="--sweep tau_px=0.5,1,2,4"` replaces the
# morph_levels x tau sweep (e.g. to compare two builds at their defaults).
set -u
. .device-vk/env.sh
. scripts/device/puget_config.sh
run() {
  echo "### $1 $2"
  # shellcheck disable=SC2086 # SWEEP is several words
  "${BIN:-.device-vk/vkterrain}" eval --config "$1" --scenario "config/scenarios/$2.toml" --methods udlod \
    ${SWEEP:---sweep morph_levels=1,0 --sweep tau_px=0.5,1,2,4} --width 1920 --height 1080 --frames 30 \
    --out "$(mktemp -d)" --force 2>&1 | tail -10
}
for sc in puget_low_horizon_down00 puget_edge_orbit_down12 puget_fast_pan_down15 \
  puget_looking_up_at_peaks_up05 puget_rotation_in_place_down20; do
  run "$PUGET" "$sc"
done
for sc in valley_flight fast_flight; do run config/ci.toml "$sc"; done
rm -f "$PUGET"

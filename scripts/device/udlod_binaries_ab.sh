#!/usr/bin/env bash
# UDLOD's frame time on the GPU machine, binary against binary: `bench` (1920x1080, 2 frames
# in flight, 300 frames after 20 of warm-up) on the CI terrain and Puget Sound at tau 1 and 4,
# two rounds, the binaries alternated within each. Binaries (each skipped when absent):
#   .device-vk/vkterrain-before  main before issue 18 (3ab4290: grid 16, its own defaults)
#   .device-vk/vkterrain-main    an earlier build of today's main, at its default and grid 16
#   .device-vk/vkterrain-cur     another build of today's main (variants `cur`, `cur-noq`)
#   .device-vk/vkterrain-mid     a build between that one and this (variant `mid`)
#   .device-vk/vkterrain         this build, at its default (grid 4) and grid 16 and 8
# Here, before carrying: release builds stripped and copied there (prepare.sh for this one),
# and the Puget Sound heights in .device-vk/data (scripts/device/udlod_before_after.sh).
# Run there from the repository root: `bash scripts/device/udlod_binaries_ab.sh > $OUT/ab.txt`
# (`PUGET_ONLY=1`: Puget Sound only; `VARIANTS="main new"` picks variants; `new-off` and
# `new-seed1`, not in the default list, are this build with `collapse = false` and with
# `seed_tiles = 1`: every level a GPU pass; `new-ml2` this build with the walk kept inside
# each tile, `morph_levels = 2`, the default until issue 18's fifteenth round; `new-g2` this
# build at grid 2; `new-noq` this build with `cull_quadrants = false`: every quadrant of a
# drawn tile drawn; `BASES="config/ci_earth.toml"` other configs than the CI terrain and
# Puget Sound, e.g. the CI terrain anchored on the earth).
set -u
. .device-vk/env.sh
. scripts/device/puget_config.sh
. scripts/device/udlod_config.sh
bases=(config/ci.toml "$PUGET")
[ -n "${PUGET_ONLY:-}" ] && bases=("$PUGET")
# shellcheck disable=SC2206 # a list of paths without spaces
[ -n "${BASES:-}" ] && bases=($BASES)
for base in "${bases[@]}"; do
  for tau in 1 4; do
    for round in 1 2; do
      for v in ${VARIANTS:-before main main-g16 new new-g16 new-g8}; do
        bin=.device-vk/vkterrain
        extra=""
        case $v in
          before) bin=.device-vk/vkterrain-before ;;
          main) bin=.device-vk/vkterrain-main ;;
          main-g16) bin=.device-vk/vkterrain-main; extra="grid_size = 16" ;;
          cur) bin=.device-vk/vkterrain-cur ;;
          cur-noq) bin=.device-vk/vkterrain-cur; extra="cull_quadrants = false" ;;
          mid) bin=.device-vk/vkterrain-mid ;;
          new-g16) extra="grid_size = 16" ;;
          new-g8) extra="grid_size = 8" ;;
          new-g2) extra="grid_size = 2" ;;
          new-off) extra="collapse = false" ;;
          new-seed1) extra="seed_tiles = 1" ;;
          new-ml2) extra="morph_levels = 2" ;;
          new-noq) extra="cull_quadrants = false" ;;
        esac
        [ -x "$bin" ] || continue
        cfg=$(udlod_config "$base" "$extra")
        r=$("$bin" bench --config "$cfg" --method udlod --tau-px "$tau" --resolutions 1920x1080 \
          --compare-frames-in-flight 2 --frames 300 --warmup 20 --out "$(mktemp -d)" 2>&1 |
          grep -E '1920x1080   2|rror')
        echo "$(basename "$base") tau $tau round $round $v: $r"
      done
    done
  done
done
rm -f "$PUGET"

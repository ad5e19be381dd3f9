#!/usr/bin/env bash
# The shaders per terrain (docs/architecture.md, "Shaders per terrain") on the GPU machine:
# frame time of a build before them (.device-vk/vkterrain-main) against this build
# (.device-vk/vkterrain), each scene through both, two rounds alternated. `bench` at
# 1920x1080, 2 frames in flight, 300 frames after 20 of warm-up, median frame and GPU ms:
#   ci        the CI terrain, flat, single texture, UDLOD at tau 1 and 4
#   ci_earth  the same terrain on the earth, UDLOD at tau 1, and brute force
#   default   the main job's terrain (flat, through the clipmap), UDLOD at its tau; its pyramid
#             is generated there first (target/data/default, `vkterrain preprocess`)
# SET=tessellation runs hardware tessellation over the same three terrains instead (its GLSL
# stages got their builds per terrain in the thirty-first round).
# Here, before carrying: both `--no-default-features` release builds stripped into
# .device-vk (prepare.sh for the loader). Run there from the repository root:
#   bash scripts/device/terrain_variants_ab.sh > $OUT/variants.txt 2>&1
set -u
. .device-vk/env.sh
.device-vk/vkterrain preprocess --procedural --style alpine --size 4097 --spacing 30 \
  --max-height 3500 --feature-size 16000 --node-size 64 --out target/data/default --force \
  > /dev/null || exit 1
runs=(
  "ci udlod 1|config/ci.toml --method udlod --tau-px 1"
  "ci udlod 4|config/ci.toml --method udlod --tau-px 4"
  "ci_earth udlod 1|config/ci_earth.toml --method udlod --tau-px 1"
  "ci_earth brute|config/ci_earth.toml --method brute"
  "default udlod|config/default.toml --method udlod"
)
if [ "${SET:-}" = tessellation ]; then
  runs=(
    "ci tessellation|config/ci.toml --method tessellation"
    "ci_earth tessellation|config/ci_earth.toml --method tessellation"
    "default tessellation|config/default.toml --method tessellation"
  )
fi
for run in "${runs[@]}"; do
  name=${run%%|*}
  args=${run#*|}
  for round in 1 2; do
    for v in main new; do
      bin=.device-vk/vkterrain
      [ "$v" = main ] && bin=.device-vk/vkterrain-main
      # shellcheck disable=SC2086 # the run's arguments are words
      r=$("$bin" bench --config $args --resolutions 1920x1080 --compare-frames-in-flight 2 \
        --frames 300 --warmup 20 --out "$(mktemp -d)" 2>&1 | grep -E '1920x1080   2|rror')
      echo "$name round $round $v: $r"
    done
  done
done

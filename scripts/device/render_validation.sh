#!/usr/bin/env bash
# Every LOD method rendered on the GPU machine with the validation layers on (incl.
# synchronization validation): NVIDIA enables what lavapipe does not (anisotropic filtering,
# mesh shaders), so the driver layer's samplers, instance and pipelines meet the layers there
# too. `vkterrain render` fails on any validation message.
#
# Prepare here: `CARGO_TARGET_DIR=/work/target-nf cargo build --release --locked
# --no-default-features`, copy target-nf/release/vkterrain to .device-vk/vkterrain (strip it),
# and the layer as scripts/device/gpu_tests.sh says (.device-vk/layers).
# Run there, carrying .device-vk: `bash scripts/device/render_validation.sh > $OUT/render_validation.txt 2>&1`.
set -u
. .device-vk/env.sh
layers=$PWD/.device-vk/layers
[ -f "$layers/libVkLayer_khronos_validation.so" ] || xz -dk "$layers/libVkLayer_khronos_validation.so.xz"
export VK_LAYER_PATH=$layers LD_LIBRARY_PATH=$layers:$LD_LIBRARY_PATH VKTERRAIN_VALIDATION=1
bin=.device-vk/vkterrain
$bin info | grep -E "^(device|driver|validation)|sampler anisotropy"
status=0
for method in brute udlod pgm geomipmap chunked tessellation; do
  echo "### $method"
  out=$(mktemp -d)
  $bin render --config config/ci.toml --method "$method" --width 1280 --height 720 \
    --frames 20 --out "$out" > "$out/log.txt" 2>&1
  rc=$?
  grep -iE '^(triangles|GPU per pass)|validation|error' "$out/log.txt"
  echo "exit $rc"
  [ "$rc" = 0 ] || status=1
done
exit $status

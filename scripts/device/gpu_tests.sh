#!/usr/bin/env bash
# Integration tests on the GPU machine (NVIDIA's Vulkan driver), validation layers on.
#
# Prepare here (the machine has no Rust toolchain and no GDAL):
#   CARGO_TARGET_DIR=/work/target-dev cargo test --no-run --locked --no-default-features \
#       --test tessellation --test chunked --test geomipmap --test udlod
#   then copy each printed test executable to .device-vk/<name>_test (strip it), and the
#   validation layer: .device-vk/layers/VkLayer_khronos_validation.json (Debian's, from
#   /usr/share/vulkan/explicit_layer.d) and libVkLayer_khronos_validation.so.xz (xz of
#   /usr/lib/x86_64-linux-gnu/libVkLayer_khronos_validation.so: the carry limit).
# Run there, carrying .device-vk: `bash scripts/device/gpu_tests.sh > $OUT/gpu_tests.txt 2>&1`.
# Tests that start the CLI (`cli_*`) are skipped: the debug CLI binary is not carried.
set -u
. .device-vk/env.sh
layers=$PWD/.device-vk/layers
[ -f "$layers/libVkLayer_khronos_validation.so" ] || xz -dk "$layers/libVkLayer_khronos_validation.so.xz"
export VK_LAYER_PATH=$layers LD_LIBRARY_PATH=$layers:$LD_LIBRARY_PATH VKTERRAIN_VALIDATION=1
for t in .device-vk/*_test; do
  echo "### $t"
  "$t" --skip cli_ --nocapture 2>&1 | grep -vE '^\s+[0-9]+: |^\s+at '
done

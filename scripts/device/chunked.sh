#!/usr/bin/env bash
# GPU chunked LOD (Hedberg 2022, issue 16 item 2) on the GPU machine at 1920x1080
# (docs/chunked.md): what Hedberg reported, measured here.
#  1. Traversal GPU time against tree depth, naive walk vs CBT: `bench` (gpu prepass ms = the
#     selection + LOD map) on a procedural 8193² terrain with 4-quad chunks (root level 11,
#     Hedberg's total depth 11 = root depth 2 + depth 9), max_depth 5, 7, 9, 11. The CBT's
#     memory per tree is logged by the renderer (RUST_LOG=vkterrain=info: "binary depth ...
#     bytes of sums"); Hedberg: 16.8 MB at total depth 11.
#  2. Instanced vs mesh-shading frame time (Hedberg: mesh ~0.1 ms slower with the naive
#     selection, equal with CBT): `bench` on the same terrain, max_depth 9, both traversals,
#     draw = instanced | mesh (VK_EXT_mesh_shader; a one-line error if the device lacks it).
#  3. The error-threshold sweep against brute force and UDLOD: `eval` on config/ci.toml,
#     error_px 1, 2, 4 (Hedberg's), 8; and the CBT variant at 4 px.
# Bench warm-up is 30 frames: with 2 frames in flight each slot's CBT steps every other frame
# and needs (tree depth - root depth) steps from its initial tree.
# No data files needed (procedural terrains generated in memory). About 2 minutes.
# Here, before carrying: a release build and `../shared/device-vulkan/prepare.sh
# target/release/vkterrain`. Run there from the repository root:
#   bash scripts/device/chunked.sh > $OUT/chunked.txt 2>&1
set -u
. .device-vk/env.sh
bin=.device-vk/vkterrain
out=out/device/chunked
mkdir -p "$out"
log() { echo "### $*"; }
$bin info | head -20
big() { # traversal max_depth [draw] -> a config on the procedural 8193² terrain
  local draw=${3:-instanced}
  printf '[render]\nwidth = 1920\nheight = 1080\nframes_in_flight = 2\n[dataset]\nkind = "procedural"\nsize = 8193\nseed = 1\nspacing = 10.0\n[method]\nname = "chunked"\ntraversal = "%s"\ndraw = "%s"\nchunk_quads = 4\nmax_depth = %s\nmax_chunks = 65535\n[scenario]\npath = "%s"\n' \
    "$1" "$draw" "$2" "$PWD/config/scenarios/default.toml" > "$out/big_$1_$2_$draw.toml"
  echo "$out/big_$1_$2_$draw.toml"
}
for depth in 5 7 9 11; do
  for traversal in naive cbt; do
    cfg=$(big "$traversal" "$depth")
    log "bench chunked $traversal max_depth $depth (8193², 4-quad chunks) 1920x1080"
    RUST_LOG=vkterrain=info timeout 60 "$bin" bench --config "$cfg" --resolutions 1920x1080 \
      --compare-frames-in-flight 2 --frames 90 --warmup 30 --json "$out/bench_${traversal}_${depth}.json" \
      || log "exit $?"
  done
done
# The instanced runs at max_depth 9 above are the other half of this comparison.
for traversal in naive cbt; do
  cfg=$(big "$traversal" 9 mesh)
  log "bench chunked $traversal draw mesh max_depth 9 1920x1080"
  timeout 60 "$bin" bench --config "$cfg" --resolutions 1920x1080 --compare-frames-in-flight 2 \
    --frames 90 --warmup 30 --json "$out/bench_${traversal}_9_mesh.json" || log "exit $?"
done
log "eval brute, udlod, chunked error_px sweep, config/ci.toml 1920x1080"
timeout 150 "$bin" eval --config config/ci.toml --width 1920 --height 1080 --frames 60 --warmup 10 \
  --methods brute,udlod,chunked --sweep error_px=1,2,4,8 --out "$out/eval" --force || log "exit $?"
printf '[render]\nwidth = 640\nheight = 360\nframes_in_flight = 2\n[dataset]\nkind = "procedural"\nsize = 513\nseed = 1\nspacing = 60.0\n[method]\nname = "chunked"\ntraversal = "cbt"\n[scenario]\npath = "%s"\n' \
  "$PWD/config/scenarios/default.toml" > "$out/ci_cbt.toml"
log "eval chunked CBT (4 px), ci terrain 1920x1080"
timeout 90 "$bin" eval --config "$out/ci_cbt.toml" --width 1920 --height 1080 --frames 60 --warmup 10 \
  --methods chunked --out "$out/eval_cbt" --force || log "exit $?"
# The mesh path's placement (GLSL port) through the evaluator: error and holes must match the
# instanced rows above (4 px).
sed 's/traversal = "cbt"/draw = "mesh"/' "$out/ci_cbt.toml" > "$out/ci_mesh.toml"
log "eval chunked mesh draw (4 px), ci terrain 1920x1080"
timeout 90 "$bin" eval --config "$out/ci_mesh.toml" --width 1920 --height 1080 --frames 60 --warmup 10 \
  --methods chunked --out "$out/eval_mesh" --force || log "exit $?"
cat "$out/eval/report.md" "$out/eval_cbt/report.md" "$out/eval_mesh/report.md" 2>/dev/null | grep '^|'

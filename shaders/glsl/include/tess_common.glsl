// Set 1 of hardware tessellation (TESS_SET in src/lod/tessellation/mod.rs): the uniforms the
// WGSL vertex stage reads too (`Tess` in shaders/tess.wgsl; tests prove the layouts equal) and
// the per-patch-quad height bounds the control stage culls with.

layout(set = 1, binding = 0, std140) uniform Tess {
    // x: target edge length (px), y: tessellation factor, z: focal length (px), w: highest level.
    vec4 params;
    // x: samples per patch side, y: patch quads per chunk side, zw: patch quads per data side.
    uvec4 grid;
    // x: frustum culling on (1) or off (0); y: edge levels from the patch centroid (1, the
    // crack-prone ablation) or from each edge's own endpoints (0); z: displace onto brute force's
    // triangles (1) or the bilinear field (0).
    uvec4 flags;
} tess;

// Per patch quad (row-major over the data): lowest and highest height of its samples.
layout(set = 1, binding = 1, std430) readonly buffer PatchBounds {
    vec2 bounds[];
} patch_bounds;

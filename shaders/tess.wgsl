// Hardware tessellation (Fischer 2024), the stages naga compiles: the vertex stage places the
// corners of flat triangle patches on the data's samples, the fragment stage shades. Between
// them the GLSL stages (shaders/glsl/tess.tesc, tess_*.tese) set each edge's level from its
// on-screen length and displace the generated vertices by the height map. See
// src/lod/tessellation/mod.rs and docs/tessellation.md.
//
// One shared index grid of patch quads (two triangle patches each) is instanced over the data:
// instance -> chunk of `tess.grid.y`^2 quads, vertex -> patch corner. Corners past the data
// clamp onto its last sample; the control stage discards the zero-area patches that makes.

//!include terrain_common.wgsl

// Mirrors `TessUniforms` in src/lod/tessellation/mod.rs and `Tess` in
// shaders/glsl/include/tess_common.glsl; tests prove the layouts equal.
struct Tess {
    // x: target edge length (px), y: tessellation factor, z: focal length (px), w: highest level.
    params: vec4<f32>,
    // x: samples per patch side, y: patch quads per chunk side, zw: patch quads per data side.
    grid: vec4<u32>,
    // x: frustum culling on (1) or off (0); y: edge levels from the patch centroid (1, the
    // crack-prone ablation) or from each edge's own endpoints (0); z: displace onto brute force's
    // triangles (1) or the bilinear field (0).
    flags: vec4<u32>,
}

@group(1) @binding(0) var<uniform> tess: Tess;

struct PatchCorner {
    // Unused downstream (the control stage reads `clip`); a vertex stage must write it.
    @builtin(position) position: vec4<f32>,
    // The corner's sample (integer-valued).
    @location(0) grid: vec2<f32>,
    @location(1) height: f32,
    // project() of the corner: WebGPU clip space (w = view depth).
    @location(2) clip: vec4<f32>,
}

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> PatchCorner {
    let quads = tess.grid.y;
    let chunks_x = (tess.grid.z + quads - 1u) / quads;
    let chunk = vec2<u32>(instance % chunks_x, instance / chunks_x);
    let local = vec2<u32>(vertex % (quads + 1u), vertex / (quads + 1u));
    let s = vec2<i32>(min((chunk * quads + local) * tess.grid.x, frame.data_size.xy - 1u));
    let h = sample_height(s);
    var out: PatchCorner;
    out.clip = project(s, vec2<f32>(0.0), h);
    out.position = out.clip;
    out.grid = vec2<f32>(s);
    out.height = h;
    return out;
}

@fragment
fn fs_main(v: TerrainVertex) -> @location(0) vec4<f32> {
    return shade(v);
}

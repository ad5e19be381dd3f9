// Brute force: every height sample is a vertex. One shared index grid of
// BRUTE_CHUNK_QUADS^2 quads is instanced over the data; instance -> chunk, vertex -> sample.
// Vertices past the data's last sample clamp onto it, giving zero-area triangles.

//!include terrain_common.wgsl

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> TerrainVertex {
    let size = frame.data_size.xy;
    let chunks_x = (size.x - 1u + BRUTE_CHUNK_QUADS - 1u) / BRUTE_CHUNK_QUADS;
    let chunk = vec2<u32>(instance % chunks_x, instance / chunks_x);
    let local = vec2<u32>(vertex % (BRUTE_CHUNK_QUADS + 1u), vertex / (BRUTE_CHUNK_QUADS + 1u));
    let s = vec2<i32>(min(chunk * BRUTE_CHUNK_QUADS + local, size - 1u));
    return TerrainVertex(project(s, vec2<f32>(0.0), sample_height(s)), vec2<f32>(s));
}

@fragment
fn fs_main(v: TerrainVertex) -> @location(0) vec4<f32> {
    return shade(v);
}

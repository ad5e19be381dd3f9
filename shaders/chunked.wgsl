// GPU chunked LOD drawing (Hedberg 2022): one chunk mesh (a `quads` x `quads` grid) instanced
// per listed chunk. Crack handling is his edge patching: a vertex on a chunk's edge looks up
// the neighbour across that edge in the LOD map and, where the neighbour is coarser, snaps
// its position along the edge down onto the neighbour's vertex grid. Snapped vertices are the
// coarse neighbour's own vertices (same sample, same height, same arithmetic), so the edge is
// closed exactly while the level difference is at most log2(quads); beyond that a fine edge
// lies between two coarse vertices and snapping drags it off its chunk (docs/chunked.md).

//!include terrain_common.wgsl
//!include chunked_common.wgsl
//!include chunked_sample.wgsl

@group(1) @binding(3) var<storage, read> final_chunks: array<Chunk>;
@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> TerrainVertex {
    let quads = chunked.sizes.x;
    let t = final_chunks[instance];
    let local = vec2<u32>(vertex % (quads + 1u), vertex / (quads + 1u));
    let last = vec2<i32>(frame.data_size.xy) - vec2<i32>(1);
    let s = min(chunk_sample(t, local), last);
    return TerrainVertex(project(s, vec2<f32>(0.0), sample_height(s)), vec2<f32>(s));
}

@fragment
fn fs_main(v: TerrainVertex) -> @location(0) vec4<f32> {
    return shade(v);
}

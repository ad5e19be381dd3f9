// GeoMipMapping (Tabakovic's ATLOD): blocks of GEOMIPMAP_BLOCK_QUADS + 1 samples, each drawn
// with the index list of its level and border permutation (src/lod/geomipmap/). The instance
// index is the block (row-major over the data, drawn one block per draw as `firstInstance`),
// the vertex index a sample of the block's full-resolution (2^n + 1)² grid; coarser lists
// simply skip samples. Vertices past the data's last sample clamp onto it.

//!include terrain_common.wgsl

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, @builtin(instance_index) block: u32) -> TerrainVertex {
    let size = frame.data_size.xy;
    let blocks_x = (size.x - 1u + GEOMIPMAP_BLOCK_QUADS - 1u) / GEOMIPMAP_BLOCK_QUADS;
    let b = vec2<u32>(block % blocks_x, block / blocks_x);
    let local = vec2<u32>(vertex % (GEOMIPMAP_BLOCK_QUADS + 1u), vertex / (GEOMIPMAP_BLOCK_QUADS + 1u));
    let s = vec2<i32>(min(b * GEOMIPMAP_BLOCK_QUADS + local, size - 1u));
    return TerrainVertex(project(s, vec2<f32>(0.0), sample_height(s)), vec2<f32>(s));
}

@fragment
fn fs_main(v: TerrainVertex) -> @location(0) vec4<f32> {
    return shade(v);
}

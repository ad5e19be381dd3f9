// UDLOD drawing: one instance per final tile, a shared indexed grid of `quads` x `quads`.
// Vertices morph towards the parent level's grid (CDLOD-style) so that a tile is fully on its
// parent's grid where it meets a coarser neighbour: crack-free and pop-free without
// tessellation. Everything here is a pure function of the vertex's integer sample position and
// the tile's level, so vertices shared by neighbouring tiles land on the same spot.

//!include terrain_common.wgsl
//!include udlod_common.wgsl

@group(1) @binding(3) var<storage, read> final_tiles: array<Tile>;

// 0 = the tile's own grid, 1 = fully on the parent's grid. `d` is the distance from the LOD
// viewer to the un-morphed vertex at the reference height, scaled by the parent level's error
// field; `parent_split` the parent level's split distance; the morph runs over the last
// `morph_range` of it (mirrors `morph_factor` in src/lod/udlod/select.rs).
fn morph_factor(sample: vec2<i32>, lod: u32) -> f32 {
    let d = length(vec3<f32>(viewer_xy(sample), udlod.viewer.z));
    let scaled = d * field_at(sample, lod + 1u);
    let parent_split = udlod.split[lod + 1u].x;
    let morph_range = udlod.params.y;
    return clamp(1.0 - (1.0 - scaled / parent_split) / morph_range, 0.0, 1.0) * udlod.params.z;
}

// Indexed drawing: the shared index grid names grid vertices `row * (quads + 1) + column`.
@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> TerrainVertex {
    let quads = udlod.sizes.x;
    return tile_vertex(final_tiles[instance], vec2<u32>(vertex % (quads + 1u), vertex / (quads + 1u)));
}

// Vertex pulling without an index buffer: six vertices per quad, in the index grid's order
// (triangles (0,0) (1,0) (0,1) and (1,0) (1,1) (0,1); `lod::brute::grid_indices`).
@vertex
fn vs_pulled(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> TerrainVertex {
    let quads = udlod.sizes.x;
    let quad = vertex / 6u;
    let corner = vertex % 6u;
    let dx = select(0u, 1u, corner == 1u || corner == 3u || corner == 4u);
    let dy = select(0u, 1u, corner == 2u || corner == 4u || corner == 5u);
    return tile_vertex(final_tiles[instance], vec2<u32>(quad % quads + dx, quad / quads + dy));
}

fn tile_vertex(tile: Tile, local: vec2<u32>) -> TerrainVertex {
    let quads = udlod.sizes.x;
    let step = 1u << tile.lod;
    let sample = vec2<i32>(vec2<u32>(tile.x, tile.y) * quads * step + local * step);
    let morph = morph_factor(sample, tile.lod);
    // Odd vertices slide onto their lower even neighbour: integer part and fraction kept apart
    // so that a fully morphed vertex is exactly the neighbour's sample.
    let odd = vec2<i32>(local & vec2<u32>(1u));
    var cell = sample - odd * i32(step);
    var frac = (1.0 - morph) * vec2<f32>(odd) * f32(step);
    // Tiles at the data's far edges reach past the last sample: clamp onto it.
    let last = vec2<i32>(frame.data_size.xy) - vec2<i32>(1);
    frac = min(frac, vec2<f32>(max(last - cell, vec2<i32>(0))));
    cell = min(cell, last);
    // One representation per position: an unmorphed odd vertex (frac = step) and the same
    // sample as an even vertex of the neighbouring tile (frac = 0) must project through the
    // same arithmetic, or far from the camera their f32 positions differ by an ulp and the
    // shared edge shows pinholes.
    let whole = floor(frac);
    cell = cell + vec2<i32>(whole);
    frac = frac - whole;
    let grid_pos = vec2<f32>(cell) + frac;
    var out: TerrainVertex;
    out.clip = project(cell, frac, height_at(grid_pos));
    out.grid_pos = grid_pos;
    return out;
}

@fragment
fn fs_main(v: TerrainVertex) -> @location(0) vec4<f32> {
    return shade(v.grid_pos);
}

// UDLOD drawing: one instance per final tile, a shared indexed grid of `quads` x `quads`.
// Vertices morph towards the parent level's grid (CDLOD-style) so that a tile is fully on its
// parent's grid where it meets a coarser neighbour: crack-free and pop-free without
// tessellation. The morph itself lives in include/udlod_morph.wgsl (shared with the test probe).

//!include terrain_common.wgsl
//!include udlod_common.wgsl
//!include udlod_morph.wgsl

@group(1) @binding(3) var<storage, read> final_tiles: array<Tile>;

// Two draws read the final list: the tiles with no vertex part-way through its morph from its
// front (by default with back-face culling), the others from its back (`*_morphing`, without:
// `final_tile_checks` in udlod_tiling.wgsl).
fn morphing_tile(instance: u32) -> Tile {
    return final_tiles[udlod.sizes.z - 1u - instance];
}

// Indexed drawing: an index grid of `quads` per side names grid vertices
// `row * (quads + 1) + column`.
fn grid_indexed_local(vertex: u32, quads: u32) -> vec2<u32> {
    return vec2<u32>(vertex % (quads + 1u), vertex / (quads + 1u));
}

fn indexed_local(vertex: u32) -> vec2<u32> {
    return grid_indexed_local(vertex, udlod.sizes.x);
}

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> TerrainVertex {
    return tile_vertex(final_tiles[instance], indexed_local(vertex));
}

@vertex
fn vs_main_morphing(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> TerrainVertex {
    return tile_vertex(morphing_tile(instance), indexed_local(vertex));
}

// Vertex pulling without an index buffer: six vertices per quad of a grid of `quads` per side,
// in the index grid's order (triangles (0,0) (1,0) (0,1) and (1,0) (1,1) (0,1);
// `lod::brute::grid_indices`).
fn grid_pulled_local(vertex: u32, quads: u32) -> vec2<u32> {
    let quad = vertex / 6u;
    let corner = vertex % 6u;
    let dx = select(0u, 1u, corner == 1u || corner == 3u || corner == 4u);
    let dy = select(0u, 1u, corner == 2u || corner == 4u || corner == 5u);
    return vec2<u32>(quad % quads + dx, quad / quads + dy);
}

fn pulled_local(vertex: u32) -> vec2<u32> {
    return grid_pulled_local(vertex, udlod.sizes.x);
}

@vertex
fn vs_pulled(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> TerrainVertex {
    return tile_vertex(final_tiles[instance], pulled_local(vertex));
}

@vertex
fn vs_pulled_morphing(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> TerrainVertex {
    return tile_vertex(morphing_tile(instance), pulled_local(vertex));
}

// Collapsed tiles (`final_tile_checks` in udlod_tiling.wgsl: every odd vertex fully on the grid
// above) are drawn as that grid, `quads / 2` per side over the tile's even vertices, from the
// final list's second half (static ones from its front, morphing ones from its back). The
// even vertices morph as in the full grid, so the surface is the same bit for bit.
fn collapsed_tile(instance: u32) -> Tile {
    return final_tiles[udlod.sizes.z + instance];
}

fn collapsed_morphing_tile(instance: u32) -> Tile {
    return final_tiles[2u * udlod.sizes.z - 1u - instance];
}

// The collapsed grid (its indices `udlod.counts.w` past the full grid's in the index buffer):
// every other vertex of the tile's grid.
fn collapsed_indexed_local(vertex: u32) -> vec2<u32> {
    return 2u * grid_indexed_local(vertex, udlod.sizes.x / 2u);
}

fn collapsed_pulled_local(vertex: u32) -> vec2<u32> {
    return 2u * grid_pulled_local(vertex, udlod.sizes.x / 2u);
}

@vertex
fn vs_collapsed(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> TerrainVertex {
    return tile_vertex(collapsed_tile(instance), collapsed_indexed_local(vertex));
}

@vertex
fn vs_collapsed_morphing(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> TerrainVertex {
    return tile_vertex(collapsed_morphing_tile(instance), collapsed_indexed_local(vertex));
}

@vertex
fn vs_pulled_collapsed(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> TerrainVertex {
    return tile_vertex(collapsed_tile(instance), collapsed_pulled_local(vertex));
}

@vertex
fn vs_pulled_collapsed_morphing(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> TerrainVertex {
    return tile_vertex(collapsed_morphing_tile(instance), collapsed_pulled_local(vertex));
}

// The morphed vertex (`morphed_vertex`, shared with the test probe) projected.
fn tile_vertex(tile: Tile, local: vec2<u32>) -> TerrainVertex {
    let v = morphed_vertex(tile, local);
    return TerrainVertex(project(v.cell, v.frac, v.height), v.grid_pos);
}

@fragment
fn fs_main(v: TerrainVertex) -> @location(0) vec4<f32> {
    return shade(v);
}

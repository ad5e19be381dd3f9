// UDLOD drawing: one instance per final tile over a shared grid of `quads` x `quads` (per
// draw mask: quadrants drawn as the parent grid or not at all, `grid::IndexLayout`).
// Vertices morph towards the parent level's grid (CDLOD-style) so that a tile is fully on its
// parent's grid where it meets a coarser neighbour: crack-free and pop-free without
// tessellation. The morph itself lives in include/udlod_morph.wgsl (shared with the test probe).

//!include terrain_common.wgsl
//!include udlod_common.wgsl
//!include udlod_morph.wgsl

@group(1) @binding(3) var<storage, read> final_tiles: array<Tile>;

// The draws read the final list's second half, sorted by draw group (`scatter` in
// udlod_tiling.wgsl); each draw's first instance is its group's first entry there, and the
// tile's `pad` holds its group.
fn drawn_tile(instance: u32) -> Tile {
    return final_tiles[udlod.sizes.z + instance];
}

// Indexed drawing: the index buffer holds one list per draw mask (`grid::IndexLayout` in
// src/lod/udlod/grid.rs), naming grid vertices `row * (quads + 1) + column`.
fn indexed_local(vertex: u32) -> vec2<u32> {
    let quads = udlod.sizes.x;
    return vec2<u32>(vertex % (quads + 1u), vertex / (quads + 1u));
}

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> TerrainVertex {
    return tile_vertex(drawn_tile(instance), indexed_local(vertex));
}

// Vertex pulling without an index buffer: six vertices per quad of a grid of `quads` per side,
// in the index grid's order (triangles (0,0) (1,0) (0,1) and (1,0) (1,1) (0,1)).
fn grid_pulled_local(vertex: u32, quads: u32) -> vec2<u32> {
    let quad = vertex / 6u;
    let corner = vertex % 6u;
    let dx = select(0u, 1u, corner == 1u || corner == 3u || corner == 4u);
    let dy = select(0u, 1u, corner == 2u || corner == 4u || corner == 5u);
    return vec2<u32>(quad % quads + dx, quad / quads + dy);
}

// The triangles of a tile drawn with mask `mask`, in the order of its index list
// (`grid::mask_vertices`): per quadrant q (digit q of the mask in base 3, quadrant origin
// `(qx, qy) * quads / 2`) its own grid of `quads / 2` per side (0), collapsed the parent grid's
// `quads / 4` over its even vertices (1), or none (2); at grid 2 a collapsed tile is the
// parent's one quad and a partly collapsed one its own grid (`grid::TileMask::new`).
fn pulled_local(vertex: u32, mask: u32) -> vec2<u32> {
    let quads = udlod.sizes.x;
    let all_collapsed = 1u + 3u + 9u + 27u;
    if quads == 2u && mask == all_collapsed {
        return 2u * grid_pulled_local(vertex, 1u);
    }
    let h = quads / 2u;
    var j = vertex;
    var rest = mask;
    var q = 0u;
    var collapsed = false;
    for (; q < 4u; q++) {
        let state = rest % 3u;
        rest /= 3u;
        collapsed = state == 1u && quads > 2u;
        let n = select(select(h, h / 2u, collapsed), 0u, state == 2u);
        if j < 6u * n * n {
            break;
        }
        j -= 6u * n * n;
    }
    let origin = h * vec2<u32>(q & 1u, q >> 1u);
    return origin + select(1u, 2u, collapsed) * grid_pulled_local(j, select(h, h / 2u, collapsed));
}

@vertex
fn vs_pulled(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> TerrainVertex {
    let tile = drawn_tile(instance);
    return tile_vertex(tile, pulled_local(vertex, tile.pad % UDLOD_TILE_MASKS));
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

// GPU chunked LOD drawing (Hedberg 2022): one chunk mesh (a `quads` x `quads` grid) instanced
// per listed chunk. Crack handling is his edge patching: a vertex on a chunk's edge looks up
// the neighbour across that edge in the LOD map and, where the neighbour is coarser, snaps
// its position along the edge down onto the neighbour's vertex grid. Snapped vertices are the
// coarse neighbour's own vertices (same sample, same height, same arithmetic), so the edge is
// closed exactly while the level difference is at most log2(quads); beyond that a fine edge
// lies between two coarse vertices and snapping drags it off its chunk (docs/chunked.md).

//!include terrain_common.wgsl
//!include chunked_common.wgsl

@group(1) @binding(3) var<storage, read> final_chunks: array<Chunk>;
@group(1) @binding(6) var<storage, read> lod_map: array<u32>;

// The level in the LOD map at level-0 chunk cell `c`, or 0 outside the map.
fn map_level(c: vec2<i32>) -> u32 {
    let size = vec2<i32>(chunked.lists.zw);
    if c.x < 0 || c.y < 0 || c.x >= size.x || c.y >= size.y {
        return 0u;
    }
    return lod_map[u32(c.y) * chunked.lists.z + u32(c.x)];
}

// Rounds `v` down to a multiple of 2^level.
fn snap_down(v: i32, level: u32) -> i32 {
    return (v >> level) << level;
}

// The sample a chunk vertex stands on, after edge patching (before clamping to the data).
fn chunk_sample(t: Chunk, local: vec2<u32>) -> vec2<i32> {
    let quads = chunked.sizes.x;
    var s = vec2<i32>(vec2<u32>(t.x * quads + local.x, t.y * quads + local.y) << vec2<u32>(t.lod));
    if chunked.params.w < 0.5 {
        return s;
    }
    // Level-0 cells: the chunk covers [lo, lo + side); the vertex's cell along each axis is
    // clamped into the chunk so a corner asks its own edge's neighbour.
    let side = i32(1u << t.lod);
    let lo = vec2<i32>(i32(t.x), i32(t.y)) * side;
    let cell = clamp(s / i32(quads), lo, lo + vec2<i32>(side - 1));
    if local.x == 0u || local.x == quads {
        let nx = select(lo.x + side, lo.x - 1, local.x == 0u);
        let l = map_level(vec2<i32>(nx, cell.y));
        if l > t.lod {
            s.y = snap_down(s.y, l);
        }
    }
    if local.y == 0u || local.y == quads {
        let ny = select(lo.y + side, lo.y - 1, local.y == 0u);
        let l = map_level(vec2<i32>(cell.x, ny));
        if l > t.lod {
            s.x = snap_down(s.x, l);
        }
    }
    return s;
}

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> TerrainVertex {
    let quads = chunked.sizes.x;
    let t = final_chunks[instance];
    let local = vec2<u32>(vertex % (quads + 1u), vertex / (quads + 1u));
    let last = vec2<i32>(frame.data_size.xy) - vec2<i32>(1);
    let s = min(chunk_sample(t, local), last);
    var out: TerrainVertex;
    out.clip = project(s, vec2<f32>(0.0), sample_height(s));
    out.grid_pos = vec2<f32>(s);
    return out;
}

@fragment
fn fs_main(v: TerrainVertex) -> @location(0) vec4<f32> {
    return shade(v.grid_pos, v.clip);
}

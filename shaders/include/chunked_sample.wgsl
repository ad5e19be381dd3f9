// Chunked LOD's vertex placement with edge patching (`chunk_sample`), shared by the vertex
// stage (shaders/chunked.wgsl) and the test probe (shaders/chunked_probe.wgsl). The GLSL port
// for the mesh path is shaders/glsl/include/chunked_common.glsl; tests/chunked.rs requires
// both and the CPU mirror (`select::chunk_sample`) to agree.

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


// Tests: UDLOD's vertex morph (`morphed_vertex`, the function the vertex shaders call) for
// given tiles and local grid vertices, through the set 0 and UDLOD set 1 a view slot last drew
// with; read back by `lod::udlod::probe::probe` and compared with `morph::morphed_vertex`.

//!include terrain_common.wgsl
//!include udlod_common.wgsl
//!include udlod_morph.wgsl

// Mirrors `ProbeVertex` in src/lod/udlod/probe.rs; a test proves the layouts equal.
struct ProbeVertex {
    // In: the tile and the vertex's column and row in the tile's grid (xy).
    tile: Tile,
    local: vec4<u32>,
    // Out: the morphed cell (xy); frac (xy) and grid_pos (zw); the morph factor (x) and the
    // height (y).
    cell: vec4<i32>,
    frac: vec4<f32>,
    values: vec4<f32>,
}

struct Probe {
    count: vec4<u32>,
    vertices: array<ProbeVertex>,
}

@group(2) @binding(0) var<storage, read_write> probe: Probe;

@compute @workgroup_size(UDLOD_PROBE_WORKGROUP)
fn probe_vertices(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= probe.count.x {
        return;
    }
    let input = probe.vertices[i];
    let v = morphed_vertex(input.tile, input.local.xy);
    probe.vertices[i].cell = vec4<i32>(v.cell, 0, 0);
    probe.vertices[i].frac = vec4<f32>(v.frac, v.grid_pos);
    probe.vertices[i].values = vec4<f32>(v.morph, v.height, 0.0, 0.0);
}

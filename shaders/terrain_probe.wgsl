// Tests: the shared geometry helpers of terrain_common.wgsl evaluated at given inputs through a
// renderer's set 0, read back by `Renderer::run_probe`. tests/glsl.rs compares the results
// with the GLSL port's (shaders/glsl/terrain_probe.comp): they must be equal bit for bit.

//!include terrain_common.wgsl

// `TerrainProbePoint` in src/render/probe.rs.
struct ProbePoint {
    // In: xy the integer sample for sample_height and project's cell.
    cell: vec4<i32>,
    // In: xy a position (samples) for height_at, zw the fraction project adds to the cell.
    pos: vec4<f32>,
    // Out: x sample_height(cell), y height_at(pos.xy).
    heights: vec4<f32>,
    // Out: project(cell, pos.zw, height_at(pos.xy)).
    clip: vec4<f32>,
}

struct Probe {
    count: vec4<u32>,
    points: array<ProbePoint>,
}

@group(1) @binding(0) var<storage, read_write> probe: Probe;

@compute @workgroup_size(TERRAIN_PROBE_WORKGROUP)
fn probe_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= probe.count.x {
        return;
    }
    let s = probe.points[i].cell.xy;
    let p = probe.points[i].pos;
    let h = height_at(p.xy);
    probe.points[i].heights = vec4<f32>(sample_height(s), h, 0.0, 0.0);
    probe.points[i].clip = project(s, p.zw, h);
}

// Tests: `world_normal` (terrain_common.wgsl, the normal every method shades with) at given
// grid positions and grid-frame normals through a renderer's set 0, read back by
// `Renderer::probe_world_normals`; tests/earth_normals.rs compares it with f64 geodesy.

//!include terrain_common.wgsl

// `NormalProbePoint` in src/render/probe.rs.
struct NormalProbePoint {
    // In: xy the position (samples).
    pos: vec4<f32>,
    // In: xyz the normal in the grid's frame; out: xyz `world_normal(pos.xy, in)`.
    normal: vec4<f32>,
}

struct Probe {
    count: vec4<u32>,
    points: array<NormalProbePoint>,
}

@group(1) @binding(0) var<storage, read_write> probe: Probe;

@compute @workgroup_size(TERRAIN_PROBE_WORKGROUP)
fn probe_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= probe.count.x {
        return;
    }
    let p = probe.points[i];
    probe.points[i].normal = vec4<f32>(world_normal(p.pos.xy, p.normal.xyz), 0.0);
}

// Tests and tools: GPU heights at given level-0 sample positions, read back by
// `clipmap::gpu::probe_heights`. x: clipmap_height(p), y: bilinear of the single texture.

//!include terrain_common.wgsl

struct Probe {
    count: vec4<u32>,
    // xy: position (samples); z, w: results.
    points: array<vec4<f32>>,
}

@group(1) @binding(0) var<storage, read_write> probe: Probe;

fn texture_height_at(p: vec2<f32>) -> f32 {
    let base = floor(p);
    let f = p - base;
    let s = vec2<i32>(base);
    let south = mix(texture_height(s), texture_height(s + vec2<i32>(1, 0)), f.x);
    let north = mix(texture_height(s + vec2<i32>(0, 1)), texture_height(s + vec2<i32>(1, 1)), f.x);
    return mix(south, north, f.y);
}

@compute @workgroup_size(CLIPMAP_PROBE_WORKGROUP)
fn probe_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= probe.count.x {
        return;
    }
    let p = probe.points[i].xy;
    probe.points[i].z = clipmap_height(p);
    probe.points[i].w = texture_height_at(p);
}

// The fragment stage's clipmap normal at each point, sampled at the finest mip (zero
// gradients): z, w = normal.x, normal.y (the normal faces up, so z follows).
@compute @workgroup_size(CLIPMAP_PROBE_WORKGROUP)
fn probe_surface_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= probe.count.x {
        return;
    }
    let p = probe.points[i].xy;
    let n = normalize(clipmap_surface(p, vec2<f32>(0.0), vec2<f32>(0.0)).normal);
    probe.points[i].z = n.x;
    probe.points[i].w = n.y;
}

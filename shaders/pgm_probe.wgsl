// Tests: PGM's reference-sphere distance (`sphere_distance`, the function pgm.wgsl's vertex
// stage calls) at given inputs, read back by `lod::pgm::probe::sphere_distances` and compared
// with `lod::pgm::earth::Sphere::distance` (tests/pgm.rs). Needs no other set.

//!include pgm_sphere.wgsl

// `SphereProbe` in src/lod/pgm/probe.rs.
struct SphereProbe {
    // In: radius, height, largest distance, the ray's depression sine.
    sphere: vec4<f32>,
    // In: the horizon's sine, distance and angle (`Sphere::gpu_terms`); out: w the distance.
    horizon: vec4<f32>,
}

struct Probe {
    count: vec4<u32>,
    items: array<SphereProbe>,
}

@group(0) @binding(0) var<storage, read_write> probe: Probe;

@compute @workgroup_size(PGM_PROBE_WORKGROUP)
fn probe_sphere(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= probe.count.x {
        return;
    }
    let p = probe.items[i];
    let v = SphereView(p.sphere.x, p.sphere.y, p.sphere.z, p.horizon.x, p.horizon.y, p.horizon.z);
    let s = p.sphere.w;
    probe.items[i].horizon.w = sphere_distance(v, s, sqrt(max(1.0 - s * s, 0.0)));
}

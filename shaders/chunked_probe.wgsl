// Tests: chunked LOD's vertex placement (`chunk_sample`, what the vertex stage calls) for given
// chunks and local grid vertices, through the set 0 and chunked set 1 a view slot last drew
// with (its LOD map); the twin of shaders/glsl/chunked_probe.comp (the mesh path's port).

//!include terrain_common.wgsl
//!include chunked_common.wgsl
//!include chunked_sample.wgsl

// Mirrors `ChunkProbe` in src/lod/chunked/probe.rs; a test proves the layouts equal.
struct ChunkProbe {
    // In: the chunk (x, y, lod, 0) and the vertex's column and row in its grid (xy).
    chunk: vec4<u32>,
    local: vec4<u32>,
    // Out: xy `chunk_sample(chunk, local)`.
    sample: vec4<i32>,
}

struct Probe {
    count: vec4<u32>,
    items: array<ChunkProbe>,
}

@group(2) @binding(0) var<storage, read_write> probe: Probe;

@compute @workgroup_size(UDLOD_PROBE_WORKGROUP)
fn probe_samples(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= probe.count.x {
        return;
    }
    let c = probe.items[i].chunk;
    let s = chunk_sample(Chunk(c.x, c.y, c.z, 0u), probe.items[i].local.xy);
    probe.items[i].sample = vec4<i32>(s, 0, 0);
}

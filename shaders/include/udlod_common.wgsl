// UDLOD bindings (descriptor set 1, one set per frame slot). Mirrors `UdlodUniforms` and
// `TilingState` in src/lod/udlod/mod.rs; a test proves the layouts equal.

struct Udlod {
    // Camera-relative frustum planes (normal.xyz, offset): dot(n, p) + offset >= 0 inside.
    frustum: array<vec4<f32>, 6>,
    // x: split distance D of each level in metres (UDLOD_NO_SPLIT past the root).
    split: array<vec4<f32>, UDLOD_MAX_LEVELS>,
    // x: offset of the level's min/max entries, y/z: tiles per side of the level.
    levels: array<vec4<u32>, UDLOD_MAX_LEVELS>,
    // x: quads per tile side, y: root level, z: final list capacity, w: temporary list capacity.
    sizes: vec4<u32>,
    // x: reference height relative to the camera (m), y: morph range, z: 1 = morphing on,
    // w: 1 = frustum culling on.
    params: vec4<f32>,
    // x: indices per tile (6 * quads^2).
    counts: vec4<u32>,
}

struct Tile {
    x: u32,
    y: u32,
    lod: u32,
    pad: u32,
}

@group(1) @binding(0) var<uniform> udlod: Udlod;

// Camera-relative metres of an integer sample position (integers subtracted first: exact).
fn relative_xy(sample: vec2<i32>) -> vec2<f32> {
    return vec2<f32>(sample - frame.camera_cell.xy) * frame.camera_offset.w - frame.camera_offset.xy;
}

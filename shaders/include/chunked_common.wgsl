// GPU chunked LOD (Hedberg 2022), descriptor set 1 (one set per frame slot): the uniforms and
// the chunk record shared by the selection kernels and the vertex stage. Mirrors
// `ChunkedUniforms` in src/lod/chunked/mod.rs; a test proves the layouts equal.

struct Chunked {
    // Camera-relative frustum planes (normal.xyz, offset): dot(n, p) + offset >= 0 inside.
    frustum: array<vec4<f32>, 6>,
    // x: offset of the level's min/max and error entries, y/z: chunks per side of the level.
    levels: array<vec4<u32>, UDLOD_MAX_LEVELS>,
    // xyz: the LOD viewer relative to the camera (m).
    viewer: vec4<f32>,
    // x: error threshold (px), y: focal length (px), z: 1 = frustum culling, w: 1 = stitching.
    params: vec4<f32>,
    // x: quads per chunk side, y: root level, z: start level (root depth), w: finest level.
    sizes: vec4<u32>,
    // x: render list capacity, y: capacity of each traversal list, z/w: LOD map cells per side.
    lists: vec4<u32>,
    // x: the CBT's binary depth, y: indices per chunk (6 * quads^2), z: the CBT's root depth
    // in binary levels (never merged above).
    cbt: vec4<u32>,
    // xy: the LOD metric's stretch of the grid frame per axis (`Levels::stretch`): exactly
    // (1, 1) on square grids (chunks split by their bounding spheres), else chunks split by
    // the distance to their box in the stretched metric (`chunk_box_distance`).
    metric: vec4<f32>,
}

struct Chunk {
    x: u32,
    y: u32,
    lod: u32,
    pad: u32,
}

@group(1) @binding(0) var<uniform> chunked: Chunked;

// Camera-relative metres of an integer sample position (integers subtracted first: exact).
fn chunk_relative_xy(sample: vec2<i32>) -> vec2<f32> {
    return vec2<f32>(sample - frame.camera_cell.xy) * frame.camera_offset.w - frame.camera_offset.xy;
}

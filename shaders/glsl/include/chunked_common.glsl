// GLSL port of shaders/include/chunked_common.wgsl and of the vertex placement of
// shaders/include/chunked_sample.wgsl (LOD-map lookup and edge patching), for the task and mesh stages of the
// chunked method's mesh path. The same integer arithmetic; change both files together.

layout(set = 1, binding = 0, std140) uniform Chunked {
    vec4 frustum[6];
    // x: offset of the level's entries, y/z: chunks per side of the level.
    uvec4 levels[UDLOD_MAX_LEVELS];
    vec4 viewer;
    // x: error threshold (px), y: focal length (px), z: 1 = culling, w: 1 = stitching.
    vec4 params;
    // x: quads per chunk side, y: root level, z: start level, w: finest level.
    uvec4 sizes;
    // x: render list capacity, y: traversal list capacity, z/w: LOD map cells per side.
    uvec4 lists;
    uvec4 cbt;
    // xy: the LOD metric's stretch per axis (the selection's; the GLSL stages do not select).
    vec4 metric;
} chunked;

// The render list: x, y, lod, pad per chunk.
layout(set = 1, binding = 3, std430) readonly buffer FinalChunks {
    uvec4 chunks[];
} final_chunks;

layout(set = 1, binding = 6, std430) readonly buffer LodMap {
    uint cells[];
} lod_map;

// `map_level` of shaders/include/chunked_sample.wgsl.
uint map_level(ivec2 c) {
    ivec2 size = ivec2(chunked.lists.zw);
    if (c.x < 0 || c.y < 0 || c.x >= size.x || c.y >= size.y) {
        return 0u;
    }
    return lod_map.cells[uint(c.y) * chunked.lists.z + uint(c.x)];
}

int snap_down(int v, uint level) {
    return (v >> level) << level;
}

// `chunk_sample` of shaders/include/chunked_sample.wgsl: the sample a chunk vertex stands on after edge
// patching (before clamping to the data).
ivec2 chunk_sample(uvec4 t, uvec2 local) {
    uint quads = chunked.sizes.x;
    ivec2 s = ivec2(uvec2(t.x * quads + local.x, t.y * quads + local.y) << uvec2(t.z));
    if (chunked.params.w < 0.5) {
        return s;
    }
    int side = int(1u << t.z);
    ivec2 lo = ivec2(int(t.x), int(t.y)) * side;
    ivec2 cell = clamp(s / int(quads), lo, lo + ivec2(side - 1));
    if (local.x == 0u || local.x == quads) {
        int nx = local.x == 0u ? lo.x - 1 : lo.x + side;
        uint l = map_level(ivec2(nx, cell.y));
        if (l > t.z) {
            s.y = snap_down(s.y, l);
        }
    }
    if (local.y == 0u || local.y == quads) {
        int ny = local.y == 0u ? lo.y - 1 : lo.y + side;
        uint l = map_level(ivec2(cell.x, ny));
        if (l > t.z) {
            s.x = snap_down(s.x, l);
        }
    }
    return s;
}

// What the task stage hands each of its mesh workgroups.
struct ChunkPayload {
    uint chunk;
};

// Hardware tessellation, evaluation stage (the body; tess_<spacing>.tese set the spacing):
// the generated vertex's position on the flat patch, in sample units, displaced by the height
// map through the shared helpers (`height_at`, `project`), like every method's vertices.

//!include terrain_common.glsl
//!include tess_common.glsl

layout(location = 0) in vec2 in_grid[];
// `TerrainVertex.grid_pos` of the WGSL fragment stage.
layout(location = 0) out vec2 out_grid_pos;

// Height of the displaced surface at `g`: the bilinear field (Fischer: the height map sampled),
// or, with `surface = "mesh"` (tess.flags.z, not through the clipmap), brute force's triangles
// (each quad split along its (c+1, r)-(c, r+1) diagonal), the reference eval measures against.
float surface_height(vec2 g) {
    if (tess.flags.z == 0u || CLIPMAP_HEIGHTS) {
        return height_at(g);
    }
    vec2 base = floor(g);
    vec2 f = g - base;
    ivec2 s = ivec2(base);
    float h00 = sample_height(s);
    float h10 = sample_height(s + ivec2(1, 0));
    float h01 = sample_height(s + ivec2(0, 1));
    float h11 = sample_height(s + ivec2(1, 1));
    return f.x + f.y <= 1.0
        ? h00 + f.x * (h10 - h00) + f.y * (h01 - h00)
        : h11 + (1.0 - f.x) * (h01 - h11) + (1.0 - f.y) * (h10 - h11);
}

void main() {
    // `precise`: no fused multiply-add, so a vertex on an edge shared by two patches (one
    // barycentric weight exactly 0, the other two exact complements by Vulkan's tessellation
    // invariance) gets the same bits from both patches, in whatever corner order they list it.
    precise vec2 g = gl_TessCoord.x * in_grid[0] + gl_TessCoord.y * in_grid[1] + gl_TessCoord.z * in_grid[2];
    float h = surface_height(g);
    vec2 base = floor(g);
    gl_Position = vulkan_clip(project(ivec2(base), g - base, h));
    out_grid_pos = g;
}

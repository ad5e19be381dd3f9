// Hardware tessellation, evaluation stage (the body; tess_<spacing>.tese set the spacing):
// the generated vertex's position on the flat patch, in sample units, displaced by the height
// map through the shared helpers (`height_at`, `project`), like every method's vertices.

//!include terrain_common.glsl

layout(location = 0) in vec2 in_grid[];
// `TerrainVertex.grid_pos` of the WGSL fragment stage.
layout(location = 0) out vec2 out_grid_pos;

void main() {
    // `precise`: no fused multiply-add, so a vertex on an edge shared by two patches (one
    // barycentric weight exactly 0, the other two exact complements by Vulkan's tessellation
    // invariance) gets the same bits from both patches, in whatever corner order they list it.
    precise vec2 g = gl_TessCoord.x * in_grid[0] + gl_TessCoord.y * in_grid[1] + gl_TessCoord.z * in_grid[2];
    float h = height_at(g);
    vec2 base = floor(g);
    gl_Position = vulkan_clip(project(ivec2(base), g - base, h));
    out_grid_pos = g;
}

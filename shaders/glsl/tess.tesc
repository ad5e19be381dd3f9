#version 450
// Hardware tessellation, control stage (Fischer 2024, after Willems' terrain example): each
// outer level from the on-screen diameter of the sphere around its edge, over the target edge
// length, times the factor, clamped to 1..64; the inner level the mean of the outer ones.
// A level depends only on the edge's two endpoints (in either order, bit for bit), so the two
// patches sharing an edge give it the same level and the same vertices. Patches outside the
// view frustum (their prism between the quad's lowest and highest height) or of zero area get
// level 0: the tessellator discards them. The CPU mirror (src/lod/tessellation/levels.rs) is
// this rule in f64; tests/tessellation.rs requires the triangles it predicts. Change both.

//!include terrain_common.glsl
//!include tess_common.glsl

layout(vertices = 3) out;

layout(location = 0) in vec2 in_grid[];
layout(location = 1) in float in_height[];
layout(location = 2) in vec4 in_clip[];

layout(location = 0) out vec2 out_grid[];

// Level of the edge between corners a and b.
float edge_level(int a, int b) {
    // World-space edge: on the flat world integer sample offsets times the spacing (exact) and
    // the height difference; on the earth the chord between the corners through the lattice
    // (a native geographic grid's samples are not square: east-west spacing shrinks with
    // cos(lat), and the grid's one nominal spacing is only one of the two).
    vec3 d = EARTH_WORLD
        ? relative_position(ivec2(in_grid[a]), vec2(0.0), in_height[a])
            - relative_position(ivec2(in_grid[b]), vec2(0.0), in_height[b])
        : vec3((in_grid[a] - in_grid[b]) * frame.camera_offset.w, in_height[a] - in_height[b]);
    float diameter = length(d);
    // View depth of the edge's midpoint (clip w is the view depth, and linear). The ablation
    // `edge_levels = "patch"` (tess.flags.y) uses the patch's centroid instead: the two patches
    // on an edge then disagree on its level, the T-junctions the edge rule avoids.
    float depth = tess.flags.y != 0u
        ? (in_clip[0].w + in_clip[1].w + in_clip[2].w) / 3.0
        : 0.5 * (in_clip[a].w + in_clip[b].w);
    // A sphere reaching the eye plane gets the highest level, one wholly behind it the lowest
    // (it is invisible; at 64, lavapipe dropped visible terrain when such patches were drawn
    // with culling off: docs/tessellation.md).
    float radius = 0.5 * diameter;
    float px = depth > radius ? diameter * tess.params.z / depth : (depth < -radius ? 0.0 : 1.0e30);
    return clamp(px / tess.params.x * tess.params.y, 1.0, tess.params.w);
}

// On the earth the surface between the corners bulges outward from their chords by up to the
// sagitta d^2 / 8R of the patch's longest edge d over the lattice's curve radius (plus 1e-3 d,
// as `earth_box` grows the other methods' boxes: docs/coordinates.md, "Culling with
// curvature"); 0 on the flat world.
float earth_bulge() {
    if (!EARTH_WORLD) {
        return 0.0;
    }
    vec3 p0 = relative_position(ivec2(in_grid[0]), vec2(0.0), 0.0);
    vec3 p1 = relative_position(ivec2(in_grid[1]), vec2(0.0), 0.0);
    vec3 p2 = relative_position(ivec2(in_grid[2]), vec2(0.0), 0.0);
    float d = max(max(distance(p0, p1), distance(p1, p2)), distance(p2, p0));
    return d * d / (8.0 * uintBitsToFloat(frame.lattice.w)) + 1e-3 * d;
}

// Whether all of the patch's prism lies outside one plane of the frustum (reversed-Z clip
// space: 0 <= z <= w).
bool outside_frustum() {
    vec2 lo = min(min(in_grid[0], in_grid[1]), in_grid[2]);
    ivec2 quad = ivec2(lo) / int(tess.grid.x);
    float bulge = earth_bulge();
    vec2 b = patch_bounds.bounds[quad.y * int(tess.grid.z) + quad.x] + vec2(-bulge, bulge);
    bvec4 all_out_xy = bvec4(true);
    bvec2 all_out_z = bvec2(true);
    for (int i = 0; i < 3; i++) {
        for (int k = 0; k < 2; k++) {
            vec4 c = project(ivec2(in_grid[i]), vec2(0.0), k == 0 ? b.x : b.y);
            all_out_xy = bvec4(all_out_xy.x && c.x < -c.w, all_out_xy.y && c.x > c.w,
                               all_out_xy.z && c.y < -c.w, all_out_xy.w && c.y > c.w);
            all_out_z = bvec2(all_out_z.x && c.z < 0.0, all_out_z.y && c.z > c.w);
        }
    }
    return any(all_out_xy) || any(all_out_z);
}

void main() {
    out_grid[gl_InvocationID] = in_grid[gl_InvocationID];
    if (gl_InvocationID != 0) {
        return;
    }
    vec2 e1 = in_grid[1] - in_grid[0];
    vec2 e2 = in_grid[2] - in_grid[0];
    bool empty = e1.x * e2.y - e1.y * e2.x == 0.0;
    if (empty || (tess.flags.x != 0u && outside_frustum())) {
        gl_TessLevelOuter[0] = 0.0;
        gl_TessLevelOuter[1] = 0.0;
        gl_TessLevelOuter[2] = 0.0;
        gl_TessLevelInner[0] = 0.0;
        return;
    }
    // Outer level i belongs to the edge opposite corner i.
    float o0 = edge_level(1, 2);
    float o1 = edge_level(2, 0);
    float o2 = edge_level(0, 1);
    gl_TessLevelOuter[0] = o0;
    gl_TessLevelOuter[1] = o1;
    gl_TessLevelOuter[2] = o2;
    gl_TessLevelInner[0] = (o0 + o1 + o2) / 3.0;
}

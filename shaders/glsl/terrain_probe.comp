#version 450
// Tests: the GLSL port of the shared geometry helpers (include/terrain_common.glsl) at given
// inputs through a renderer's set 0; the twin of shaders/terrain_probe.wgsl, whose results
// tests/glsl.rs requires to be equal bit for bit.

//!include terrain_common.glsl

struct ProbePoint {
    ivec4 cell;
    vec4 pos;
    vec4 heights;
    vec4 clip;
};

layout(set = 1, binding = 0, std430) buffer Probe {
    uvec4 count;
    ProbePoint points[];
} probe;

layout(local_size_x = TERRAIN_PROBE_WORKGROUP) in;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= probe.count.x) {
        return;
    }
    ivec2 s = probe.points[i].cell.xy;
    vec4 p = probe.points[i].pos;
    float h = height_at(p.xy);
    probe.points[i].heights = vec4(sample_height(s), h, 0.0, 0.0);
    probe.points[i].clip = project(s, p.zw, h);
}

#version 450
// Tests: the GLSL port of chunked LOD's vertex placement (include/chunked_common.glsl, the
// mesh path's) at given inputs through a renderer's set 0 and chunked set 1; the twin of
// shaders/chunked_probe.wgsl, whose results tests/chunked.rs requires to be equal.

//!include terrain_common.glsl
//!include chunked_common.glsl

struct ChunkProbe {
    uvec4 chunk;
    uvec4 local_;
    ivec4 sample_;
};

layout(set = 2, binding = 0, std430) buffer Probe {
    uvec4 count;
    ChunkProbe items[];
} probe;

layout(local_size_x = UDLOD_PROBE_WORKGROUP) in;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= probe.count.x) {
        return;
    }
    ivec2 s = chunk_sample(probe.items[i].chunk, probe.items[i].local_.xy);
    probe.items[i].sample_ = ivec4(s, 0, 0);
}

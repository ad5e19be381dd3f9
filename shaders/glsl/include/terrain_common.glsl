// GLSL port of the geometry half of shaders/include/terrain_common.wgsl and
// shaders/include/clipmap.wgsl, for the stages naga cannot compile (tessellation, mesh).
// Statement for statement the same arithmetic in the same order, so a vertex lands where the
// WGSL helpers put it: tests/glsl.rs evaluates `sample_height`, `height_at` and `project` of
// both on the GPU through one renderer's set 0 (single texture and clipmap) and requires equal
// bits. Change both files together. Shading (`shade`) stays in WGSL: fragment stages are WGSL.
//
// Set 0 as src/frame/terrain.rs declares it (TERRAIN_SET); names match the WGSL globals.
// Texels are fetched without a sampler, as WGSL's textureLoad does.

#extension GL_EXT_samplerless_texture_functions : require

// A uniform buffer as in the WGSL, or in the build's second variant (VKTERRAIN_FRAME_STORAGE
// defined) a read-only storage buffer with the same layout (why: there).
#ifdef VKTERRAIN_FRAME_STORAGE
layout(set = 0, binding = 0, std430) readonly buffer Frame {
#else
layout(set = 0, binding = 0, std140) uniform Frame {
#endif
    // Rotation-only view times reversed-Z projection: positions are camera-relative.
    mat4 view_proj;
    // xy: the sample cell the camera is in (floor(camera_xy / spacing)).
    ivec4 camera_cell;
    // xy: camera_xy - camera_cell * spacing (metres); z: camera height (m); w: spacing (m).
    vec4 camera_offset;
    vec4 sun_dir;
    // xy: height samples per side.
    uvec4 data_size;
    vec4 haze;
    // The geolocation lattice: x samples per node (0: flat world), y/z nodes per row/column.
    uvec4 lattice;
    // xyz: the camera's world position split into f32 hi and lo parts.
    vec4 camera_hi;
    vec4 camera_lo;
} frame;
// What this build draws, as the WGSL's overrides: build.rs defines EARTH_WORLD and
// CLIPMAP_HEIGHTS (true or false) per terrain variant (`driver::shaders::TerrainVariant`:
// `frame.lattice.x != 0` exactly when EARTH_WORLD, the clipmap's `params.x != 0` exactly when
// CLIPMAP_HEIGHTS), so no stage branches on a buffer's value for them.
layout(set = 0, binding = 1) uniform texture2D height_tex;

// The chunked clipmap (docs/clipmap.md), bindings 5 and 6.
layout(set = 0, binding = 5) uniform texture2DArray atlas_height;
layout(set = 0, binding = 6, std430) readonly buffer Clipmap {
    // x: enabled, y: levels, z: node_count, w: centre texels.
    uvec4 params;
    // x: border texels, y: texels per layer side, z: f32 bits of 1 / blend band, w: f32 bits
    // of 1 / centre texels.
    uvec4 params2;
    // xy: the viewer in level-0 samples, clamped into the data.
    vec4 viewer;
    // Per level: window origin (nodes) xy, the level's node counts zw.
    ivec4 levels[CLIPMAP_MAX_LEVELS];
    uint entries[];
} clipmap;

// The geolocation lattice (binding 9): per node hi.xyz, lo.xyz, up.xyz as three vec4.
layout(set = 0, binding = 9, std430) readonly buffer GeoLattice {
    vec4 nodes[];
} geo_lattice;

// The WGSL's Vulkan output convention: naga flips clip-space y of a vertex stage's position
// (WriterFlags::ADJUST_COORDINATE_SPACE); GLSL stages that write gl_Position do it here.
vec4 vulkan_clip(vec4 clip) {
    return vec4(clip.x, -clip.y, clip.z, clip.w);
}

float clipmap_inv_pow2(uint l) {
    return uintBitsToFloat((127u - l) << 23u);
}

vec2 clipmap_level_coord(vec2 p, uint l) {
    float half_ = (float(1u << l) - 1.0) * 0.5;
    return (p - vec2(half_)) * clipmap_inv_pow2(l);
}

float clipmap_level_height(vec2 p, uint l, ivec2 node) {
    int n = int(clipmap.params.z);
    int c = int(clipmap.params.w);
    int cell = (int(l) * n + node.y % n) * n + node.x % n;
    uint e = clipmap.entries[cell];
    if (e == 0xffffffffu) {
        return 0.0;
    }
    int layer = int(e & ((1u << CLIPMAP_LOD_SHIFT) - 1u));
    uint al = e >> CLIPMAP_LOD_SHIFT;
    int b = int(clipmap.params2.x);
    int side = int(clipmap.params2.y);
    ivec2 anc = node >> ivec2(uvec2(al - l));
    vec2 t = clipmap_level_coord(p, al);
    vec2 local_ = t - vec2(anc * c);
    vec2 base = floor(local_);
    vec2 f = local_ - base;
    ivec2 ij = clamp(ivec2(base) + ivec2(b), ivec2(0), ivec2(side - 2));
    float h00 = texelFetch(atlas_height, ivec3(ij, layer), 0).r;
    float h10 = texelFetch(atlas_height, ivec3(ij + ivec2(1, 0), layer), 0).r;
    float h01 = texelFetch(atlas_height, ivec3(ij + ivec2(0, 1), layer), 0).r;
    float h11 = texelFetch(atlas_height, ivec3(ij + ivec2(1, 1), layer), 0).r;
    float south = h00 + (h10 - h00) * f.x;
    float north = h01 + (h11 - h01) * f.x;
    return south + (north - south) * f.y;
}

ivec2 clipmap_node(vec2 p, uint l) {
    vec2 t = clipmap_level_coord(p, l);
    float inv_c = uintBitsToFloat(clipmap.params2.w);
    return clamp(ivec2(floor(t * inv_c)), ivec2(0), clipmap.levels[l].zw - ivec2(1));
}

bool clipmap_in_window(ivec2 node, uint l) {
    ivec4 lv = clipmap.levels[l];
    ivec2 hi = lv.xy + min(ivec2(int(clipmap.params.z)), lv.zw);
    return all(greaterThanEqual(node, lv.xy)) && all(lessThan(node, hi));
}

uint clipmap_first_level(vec2 p) {
    float d = max(abs(p.x - clipmap.viewer.x), abs(p.y - clipmap.viewer.y));
    float span = float(clipmap.params.z * clipmap.params.w);
    if (d < 2.0 * span) {
        return 0u;
    }
    uint l = uint(floor(log2(d / span)));
    return min(l, clipmap.params.y - 1u);
}

struct ClipmapSite {
    uint lod;
    ivec2 node;
};

// The WGSL's `loop { node = ...; if found { break; } l += 1u; }` as the equivalent `while`:
// glslang 12's SPIR-V of the `for (;;)`-with-break form returned node (-1, -1) for the first
// level on lavapipe (Mesa 22.3), while every step evaluated on its own was right.
ClipmapSite clipmap_find(vec2 p) {
    uint lods = clipmap.params.y;
    uint l = clipmap_first_level(p);
    ivec2 node = clipmap_node(p, l);
    while (!clipmap_in_window(node, l) && l + 1u < lods) {
        l += 1u;
        node = clipmap_node(p, l);
    }
    return ClipmapSite(l, node);
}

float clipmap_blend_weight(vec2 p, uint l) {
    float blend_inv = uintBitsToFloat(clipmap.params2.z);
    if (l + 1u >= clipmap.params.y || blend_inv == 0.0) {
        return 1.0;
    }
    int c = int(clipmap.params.w);
    ivec4 lv = clipmap.levels[l];
    ivec2 w = min(ivec2(int(clipmap.params.z)), lv.zw);
    vec2 t = clipmap_level_coord(p, l);
    vec2 lo = t - vec2(lv.xy * c);
    vec2 hi = vec2((lv.xy + w) * c) - t;
    vec2 far_ = vec2(3.0e38);
    vec2 dlo = mix(lo, far_, equal(lv.xy, ivec2(0)));
    vec2 dhi = mix(hi, far_, greaterThanEqual(lv.xy + w, lv.zw));
    float d = min(min(dlo.x, dlo.y), min(dhi.x, dhi.y));
    return clamp(d * blend_inv, 0.0, 1.0);
}

float clipmap_height(vec2 p) {
    if (clipmap.params.x == 0u) {
        return 0.0;
    }
    ClipmapSite site = clipmap_find(p);
    uint l = site.lod;
    float h = clipmap_level_height(p, l, site.node);
    float weight = clipmap_blend_weight(p, l);
    if (weight >= 1.0) {
        return h;
    }
    ivec2 node1 = clipmap_node(p, l + 1u);
    if (!clipmap_in_window(node1, l + 1u)) {
        return h;
    }
    float h1 = clipmap_level_height(p, l + 1u, node1);
    return h1 + (h - h1) * weight;
}

// Height in metres at an integer sample of the single height texture, clamped to the data.
float texture_height(ivec2 s) {
    ivec2 hi = ivec2(frame.data_size.xy) - ivec2(1);
    return texelFetch(height_tex, clamp(s, ivec2(0), hi), 0).r;
}

// Height in metres at an integer sample, clamped to the data: through the clipmap in its
// variant, else from the single height texture.
float sample_height(ivec2 s) {
    ivec2 hi = ivec2(frame.data_size.xy) - ivec2(1);
    ivec2 c = clamp(s, ivec2(0), hi);
    if (CLIPMAP_HEIGHTS) {
        return clipmap_height(vec2(c));
    }
    return texelFetch(height_tex, c, 0).r;
}

// Bilinear height at a position in sample units; exact at integer positions.
float height_at(vec2 grid_pos) {
    if (CLIPMAP_HEIGHTS) {
        vec2 hi = vec2(frame.data_size.xy) - vec2(1.0);
        return clipmap_height(clamp(grid_pos, vec2(0.0), hi));
    }
    vec2 base = floor(grid_pos);
    vec2 f = grid_pos - base;
    ivec2 s = ivec2(base);
    float south = mix(sample_height(s), sample_height(s + ivec2(1, 0)), f.x);
    float north = mix(sample_height(s + ivec2(0, 1)), sample_height(s + ivec2(1, 1)), f.x);
    return mix(south, north, f.y);
}

vec3 lattice_relative(ivec2 node) {
    int i = 3 * (node.y * int(frame.lattice.y) + node.x);
    return (geo_lattice.nodes[i].xyz - frame.camera_hi.xyz) + (geo_lattice.nodes[i + 1].xyz - frame.camera_lo.xyz);
}

vec3 lattice_up(ivec2 node) {
    return geo_lattice.nodes[3 * (node.y * int(frame.lattice.y) + node.x) + 2].xyz;
}

// On the earth: the camera-relative surface point at height 0 of the datum and the up vector
// at a sample position (integer cell + fraction), both bilinear in the lattice.
struct LatticePoint {
    vec3 p;
    vec3 up;
};

LatticePoint lattice_point(ivec2 cell, vec2 frac_) {
    int step_ = int(frame.lattice.x);
    ivec2 node = clamp(cell / step_, ivec2(0), ivec2(frame.lattice.yz) - ivec2(2));
    vec2 f = (vec2(cell - node * step_) + frac_) / float(step_);
    vec3 p00 = lattice_relative(node);
    vec3 p10 = lattice_relative(node + ivec2(1, 0));
    vec3 p01 = lattice_relative(node + ivec2(0, 1));
    vec3 p11 = lattice_relative(node + ivec2(1, 1));
    vec3 u00 = lattice_up(node);
    vec3 u10 = lattice_up(node + ivec2(1, 0));
    vec3 u01 = lattice_up(node + ivec2(0, 1));
    vec3 u11 = lattice_up(node + ivec2(1, 1));
    vec3 p = mix(mix(p00, p10, f.x), mix(p01, p11, f.x), f.y);
    vec3 up = mix(mix(u00, u10, f.x), mix(u01, u11, f.x), f.y);
    return LatticePoint(p, up);
}

// Camera-relative position (metres, world axes) of a surface point: the flat world's integer
// cell subtraction, or the geolocation lattice interpolated bilinearly plus height * up.
vec3 relative_position(ivec2 cell, vec2 frac_, float height_m) {
    if (!EARTH_WORLD) {
        float spacing = frame.camera_offset.w;
        vec2 rel_xy = vec2(cell - frame.camera_cell.xy) * spacing + frac_ * spacing - frame.camera_offset.xy;
        return vec3(rel_xy, height_m - frame.camera_offset.z);
    }
    LatticePoint s = lattice_point(cell, frac_);
    return s.p + height_m * s.up;
}

// Clip position (WebGPU clip space, y up, like the WGSL) of a surface point given in sample
// units (integer cell + fraction) and metres.
vec4 project(ivec2 cell, vec2 frac_, float height_m) {
    return frame.view_proj * vec4(relative_position(cell, frac_, height_m), 1.0);
}


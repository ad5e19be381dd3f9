// The chunked clipmap lookup (docs/clipmap.md). Mirrors `ViewQuadtree::lookup` in
// src/clipmap/quadtree.rs operation for operation; tests/clipmap.rs reads GPU heights back and
// proves them equal to the CPU's.

struct Clipmap {
    // x: enabled (0: heights come from height_tex), y: levels, z: node_count, w: centre texels.
    params: vec4<u32>,
    // x: border texels, y: texels per layer side, z: f32 bits of 1 / blend band (level texels;
    // 0: no blending between levels), w: f32 bits of 1 / centre texels.
    params2: vec4<u32>,
    // Per level: window origin (nodes) xy, the level's node counts zw.
    // xy: the viewer in level-0 samples, clamped into the data.
    viewer: vec4<f32>,
    levels: array<vec4<i32>, CLIPMAP_MAX_LEVELS>,
    // levels x node_count x node_count, index (l * n + y % n) * n + x % n:
    // atlas layer | atlas lod << CLIPMAP_LOD_SHIFT; 0xffffffff: nothing resident.
    entries: array<u32>,
}

// Heights of resident nodes, one layer per atlas slot, read with textureLoad (exact texels).
@group(0) @binding(5) var atlas_height: texture_2d_array<f32>;
@group(0) @binding(6) var<storage, read> clipmap: Clipmap;
// Unit normals (RGBA8 snorm) and albedo (RGBA8 sRGB) of the same layers, filtered.
@group(0) @binding(7) var atlas_normal: texture_2d_array<f32>;
@group(0) @binding(8) var atlas_albedo: texture_2d_array<f32>;

// 2^-l exactly (from the exponent bits; no division or exp2 whose precision varies).
fn clipmap_inv_pow2(l: u32) -> f32 {
    return bitcast<f32>((127u - l) << 23u);
}

// Level-l texel coordinate of a level-0 sample position (texel centres at integers).
fn clipmap_level_coord(p: vec2<f32>, l: u32) -> vec2<f32> {
    let half = (f32(1u << l) - 1.0) * 0.5;
    return (p - vec2<f32>(half)) * clipmap_inv_pow2(l);
}

// Height at p from the entry of quadtree level l for `node` (a node of level l in its window):
// bilinear within the best resident node.
fn clipmap_level_height(p: vec2<f32>, l: u32, node: vec2<i32>) -> f32 {
    let n = i32(clipmap.params.z);
    let c = i32(clipmap.params.w);
    let cell = (i32(l) * n + node.y % n) * n + node.x % n;
    let e = clipmap.entries[cell];
    if e == 0xffffffffu {
        return 0.0;
    }
    let layer = i32(e & ((1u << CLIPMAP_LOD_SHIFT) - 1u));
    let al = e >> CLIPMAP_LOD_SHIFT;
    let b = i32(clipmap.params2.x);
    let side = i32(clipmap.params2.y);
    let anc = node >> vec2<u32>(al - l);
    let t = clipmap_level_coord(p, al);
    let local = t - vec2<f32>(anc * c);
    let base = floor(local);
    let f = local - base;
    let ij = clamp(vec2<i32>(base) + vec2<i32>(b), vec2<i32>(0), vec2<i32>(side - 2));
    let h00 = textureLoad(atlas_height, ij, layer, 0).r;
    let h10 = textureLoad(atlas_height, ij + vec2<i32>(1, 0), layer, 0).r;
    let h01 = textureLoad(atlas_height, ij + vec2<i32>(0, 1), layer, 0).r;
    let h11 = textureLoad(atlas_height, ij + vec2<i32>(1, 1), layer, 0).r;
    let south = h00 + (h10 - h00) * f.x;
    let north = h01 + (h11 - h01) * f.x;
    return south + (north - south) * f.y;
}

// The node of level l containing p (clamped into the level's node grid).
fn clipmap_node(p: vec2<f32>, l: u32) -> vec2<i32> {
    // floor(t * (1 / centre)) rather than an integer division (slow on CPU rasterizers); the
    // reciprocal is the same f32 on both sides and a position on a node boundary may land in
    // either node (both cover it, with the border).
    let t = clipmap_level_coord(p, l);
    let inv_c = bitcast<f32>(clipmap.params2.w);
    return clamp(vec2<i32>(floor(t * inv_c)), vec2<i32>(0), clipmap.levels[l].zw - vec2<i32>(1));
}

// Whether a node of level l lies in that level's window.
fn clipmap_in_window(node: vec2<i32>, l: u32) -> bool {
    let lv = clipmap.levels[l];
    let hi = lv.xy + min(vec2<i32>(i32(clipmap.params.z)), lv.zw);
    return all(node >= lv.xy) && all(node < hi);
}

// A level no finer than the finest window holding p: a window spans n nodes around the
// (clamped) viewer's node, so levels l with max|p - viewer| >= n * centre * 2^l cannot hold p.
// One level of margin absorbs log2's imprecision; the search result is then the same as
// searching from level 0 (which the CPU does).
fn clipmap_first_level(p: vec2<f32>) -> u32 {
    let d = max(abs(p.x - clipmap.viewer.x), abs(p.y - clipmap.viewer.y));
    let span = f32(clipmap.params.z * clipmap.params.w);
    if d < 2.0 * span {
        return 0u;
    }
    let l = u32(floor(log2(d / span)));
    return min(l, clipmap.params.y - 1u);
}

// The finest level whose window holds p, and p's node in it (the coarsest level holds every
// position).
struct ClipmapSite {
    lod: u32,
    node: vec2<i32>,
}

fn clipmap_find(p: vec2<f32>) -> ClipmapSite {
    let lods = clipmap.params.y;
    var l = clipmap_first_level(p);
    var node = vec2<i32>(0);
    loop {
        node = clipmap_node(p, l);
        if clipmap_in_window(node, l) || l + 1u >= lods {
            break;
        }
        l += 1u;
    }
    return ClipmapSite(l, node);
}

// Weight of level l at p: 1 outside the blend band, falling to 0 at the window's inner edges
// (edges on the data's border do not blend); 1 where there is no coarser level or blending
// is off.
fn clipmap_blend_weight(p: vec2<f32>, l: u32) -> f32 {
    let blend_inv = bitcast<f32>(clipmap.params2.z);
    if l + 1u >= clipmap.params.y || blend_inv == 0.0 {
        return 1.0;
    }
    // Distance (level-l texels) to the window's edges that are not the data's edges.
    let c = i32(clipmap.params.w);
    let lv = clipmap.levels[l];
    let w = min(vec2<i32>(i32(clipmap.params.z)), lv.zw);
    let t = clipmap_level_coord(p, l);
    let lo = t - vec2<f32>(lv.xy * c);
    let hi = vec2<f32>((lv.xy + w) * c) - t;
    let far = vec2<f32>(3.0e38);
    let dlo = select(lo, far, lv.xy == vec2<i32>(0));
    let dhi = select(hi, far, lv.xy + w >= lv.zw);
    let d = min(min(dlo.x, dlo.y), min(dhi.x, dhi.y));
    return clamp(d * blend_inv, 0.0, 1.0);
}

// Height in metres at a level-0 sample position. Constant time: at most `levels` integer
// window tests, then one entry and four texel loads (two of each within the blend band near a
// window's inner edge, where the level and the next coarser one are mixed).
fn clipmap_height(p: vec2<f32>) -> f32 {
    if clipmap.params.x == 0u {
        return 0.0;
    }
    let site = clipmap_find(p);
    let l = site.lod;
    let h = clipmap_level_height(p, l, site.node);
    let weight = clipmap_blend_weight(p, l);
    if weight >= 1.0 {
        return h;
    }
    let node1 = clipmap_node(p, l + 1u);
    if !clipmap_in_window(node1, l + 1u) {
        return h;
    }
    let h1 = clipmap_level_height(p, l + 1u, node1);
    return h1 + (h - h1) * weight;
}

struct ClipmapSurface {
    // Not normalized (the shading normalizes once, after turning it to world axes).
    normal: vec3<f32>,
    albedo: vec3<f32>,
}

// Normal and albedo from the entry of quadtree level l for `node`, with explicit gradients
// scaled to the resident node's level and layer size, so filtering (and anisotropy where
// enabled) follows the node's own texel density.
fn clipmap_level_surface(p: vec2<f32>, l: u32, node: vec2<i32>, gx: vec2<f32>, gy: vec2<f32>) -> ClipmapSurface {
    let n = i32(clipmap.params.z);
    let c = i32(clipmap.params.w);
    let e = clipmap.entries[(i32(l) * n + node.y % n) * n + node.x % n];
    var out: ClipmapSurface;
    out.normal = vec3<f32>(0.0, 0.0, 1.0);
    out.albedo = vec3<f32>(0.5);
    if e == 0xffffffffu {
        return out;
    }
    let layer = i32(e & ((1u << CLIPMAP_LOD_SHIFT) - 1u));
    let al = e >> CLIPMAP_LOD_SHIFT;
    let b = f32(clipmap.params2.x);
    let side = f32(clipmap.params2.y);
    let anc = node >> vec2<u32>(al - l);
    let local = clipmap_level_coord(p, al) - vec2<f32>(anc * c);
    // Texel centres at integers in `local` -> normalized layer coordinates.
    let uv = (local + vec2<f32>(b + 0.5)) / side;
    let scale = clipmap_inv_pow2(al) / side;
    out.normal = textureSampleGrad(atlas_normal, linear_sampler, uv, layer, gx * scale, gy * scale).xyz;
    out.albedo = textureSampleGrad(atlas_albedo, linear_sampler, uv, layer, gx * scale, gy * scale).rgb;
    return out;
}

// Fragment stage: normal and albedo at a level-0 sample position from the best resident node
// of the finest level whose window holds it (`gx`, `gy`: the screen derivatives of p, taken
// in uniform control flow; explicit gradients need no uniformity). In the blend band near a
// window's inner edge the next coarser level is mixed in with the same weight as the heights,
// so shading does not change resolution in a visible line at ring edges.
fn clipmap_surface(p: vec2<f32>, gx: vec2<f32>, gy: vec2<f32>) -> ClipmapSurface {
    let site = clipmap_find(p);
    let l = site.lod;
    var out = clipmap_level_surface(p, l, site.node, gx, gy);
    let weight = clipmap_blend_weight(p, l);
    if weight < 1.0 {
        let node1 = clipmap_node(p, l + 1u);
        if clipmap_in_window(node1, l + 1u) {
            let coarse = clipmap_level_surface(p, l + 1u, node1, gx, gy);
            out.normal = mix(coarse.normal, out.normal, weight);
            out.albedo = mix(coarse.albedo, out.albedo, weight);
        }
    }
    return out;
}

// Bindings and helpers every terrain method shares (descriptor set 0, one set per frame slot).
// Mirrors `FrameUniforms` in src/render/terrain.rs; a test proves the layouts equal.

struct Frame {
    // Rotation-only view times reversed-Z projection: positions are camera-relative.
    view_proj: mat4x4<f32>,
    // xy: the sample cell the camera is in (floor(camera_xy / spacing)).
    camera_cell: vec4<i32>,
    // xy: camera_xy - camera_cell * spacing (metres); z: camera height (m); w: spacing (m).
    camera_offset: vec4<f32>,
    // xyz: unit vector towards the sun.
    sun_dir: vec4<f32>,
    // xy: height samples per side.
    data_size: vec4<u32>,
    // rgb: haze (sky) colour, linear; w: 1 / haze distance in metres (0: no haze).
    haze: vec4<f32>,
    // The geolocation lattice (src/geo/lattice.rs): x samples per node (0: flat world), y/z
    // nodes per row/column, w: bits of the f32 curve radius (metres; `earth_box`).
    lattice: vec4<u32>,
    // xyz: the camera's world position split into f32 hi and lo parts.
    camera_hi: vec4<f32>,
    camera_lo: vec4<f32>,
}

// A uniform buffer: NVIDIA's driver reads it faster than a read-only storage buffer (3-5 % of
// UDLOD's GPU time at 1080p on an H100 and an H200). build.rs also compiles every shader with
// this line as `var<storage, read>`, which Debian 12's lavapipe (Mesa 22.3) gets: it spares
// that driver a shader rebuild per frame (`driver::shaders::FrameBlock`, docs/architecture.md,
// "Uniform buffers on Mesa 22.3"). Keep the line as it is: build.rs finds it by its text.
@group(0) @binding(0) var<uniform> frame: Frame;
// What this build of the shader draws: set by build.rs per variant (`driver::shaders::
// TerrainVariant`, one per terrain: `frame.lattice.x != 0` exactly when EARTH_WORLD, the
// clipmap's `params.x != 0` exactly when CLIPMAP_HEIGHTS). naga leaves a branch on them with a
// constant condition, whose dead side the driver drops; lavapipe before Mesa 24 runs both sides
// of a branch on a storage buffer's value (docs/architecture.md, "Shaders per terrain").
override EARTH_WORLD: bool;
override CLIPMAP_HEIGHTS: bool;
// Heights in metres, one texel per sample, read with textureLoad (exact values, no filtering).
@group(0) @binding(1) var height_tex: texture_2d<f32>;
// Unit normals per sample (RGBA8 snorm), filtered in the fragment stage.
@group(0) @binding(2) var normal_tex: texture_2d<f32>;
// sRGB albedo covering the data extent edge to edge.
@group(0) @binding(3) var albedo_tex: texture_2d<f32>;
@group(0) @binding(4) var linear_sampler: sampler;
// Bindings 5 and 6: the chunked clipmap (atlas + this view's quadtree).
//!include clipmap.wgsl
// Per lattice node three vec4: world position at height 0 as hi.xyz and lo.xyz (split
// doubles), and the unit up vector (the ellipsoid normal in the world frame).
@group(0) @binding(9) var<storage, read> geo_lattice: array<vec4<f32>>;

struct TerrainVertex {
    @builtin(position) clip: vec4<f32>,
    // Position in sample units (x = column, y = row), for texturing.
    @location(0) grid_pos: vec2<f32>,
}

// Height in metres at an integer sample of the single height texture, clamped to the data.
fn texture_height(s: vec2<i32>) -> f32 {
    let hi = vec2<i32>(frame.data_size.xy) - vec2<i32>(1);
    return textureLoad(height_tex, clamp(s, vec2<i32>(0), hi), 0).r;
}

// Height in metres at an integer sample, clamped to the data: through the clipmap in its
// variant, else from the single height texture.
fn sample_height(s: vec2<i32>) -> f32 {
    let hi = vec2<i32>(frame.data_size.xy) - vec2<i32>(1);
    let c = clamp(s, vec2<i32>(0), hi);
    if CLIPMAP_HEIGHTS {
        return clipmap_height(vec2<f32>(c));
    }
    return textureLoad(height_tex, c, 0).r;
}

// Bilinear height at a position in sample units; exact at integer positions (weights 1 and 0).
// Through the clipmap: one lookup, bilinear within the best resident node (clamped to the data).
fn height_at(grid_pos: vec2<f32>) -> f32 {
    if CLIPMAP_HEIGHTS {
        let hi = vec2<f32>(frame.data_size.xy) - vec2<f32>(1.0);
        return clipmap_height(clamp(grid_pos, vec2<f32>(0.0), hi));
    }
    let base = floor(grid_pos);
    let f = grid_pos - base;
    let s = vec2<i32>(base);
    let south = mix(sample_height(s), sample_height(s + vec2<i32>(1, 0)), f.x);
    let north = mix(sample_height(s + vec2<i32>(0, 1)), sample_height(s + vec2<i32>(1, 1)), f.x);
    return mix(south, north, f.y);
}

// Camera-relative position (metres, world axes) of lattice node `node`: hi parts subtracted
// first, then lo parts (split-double arithmetic, exact for nearby nodes).
fn lattice_relative(node: vec2<i32>) -> vec3<f32> {
    let i = 3 * (node.y * i32(frame.lattice.y) + node.x);
    return (geo_lattice[i].xyz - frame.camera_hi.xyz) + (geo_lattice[i + 1].xyz - frame.camera_lo.xyz);
}

fn lattice_up(node: vec2<i32>) -> vec3<f32> {
    return geo_lattice[3 * (node.y * i32(frame.lattice.y) + node.x) + 2].xyz;
}

// Camera-relative position (metres, world axes) of a surface point given in sample units
// (integer cell + fraction) and metres of height. Flat world: the camera cell is subtracted in
// integers, so precision does not depend on the distance from the world origin. On the earth:
// the geolocation lattice interpolated bilinearly (camera-relative corners) plus height * up.
fn relative_position(cell: vec2<i32>, frac: vec2<f32>, height_m: f32) -> vec3<f32> {
    if !EARTH_WORLD {
        let spacing = frame.camera_offset.w;
        let rel_xy = vec2<f32>(cell - frame.camera_cell.xy) * spacing + frac * spacing - frame.camera_offset.xy;
        return vec3<f32>(rel_xy, height_m - frame.camera_offset.z);
    }
    let s = lattice_point(cell, frac);
    return s.p + height_m * s.up;
}

// On the earth: the camera-relative surface point at height 0 of the datum and the up vector
// at a sample position (integer cell + fraction), both bilinear in the lattice.
struct LatticePoint {
    p: vec3<f32>,
    up: vec3<f32>,
}

fn lattice_point(cell: vec2<i32>, frac: vec2<f32>) -> LatticePoint {
    let lstep = i32(frame.lattice.x);
    let node = clamp(cell / lstep, vec2<i32>(0), vec2<i32>(frame.lattice.yz) - vec2<i32>(2));
    let f = (vec2<f32>(cell - node * lstep) + frac) / f32(lstep);
    let p00 = lattice_relative(node);
    let p10 = lattice_relative(node + vec2<i32>(1, 0));
    let p01 = lattice_relative(node + vec2<i32>(0, 1));
    let p11 = lattice_relative(node + vec2<i32>(1, 1));
    let u00 = lattice_up(node);
    let u10 = lattice_up(node + vec2<i32>(1, 0));
    let u01 = lattice_up(node + vec2<i32>(0, 1));
    let u11 = lattice_up(node + vec2<i32>(1, 1));
    let p = mix(mix(p00, p10, f.x), mix(p01, p11, f.x), f.y);
    let up = mix(mix(u00, u10, f.x), mix(u01, u11, f.x), f.y);
    return LatticePoint(p, up);
}

// An axis-aligned camera-relative box (metres).
struct Box3 {
    lo: vec3<f32>,
    hi: vec3<f32>,
}

// On the earth: the camera-relative box around the terrain over the grid rectangle from sample
// c0 to sample c1 (inclusive) between heights.x..heights.y: the box around the rectangle's
// corners at both heights through the lattice, grown on every axis by the sagitta of its
// horizontal diagonal d over the lattice's curve radius, d^2 / (8 R), plus 1e-3 d. The one
// definition every method culls with on the earth; `Lattice::rect_box` in
// src/geo/lattice.rs is its CPU twin (f64), proven to decide as this one in tests/udlod.rs
// and tests/chunked.rs.
fn earth_box(c0: vec2<i32>, c1: vec2<i32>, heights: vec2<f32>) -> Box3 {
    let corners = array<vec2<i32>, 4>(c0, vec2<i32>(c1.x, c0.y), vec2<i32>(c0.x, c1.y), c1);
    var lo = vec3<f32>(3.0e38);
    var hi = vec3<f32>(-3.0e38);
    for (var k = 0u; k < 4u; k++) {
        // Each corner's lattice point once, for both heights.
        let c = lattice_point(corners[k], vec2<f32>(0.0));
        let low = c.p + heights.x * c.up;
        let high = c.p + heights.y * c.up;
        lo = min(lo, min(low, high));
        hi = max(hi, max(low, high));
    }
    let d = length(hi.xy - lo.xy);
    let bulge = vec3<f32>(d * d / (8.0 * bitcast<f32>(frame.lattice.w)) + 1e-3 * d);
    return Box3(lo - bulge, hi + bulge);
}

// Is the box wholly outside one of the planes (dot(n, p) + offset >= 0 inside) by more than
// `slack` metres? The corner farthest along each normal decides (`WorldBox::outside`).
fn box_outside(planes: array<vec4<f32>, 6>, b: Box3, slack: f32) -> bool {
    for (var i = 0u; i < 6u; i++) {
        let pl = planes[i];
        let p = select(b.lo, b.hi, pl.xyz >= vec3<f32>(0.0));
        if pl.x * p.x + pl.y * p.y + pl.z * p.z + pl.w < -slack {
            return true;
        }
    }
    return false;
}

// Whether box `b` lies inside every plane (its corner nearest each plane's back side on or
// in front of it).
fn box_inside(planes: array<vec4<f32>, 6>, b: Box3) -> bool {
    for (var i = 0u; i < 6u; i++) {
        let pl = planes[i];
        let p = select(b.hi, b.lo, pl.xyz >= vec3<f32>(0.0));
        if pl.x * p.x + pl.y * p.y + pl.z * p.z + pl.w < 0.0 {
            return false;
        }
    }
    return true;
}

// Clip position of a surface point given in sample units (integer cell + fraction) and metres.
fn project(cell: vec2<i32>, frac: vec2<f32>, height_m: f32) -> vec4<f32> {
    return frame.view_proj * vec4<f32>(relative_position(cell, frac, height_m), 1.0);
}

// Cheap shading shared by all methods: albedo times ambient + Lambert from the normal map,
// faded towards the sky with view depth (aerial perspective; the fragment position's w is
// 1 / clip w, and clip w is the view depth). Through the clipmap albedo and normal come from
// the atlas (`clipmap_surface`). The normal maps hold normals in the axes the sun is given in:
// the grid's in the flat world, the world's on the earth (baked on the host through the
// lattice: docs/coordinates.md, "Normals on the earth").
fn shade(v: TerrainVertex) -> vec4<f32> {
    let grid_pos = v.grid_pos;
    let gx = dpdx(grid_pos);
    let gy = dpdy(grid_pos);
    var n: vec3<f32>;
    var albedo: vec3<f32>;
    if CLIPMAP_HEIGHTS {
        let s = clipmap_surface(grid_pos, gx, gy);
        n = s.normal;
        albedo = s.albedo;
    } else {
        let size = vec2<f32>(frame.data_size.xy);
        n = textureSampleGrad(normal_tex, linear_sampler, (grid_pos + 0.5) / size, gx / size, gy / size).xyz;
        albedo = textureSampleGrad(albedo_tex, linear_sampler, grid_pos / (size - 1.0), gx / (size - 1.0), gy / (size - 1.0)).rgb;
    }
    n = normalize(n);
    let light = LIGHT_AMBIENT + LIGHT_DIFFUSE * max(dot(n, frame.sun_dir.xyz), 0.0);
    let haze = 1.0 - exp(-frame.haze.w / v.clip.w);
    return vec4<f32>(mix(albedo * light, frame.haze.rgb, haze), 1.0);
}

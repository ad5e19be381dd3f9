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
    // xy: the stated metres between samples along x and y that the normal maps' slopes were
    // taken with (`Terrain::axis_spacing`); `world_normal` turns them into the lattice's metres.
    // z: 1 when `normal_model` models the grid's normals (`world_normal`), 0: read the lattice.
    normal_spacing: vec4<f32>,
    // The quadratic model of the grid's normal matrices (src/geo/normal_model.rs): three xyz
    // columns per term, the terms 1, fx, fx^2, fy, fy^2, fx fy of the grid fraction.
    normal_model: array<vec4<f32>, NORMAL_MODEL_VEC4S>,
}

@group(0) @binding(0) var<uniform> frame: Frame;
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
    // The normal model's matrix at the vertex, by columns (`modelled_matrix`), interpolated
    // across the triangle: the fragment stage's normal is one matrix product. Written where
    // the grid's normals are modelled (`terrain_vertex`), zero elsewhere and not read.
    @location(1) normal_x: vec3<f32>,
    @location(2) normal_y: vec3<f32>,
    @location(3) normal_z: vec3<f32>,
}

// A drawn vertex at clip position `clip` and grid position `grid_pos` (samples), with the
// normal model's matrix when the grid's normals are modelled (`normals_modelled`). The model
// is quadratic in the grid fraction, so interpolating it linearly across a triangle that spans
// a fraction `d` of the grid departs from it by at most `d^2 / 8` times its second derivative
// (docs/coordinates.md, "Normals on the earth").
fn terrain_vertex(clip: vec4<f32>, grid_pos: vec2<f32>) -> TerrainVertex {
    var out: TerrainVertex;
    out.clip = clip;
    out.grid_pos = grid_pos;
    if normals_modelled() {
        let m = modelled_matrix(grid_pos);
        out.normal_x = m[0];
        out.normal_y = m[1];
        out.normal_z = m[2];
    }
    return out;
}

// Height in metres at an integer sample of the single height texture, clamped to the data.
fn texture_height(s: vec2<i32>) -> f32 {
    let hi = vec2<i32>(frame.data_size.xy) - vec2<i32>(1);
    return textureLoad(height_tex, clamp(s, vec2<i32>(0), hi), 0).r;
}

// Height in metres at an integer sample, clamped to the data: through the clipmap when it is
// enabled (a uniform branch), else from the single height texture.
fn sample_height(s: vec2<i32>) -> f32 {
    let hi = vec2<i32>(frame.data_size.xy) - vec2<i32>(1);
    let c = clamp(s, vec2<i32>(0), hi);
    if clipmap.params.x != 0u {
        return clipmap_height(vec2<f32>(c));
    }
    return textureLoad(height_tex, c, 0).r;
}

// Bilinear height at a position in sample units; exact at integer positions (weights 1 and 0).
// Through the clipmap: one lookup, bilinear within the best resident node (clamped to the data).
fn height_at(grid_pos: vec2<f32>) -> f32 {
    if clipmap.params.x != 0u {
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
    let lstep = i32(frame.lattice.x);
    if lstep == 0 {
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
    let sw = lattice_point(c0, vec2<f32>(0.0));
    let se = lattice_point(vec2<i32>(c1.x, c0.y), vec2<f32>(0.0));
    let nw = lattice_point(vec2<i32>(c0.x, c1.y), vec2<f32>(0.0));
    let ne = lattice_point(c1, vec2<f32>(0.0));
    return corner_box(array<LatticePoint, 4>(sw, se, nw, ne), heights);
}

// `earth_box` from the lattice points of the rectangle's four corners.
fn corner_box(corners: array<LatticePoint, 4>, heights: vec2<f32>) -> Box3 {
    var lo = vec3<f32>(3.0e38);
    var hi = vec3<f32>(-3.0e38);
    for (var k = 0u; k < 4u; k++) {
        let low = corners[k].p + heights.x * corners[k].up;
        let high = corners[k].p + heights.y * corners[k].up;
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

// Clip position of a surface point given in sample units (integer cell + fraction) and metres.
fn project(cell: vec2<i32>, frac: vec2<f32>, height_m: f32) -> vec4<f32> {
    return frame.view_proj * vec4<f32>(relative_position(cell, frac, height_m), 1.0);
}

// The grid's local frame at a position: the unit up vector `u` and the metres per sample
// along columns and rows (`ax`, `ay`, not yet made tangent to `u`).
struct GridFrame {
    u: vec3<f32>,
    ax: vec3<f32>,
    ay: vec3<f32>,
}

// The grid's frame at `grid_pos` from the lattice (`Lattice::grid_frame` is its CPU twin):
// the bilinear up vector normalized, the bilinear lattice's derivatives along x and y (node
// differences, hi and lo parts subtracted separately, interpolated across the cell). Twelve
// lattice reads per fragment: used only where the quadratic model (`modelled_matrix`) is not close enough.
fn lattice_grid_frame(grid_pos: vec2<f32>) -> GridFrame {
    let lstep = i32(frame.lattice.x);
    let cell = vec2<i32>(floor(grid_pos));
    let node = clamp(cell / lstep, vec2<i32>(0), vec2<i32>(frame.lattice.yz) - vec2<i32>(2));
    let f = (grid_pos - vec2<f32>(node * lstep)) / f32(lstep);
    let i00 = 3 * (node.y * i32(frame.lattice.y) + node.x);
    let i10 = i00 + 3;
    let i01 = i00 + 3 * i32(frame.lattice.y);
    let i11 = i01 + 3;
    // Node differences along x (south and north edges) and y (west and east edges).
    let dx0 = (geo_lattice[i10].xyz - geo_lattice[i00].xyz) + (geo_lattice[i10 + 1].xyz - geo_lattice[i00 + 1].xyz);
    let dx1 = (geo_lattice[i11].xyz - geo_lattice[i01].xyz) + (geo_lattice[i11 + 1].xyz - geo_lattice[i01 + 1].xyz);
    let dy0 = (geo_lattice[i01].xyz - geo_lattice[i00].xyz) + (geo_lattice[i01 + 1].xyz - geo_lattice[i00 + 1].xyz);
    let dy1 = (geo_lattice[i11].xyz - geo_lattice[i10].xyz) + (geo_lattice[i11 + 1].xyz - geo_lattice[i10 + 1].xyz);
    var g: GridFrame;
    g.u = normalize(mix(
        mix(geo_lattice[i00 + 2].xyz, geo_lattice[i10 + 2].xyz, f.x),
        mix(geo_lattice[i01 + 2].xyz, geo_lattice[i11 + 2].xyz, f.x),
        f.y,
    ));
    g.ax = mix(dx0, dx1, f.y) / f32(lstep);
    g.ay = mix(dy0, dy1, f.x) / f32(lstep);
    return g;
}

// Whether the normals come from the quadratic model (`NORMAL_PATH` 1, or 3 with the uniforms
// saying so).
fn normals_modelled() -> bool {
    return NORMAL_PATH == 1u || (NORMAL_PATH == 3u && frame.lattice.x != 0u && frame.normal_spacing.z != 0.0);
}

// The quadratic model's normal matrix at `grid_pos` (`frame.normal_model`; `NormalModel::matrix`
// in src/geo/normal_model.rs is its CPU twin): it takes a normal in the grid's frame to world
// axes (not normalized). No memory reads beyond the uniforms and no frame to build. Taken where
// the model is within `NORMAL_MODEL_TOLERANCE` of the lattice's matrices at every node
// (`NormalModel::fit`).
fn modelled_matrix(grid_pos: vec2<f32>) -> mat3x3<f32> {
    let f = grid_pos / (vec2<f32>(frame.data_size.xy) - vec2<f32>(1.0));
    let along_x = model_term(1u) + model_term(2u) * f.x + model_term(5u) * f.y;
    let along_y = model_term(3u) + model_term(4u) * f.y;
    return model_term(0u) + along_x * f.x + along_y * f.y;
}

// Term `i` of the normal model, its matrix (called with constant `i`: constant uniform
// indices once inlined).
fn model_term(i: u32) -> mat3x3<f32> {
    let k = 3u * i;
    return mat3x3<f32>(frame.normal_model[k].xyz, frame.normal_model[k + 1u].xyz, frame.normal_model[k + 2u].xyz);
}

// The normal, in world axes, of the terrain at `grid_pos` (samples) whose normal in the grid's
// frame is `n`: the normal maps hold (-dh/dx, -dh/dy, 1) normalized, slopes per metre along
// the grid's x (columns) and y (rows) with the stated spacing `frame.normal_spacing.xy`.
// Flat world: the grid's frame is the world's, `n` as it is. On the earth (a uniform branch)
// the normal matrix (`normal_matrix` in src/geo/normal_model.rs) times `n`, normalized: its
// quadratic model over the grid, or built from the grid's frame read from the lattice: `tx`,
// `ty` the metres per sample along columns and rows made tangent to the up vector `u`. The
// surface's tangents are `tx + hx u` and `ty + hy u` with `hx = -n.x / n.z * sx` (height per
// sample), so its normal is their cross product times n.z:
// `n.x sx (ty x u) + n.y sy (u x tx) + n.z (tx x ty)`: the inverse-transpose (cofactor) of the
// grid-to-world map applied to `n`. On an orthogonal grid whose stated spacing is its metric
// one this is the rotation into the local frame (tx, ty, u); it also corrects the slopes where
// the stated spacing is not the local one (a geographic grid's east-west spacing holds at one
// latitude). docs/coordinates.md ("Normals on the earth") has the error budget.
//
// `NORMAL_PATH` (a constant build.rs prepends) picks the path at compile time: 0 the flat world,
// 1 the normal model, 2 the lattice (the drawing pipelines take the variant of their terrain:
// `NormalPath`), 3 whichever the uniforms say (probes and analysis passes).
fn world_normal(grid_pos: vec2<f32>, n: vec3<f32>) -> vec3<f32> {
    if NORMAL_PATH == 0u || (NORMAL_PATH == 3u && frame.lattice.x == 0u) {
        return n;
    }
    if normals_modelled() {
        return normalize(modelled_matrix(grid_pos) * n);
    }
    let g = lattice_grid_frame(grid_pos);
    let u = g.u;
    let tx = g.ax - dot(g.ax, u) * u;
    let ty = g.ay - dot(g.ay, u) * u;
    let s = frame.normal_spacing.xy;
    return normalize(n.x * s.x * cross(ty, u) + n.y * s.y * cross(u, tx) + n.z * cross(tx, ty));
}

// The unit world normal a drawn fragment shades with, of `n` from the normal map (in the
// grid's frame, any length: normalized once, here): as `world_normal`, but the normal model's
// matrix is interpolated from the vertices (`terrain_vertex`), not evaluated per fragment.
fn fragment_normal(v: TerrainVertex, n: vec3<f32>) -> vec3<f32> {
    if NORMAL_PATH == 0u {
        return normalize(n);
    }
    if NORMAL_PATH == 1u {
        return normalize(mat3x3<f32>(v.normal_x, v.normal_y, v.normal_z) * n);
    }
    // The lattice's normal is a linear map of `n`, normalized.
    return world_normal(v.grid_pos, n);
}

// Cheap shading shared by all methods: albedo times ambient + Lambert from the normal map
// (in world axes: `fragment_normal`), faded towards the sky with view depth (aerial
// perspective; the fragment position's w is 1 / clip w, and clip w is the view depth). Through
// the clipmap albedo and normal come from the atlas (`clipmap_surface`).
fn shade(v: TerrainVertex) -> vec4<f32> {
    let grid_pos = v.grid_pos;
    let gx = dpdx(grid_pos);
    let gy = dpdy(grid_pos);
    var n: vec3<f32>;
    var albedo: vec3<f32>;
    if clipmap.params.x != 0u {
        let s = clipmap_surface(grid_pos, gx, gy);
        n = s.normal;
        albedo = s.albedo;
    } else {
        let size = vec2<f32>(frame.data_size.xy);
        n = textureSampleGrad(normal_tex, linear_sampler, (grid_pos + 0.5) / size, gx / size, gy / size).xyz;
        albedo = textureSampleGrad(albedo_tex, linear_sampler, grid_pos / (size - 1.0), gx / (size - 1.0), gy / (size - 1.0)).rgb;
    }
    n = fragment_normal(v, n);
    let light = LIGHT_AMBIENT + LIGHT_DIFFUSE * max(dot(n, frame.sun_dir.xyz), 0.0);
    let haze = 1.0 - exp(-frame.haze.w / v.clip.w);
    return vec4<f32>(mix(albedo * light, frame.haze.rgb, haze), 1.0);
}
